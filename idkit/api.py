"""The library's one-line entries: ``idkit.identify`` (a robot's logs → a model),
``idkit.identify_simulator`` (a MuJoCo model and logs of commands and states → a simulator that moves
like the robot) and ``idkit.run`` (one fit of any kind → its result), each writing its report when
``out_dir`` is given.

The study (:mod:`idkit.studies.single`) computes and never imports a report; this layer, above
both, gives the result ``idkit.run`` returns the report's two shortcuts (:class:`Run`: ``table()``,
``save()``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

from idkit.studies.build import Spec
from idkit.studies.single import RunResult

if TYPE_CHECKING:
    from idkit.model import IdentifiedModel
    from idkit.sim.simulator_model import SimulatorModel


def identify(
    robot: Spec,
    data: Any,
    *,
    validate: Any = None,
    out_dir: str | Path | None = None,
    plots: bool = False,
    **options: Any,
) -> IdentifiedModel:
    """Identify ``robot`` from the recordings ``data``; the library's form of
    ``idkit robot=... data=... validate=...``.

    It runs the same study as that command (:func:`idkit.studies.single.run`) with the same defaults
    — the command's real-robot ones included (:mod:`idkit.studies.defaults`: a ``urdf``/``mjcf`` robot
    gets ``estimator=pcls``, no cost, friction and offsets, each unless given, said in one note) —
    where ``estimator``, ``cost``, ``preprocess`` ... are ``options``, and returns the model::

        import idkit
        m = idkit.identify({"_name_": "urdf", "urdf": "arm.urdf", "friction": True}, "train.csv",
                           validate=["test.csv"])
        tau = m.predict(q, qd, qdd)         # numpy or torch, any leading dimensions
        m.params["link2.m"], m.params.std["link2.m"]
        m.validation[0].scores.rel_all      # held-out score of test.csv
        m.save("identified.urdf")           # or .xml (MJCF)
        m.result.table()                    # the run: provenance, cost, the command's report

    Args:
        robot: a registry name, a config mapping or a ready robot object.
        data: the training recordings: a path (CSV, ``.npz``, ROS log), ``Samples``, or a list.
        validate: held-out recordings the model is scored on (``m.validation``).
        out_dir: also write the command's report (``result.json``, ``identified.urdf`` ...) here.
        plots: with ``out_dir``, also the PNG plots.
        options: the rest of :func:`idkit.studies.single.run`'s keywords (``estimator``, ``cost``,
            ``seed``, ``preprocess``, ``recording``, ``device``, ``dtype`` ...).

    Raises:
        ValueError: no robot, or no data (a fit of a simulation is :func:`idkit.run`'s, not this).
        TypeError: ``data`` or ``validate`` is not recordings (``3.5``).
    """
    from idkit.data.files import RECORDINGS, as_paths

    if robot is None:
        raise ValueError(
            'identify: robot is None; give a registry name ("urdf"), a config mapping '
            '({"_name_": "urdf", "urdf": "arm.urdf"}) or a robot object'
        )
    if data is None:
        raise ValueError(
            f"identify: no data (data=None); give the recordings to identify from: {RECORDINGS} "
            "(idkit.run(robot, scenario=...) fits a simulation instead)"
        )
    as_paths(data, "data")  # what is not recordings is refused before the robot is built
    as_paths(validate, "validate")
    robot, options = _real_robot_defaults(robot, data, options)
    result = run(robot, data=data, validate=validate, out_dir=out_dir, plots=plots, **options)
    return result.model


def identify_simulator(
    model: str | Path,
    data: Any,
    validate: Any = None,
    out_dir: str | Path | None = None,
    *,
    plots: bool = False,
    **options: Any,
) -> SimulatorModel:
    """Fit a MuJoCo model's simulator quantities to a robot's logs; the library's form of
    ``idkit +experiment=rollout rollout.model=... data=... validate=...`` (docs/rollout.md).

    It runs the same study (:func:`idkit.studies.rollout.run`, ``options`` its keywords: ``params``,
    ``bounds``, ``start``, ``segment``, ``estimator``, ``seed`` …) and returns the model::

        import idkit
        sim = idkit.identify_simulator("servo_arm.xml", "train.csv", validate=["held_out.csv"])
        sim.values["j1.damping"], sim.std["j1.damping"], sim.interval95["j1.damping"]
        run = sim.simulate("held_out.csv", horizon=0.5)   # MuJoCo, from the logged states
        sim.save("identified.xml"); sim.to_mujoco()       # the fitted model, for MuJoCo

    Args:
        model: the MJCF (``.xml``) or URDF file, or its text.
        data: the fit log(s): CSV, ``.npz``, ROS log (:mod:`idkit.data.commands`).
        validate: held-out logs (``model.held_out``).
        out_dir: also write the command's report here (``result.json``, ``report.html``,
            ``identified.xml`` …).
        plots: with ``out_dir``, also the PNG plots (and so the trajectories in ``report.html``).
    """
    from idkit.reports import files
    from idkit.reports import rollout as report
    from idkit.studies import rollout

    if out_dir is not None:  # a folder it cannot write into fails now, not after the fit
        files.writable_folder(out_dir, "out_dir")
    result = rollout.run(str(model), data, validate=validate, **options)
    if out_dir is not None:
        report.write(result, out_dir, plots=plots)
    return result.model


def _real_robot_defaults(robot: Spec, data: Any, options: Mapping[str, Any]) -> tuple[Spec, dict[str, Any]]:
    """``(robot, options)`` with the command's real-robot defaults (:mod:`idkit.studies.defaults`) for
    what is not given: ``robot``'s own keys and ``options``' names count as given, as typed overrides do
    on the command line. A ready robot object is kept as built (its friction and offset are given);
    the estimator and cost follow the same rule. Says what it chose in one ``RealRobotNote``."""
    import warnings

    from idkit.robots.urdf import URDFRobot
    from idkit.studies.build import plain
    from idkit.studies.defaults import RealRobotNote, applies, chosen, describe, searches_cost

    robot, options = plain(robot), dict(options)
    node: dict[str, Any] | None = None  # the robot's config node, which the defaults may extend
    estimator = plain(options.get("estimator"))
    if isinstance(robot, (str, Mapping)):
        if not applies("single", robot, data, estimator):
            return robot, options
        node = {"_name_": robot} if isinstance(robot, str) else dict(robot)
        given = {f"robot.{key}" for key in node}
    elif isinstance(robot, URDFRobot) and applies("single", "urdf", data, estimator):
        given = {"robot.friction", "robot.offset"}  # built already: kept as it is
    else:
        return robot, options
    picked = chosen(given | set(options), searches_cost(estimator))
    if not picked:
        return robot, options
    for key, value in picked.items():
        if node is not None and key.startswith("robot."):
            node[key.removeprefix("robot.")] = value
        else:
            options[key] = value
    warnings.warn(describe(picked), RealRobotNote, stacklevel=3)
    return (robot if node is None else node), options


@dataclass
class Run(RunResult):
    """A :class:`~idkit.studies.single.RunResult` with its report's shortcuts: what ``idkit.run`` returns."""

    @classmethod
    def of(cls, result: RunResult) -> Run:
        """``result`` with the shortcuts (the same fields, not copied)."""
        return cls(**{f.name: getattr(result, f.name) for f in fields(result)})

    def table(self) -> str:
        """The report's text table (``idkit.reports.single.text``)."""
        from idkit.reports import single

        return single.text(self)

    def save(self, out_dir: str | Path, make_plots: bool = True) -> dict[str, str]:
        """Write the report into ``out_dir`` (``idkit.reports.single.write``: ``result.json``,
        ``report.html``, plots …); returns the files."""
        from idkit.reports import single

        return single.write(self, out_dir, plots=make_plots)


def run(
    robot: Spec = "cylindrical",
    estimator: Spec = "pso",
    cost: Spec | None = "f13",
    scenario: Any = None,
    *,
    out_dir: str | Path | None = None,
    plots: bool = False,
    **options: Any,
) -> Run:
    """``idkit.studies.single.run(robot, estimator, cost, scenario, **options)``, then, if
    ``out_dir`` is given, ``idkit.reports.single.write`` into it (``plots``: also the PNG plots).

    Example: ``idkit.run(estimator="pso", cost="f13", scenario="outliers", seed=0).table()``.
    """
    from idkit.reports import files
    from idkit.studies import single

    if out_dir is not None:  # a folder it cannot write into fails now, not after the fit
        files.writable_folder(out_dir, "out_dir")
    result = Run.of(single.run(robot, estimator, cost, scenario, **options))
    if out_dir is not None:
        result.save(out_dir, make_plots=plots)
    return result
