"""What an arm's owner gets by default: the options a measured recording of a model robot calls for.

The config's defaults (``estimator=pso cost=f13``, no friction) are the paper's: its simulated
cylindrical robot has neither friction nor offsets, and PSO over a relative cost is what the paper
studies. On a real arm they are wrong — worse than predicting zero torque, with negative masses —
so when a ``urdf`` or ``mjcf`` robot is fitted to measured ``data=``, each option the user did not
set takes the value a robot owner needs (:data:`REAL_ROBOT`):

* ``estimator=pcls``: every link a body that can exist, pulled towards the model's inertials by a
  weight chosen from the data (the most accurate held-out fit idkit has on real arms, and one a
  simulator can load), and kept plausible — masses within [0.5, 2] × CAD, inside the link's real
  geometry — unless the same cross-validation says that costs accuracy beyond the noise (pcls's
  ``plausible=auto``, which says its decision with the figure both ways in its own note; a given
  ``total_mass`` or ``mass_ratio`` is enforced);
* ``robot.friction=true``, ``robot.offset=true``: Coulomb and viscous friction and a torque offset
  per joint — every drive has them, and without them the rigid-body parameters absorb them;
* ``robot.coulomb_velocity=auto``: the Coulomb term ``sign(q̇)`` or ``tanh(q̇ / v_c)``, whichever
  cross-validation on the training data prefers (:mod:`idkit.studies.coulomb`; its own note says
  the choice): a joint at rest is not predicted at ``±fc`` by the sign of its velocity noise;
* no ``cost``: pcls minimises its own criterion, and the paper's relative cost would only add a
  figure and a warning about floored near-zero torques.

An option the user gave is kept, and the command says in one ``note:`` line what it chose and how
to change it (:class:`RealRobotNote`). ``+experiment=paper`` and simulated scenarios are untouched.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Any

from idkit.notes import Note

#: Robots described by a model file (the ones a real arm's owner brings).
MODEL_ROBOTS = ("urdf", "mjcf")
#: The option (``group`` or ``group.key``) → its value for a measured recording of a model robot.
REAL_ROBOT: dict[str, Any] = {
    "estimator": "pcls",
    "cost": None,
    "robot.friction": True,
    "robot.offset": True,
    "robot.coulomb_velocity": "auto",
}


class RealRobotNote(Note):
    """The real-robot defaults were applied: which options, and how to change them."""


#: Estimators that hold the arm's model fixed (a payload on it): its friction and offsets are the
#: model file's, not new unknowns.
FIXED_ARM_ESTIMATORS = ("payload",)


def applies(task: str, robot: Any, data: Any, estimator: Any = None) -> bool:
    """Whether the real-robot defaults apply: one fit (``task=single``) of a model robot (``robot`` a
    registry name or a config node naming one) to measured ``data``, by an estimator that identifies
    the arm (not one of :data:`FIXED_ARM_ESTIMATORS`)."""
    name = robot.get("_name_") if isinstance(robot, Mapping) else robot
    method = estimator.get("_name_") if isinstance(estimator, Mapping) else estimator
    return (
        task == "single" and name in MODEL_ROBOTS and data is not None and method not in FIXED_ARM_ESTIMATORS
    )


def chosen(given: Collection[str], searches_cost: bool = False) -> dict[str, Any]:
    """The real-robot options the user left to idkit: ``REAL_ROBOT`` without those in ``given``
    (``"estimator"``, ``"robot.friction"``, ...). A given estimator is kept, and with it the config's
    cost when it searches one (``searches_cost``: PSO, Adam); an estimator with its own criterion
    (``ls``, ``pcls``, ``varpro``) gets none, unless a cost was given too."""
    out = {}
    for option, value in REAL_ROBOT.items():
        if option in given or (option == "estimator" and "estimator" in given):
            continue
        if option == "cost" and "estimator" in given and searches_cost:
            continue
        if option == "robot.coulomb_velocity" and "robot.friction" in given:  # part of the friction default
            continue
        out[option] = value
    return out


def searches_cost(estimator: Any) -> bool:
    """Whether ``estimator`` (a registry name, a config node naming one, or an object) searches a cost,
    and so needs ``cost=`` (PSO, Adam)."""
    from idkit import registry
    from idkit.interfaces import CostSearcher

    if isinstance(estimator, Mapping):
        estimator = estimator.get("_name_")
    if isinstance(estimator, str):
        return issubclass(registry.load("estimator", estimator), CostSearcher)
    return estimator is not None and isinstance(estimator, CostSearcher)


def describe(options: Mapping[str, Any]) -> str:
    """The note's text for the options applied: what they are, in words, and nothing the user set
    (``estimator=ls`` typed: not "a physically consistent fit")."""
    shown = " ".join(f"{key}={'null' if v is None else str(v).lower()}" for key, v in options.items())
    terms = " and ".join(
        name
        for key, name in (
            ("robot.friction", "friction"),
            ("robot.offset", "torque offsets"),
            ("robot.coulomb_velocity", "a Coulomb term smoothed at rest where cross-validation prefers it"),
        )
        if key in options
    )
    if "estimator" in options:
        what = (
            "a physically consistent fit"
            + (f" with {terms}" if terms else "")
            + ", its links kept plausible unless cross-validation says it costs accuracy"
        )
    elif terms:
        what = f"{terms} in the model"
    else:
        what = "no cost: the estimator minimises its own criterion"
    return (
        f"measured data on a model robot: {shown} ({what}); set any of them to change it, e.g. "
        "estimator=ls robot.friction=false"
    )
