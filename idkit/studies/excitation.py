"""The ``excitation`` task: optimise a robot's excitation so that it can be run on the robot.

``idkit +experiment=excitation robot=cylindrical`` calls :func:`run`, which calls
:func:`idkit.excitation.optimize.optimize_excitation` with the section ``excitation`` of the
config as arguments; the report (``idkit.reports.excitation``) writes the motion as a file that
``scenario.excitation=<file>`` loads back, and its samples at the controller rate (``rate``) as
``excitation.csv`` / ``excitation.npz``, checked by ``idkit.excitation.check`` (limits, effort,
rest at the ends, sample rate, self-collision) with the margins per joint.

By default the motion starts and ends at rest (``rest``: the Fourier series' boundary
constraints, period = ``t_end`` unless given). A URDF declares no acceleration limits: without
``acceleration_limit`` they are derived from its effort limits (``idkit.excitation.effort``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from idkit.data.presets import Scenario
from idkit.excitation.margins import DEFAULT_MARGIN
from idkit.progress import reporting
from idkit.seeds import Seed
from idkit.studies.build import Spec, build, describe
from idkit.studies.result import Provenance

TASK = "excitation"

#: Where the acceleration limits came from, as the report says it.
ACCELERATION_SOURCES = {
    "given": "given (excitation.acceleration_limit)",
    "robot": "the robot's",
    "effort": "derived from the effort limits (a URDF declares none; idkit.excitation.effort)",
}


@dataclass
class ExcitationStudy:
    """An optimised excitation (``result``) and the envelope of the run.

    Attributes:
        provenance: the common ``result.json`` envelope.
        result: ``idkit.excitation.optimize.ExcitationResult`` (the optimised member, the robot's
            default one, the criterion before and after, the limits and the dense check grid).
        robot_name: the robot's class name, for titles.
        baseline_name: registry name of the robot's default excitation (``paper``, ``fourier``).
        trajectory: ``idkit.excitation.export.Trajectory``, the samples at the controller rate
            (``None`` without a rate).
        check: ``idkit.excitation.check.TrajectoryCheck`` of ``trajectory`` (of the check grid's
            samples without a rate).
        acceleration_source: where the acceleration limits came from (``ACCELERATION_SOURCES``).
        rate: the controller rate in Hz, or ``None``.
    """

    provenance: Provenance
    result: Any
    robot_name: str
    baseline_name: str | None
    trajectory: Any
    check: Any
    acceleration_source: str
    rate: float | None

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
            "start": r.start,
            "after": r.after,
            "improved": r.improved,
            "margins": r.margins.as_dict(),
            "n_samples": int(r.t.numel()),
            "t_end": float(r.grid[-1]),
            "limits": r.limits.as_dict(),
            "acceleration_limits": ACCELERATION_SOURCES[self.acceleration_source],
            "effort_limits": None if r.effort is None else dict(zip(names, r.effort.tolist(), strict=True)),
            "excess_before": _by_joint(r.excess_before.tolist(), names),
            "excess_after": _by_joint(r.excess_after.tolist(), names),
            "rate": self.rate,
            "check": self.check.as_dict(),
            "details": r.details,
        }


def _by_joint(excess: list[list[float]], joints: Sequence[str]) -> dict[str, dict[str, float]]:
    from idkit.limits import MOTION_VARIABLES

    return {j: {v: excess[i][k] for i, v in enumerate(MOTION_VARIABLES)} for k, j in enumerate(joints)}


def rest_options(family: str, options: Mapping[str, Any] | None, t_end: float) -> dict[str, Any]:
    """``options`` with ``rest=True`` and, unless given, ``period = t_end``.

    Raises:
        ValueError: the family cannot start and end at rest, ``t_end`` or the period is not a finite
            number > 0, or ``t_end`` is not a whole number of periods (the motion would stop
            mid-period, not at rest).
    """
    import inspect

    from idkit.options import positive_number
    from idkit.registry import load

    accepted = inspect.signature(load("excitation", family)).parameters
    if "rest" not in accepted or "period" not in accepted:
        raise ValueError(
            f"excitation family {family!r} cannot start and end at rest (it has no rest option); "
            "set excitation.rest=false"
        )
    chosen = {**dict(options or {}), "rest": True}
    period = chosen.setdefault("period", t_end)
    for name, value in (("t_end", t_end), ("options.period", period)):
        if not positive_number(value):
            raise ValueError(f"excitation.{name} must be a finite number of seconds > 0, got {value!r}")
    periods = t_end / period
    if abs(periods - round(periods)) > 1e-9 * periods or round(periods) < 1:
        raise ValueError(
            f"excitation.rest needs t_end to be a whole number of periods, but t_end={t_end:g} s and "
            f"period={period:g} s; leave the period out (it is then t_end) or set t_end to a multiple of it"
        )
    return chosen


def run(
    robot: Spec = "cylindrical",
    *,
    family: str = "fourier",
    options: Mapping[str, Any] | None = None,
    criterion: str = "cond",
    noise: Mapping[str, Any] | None = None,
    n_samples: int | None = None,
    t_end: float = 10.0,
    rest: bool = True,
    rate: float | None = 1000.0,
    acceleration_limit: float | Sequence[float] | None = None,
    collision: bool = True,
    margin: float | Mapping[str, float] = DEFAULT_MARGIN,
    method: str = "pso+adam",
    swarms: int = 4,
    particles: int = 32,
    iterations: int = 100,
    adam_steps: int = 300,
    learning_rate: float = 0.01,
    grid_points: int = 1001,
    check_points: int | None = None,
    seed: Seed = 0,
    device: str = "cpu",
    dtype: str = "float64",
    progress: bool = False,
) -> ExcitationStudy:
    """Optimise an excitation for ``robot`` (see ``optimize_excitation`` for the search options).

    Args:
        robot: robot spec; its motion and effort limits are the hard constraints.
        family: registry name of the excitation family (``fourier``, ``paper``, a plugin).
        options: the family's structural options (e.g. ``{harmonics: 5, period: 10.0}``).
        criterion: ``cond`` (column-scaled condition number, minimised), ``logdet`` (maximised) or
            ``ls_error`` (expected LS parameter error under ``noise``, minimised).
        noise: ``ls_error``'s noise model: ``state``, ``torque`` levels and ``draws``
            (``idkit.excitation.criterion.NoiseModel``; its seed is ``seed``).
        n_samples: the sample times of the criterion, as a scenario samples them (``None``: a
            scenario's default, 10).
        t_end: length of the motion in seconds (the scenarios' ``t_end``).
        rest: start and end at rest (``qd = qdd = 0``; see :func:`rest_options`).
        rate: controller rate (Hz) of the exported samples ``excitation.csv``/``.npz``, which are
            also the grid the result is made feasible and checked on; ``None``: no export, checked
            on ``check_points``. ``t_end · rate`` must be a whole number.
        acceleration_limit: ``|q̈|`` bound, one number or one per joint (replaces the robot's own);
            ``None``: the robot's, else derived from its effort limits.
        collision: check self-collision (pinocchio + coal, where installed and the URDF has
            collision geometry) and shrink the motion until none is found.
        margin: the safety margin kept inside every limit (position, velocity, acceleration,
            effort), a share of its half-range; or one per quantity (``{effort: 0.1}``, the others
            5 %). The optimiser keeps it and the check enforces it (:mod:`idkit.excitation.margins`).
        check_points: the result's check grid (``None``: the controller samples, or 10001 points).
        dtype: only ``float64`` (limits are checked and coefficients written in double precision).
        progress: a line every few seconds while the search runs (stage, iteration, best loss:
            :mod:`idkit.progress`); the command sets it on a terminal.

    Raises:
        ValueError: bad options, or a joint without an acceleration limit on a robot without
            effort limits.
    """
    from idkit.excitation.check import check_trajectory
    from idkit.excitation.collision import NotChecked, SelfCollision, self_collision
    from idkit.excitation.criterion import NoiseModel
    from idkit.excitation.effort import acceleration_bounded_limits, nominal_torques
    from idkit.excitation.export import Trajectory, controller_times
    from idkit.excitation.optimize import optimize_excitation
    from idkit.excitation.spec import family_name

    if dtype != "float64":
        raise ValueError(
            f"the excitation task computes in float64 (limits, written coefficients), got dtype={dtype}"
        )
    robot_obj = build("robot", robot)
    limits, source = acceleration_bounded_limits(robot_obj, acceleration_limit)
    options = rest_options(family, options, t_end) if rest else dict(options or {})
    times = controller_times(t_end, rate, robot_obj.n_joints) if rate is not None else None
    if check_points is None:
        check_points = 10001 if times is None else times.numel()
    test = self_collision(robot_obj) if collision else NotChecked("switched off (excitation.collision=false)")
    n = Scenario().n_samples if n_samples is None else n_samples
    with reporting("excitation", progress):
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
            noise=NoiseModel(**dict(noise or {}), seed=seed),
            collision=test if isinstance(test, SelfCollision) else None,
            margin=margin,
        )
    samples = result.excitation(result.grid if times is None else times)
    trajectory = Trajectory.of(robot_obj.joint_names, result.grid if times is None else times, *samples)
    torques = None if result.effort is None else nominal_torques(robot_obj, *samples).numpy()
    effort = None if result.effort is None else result.effort.numpy()
    check = check_trajectory(trajectory, limits, torques, effort, test, margins=result.margins)
    provenance = Provenance(
        task=TASK,
        label=f"{family} excitation ({criterion})",
        seed=seed,
        data={"sample_times": {"n_samples": n, "t_end": t_end}},
        plugins={
            "robot": describe("robot", robot),
            "excitation": describe("excitation", {"_name_": family, **options}),
        },
        unit="optimisation",
    )
    return ExcitationStudy(
        provenance,
        result,
        type(robot_obj).__name__,
        family_name(result.baseline),
        trajectory if times is not None else None,
        check,
        source,
        rate,
    )
