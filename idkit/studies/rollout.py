"""Simulator parameters from robot logs (the ``rollout`` task): model + logs → fitted model.

``run``'s signature is the command line's config (``idkit +experiment=rollout rollout.model=arm.xml
data=run.csv 'rollout.params=[armature,damping,frictionloss,kp,kv,command_delay]'``). It reads the model
(:mod:`idkit.sim.model`) and the logs of commands and joint states (read, checked and joined by
:mod:`idkit.data.commands`, as torque logs are by :mod:`idkit.data.pipeline`),
chooses the unknowns (:mod:`idkit.sim.quantities`), hands the estimator a
:class:`~idkit.sim.problem.RolloutProblem`, and replays the fitted model on every log: the fit log in
its segments from the fitted initial states; each ``validate=`` log is scored by
:mod:`idkit.sim.validation` on the horizon the model is for (segments of ``segment`` seconds from the
logged state; also whole where position servos make a whole rollout stable), at the fitted values and
at the start values (the model before this fit) side by side, the default mode's verdict marked.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np

from idkit.estimate import Estimate
from idkit.optim.robust import mad_scale
from idkit.progress import reporting
from idkit.seeds import Seed
from idkit.studies.build import Spec, build, describe
from idkit.studies.result import Provenance

if TYPE_CHECKING:
    from idkit.sim.details import RolloutDetails
    from idkit.sim.simulator_model import SimulatorModel
    from idkit.sim.validation import HeldOut

#: What ``rollout.params`` fits when not told: the joints' passive terms.
DEFAULT_PARAMS = ("armature", "damping", "frictionloss")


@dataclass(frozen=True)
class Replay:
    """A log and the fitted model's prediction of it.

    Attributes:
        file: where the log came from.
        t: ``[k]`` the predicted samples' times.
        measured, simulated: ``[k, 2n]`` positions then velocities.
        joints: the ``n`` joints.
        noise: ``[2n]`` the log's noise level per channel (from its own samples).
        segments: how many rollouts the prediction restarted (1: the whole log).
    """

    file: str
    t: np.ndarray
    measured: np.ndarray
    simulated: np.ndarray
    joints: tuple[str, ...]
    noise: np.ndarray
    segments: int

    @property
    def rms(self) -> np.ndarray:
        """``[2n]`` RMS error per channel (glitched samples included)."""
        return np.sqrt(np.mean((self.measured - self.simulated) ** 2, axis=0))

    @property
    def robust(self) -> np.ndarray:
        """``[2n]`` robust error per channel: 1.4826 × the median absolute error (the RMS of Gaussian
        errors, whatever a few glitched samples do)."""
        return mad_scale(self.measured - self.simulated, axis=0)

    def scores(self) -> dict[str, Any]:
        n = len(self.joints)

        def per_joint(values: np.ndarray) -> dict[str, dict[str, float]]:
            return {
                "q": dict(zip(self.joints, values[:n].tolist(), strict=True)),
                "qd": dict(zip(self.joints, values[n:].tolist(), strict=True)),
            }

        return {
            "segments": self.segments,
            "rms": per_joint(self.rms),
            "robust": per_joint(self.robust),
            "noise": per_joint(self.noise),
        }


@dataclass
class RolloutResult:
    """A rollout identification and what it reproduces.

    Attributes:
        estimate: the estimator's result (values; uncertainty and flat directions in ``details``).
        unknowns: per unknown its kind, start and bounds.
        provenance: the envelope (task, seed, data, plugins, config, run id).
        mjcf: the ``identified.xml`` text (``None`` if MuJoCo refused it: ``mjcf_problem`` says why).
        fit: the fit log replayed in its segments.
        validation: each ``validate=`` log's scores (:class:`idkit.sim.validation.HeldOut`): every
            mode that applies, at the fitted and at the start values.
        robot: the model and the unknowns fitted (``model`` puts the estimate back on it).
    """

    estimate: Estimate
    unknowns: dict[str, dict[str, Any]]
    provenance: Provenance
    mjcf: str | None
    fit: Replay
    validation: list[HeldOut] = field(default_factory=list)
    mjcf_problem: str | None = None
    robot: Any = field(default=None, repr=False)

    @property
    def seed(self) -> int:
        return self.provenance.seed

    @property
    def details(self) -> RolloutDetails | None:
        """The estimator's typed record (``None``: an estimator of another make kept a plain dict)."""
        from idkit.sim.details import RolloutDetails

        details = self.estimate.details
        return details if isinstance(details, RolloutDetails) else None

    @property
    def model(self) -> SimulatorModel:
        """The identified simulator (``simulate``, values with σ, ``save``, ``to_mujoco``)."""
        from idkit.sim.simulator_model import SimulatorModel

        return SimulatorModel.from_result(self)

    def payload(self) -> dict[str, Any]:
        """The task's part of ``result.json``."""
        return {
            "estimate": self.estimate.to_dict(),
            "unknowns": self.unknowns,
            "fit": {self.fit.file: self.fit.scores()},
            "validation": {
                file: [r.scores() for r in self.validation if r.file == file]
                for file in dict.fromkeys(r.file for r in self.validation)
            },
            "identified_xml": None if self.mjcf is None else "identified.xml",
            "identified_xml_problem": self.mjcf_problem,
        }


def _joints(sim: Any, log: Any, joints: Sequence[str] | None) -> tuple[str, ...]:
    """The joints fitted: ``joints``, else every hinge or slide joint of the model the log holds."""
    if joints is not None:
        return tuple(joints)
    found = tuple(j for j in sim.joint_names() if j in log.joint_names)
    if not found:
        raise ValueError(
            f"{log.source}: none of the model's joints ({', '.join(sim.joint_names())}) is in the log "
            f"({', '.join(log.joint_names)})"
        )
    return found


def _note_artefacts(problem: Any) -> None:
    """Say in one ``note:`` line what the fit leaves out of the log as a driver's artefacts."""
    from idkit.notes import Note

    counts = problem.outliers()
    parts = []
    if counts["stalled"]:
        parts.append(
            f"{counts['stalled']} stalled rows ({counts['stalls']} stretches repeating the last row)"
        )
    if counts["dropped"]:
        parts.append(f"{counts['dropped']} samples missing in gaps")
    if parts:
        warnings.warn(
            f"{problem.samples.source}: {' and '.join(parts)} left out of the fit as the driver's, not "
            "the robot's",
            Note,
            stacklevel=3,
        )


def replay(problem: Any, values: np.ndarray, file: str, initial: Any = None, whole: bool = False) -> Replay:
    """The fitted model's prediction of ``problem``'s log: in its segments from ``initial`` (default
    the logged states) or, ``whole``, in one rollout per stretch between gaps."""
    from idkit.sim.problem import noise_scale
    from idkit.sim.segments import split

    log = problem.samples
    segments = split(log.t, None, problem.artefacts().stalled) if whole else problem.segments()
    simulator = problem.simulator(segments, initial=initial)
    try:
        q, qd = simulator.predict(values[None])
    finally:
        simulator.close()
    rows = simulator.samples
    measured = np.hstack([log.q[rows], log.qd[rows]])
    simulated = np.hstack([q[0], qd[0]])
    noise = noise_scale(np.hstack([log.q, log.qd]))
    return Replay(file, log.t[rows], measured, simulated, log.joint_names, noise, len(segments))


def run(
    model: str,
    data: Any,
    estimator: Spec = "rollout",
    cost: Spec | None = None,
    *,
    params: Sequence[str] = DEFAULT_PARAMS,
    joints: Sequence[str] | None = None,
    shared: Sequence[str] = (),
    bounds: Mapping[str, Sequence[float]] | None = None,
    start: Mapping[str, float] | None = None,
    box: Sequence[float] = (0.1, 10.0),
    segment: float | None = 0.5,
    validate: Any = None,
    state_topic: str | None = None,
    command_topic: str | None = None,
    threads: int | None = None,
    seed: Seed = 0,
    device: str = "cpu",
    dtype: str = "float64",
    progress: bool = True,
) -> RolloutResult:
    """Identify a MuJoCo model's quantities from logged commands and joint states.

    Args:
        model: the MJCF (``.xml``) or URDF (``.urdf``) file, or its text; or a torque fit's run folder
            (:mod:`idkit.sim.from_run`: its model, with the logs' efforts as motor commands).
        data: the fit log (CSV, ``.npz``, ROS log) or a list of logs of one robot (joined).
        estimator: ``"rollout"`` (a registry name, a config mapping or an object) with its options.
        cost: the search's score, a registered cost of the scaled error ``E`` (``None``: the
            estimator's robust default).
        params: the unknowns: kinds (``armature``, ``damping``, ``frictionloss``, ``stiffness``,
            ``kp``, ``kv``, ``gear``, ``bias``, ``inertia``, ``command_delay``) and/or names (``j1.damping``,
            ``link3.inertia``).
        joints: the joints in scope (default: the model's that the log holds).
        shared: kinds fitted as one value for all their elements.
        bounds: ``{name or kind: [lower, upper]}`` (default ``box`` × the start; ``command_delay``:
            [0, 0.05] s).
        start: ``{name or kind: value}`` (default the model's values; ``command_delay``: 0).
        box: ``(a, b)``: the bounds of an unknown without given bounds, as factors of its start.
        segment: seconds per multiple-shooting segment (``None``: whole stretches between gaps).
        validate: held-out logs, each scored by :func:`idkit.sim.validation.held_out`.
        state_topic, command_topic: a ROS log's ``JointState`` topics (:mod:`idkit.data.commands`).
        threads: rollout threads (``None``: every CPU the process may use).
        seed: seeds the search.
        device, dtype: where a registered cost is evaluated.
        progress: print a line every few seconds during the search and the polish (stage, iteration,
            best cost, rollouts, elapsed: :mod:`idkit.progress`); the command sets it on a terminal.
    """
    from idkit.data.commands import read_robot_logs
    from idkit.data.files import as_paths, refuse_repeated_files, refuse_training_files
    from idkit.sim.export import identified_xml
    from idkit.sim.from_run import is_run_folder, read_torque_run
    from idkit.sim.model import load_model
    from idkit.sim.passive_bounds import derived_bounds
    from idkit.sim.problem import RolloutProblem, SimRobot
    from idkit.sim.quantities import select_unknowns
    from idkit.sim.validation import held_out as score_held_out

    torque_run = read_torque_run(model, partial(build, "robot")) if is_run_folder(model) else None
    sim = load_model(model) if torque_run is None else torque_run.model()
    reader = None if torque_run is None else torque_run.reader(sim)
    log = read_robot_logs(data, None, state_topic, command_topic, reader)
    scope = _joints(sim, log, joints)
    log_joints = tuple(j for j in log.joint_names if j in {*sim.joint_names()})
    if log_joints != log.joint_names:
        log = read_robot_logs(data, log_joints, state_topic, command_topic, reader)
    if torque_run is not None:
        bounds = derived_bounds(sim, log, scope, params, bounds)
    unlogged = [j for j in sim.joint_names() if j not in log_joints]
    if unlogged:
        warnings.warn(
            f"{log.source}: the model's joint(s) {', '.join(unlogged)} are not in the log: every segment "
            "starts them at the model's qpos0, at rest",
            stacklevel=2,
        )
    unknowns = select_unknowns(sim, scope, params, shared, bounds, start, box)
    robot = SimRobot(sim, unknowns, log.joint_names)
    problem = RolloutProblem(
        robot,
        log,
        build("cost", cost),
        seed=seed,
        segment=segment,
        threads=threads,
        device=device,
        dtype=dtype,
        start_fitted=torque_run is not None,
    )
    _note_artefacts(problem)
    fitter = build("estimator", estimator)
    with reporting("rollout", progress):
        estimate = fitter.fit(problem)
    values = np.array([estimate.params[name] for name in unknowns.names])
    from idkit.sim.details import RolloutDetails

    details = estimate.details
    fitted = details.initial_states if isinstance(details, RolloutDetails) else None
    initial = None if fitted is None else (fitted.q, fitted.qd)
    fit = replay(problem, values, log.source, initial)
    held_out = []
    refuse_repeated_files(validate, "validate")
    refuse_training_files(data, validate)
    for path in as_paths(validate):
        other = read_robot_logs(path, log.joint_names, state_topic, command_topic, reader)
        compared = {"fitted": values, "start": unknowns.vector("start")}
        held_out += score_held_out(
            robot, compared, other, segment, file=str(path), seed=problem.seed, threads=threads
        )
    try:
        text, problem_text = identified_xml(sim, unknowns, values), None
    except ValueError as error:
        text, problem_text = None, str(error)
    provenance = Provenance(
        task="rollout",
        label=estimate.estimator,
        seed=seed,
        data={
            "model": sim.label,
            "files": [str(p) for p in as_paths(data)],
        },
        plugins={"estimator": describe("estimator", estimator), "cost": describe("cost", cost)},
    )
    described = {
        u.name: {"kind": u.kind, "start": u.start, "bounds": [u.lower, u.upper]} for u in unknowns.items
    }
    return RolloutResult(estimate, described, provenance, text, fit, held_out, problem_text, robot)
