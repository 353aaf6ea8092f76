"""Held-out validation on the horizon the model is for: segments from the logged state, or whole.

A model fitted on 0.5 s segments is a model of what the arm does in 0.5 s from a known state. Rolled
out open loop for a whole 40 s log, a torque-driven arm drifts away from any log, however good the
model (a small error in a velocity integrates without bound), and the error then says nothing about
it. So a held-out log is scored in one of two modes:

* ``"segments"``: rollouts of ``horizon`` seconds (the fit's ``segment``), each started from the logged
  state at its first sample — robustly: a glitched first sample is replaced by the local fit around it
  (:func:`idkit.sim.initial.robust_states`). This always applies.
* ``"whole"``: one rollout per stretch between gaps, from its first state. It only means something
  where the system is stable under a whole rollout: every logged joint held by a position servo, which
  pulls the rollout back to the reference as the real arm's servo does (a velocity servo alone lets the
  position drift). :func:`default_mode` picks it then, and says why either way.

Each joint's error is compared with what a *perfect* model would score on this log (``expected``): the
measurement noise, and, in segments, the noise of the start state carried forward by the model (a
velocity off by its noise moves a torque-driven joint by ``σ_qd · t``). It is measured, not assumed:
the same segments rolled out from starts moved by ``DRAWS`` draws (seeded) of the log's noise, fresh
noise added, the same robust statistic taken per draw; ``expected`` is its 90th percentile over the
draws, since the log's own start states are one such draw (with 4 segments of a torque-driven arm a
perfect model's error scattered by a factor up to ~3 over 20 logs). The verdict per joint is ``within
noise`` when the robust position error is at most ``WITHIN`` times ``expected``, else ``k× noise``. The
robust error (1.4826 × the median absolute error) is what the verdict reads: a held-out log's glitched
samples are the log's fault, not the model's; the RMS is reported beside it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np

from idkit.data.commands import RobotLog
from idkit.optim.robust import mad_scale
from idkit.sim.initial import robust_states
from idkit.sim.model import SimModel
from idkit.sim.problem import RolloutProblem, SimRobot, channel_scales
from idkit.sim.quantities import servo_kind
from idkit.sim.segments import split

Mode = Literal["segments", "whole"]
MODES: tuple[Mode, ...] = ("segments", "whole")
#: The fit's default horizon (s): ``segment`` of the rollout task.
SEGMENT = 0.5
#: A joint whose robust position error is at most this many times a perfect model's is within noise.
WITHIN = 2.0
#: Draws of the start states' noise that measure what a perfect model scores.
DRAWS = 16


@dataclass(frozen=True)
class HeldOut:
    """A held-out log scored in one mode at one set of values (module docstring).

    Attributes:
        file: where the log came from.
        mode: ``"segments"`` or ``"whole"``.
        horizon: seconds per segment (``None`` in ``"whole"``).
        values: which values were rolled out: ``"fitted"`` or ``"start"`` (the model before the fit).
        joints: the ``n`` joints.
        t: ``[k]`` the scored samples' times.
        measured, simulated: ``[k, 2n]`` positions then velocities.
        noise: ``[2n]`` the log's noise level per channel (:func:`idkit.sim.problem.noise_scale`).
        expected: ``[2n]`` the robust error a perfect model scores here at most, 9 times in 10
            (module docstring).
        segments: how many rollouts the prediction started.
        default: whether this mode is the one the verdict is read from.
        reason: why the default mode is the default.
    """

    file: str
    mode: Mode
    horizon: float | None
    values: str
    joints: tuple[str, ...]
    t: np.ndarray
    measured: np.ndarray
    simulated: np.ndarray
    noise: np.ndarray
    expected: np.ndarray
    segments: int
    default: bool = False
    reason: str = ""

    @property
    def rms(self) -> np.ndarray:
        """``[2n]`` RMS error per channel (every sample, glitches included)."""
        return np.sqrt(np.mean((self.measured - self.simulated) ** 2, axis=0))

    @property
    def robust(self) -> np.ndarray:
        """``[2n]`` 1.4826 × the median absolute error per channel (the RMS of Gaussian errors)."""
        return mad_scale(self.measured - self.simulated, axis=0)

    def _per_joint(self, values: np.ndarray) -> dict[str, float]:
        return {j: float(v) for j, v in zip(self.joints, values, strict=True)}

    @property
    def rms_q(self) -> dict[str, float]:
        return self._per_joint(self.rms[: len(self.joints)])

    @property
    def rms_qd(self) -> dict[str, float]:
        return self._per_joint(self.rms[len(self.joints) :])

    @property
    def noise_q(self) -> dict[str, float]:
        return self._per_joint(self.noise[: len(self.joints)])

    @property
    def noise_qd(self) -> dict[str, float]:
        return self._per_joint(self.noise[len(self.joints) :])

    @property
    def ratio(self) -> dict[str, float]:
        """Per joint: robust position error / a perfect model's (1 ≈ as good as the log allows)."""
        n = len(self.joints)
        return self._per_joint(self.robust[:n] / np.maximum(self.expected[:n], 1e-300))

    @property
    def verdicts(self) -> dict[str, str]:
        """Per joint ``within noise`` or ``k× noise``."""
        return {joint: verdict(r) for joint, r in self.ratio.items()}

    @property
    def verdict(self) -> str:
        """The worst joint's verdict, naming it."""
        worst = max(self.ratio, key=self.ratio.__getitem__)
        said = verdict(self.ratio[worst])
        return said if said == "within noise" else f"{said} (worst joint {worst})"

    def scores(self) -> dict[str, Any]:
        """``result.json``'s record of this score (the traces stay in the plots)."""
        n = len(self.joints)
        return {
            "mode": self.mode,
            "horizon": self.horizon,
            "values": self.values,
            "segments": self.segments,
            "default": self.default,
            "reason": self.reason,
            "rms_q": self.rms_q,
            "rms_qd": self.rms_qd,
            "robust_q": self._per_joint(self.robust[:n]),
            "robust_qd": self._per_joint(self.robust[n:]),
            "noise_q": self.noise_q,
            "noise_qd": self.noise_qd,
            "expected_q": self._per_joint(self.expected[:n]),
            "ratio": self.ratio,
            "verdicts": self.verdicts,
            "verdict": self.verdict,
        }


def verdict(ratio: float) -> str:
    """``within noise`` at most ``WITHIN``, else ``k× noise`` (two significant digits)."""
    if not np.isfinite(ratio):
        return "diverged"
    return "within noise" if ratio <= WITHIN else f"{ratio:.2g}× noise"


def _sim(model: SimModel | SimRobot | RolloutProblem) -> SimModel:
    if isinstance(model, RolloutProblem):
        return model.robot.sim
    return model.sim if isinstance(model, SimRobot) else model


def default_mode(model: SimModel | SimRobot | RolloutProblem, log: RobotLog) -> tuple[Mode, str]:
    """``("whole", why)`` when every logged joint of the model is held by a position servo, else
    ``("segments", why)`` (module docstring)."""
    sim = _sim(model)
    held: list[str] = []
    loose: list[str] = []
    for joint in log.joint_names:
        index = sim.joint_id(joint)
        kinds = {servo_kind(sim.model, a) for a in range(sim.model.nu) if sim.actuated_joint(a) == index}
        (held if "position" in kinds else loose).append(joint)
    if not loose:
        return "whole", (
            f"every joint ({', '.join(held)}) is held by a position servo: a whole rollout stays on the "
            "log, so the verdict is the whole log's"
        )
    return "segments", (
        f"{', '.join(loose)} {'is' if len(loose) == 1 else 'are'} not held by a position servo (torque "
        "or velocity driven): a whole open-loop rollout drifts whatever the model, so the verdict is "
        "on segments of the fit's horizon from the logged state"
    )


def score(
    model: RolloutProblem | SimRobot,
    values: np.ndarray | Mapping[str, float],
    log: RobotLog,
    mode: Mode = "segments",
    horizon: float | None = SEGMENT,
    *,
    file: str | None = None,
    label: str = "fitted",
    seed: int = 0,
    threads: int | None = None,
) -> HeldOut:
    """``log`` rolled out at ``values`` in ``mode`` (module docstring).

    Args:
        model: the fit's problem or robot (the model and its unknowns).
        values: ``[P]`` the unknowns' values (or ``{name: value}``).
        log: the held-out log (the robot's joints).
        mode: ``"segments"`` of ``horizon`` seconds, or ``"whole"`` stretches between gaps.
        horizon: the fit's segment length (``None``: ``SEGMENT``).
        file: the log's name in the record (default its source).
        label: which values these are (``"fitted"``, ``"start"``).
        seed: seeds the start-state noise draws.
        threads: rollout threads.

    Raises:
        ValueError: an unknown mode, a log of other joints, or values of the wrong length.
    """
    if mode not in MODES:
        raise ValueError(f"validation mode must be one of {', '.join(MODES)}, got {mode!r}")
    robot = model.robot if isinstance(model, RolloutProblem) else model
    vector = _vector(robot, values)
    horizon = SEGMENT if horizon is None else horizon
    segments = split(log.t, horizon if mode == "segments" else None)
    problem = RolloutProblem(robot, log, segment=horizon, threads=threads)
    noise = channel_scales(log)
    starts = np.array([s for s, _ in segments])
    q0, qd0 = robust_states(log.t, log.q, log.qd, starts, noise)
    simulator = problem.simulator(segments, initial=(q0, qd0), threads=threads)
    rng = np.random.default_rng(seed)
    n = log.n_joints
    moved = rng.standard_normal((DRAWS, len(segments), 2 * n)) * noise
    batch = np.repeat(vector[None], DRAWS + 1, axis=0)
    initial = (
        np.concatenate([q0[None], q0[None] + moved[..., :n]]),
        np.concatenate([qd0[None], qd0[None] + moved[..., n:]]),
    )
    try:
        q, qd = simulator.predict(batch, initial)
    finally:
        simulator.close()
    simulated = np.concatenate([q, qd], axis=2)  # [1 + DRAWS, k, 2n]
    perfect = simulated[1:] - simulated[:1] + rng.standard_normal(simulated[1:].shape) * noise
    rows = simulator.samples
    return HeldOut(
        file=log.source if file is None else file,
        mode=mode,
        horizon=horizon if mode == "segments" else None,
        values=label,
        joints=log.joint_names,
        t=log.t[rows],
        measured=np.hstack([log.q[rows], log.qd[rows]]),
        simulated=simulated[0],
        noise=noise,
        expected=np.quantile(mad_scale(perfect, axis=1), 0.9, axis=0),
        segments=len(segments),
    )


def held_out(
    robot: SimRobot,
    values: Mapping[str, np.ndarray],
    log: RobotLog,
    horizon: float | None = SEGMENT,
    *,
    file: str | None = None,
    seed: int = 0,
    threads: int | None = None,
) -> list[HeldOut]:
    """A held-out log scored in every mode that applies (segments always, whole where
    :func:`default_mode` says a whole rollout is stable) at each set of ``values`` (``{label: [P]}``,
    e.g. ``fitted`` and ``start``), the default mode's records marked ``default``."""
    mode, reason = default_mode(robot, log)
    modes: Sequence[Mode] = ("segments", "whole") if mode == "whole" else ("segments",)
    out = []
    for label, vector in values.items():
        for m in modes:
            record = score(robot, vector, log, m, horizon, file=file, label=label, seed=seed, threads=threads)
            out.append(replace(record, default=m == mode, reason=reason))
    return out


def _vector(robot: SimRobot, values: np.ndarray | Mapping[str, float]) -> np.ndarray:
    names = robot.unknowns.names
    if isinstance(values, Mapping):
        missing = [n for n in names if n not in values]
        if missing:
            raise ValueError(f"validation: no value for {', '.join(missing)}")
        return np.array([float(values[n]) for n in names])
    vector = np.asarray(values, dtype=np.float64).reshape(-1)
    if vector.size != len(names):
        raise ValueError(f"validation: {vector.size} values for {len(names)} unknowns ({', '.join(names)})")
    return vector
