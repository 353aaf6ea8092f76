"""``rollout``: simulator parameters from what the robot did — a swarm over rollouts, then a robust polish.

The problem (:class:`idkit.sim.problem.RolloutProblem`) holds a MuJoCo model, the unknowns (armature,
damping, friction loss, servo gains, delay, … with bounds and a start) and a log of commands and
measured joint positions and velocities. The fit, in three steps:

1. **Search.** A cooperative particle swarm (:mod:`idkit.optim.blocks` on :mod:`idkit.optim.swarm`):
   one swarm per joint over that joint's unknowns (and one over the shared ones: ``delay``, inertias),
   scored on that joint's part of the error, every particle a full candidate rolled out with all the
   others at once (:mod:`idkit.sim.simulate`). It simulates a share (``search_share``) of the log's
   segments, each started from its logged state unless that is a glitch (:mod:`idkit.sim.initial`).
   The score is the problem's cost (any registered cost of the scaled error ``E``), or by default the
   sum over channels of the log of a trimmed RMS error: scale-free and blind to a few glitched samples.
2. **Polish.** Levenberg–Marquardt (:mod:`idkit.optim.levenberg`, bounded) from the search's best,
   coarse to fine: least squares on the search's segments (fast from far; exact on a noiseless log,
   which ends the fit), then a robust loss (``loss``, default Huber) with every segment's initial state
   free as well (:mod:`idkit.sim.shooting`: a segment's noisy first sample no longer biases the fit),
   on the search's segments and then on all. The loss's scale is each channel's median absolute
   residual (:mod:`idkit.optim.robust`), re-estimated until it settles; none is set by hand.
3. **Uncertainty.** Standard deviations, 95 % intervals and flat directions from the polish's Jacobian,
   widened from the spread over stretches of the log when the residual says the model, not the noise,
   limits the fit (:mod:`idkit.sim.uncertainty`), in ``Estimate.details``.

``Estimate.cost`` is the search's score at the result on the problem's own error (segments from the
logged states); ``details`` is a :class:`~idkit.sim.details.RolloutDetails`: the polish's solves, the
uncertainty, the fitted initial states, the rollouts run.
"""

from __future__ import annotations

import time
from typing import Any, ClassVar

import numpy as np

from idkit import progress
from idkit.estimate import Estimate
from idkit.interfaces import Estimator
from idkit.optim.blocks import SearchResult, cooperative_search
from idkit.optim.levenberg import least_squares
from idkit.optim.robust import LOSSES, TUNING, Loss, channel_log_scales, mad_scale
from idkit.runtime import torch_threads
from idkit.sim.details import PolishSolve, RolloutDetails, SearchSummary, States
from idkit.sim.initial import robust_states
from idkit.sim.log_check import warn_unsupported
from idkit.sim.problem import RolloutProblem
from idkit.sim.shooting import Shooting
from idkit.sim.uncertainty import heavier_links_change, uncertainty

#: Where the registry's conformance suite finds a small rollout problem for this estimator.
CONFORMANCE_PROBLEM = "idkit.testing.rollout_cases:conformance_problem"
#: A robust scale re-estimated within ``exp(±SETTLED)`` of the last is settled (Huber's estimate hardly
#: moves with its scale; a re-solve costs Jacobians).
SETTLED = 0.3
#: Solves at most in a robust stage of the polish (the scale re-estimated before each).
ROUNDS = 3
#: Relative loss reduction below which a solve stops: the last (about a tenth of a standard deviation
#: of the best-determined unknown), and the others.
TIGHT, LOOSE = 1e-6, 1e-4
#: Residuals below this many channel scales (the noise, or a millionth of the spread) fit exactly: a
#: noiseless log, for which a robust scale and free initial states have nothing left to do.
EXACT = 0.1
#: The search's trim of the default score (a fraction of each channel's samples).
TRIM = 0.1
#: Levenberg–Marquardt iterations at most per solve of the polish, from a guessed start and from a
#: fitted model's (a torque run, whose rigid body and friction are already fitted: what is left is
#: model error, which more iterations fit no better; measured on a real arm, docs/rollout.md: 5 per
#: solve and one solve per stage give the held-out figures of 50 and 3 at a sixth of the rollouts).
POLISH_ITERATIONS, FITTED_POLISH_ITERATIONS = 50, 5
#: Solves at most per robust stage from a fitted model's start (the scale estimated once per stage).
FITTED_ROUNDS = 1


class RolloutEstimator(Estimator[RolloutProblem]):
    """Identify simulator parameters by rolling a MuJoCo model out under the logged commands.

    Args:
        particles: particles per swarm (one swarm per joint, one for the shared unknowns); ``None``:
            ``4 + 2w`` for swarms of at most ``w`` unknowns (at most 32).
        iterations: evaluations per particle (0: no search, the polish starts at the problem's start);
            ``None``: ``10 + 2w`` (at most 40), half that from a fitted start (``problem.start_fitted``).
        cooperative: one swarm per joint (``True``) or one swarm over every unknown.
        search_share: the share of the log's segments the search simulates (evenly spread).
        loss: the polish's loss: ``huber``, ``cauchy`` (its pull vanishes for large errors) or
            ``linear`` (least squares); its scale is the robust one, never set by hand.
        polish_iterations: Levenberg–Marquardt iterations at most per scale re-estimate; ``None``:
            :data:`POLISH_ITERATIONS`, or :data:`FITTED_POLISH_ITERATIONS` when the start is a fitted
            model (``problem.start_fitted``: a torque fit's run folder).
        free_initial: fit every segment's initial state in the polish's robust stages.
        threads: rollout threads (``None``: the problem's).
        jacobian_every: polish iterations at most per finite-difference Jacobian (each costs a
            rollout per unknown and segment); between two, the last one follows the steps taken
            (:meth:`idkit.optim.levenberg.BlockJacobian.broyden`). 1: a new one every iteration.
    """

    #: The kind of problem it fits: the command line runs it in the task that builds one
    #: (``idkit +experiment=rollout``) and refuses it in the others.
    problem_type: ClassVar[type[RolloutProblem]] = RolloutProblem
    conformance_problem: ClassVar[str] = CONFORMANCE_PROBLEM
    conformance_options: ClassVar[dict[str, Any]] = {"particles": 4, "iterations": 3, "polish_iterations": 5}

    def __init__(
        self,
        particles: int | None = None,
        iterations: int | None = None,
        cooperative: bool = True,
        search_share: float = 0.35,
        loss: Loss = "huber",
        polish_iterations: int | None = None,
        free_initial: bool = True,
        threads: int | None = None,
        jacobian_every: int = 3,
    ) -> None:
        self.particles = particles
        self.iterations = iterations
        self.cooperative = cooperative
        self.search_share = search_share
        self.loss = loss
        self.polish_iterations = polish_iterations
        self.free_initial = free_initial
        self.threads = threads
        self.jacobian_every = jacobian_every
        self.resolve()

    def resolve(self) -> None:
        """Check the options as they are now (at construction and at every fit: ``idkit.hyperparameters``)."""
        particles, iterations = self.particles, self.iterations
        if (particles is not None and particles < 1) or (iterations is not None and iterations < 0):
            raise ValueError(
                f"rollout: particles >= 1 and iterations >= 0 (or null), got {particles}, {iterations}"
            )
        if self.polish_iterations is not None and self.polish_iterations < 0:
            raise ValueError(f"rollout: polish_iterations must be >= 0, got {self.polish_iterations}")
        if not 0 < self.search_share <= 1:
            raise ValueError(f"rollout: search_share must be in (0, 1], got {self.search_share}")
        if self.loss not in LOSSES:
            raise ValueError(f"rollout: loss must be one of {', '.join(LOSSES)}, got {self.loss!r}")
        if self.jacobian_every < 1:
            raise ValueError(f"rollout: jacobian_every must be >= 1, got {self.jacobian_every}")
        if self.threads is not None and self.threads < 1:
            raise ValueError(f"rollout: threads must be >= 1 or null, got {self.threads}")

    def fit(self, problem: RolloutProblem) -> Estimate:
        with torch_threads(1):  # the swarm's and the costs' tensors are small (idkit.runtime)
            return self._fit(problem)

    def _fit(self, problem: RolloutProblem) -> Estimate:
        if not isinstance(problem, RolloutProblem):  # a caller without a type checker
            raise ValueError(
                "estimator rollout identifies a simulator from logged commands and joint states, not from "
                "torques: run it as `idkit +experiment=rollout rollout.model=<MJCF or URDF> data=<log>` "
                "(or hand it an idkit.sim.problem.RolloutProblem)"
            )
        self.resolve()
        problem.check_identifiable()
        started = time.perf_counter()
        search_sim = full_sim = None
        try:
            full_sim, search_sim, initial = _simulators(problem, self.search_share, self.threads)
            progress.count_rollouts(
                lambda: sum(
                    s.counter.rollouts for s in {id(search_sim): search_sim, id(full_sim): full_sim}.values()
                )
            )
            unknowns = problem.robot.unknowns
            start = unknowns.to_coordinates(unknowns.vector("start"))
            found = _search(problem, search_sim, self, start) if self.iterations != 0 else None
            z = found.x if found is not None else start
            polished = _polish(problem, (search_sim, full_sim), z, self, _polish_iterations(problem, self))
        finally:
            for simulator in {id(s): s for s in (search_sim, full_sim) if s is not None}.values():
                simulator.close()
        values = unknowns.from_coordinates(polished["z"])
        cost = _score(problem, values)
        simulators = {id(s): s for s in (search_sim, full_sim)}.values()
        rollouts = sum(s.counter.rollouts for s in simulators)
        steps = sum(s.counter.steps for s in simulators)
        details = RolloutDetails(
            loss=self.loss,
            criterion="problem cost" if problem.cost is not None else f"sum of log trimmed RMS ({TRIM:g})",
            search=None
            if found is None
            else SearchSummary(found.cost, found.evaluations, unknowns.from_coordinates(found.x)),
            history=[] if found is None else list(found.history),
            polish=tuple(polished["record"]),
            uncertainty=polished["uncertainty"],
            exact_fit=polished["exact"],
            segments=tuple((int(a), int(b)) for a, b in full_sim.segments),
            initial_states=polished["initial"],
            search_initial_states=States(initial[0], initial[1]),
            bodies=unknowns.bodies(problem.robot.sim, values),
            rollouts=rollouts,
            simulated_seconds=steps * problem.robot.sim.timestep,
            outliers=problem.outliers(),
        )
        warn_unsupported(unknowns, values, details.uncertainty.std)
        return Estimate(
            "rollout",
            dict(zip(unknowns.names, (float(v) for v in values), strict=True)),
            cost,
            time.perf_counter() - started,
            details=details,
        )

    def __repr__(self) -> str:
        return (
            f"RolloutEstimator(particles={self.particles}, iterations={self.iterations}, "
            f"cooperative={self.cooperative}, search_share={self.search_share}, loss={self.loss!r}, "
            f"polish_iterations={self.polish_iterations}, free_initial={self.free_initial}, "
            f"threads={self.threads}, jacobian_every={self.jacobian_every})"
        )


def _polish_iterations(problem: RolloutProblem, options: RolloutEstimator) -> int:
    """Iterations at most per polish solve: the option, else by where the start comes from."""
    if options.polish_iterations is not None:
        return options.polish_iterations
    return FITTED_POLISH_ITERATIONS if problem.start_fitted else POLISH_ITERATIONS


def _simulators(problem: RolloutProblem, share: float, threads: int | None) -> tuple[Any, Any, tuple]:
    """The whole log's simulator and the search's (every few segments; the same one when that is every
    segment), both from the start states of :func:`idkit.sim.initial.robust_states`."""
    segments = problem.segments()
    starts = np.array([s for s, _ in segments])
    log = problem.samples
    initial = robust_states(log.t, log.q, log.qd, starts, problem.scales())
    threads = threads or problem.threads
    full = problem.simulator(segments, initial=initial, threads=threads)
    stride = max(1, int(round(1 / share)))
    chosen = list(range(0, len(segments), stride))
    if len(chosen) == len(segments):
        return full, full, initial
    search = problem.simulator(
        [segments[i] for i in chosen], initial=(initial[0][chosen], initial[1][chosen]), threads=threads
    )
    return full, search, initial


def _parts(problem: RolloutProblem, error: np.ndarray, rows: list[np.ndarray], measured: np.ndarray) -> tuple:
    """``(parts [B, G], total [B])`` of the search score of errors ``E[B, C, k]`` (``rows``: the channels
    of each part)."""
    if problem.cost is None:
        channels = default_score(error)
        return np.stack([channels[:, r].sum(axis=1) for r in rows], axis=1), channels.sum(axis=1)
    import torch

    e = torch.from_numpy(np.where(np.isfinite(error), error, 1e150))
    m = torch.from_numpy(measured)
    with torch.no_grad():
        total = problem.cost(e, m).numpy()
        parts = [problem.cost(e[:, r], m[r]).numpy() for r in rows]
    return np.stack(parts, axis=1), total


def _blocks(problem: RolloutProblem, cooperative: bool) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The search's blocks of unknowns and the error rows (channels) each is scored on."""
    unknowns, n = problem.robot.unknowns, problem.samples.n_joints
    everything = np.arange(2 * n)
    if not cooperative:
        return [np.arange(len(unknowns))], [everything]
    sim = problem.robot.sim
    position = {sim.joint_id(name): j for j, name in enumerate(problem.samples.joint_names)}
    owner = [position.get(joint, -1) if joint is not None else -1 for joint in unknowns.joints(sim)]
    blocks, rows = [], []
    for j in sorted(set(owner)):
        blocks.append(np.flatnonzero(np.array(owner) == j))
        rows.append(everything if j < 0 else np.array([j, n + j]))
    return blocks, rows


def _search(
    problem: RolloutProblem, simulator: Any, options: RolloutEstimator, start: np.ndarray
) -> SearchResult:
    unknowns = problem.robot.unknowns
    lower, upper = unknowns.coordinate_bounds()
    blocks, rows = _blocks(problem, options.cooperative)
    measured = problem.measured(simulator)

    width = max(len(b) for b in blocks)
    particles = options.particles or min(32, 4 + 2 * width)
    iterations = options.iterations if options.iterations is not None else min(40, 10 + 2 * width)
    if options.iterations is None and problem.start_fitted:
        iterations = (iterations + 1) // 2  # a fitted start: its best found early (docs/rollout.md)
    calls, best = [0], [np.inf]  # for the progress lines

    def objective(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        parts, total = _parts(problem, problem.error(unknowns.from_coordinates(z), simulator), rows, measured)
        calls[0] += 1
        best[0] = min(best[0], float(np.min(np.where(np.isfinite(total), total, np.inf))))
        progress.report("search", calls[0], iterations + 1, best[0])
        return parts, total

    return cooperative_search(
        objective, lower, upper, start, blocks, particles, iterations, problem.generator()
    )


def _polish(
    problem: RolloutProblem,
    simulators: tuple[Any, Any],
    z: np.ndarray,
    options: RolloutEstimator,
    iterations: int,
) -> dict[str, Any]:
    """Levenberg–Marquardt, coarse to fine (``_STAGES``): least squares on the search's segments from
    their start states (fast from far; exact on a noiseless log, which ends the polish), then the robust
    loss with the initial states free (``free_initial``) on those segments, then on every segment. In a
    robust stage the scale is re-estimated until it settles (``ROUNDS`` solves at most); the very last
    solve has a tight tolerance."""
    search_sim, full_sim = simulators
    record: list[PolishSolve] = []
    x, offsets = z, dict[int, np.ndarray]()
    shooting: Shooting | None = None
    stages = _STAGES if search_sim is not full_sim else _STAGES[:1] + _STAGES[2:]
    for subset, robust, rounds in stages:
        simulator = search_sim if subset else full_sim
        shooting = Shooting(problem, simulator, options.free_initial and robust)
        x = shooting.start(x[: len(z)], offsets)
        scales = None
        if problem.start_fitted:
            rounds = min(rounds, FITTED_ROUNDS)
        for round_ in range(rounds):
            new = _robust_scales(problem, shooting, x)
            if np.all(new < EXACT):
                return _finish(
                    problem, Shooting(problem, full_sim, False), x[: len(z)], record, options, True
                )
            settled = scales is not None and bool(np.all(np.abs(np.log(new / scales)) < SETTLED))
            if scales is None or not settled:
                scales = new
            last = settled or round_ == rounds - 1
            tight = last and not subset
            x = _solve(shooting, x, scales, options, robust, tight, record, iterations)
            if last or options.loss == "linear":
                break
        offsets = shooting.offsets(x)
    assert shooting is not None  # the stages are never empty
    exact = bool(np.all(_robust_scales(problem, shooting, x) < EXACT))
    return _finish(problem, shooting, x, record, options, exact)


#: The polish's stages: (on the search's segments only, robust loss with free initial states, solves at
#: most; from a fitted start at most ``FITTED_ROUNDS``).
_STAGES = ((True, False, 1), (True, True, ROUNDS), (False, True, ROUNDS))


def _robust_scales(problem: RolloutProblem, shooting: Shooting, x: np.ndarray) -> np.ndarray:
    """``[C]`` each channel's robust scale of the error at ``x`` (floored at 1e-9 of its spread)."""
    return np.maximum(mad_scale(shooting.errors(x[:, None])[0]), 1e-9 * problem.spreads())


def _solve(
    shooting: Shooting,
    x: np.ndarray,
    scales: np.ndarray,
    options: RolloutEstimator,
    robust: bool,
    tight: bool,
    record: list,
    iterations: int,
) -> np.ndarray:
    """One Levenberg–Marquardt solve at fixed channel scales: least squares (``robust=False``: fast from
    far, and exact on a noiseless log) or the robust loss; the last (``tight``) with Huber's own Hessian
    and a tight tolerance, the others with the IRLS Hessian (steadier while the scale still moves)."""
    loss = options.loss if robust else "linear"
    root = np.sqrt(shooting.measured.size)
    shooting.divisor = scales * root
    lower, upper = shooting.unknowns.coordinate_bounds()
    best = [np.inf]  # for the progress lines

    def residual(x: np.ndarray) -> np.ndarray:
        r = shooting.residual(x)
        if progress.listening():  # once per step tried: where the polish is (its best error in noise levels)
            error = r[:, 0] * shooting.divisor[shooting.channel_of_entry()]
            best[0] = min(best[0], float(mad_scale(error)))
            progress.report("polish", best=best[0], what="error / noise")
        return r

    x, trace = least_squares(
        x,
        residual,
        shooting.jacobian,
        lower,
        upper,
        loss,
        TUNING[loss] / root,
        hessian="newton" if tight else "irls",
        max_iter=iterations,
        ftol=TIGHT if tight else LOOSE,
        xtol=1e-7,
        refresh=options.jacobian_every,
    )
    record.append(
        PolishSolve(
            segments=len(shooting.simulator.segments),
            initial_states_free=shooting.free_initial,
            iterations=len(trace.losses) - 1,
            losses=list(trace.losses),
            stop=trace.status,
            scales=(scales * shooting.scales).tolist(),
            jacobians=trace.jacobians,
        )
    )
    return x


def _finish(
    problem: RolloutProblem,
    shooting: Shooting,
    x: np.ndarray,
    record: list,
    options: RolloutEstimator,
    exact: bool,
) -> dict[str, Any]:
    """The result of the polish at variables ``x``, with its uncertainty."""
    error = shooting.errors(x[:, None])[0]
    shooting.divisor = np.maximum(mad_scale(error), 1e-9 * problem.spreads()) * np.sqrt(error.size)
    residual = shooting.residual(x[:, None])
    jac = shooting.jacobian(x[:, None], residual)
    values, initial = shooting.split(x[:, None])
    n = shooting.n_unknowns
    threshold = TUNING[options.loss] / np.sqrt(residual.size)
    edges = np.cumsum([0, *(v.samples.size for v in shooting.simulator.views)]) * shooting.n_channels
    found = uncertainty(
        jac, residual[:, 0], threshold, options.loss, problem.robot.unknowns, x[:n],
        list(zip(edges[:-1], edges[1:], strict=True)), mad_scale(error),
        heavier_links_change(shooting, x, residual[:, 0]),
    )  # fmt: skip
    states = shooting.simulator.initial_states if initial is None else (initial[0][0], initial[1][0])
    return {
        "z": x[:n],
        "record": record,
        "uncertainty": found,
        "initial": States(states[0], states[1]),
        "exact": exact,
    }


def _score(problem: RolloutProblem, values: np.ndarray) -> float:
    """The search's score at ``values`` on the problem's own error (segments from the logged states)."""
    simulator = problem.simulator()
    try:
        error = problem.error(values[None], simulator)
        rows = [np.arange(2 * problem.samples.n_joints)]
        return float(_parts(problem, error, rows, problem.measured(simulator))[1][0])
    finally:
        simulator.close()


def default_score(error: np.ndarray) -> np.ndarray:
    """``[B, C]`` per-channel parts of the default search score of errors ``E[B, C, k]``."""
    return channel_log_scales(error, TRIM)
