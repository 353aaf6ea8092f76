"""A rollout identification problem: a model, its unknowns and a log, and the error between them.

The error is the paper's error matrix with other rows: ``E[..., 2n, k]``, the logged minus the
simulated joint positions (rows ``0..n-1``) and velocities (rows ``n..2n-1``) at the ``k`` samples the
segments predict, each row divided by its channel's *scale* — the measurement noise estimated from the
log itself (:func:`noise_scale`), floored at a millionth of the channel's spread — so that every
registered cost compares dimensionless numbers, and ``huber``'s ``delta=1.5`` means 1.5 noise levels.

:class:`RolloutProblem` is the rollout kind of :class:`idkit.problem.IdentificationProblem` (the torque
:class:`~idkit.problem.Problem` is the other): its ``robot`` is a :class:`SimRobot` (the model and the
unknowns) and its ``samples`` a :class:`~idkit.data.commands.RobotLog`. An estimator that fits it
declares ``problem_type = RolloutProblem``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from idkit.data.artefacts import Artefacts, find_artefacts
from idkit.data.commands import RobotLog
from idkit.problem import IdentificationError, IdentificationProblem, resolve_dtype
from idkit.seeds import check_seed
from idkit.sim.log_check import check_delay_bound, check_log
from idkit.sim.model import SimModel
from idkit.sim.quantities import Unknowns
from idkit.sim.segments import split
from idkit.sim.simulate import BatchSimulator

if TYPE_CHECKING:
    import torch
    from torch import Tensor

    from idkit.interfaces import Cost

#: A channel's scale is at least this fraction of its spread (a noiseless log has no noise to scale by).
SCALE_FLOOR = 1e-6
#: ``sqrt(70)``: the standard deviation of the 4th difference of unit white noise.
_D4 = float(np.sqrt(70.0))


def noise_scale(x: np.ndarray) -> np.ndarray:
    """Robust noise level ``[n]`` of signals ``x[N, n]`` sampled evenly: the MAD of their 4th
    differences over ``sqrt(70)`` (a smooth signal's 4th difference is nearly zero; a glitch moves
    five of them, which a median ignores)."""
    d4 = np.diff(x, n=4, axis=0)
    if d4.shape[0] < 1:
        return np.zeros(x.shape[1])
    mad = np.median(np.abs(d4 - np.median(d4, axis=0)), axis=0)
    return 1.4826 * mad / _D4


def channel_spread(log: RobotLog) -> np.ndarray:
    """``[2n]`` interquartile range of each position and velocity channel (its largest magnitude for a
    channel that does not move, 1 for one that is zero throughout)."""
    x = np.hstack([log.q, log.qd])
    spread = np.percentile(x, 75, axis=0) - np.percentile(x, 25, axis=0)
    spread = np.where(spread > 0, spread, np.abs(x).max(axis=0))
    return np.where(spread > 0, spread, 1.0)


def channel_scales(log: RobotLog) -> np.ndarray:
    """``[2n]`` scales of the position and velocity channels (module docstring)."""
    x = np.hstack([log.q, log.qd])
    return np.maximum(noise_scale(x), SCALE_FLOOR * channel_spread(log))


@dataclass(frozen=True)
class SimRobot:
    """The model as a rollout sees it, with the unknowns a fit sets: ``param_names`` are theirs.

    Attributes:
        sim: the model.
        unknowns: what is fitted, with starts and bounds.
        joint_names: the joints the log holds, in its order.
    """

    sim: SimModel
    unknowns: Unknowns
    joint_names: tuple[str, ...]
    base_param_names: tuple[str, ...] = ()

    @property
    def param_names(self) -> tuple[str, ...]:
        return self.unknowns.names

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @property
    def n_params(self) -> int:
        return len(self.unknowns)

    def bounds(self) -> tuple[Tensor, Tensor]:
        import torch

        return torch.from_numpy(self.unknowns.vector("lower")), torch.from_numpy(
            self.unknowns.vector("upper")
        )

    def nominal_params(self) -> Tensor:
        """The start values."""
        import torch

        return torch.from_numpy(self.unknowns.vector("start"))


@dataclass(frozen=True)
class RolloutProblem(IdentificationProblem):
    """Everything a rollout estimator needs (module docstring).

    Attributes:
        robot: the model and the unknowns.
        samples: the log.
        cost: a registered cost of ``E`` (``None``: the estimator's own criterion).
        seed: every random draw of the fit derives from it.
        segment: seconds per multiple-shooting segment (``None``: the whole log, split only at gaps).
        threads: rollout threads (``None``: every CPU the process may use).
        device, dtype: where torch costs are evaluated (rollouts are MuJoCo's, float64 on the CPU).
        leave_out_stalls: leave a driver's stalled rows out of the error (:mod:`idkit.data.artefacts`);
            ``False`` fits them as data (to measure what they do).
        start_fitted: the start is a fitted model's (a torque fit's run folder), not a guess: the
            estimator may polish it with a shorter schedule (``RolloutEstimator.polish_iterations``).
    """

    robot: SimRobot
    samples: RobotLog
    cost: Cost | None = None
    seed: int = 0
    segment: float | None = 0.5
    threads: int | None = None
    device: str = "cpu"
    dtype: Any = "float64"
    leave_out_stalls: bool = True
    start_fitted: bool = False
    _cache: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "seed", check_seed(self.seed))
        resolve_dtype(self.dtype)
        missing = [j for j in self.robot.joint_names if j not in self.samples.joint_names]
        if missing or len(self.robot.joint_names) != self.samples.n_joints:
            raise ValueError(
                f"samples have joints {', '.join(self.samples.joint_names)} but the robot expects "
                f"{', '.join(self.robot.joint_names)}"
            )
        split(self.samples.t, self.segment)  # refuse a bad segment length here, not in a fit
        log = self.samples
        check_log(self.robot.sim, log.t, log.q, log.qd, log.joint_names, log.source)
        check_delay_bound(self.robot.unknowns, log.t, log.source)

    @property
    def n_identifiable(self) -> int:
        return self.robot.n_params

    def check_identifiable(self) -> None:
        """``IdentificationError`` when the predicted samples give fewer equations than unknowns."""
        predicted = sum(stop - start - 1 for start, stop in self.segments())
        equations = 2 * self.samples.n_joints * predicted
        if equations < self.n_identifiable:
            raise IdentificationError(
                f"{self.samples.source}: {equations} equations (2 × {self.samples.n_joints} joints × "
                "predicted "
                f"samples) < {self.n_identifiable} unknowns; give a longer log"
            )

    def segments(self) -> list[tuple[int, int]]:
        """The log's segments, around its gaps and stalled rows (:meth:`artefacts`)."""
        return split(self.samples.t, self.segment, self.artefacts().stalled)

    def artefacts(self) -> Artefacts:
        """The driver's artefacts in the log (:mod:`idkit.data.artefacts`): stalled rows are left out of
        every segment, so of the error."""
        if "artefacts" not in self._cache:
            log = self.samples
            found = find_artefacts(log.t, log.q, log.qd, log.command_t, log.commands)
            if not self.leave_out_stalls:
                found = replace(found, stalled=np.zeros_like(found.stalled), stalls=0)
            self._cache["artefacts"] = found
        return self._cache["artefacts"]

    def outliers(self) -> dict[str, int]:
        """How many log samples the fit treats as a driver's artefacts, not data (by kind)."""
        return self.artefacts().counts()

    def scales(self) -> np.ndarray:
        """``[2n]`` channel scales (module docstring)."""
        if "scales" not in self._cache:
            self._cache["scales"] = channel_scales(self.samples)
        return self._cache["scales"]

    def spreads(self) -> np.ndarray:
        """``[2n]`` each channel's spread in its scale's units (:func:`channel_spread` / ``scales``)."""
        return channel_spread(self.samples) / self.scales()

    def simulator(self, segments: Sequence[tuple[int, int]] | None = None, **options: Any) -> BatchSimulator:
        """A simulator of this problem's log (its segments, or ``segments``) and unknowns; ``options``
        go to :class:`~idkit.sim.simulate.BatchSimulator` (``initial``, ``threads``)."""
        return BatchSimulator(
            self.robot.sim,
            self.samples,
            self.robot.unknowns,
            self.segments() if segments is None else list(segments),
            threads=options.pop("threads", self.threads),
            **options,
        )

    def measured(self, simulator: BatchSimulator) -> np.ndarray:
        """``[2n, k]`` the scaled measured channels at the samples ``simulator`` predicts."""
        rows = simulator.samples
        return (np.hstack([self.samples.q[rows], self.samples.qd[rows]]) / self.scales()).T

    def error(
        self,
        values: np.ndarray,
        simulator: BatchSimulator,
        initial: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> np.ndarray:
        """``E[B, 2n, k]``: scaled measured minus simulated channels for ``values[B, P]`` (segments
        started from ``initial``, ``([B, S, n], [B, S, n])``, or the simulator's); a non-finite
        prediction gives ``inf`` entries."""
        q, qd = simulator.predict(values, initial)
        predicted = np.concatenate([q, qd], axis=2) / self.scales()
        error = self.measured(simulator)[None] - predicted.transpose(0, 2, 1)
        return np.where(np.isfinite(error), error, np.inf)

    def evaluate(self, params: Tensor) -> Tensor:
        """The problem's cost ``[...]`` at values ``params[..., P]`` (rollouts of this problem's segments)."""
        import torch

        if self.cost is None:
            raise ValueError("this problem has no cost to evaluate (RolloutProblem.cost is None)")
        flat = params.detach().to(torch.float64).reshape(-1, params.shape[-1]).cpu().numpy()
        simulator = self.simulator()
        try:
            error = torch.from_numpy(self.error(flat, simulator))
        finally:
            simulator.close()
        measured = torch.from_numpy(self.measured(simulator))
        return self.cost(error, measured).reshape(params.shape[:-1])

    def generator(self) -> torch.Generator:
        """A fresh torch generator whose whole state comes from ``seed``."""
        from idkit.seeds import torch_generator

        return torch_generator(self.seed, "cpu")

    def head(self, n: int) -> RolloutProblem:
        """The same problem on the log's first ``n`` samples."""
        return replace(self, samples=self.samples.head(n), _cache={})
