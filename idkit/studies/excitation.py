"""The ``excitation`` task: optimise a robot's excitation within its motion limits.

``idkit +experiment=excitation robot=cylindrical`` calls :func:`run`, which calls
:func:`idkit.excitation.optimize.optimize_excitation` with the section ``excitation`` of the
config as arguments; the report (``idkit.reports.excitation``) writes the motion as a file that
``scenario.excitation=<file>`` loads back. A URDF declares no acceleration limits, so for
``robot=urdf`` the study needs ``excitation.acceleration_limit`` (an unbounded acceleration would
let the search pick arbitrarily violent motions).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from idkit.data.presets import Scenario
from idkit.seeds import Seed
from idkit.studies.build import Spec, build, describe
from idkit.studies.result import Provenance

TASK = "excitation"


@dataclass
class ExcitationStudy:
    """An optimised excitation (``result``) and the envelope of the run.

    Attributes:
        provenance: the common ``result.json`` envelope.
        result: ``idkit.excitation.optimize.ExcitationResult`` (the optimised member, the robot's
            default one, the criterion before and after, the limits and the dense check grid).
        robot_name: the robot's class name, for titles.
        baseline_name: registry name of the robot's default excitation (``paper``, ``fourier``).
    """

    provenance: Provenance
    result: Any
    robot_name: str
    baseline_name: str | None

    def payload(self) -> dict[str, Any]:
        """The ``result.json`` payload: family, coefficients, criterion before/after, limits."""
        r = self.result
        names = r.limits.joint_names
        return {
            "excitation": r.name,
            "options": r.excitation.options(),
            "baseline": self.baseline_name,
            "criterion": r.criterion,
            "before": r.before,
            "after": r.after,
            "n_samples": int(r.t.numel()),
            "t_end": float(r.grid[-1]),
            "limits": r.limits.as_dict(),
            "excess_before": _by_joint(r.excess_before.tolist(), names),
            "excess_after": _by_joint(r.excess_after.tolist(), names),
            "details": r.details,
        }


def _by_joint(excess: list[list[float]], joints: Sequence[str]) -> dict[str, dict[str, float]]:
    from idkit.limits import MOTION_VARIABLES

    return {j: {v: excess[i][k] for i, v in enumerate(MOTION_VARIABLES)} for k, j in enumerate(joints)}


def motion_limits(robot: Any, acceleration_limit: float | Sequence[float] | None) -> Any:
    """The robot's motion limits, with ``|q̈_j| <= acceleration_limit[_j]`` when given.

    Raises:
        ValueError: a bad ``acceleration_limit`` (not positive and finite, wrong length), or a
            joint left without an acceleration limit (a URDF declares none).
    """
    limits = robot.motion_limits()
    names = limits.joint_names
    if acceleration_limit is not None:
        values = (
            [acceleration_limit] if isinstance(acceleration_limit, (int, float)) else list(acceleration_limit)
        )
        bad = [
            v
            for v in values
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v < math.inf
        ]
        if bad or len(values) not in (1, len(names)):
            raise ValueError(
                f"excitation.acceleration_limit must be one positive number or one per joint "
                f"({len(names)}: {', '.join(names)}), got {acceleration_limit!r}"
            )
        bound = values * len(names) if len(values) == 1 else values
        limits = limits.replace("acceleration", [-v for v in bound], bound)
    unbounded = [
        names[j]
        for j in range(len(names))
        if math.isinf(limits.lower[2, j]) or math.isinf(limits.upper[2, j])
    ]
    if unbounded:
        raise ValueError(
            f"robot {type(robot).__name__} has no acceleration limit for joint(s) {', '.join(unbounded)} "
            "(a URDF declares none); give excitation.acceleration_limit=<one number, or a list with one "
            "per joint> in rad/s² (m/s² for a prismatic joint)"
        )
    return limits


def run(
    robot: Spec = "cylindrical",
    *,
    family: str = "fourier",
    options: Mapping[str, Any] | None = None,
    criterion: str = "cond",
    n_samples: int | None = None,
    t_end: float = 10.0,
    acceleration_limit: float | Sequence[float] | None = None,
    method: str = "pso+adam",
    swarms: int = 4,
    particles: int = 64,
    iterations: int = 200,
    adam_steps: int = 200,
    learning_rate: float = 0.01,
    grid_points: int = 1001,
    check_points: int = 10001,
    seed: Seed = 0,
    device: str = "cpu",
    dtype: str = "float64",
) -> ExcitationStudy:
    """Optimise an excitation for ``robot`` (see ``optimize_excitation`` for the search options).

    Args:
        robot: robot spec; its ``motion_limits()`` are the hard constraints.
        family: registry name of the excitation family (``fourier``, ``paper``, a plugin).
        options: the family's structural options (e.g. ``{harmonics: 5, period: 10.0}``).
        criterion: ``cond`` (column-scaled condition number, minimised) or ``logdet`` (maximised).
        n_samples: the sample times of the criterion, as a scenario samples them (``None``: a
            scenario's default, 10).
        t_end: length of the motion in seconds (the scenarios' ``t_end``).
        acceleration_limit: ``|q̈|`` bound, one number or one per joint; required when the robot
            declares none (a URDF), replaces the robot's own otherwise.
        dtype: only ``float64`` (limits are checked and coefficients written in double precision).

    Raises:
        ValueError: bad options, or a joint without an acceleration limit (see :func:`motion_limits`).
    """
    from idkit.excitation.optimize import optimize_excitation
    from idkit.excitation.spec import family_name

    if dtype != "float64":
        raise ValueError(
            f"the excitation task computes in float64 (limits, written coefficients), got dtype={dtype}"
        )
    robot_obj = build("robot", robot)
    limits = motion_limits(robot_obj, acceleration_limit)
    n = Scenario().n_samples if n_samples is None else n_samples
    result = optimize_excitation(
        robot_obj,
        family,
        options,
        criterion=criterion,
        n_samples=n,
        t_end=t_end,
        limits=limits,
        method=method,
        swarms=swarms,
        particles=particles,
        iterations=iterations,
        adam_steps=adam_steps,
        learning_rate=learning_rate,
        grid_points=grid_points,
        check_points=check_points,
        seed=seed,
        device=device,
    )
    provenance = Provenance(
        task=TASK,
        label=f"{family} excitation ({criterion})",
        seed=seed,
        data={"sample_times": {"n_samples": n, "t_end": t_end}},
        plugins={
            "robot": describe("robot", robot),
            "excitation": describe("excitation", {"_name_": family, **dict(options or {})}),
        },
        unit="optimisation",
    )
    return ExcitationStudy(provenance, result, type(robot_obj).__name__, family_name(result.baseline))
