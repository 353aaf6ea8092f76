"""The fast engine: whole swarm runs on the compiled kernel (``idkit.optim.kernel``), array in,
array out.

What it minimises is a ``ProductSpec``: per slot ``l``, the cost of a position ``x`` is the product
of the slot's factors (``NormStructure``) of the error ``E = offset[l] + base(x) · linear[l]`` — an
error affine in the base parameters, as a robot's torque error is through its regressor. Neither a
``Problem`` nor an estimator is needed: the PSO estimator builds a spec from its objective, and
anything else with that structure (excitation design, variable projection) can too.

How a run is cut into calls: one call moves one trial's swarms (they share the trial's random
stream) through a block of moves of about ``EVALUATIONS_PER_CALL`` cost evaluations, so control
returns to Python every few tens of milliseconds (Ctrl-C stops a fit within a second) and trials are
spread over threads (the kernel releases the GIL; a trial stays on one thread, so the numbers do
not depend on the thread count).

The kernel is compiled by numba the first time a machine needs it (seconds, recorded apart from
the fit: ``Build.seconds``) and cached in idkit's checked cache directory (``idkit.optim.cache``),
keyed by numba on the CPU's name and features; later processes load it. If numba is missing or
the build fails twice, ``kernel()`` says why and callers run the eager engine.
"""

from __future__ import annotations

import re
import threading
import time
import warnings
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import cache, cached_property, lru_cache

import numpy as np
import torch
from torch import Tensor

from idkit.costs.factors import factor_parameters
from idkit.costs.reductions import kept_entries
from idkit.interfaces import NormStructure
from idkit.optim import codes, swarm
from idkit.optim.base_map import Tape, identity
from idkit.optim.cache import CacheWarning

#: Cost evaluations per kernel call: a call returns within a fraction of a second (docs/speed.md),
#: so Ctrl-C and threads act between calls.
EVALUATIONS_PER_CALL = 1 << 20
#: Cost evaluations per thread below which a call does not use another thread.
EVALUATIONS_PER_THREAD = 20_000


@dataclass(frozen=True)
class Build:
    """The loaded kernel: its entry point, how it was obtained, and this process's seconds for it."""

    run_trial: Callable[..., None]
    how: str
    seconds: float


@cache
def kernel() -> Build | str:
    """The kernel (``Build``), or why there is none (a one-line reason).

    The first call of a process imports numba and loads the kernel from the cache, or compiles
    it there (``Build.how`` says which). A cache entry that fails to load is removed and the
    kernel compiled again, once, with a ``CacheWarning``.
    """
    started = time.perf_counter()
    try:
        from numba.core import config

        if config.DISABLE_JIT:
            return "numba's JIT is disabled (NUMBA_DISABLE_JIT)"
        from idkit.optim import kernel as compiled
    except Exception as error:  # numba missing or broken on this platform
        return f"the fast kernel cannot be loaded ({type(error).__name__}: {error})"
    misses = 0  # kernels numba compiled: set by the attempt that succeeds (the other returns)
    for attempt in (1, 2):
        try:
            with compiled.MANIFEST.locked():  # numba's files are recorded before another process checks
                misses = _warm_up(compiled.run_trial)
                if misses:
                    compiled.MANIFEST.record()
            break
        except Exception as error:
            if attempt == 2:
                return f"the fast kernel failed to build ({_one_line(error)})"
            warnings.warn(
                f"idkit's kernel cache {compiled.FOLDER} failed to load ({type(error).__name__}); "
                "removed it, compiling again",
                CacheWarning,
                stacklevel=2,
            )
            compiled.MANIFEST.clear()
    seconds = time.perf_counter() - started
    if misses:
        how = f"compiled by numba in {seconds:.1f} s (once per machine; cached in {compiled.FOLDER})"
    else:
        how = f"loaded from the cache in {seconds:.2f} s"
    built = Build(compiled.run_trial, how, seconds)
    stats = getattr(compiled.run_trial, "stats", None)
    _RECORDED[id(built)] = sum(stats.cache_misses.values()) if stats is not None else 0
    return built


def _one_line(error: BaseException) -> str:
    """``Type: first line`` of an error, without the terminal colours numba adds."""
    text = re.sub(r"\x1b\[[0-9;]*m", "", str(error)).strip().splitlines()
    return f"{type(error).__name__}: {text[-1] if text else ''}"[:300]


def _warm_up(run_trial: Callable[..., None]) -> int:
    """One tiny call with every argument of the type real calls use (compiles or loads the code);
    returns how many signatures had to be compiled."""
    before = run_trial.stats.cache_misses.copy() if hasattr(run_trial, "stats") else {}
    x = np.zeros((1, 2, 1))
    run_trial(
        np.random.Generator(np.random.SFC64(0)),
        0,
        1,
        np.ones(1),
        True,
        np.empty((2, 1)),
        x,
        np.zeros_like(x),
        x.copy(),
        np.full((1, 2), np.inf),
        np.empty((1, 1)),
        np.ones((1, 1, 3)),
        np.zeros((1, 3)),
        np.zeros(1, dtype=np.int64),
        np.array([[codes.FRO, 0, 0, 0]], dtype=np.int64),
        np.zeros((1, codes.MAX_FACTORS)),
        3,
        -np.ones(1),
        np.ones(1),
        np.array([1.0, 1.0, 0.0]),
        np.array([codes.CLAMP, 0, codes.MAP_IDENTITY], dtype=np.int64),
        np.zeros((0, 4), dtype=np.int64),
        np.zeros(0),
        np.zeros(0, dtype=np.int64),
        np.zeros((0, 0, 0)),
    )
    after = run_trial.stats.cache_misses if hasattr(run_trial, "stats") else {}
    return sum(after.values()) - sum(before.values())


@dataclass(frozen=True)
class ProductSpec:
    """Costs the kernel evaluates: per slot ``l``, ``Π_f factor_f(offset[l] + base(x) · linear[l])``.

    Attributes:
        linear: ``[L, B, M]`` float64 on the CPU; ``M = joints × samples``, joint-major.
        offset: ``[L, M]``.
        joints: rows of each error matrix.
        structures: ``L`` structures (their factors; ``relative``/``floor`` are already in
            ``offset`` and ``linear``).
        base: positions ``x[..., D]`` → base parameters ``[..., B]`` (torch), used when ``tape``
            is ``None``.
        tape: ``base`` as a kernel tape (``idkit.optim.base_map``), or ``None``.
    """

    linear: Tensor
    offset: Tensor
    joints: int
    structures: tuple[NormStructure, ...]
    base: Callable[[Tensor], Tensor]
    tape: Tape | None

    @cached_property
    def arrays(self) -> KernelArrays:
        """The spec as the kernel's arrays (converted once per spec: a spec reused for many runs,
        as the PSO estimator's cache of prepared problems does, pays the conversion once).

        Raises:
            ValueError: a factor without a kernel form (``factor_codes``).
        """
        code, parameter = factor_codes(self.structures, self.offset.shape[-1])
        tape = self.tape if self.tape is not None else identity(0)
        return KernelArrays(
            linear=self.linear.contiguous().numpy(),
            offset=self.offset.contiguous().numpy(),
            codes=code,
            parameters=parameter,
            mode=codes.MAP_TAPE if self.tape is not None else codes.MAP_GIVEN,
            tape=tape,
        )


@dataclass(frozen=True)
class KernelArrays:
    """A ``ProductSpec`` in the kernel's calling convention (``idkit.optim.codes``): ``linear[L, B, M]``,
    ``offset[L, M]``, the factor ``codes``/``parameters`` ``[L, MAX_FACTORS]``, the base map's
    ``mode`` and its ``tape`` (an empty one when the map runs in torch)."""

    linear: np.ndarray
    offset: np.ndarray
    codes: np.ndarray
    parameters: np.ndarray
    mode: int
    tape: Tape


def factor_codes(structures: Sequence[NormStructure], entries: int) -> tuple[np.ndarray, np.ndarray]:
    """Per slot, the kernel's factor codes ``[L, MAX_FACTORS]`` (int64, 0 = none) and parameters.

    Parameters are checked by ``idkit.costs.factors.factor_parameters``; a trimmed factor's is
    handed over as the count of entries it keeps (``kept_entries``, for ``entries`` entries).

    Raises:
        ValueError: a factor without a kernel form, too many factors, or a bad parameter.
    """
    found = np.zeros((len(structures), codes.MAX_FACTORS), dtype=np.int64)
    values = np.zeros((len(structures), codes.MAX_FACTORS))
    for slot, structure in enumerate(structures):
        names = tuple(structure.norms)
        if not names:
            raise ValueError("norm structure without factors: the kernel needs at least one")
        if len(names) > codes.MAX_FACTORS:
            raise ValueError(f"norm structure {names}: the kernel takes at most {codes.MAX_FACTORS} factors")
        unknown = [name for name in names if name not in codes.FORMS]
        if unknown:
            raise ValueError(f"the fast kernel has no form for {', '.join(unknown)}")
        for f, (name, value) in enumerate(
            zip(names, factor_parameters(names, structure.parameters), strict=True)
        ):
            found[slot, f] = codes.FORMS[name]
            values[slot, f] = kept_entries(entries, value) if name == "trimmed" else value
    return found, values


def refusal(spec: ProductSpec) -> str | None:
    """Why the kernel cannot run ``spec``, or ``None``."""
    if spec.linear.device.type != "cpu" or spec.linear.dtype != torch.float64:
        return "the fast kernel runs float64 on the CPU"
    try:
        factor_codes(spec.structures, spec.offset.shape[-1])
    except ValueError as error:
        return str(error)
    if spec.joints != 3 and any("2" in s.norms for s in spec.structures):
        return "the fast kernel's spectral norm is for 3 joints only"
    built = kernel()
    return built if isinstance(built, str) else None


def evaluate(spec: ProductSpec, x: Tensor) -> Tensor:
    """The kernel's cost of positions ``x[L, K, D]`` (slot ``l`` by ``spec``'s slot ``l``) ``[L, K]``:
    one evaluation, nothing moved. A cost that is NaN comes back as ``inf`` (the kernel never lets
    it become a best)."""
    built = kernel()
    if isinstance(built, str):
        raise RuntimeError(f"the fast kernel is unavailable: {built}")
    slots, particles, dimension = x.shape
    position = x.to(torch.float64).contiguous().numpy().copy()
    pcost = np.full((slots, particles), np.inf)
    arrays = spec.arrays
    tape = arrays.tape
    given = spec.base(x).contiguous().numpy() if spec.tape is None else np.zeros((0, 0, 0))
    built.run_trial(
        np.random.Generator(np.random.SFC64(0)), 0, slots, np.empty(0), True, np.empty((1, slots)),
        position, np.zeros_like(position), position.copy(), pcost, np.empty((slots, dimension)),
        arrays.linear, arrays.offset, np.arange(slots, dtype=np.int64), arrays.codes, arrays.parameters,
        int(spec.joints), np.zeros(dimension), np.ones(dimension), np.array([1.0, 1.0, 0.0]),
        np.array([codes.CLAMP, 0, arrays.mode], dtype=np.int64), tape.ops, tape.constants, tape.outputs,
        given,
    )  # fmt: skip
    _record_new_code(built)
    return torch.from_numpy(pcost)


def _record_new_code(built: Build) -> None:
    """Record the cache's files again if a call compiled code the warm-up did not (numba rewrote its
    index): the next process would otherwise take them for damage."""
    stats = getattr(built.run_trial, "stats", None)
    misses = sum(stats.cache_misses.values()) if stats is not None else 0
    if misses != _RECORDED.get(id(built), 0):
        from idkit.optim import kernel as compiled

        compiled.MANIFEST.record()
    _RECORDED[id(built)] = misses


_RECORDED: dict[int, int] = {}


@lru_cache(maxsize=64)
def _inertias(rules: swarm.SwarmRules, moves: int) -> np.ndarray:
    """``rules.weight`` of every move ``[moves]`` (cached: 300 Python calls cost a tenth of a run)."""
    return np.array([rules.weight(m) for m in range(moves)], dtype=np.float64)


_POOL: ThreadPoolExecutor | None = None


def _pool(threads: int) -> ThreadPoolExecutor:
    global _POOL
    if _POOL is None or _POOL._max_workers < threads:  # noqa: SLF001  (grow on demand)
        _POOL = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="idkit-swarm")
    return _POOL


def run(
    spec: ProductSpec,
    lower: Tensor,
    upper: Tensor,
    runs: int,
    particles: int,
    iterations: int,
    rules: swarm.SwarmRules,
    draws: swarm.Draws,
    threads: int = 1,
    stride: int = 1,
) -> tuple[swarm.SwarmState, Tensor]:
    """``swarm.run`` of ``spec`` on the kernel: the same numbers, update and history.

    Args:
        spec: ``L`` slots, trial-major: ``draws`` has ``T`` streams and slot ``l`` belongs to
            trial ``l // (L / T)``.
        lower, upper: the box ``[D]``.
        runs: independent swarms per slot (``R``).
        particles, iterations, rules: as ``swarm.run``.
        draws: one numpy stream per trial, advanced as the eager engine would advance it.
        threads: spread the trials over up to this many threads (the numbers do not depend on it).
        stride: keep every ``stride``-th iteration in the history (``swarm.history_rows``).

    Returns:
        The final state ``[L, R, ...]`` and the history ``[rows, L, R]``.
    """
    built = kernel()
    if isinstance(built, str):
        raise RuntimeError(f"the fast kernel is unavailable: {built}")
    slots, trials = spec.offset.shape[0], len(draws.streams)
    if slots % trials or any(stream.numpy is None for stream in draws.streams):
        raise ValueError(f"fast engine: {slots} slots do not split into {trials} CPU streams")
    dimension = lower.shape[-1]
    low, high = lower.numpy(), upper.numpy()
    # the eager engine's initial positions, operation by operation (the same rounding)
    x = low + (high - low) * draws.draw((slots, runs, particles, dimension)).numpy()
    x = x.reshape(slots * runs, particles, dimension)
    v, pbest, pcost = np.zeros(x.shape), x.copy(), np.full(x.shape[:2], np.inf)
    gpos = np.empty((slots * runs, dimension))
    arrays = spec.arrays
    mode, tape = arrays.mode, arrays.tape
    fixed = (
        arrays.linear,
        arrays.offset,
        np.repeat(np.arange(slots, dtype=np.int64), runs),
        arrays.codes,
        arrays.parameters,
        int(spec.joints),
        low,
        high,
        np.array([rules.c1, rules.c2, rules.velocity_limit or 0.0]),
        np.array([swarm.BOUNDARIES.index(rules.boundary), int(rules.per_particle), mode], dtype=np.int64),
        tape.ops,
        tape.constants,
        tape.outputs,
    )
    kept = swarm.history_rows(iterations, stride)
    history = np.empty((len(kept), slots * runs))
    per_trial = slots // trials * runs
    weights = _inertias(rules, iterations - 1)
    moves = iterations - 1
    if mode == codes.MAP_GIVEN:  # one move per call, given its base parameters; the last evaluation apart
        blocks = [(m, m + 1, False) for m in range(moves)] + [(moves, moves, True)]
    else:
        step = max(1, EVALUATIONS_PER_CALL // (per_trial * particles))
        blocks = [(m, min(m + step, moves), m + step >= moves) for m in range(0, moves, step)]
        blocks = blocks or [(0, 0, True)]

    def call(trial: int, block: tuple[int, int, bool], given: np.ndarray) -> None:
        start, stop, last = block
        first = trial * per_trial
        if stride == 1 and trials == 1:  # the kernel writes the history rows in place
            built.run_trial(
                draws.streams[0].numpy, 0, per_trial, weights[start:stop], last, history[start : stop + last],
                x, v, pbest, pcost, gpos, *fixed, given,
            )  # fmt: skip
            return
        rows = np.empty((stop - start + last, per_trial))
        built.run_trial(
            draws.streams[trial].numpy, first, per_trial, weights[start:stop], last, rows,
            x, v, pbest, pcost, gpos, *fixed, given,
        )  # fmt: skip
        if stride == 1:  # every iteration kept: one block copy, much cheaper than fancy indexing
            history[start : stop + last, first : first + per_trial] = rows
            return
        # the kept iterations of this block (every stride-th, and the last) into their history rows
        iteration = np.arange(start, start + len(rows))
        keep = (iteration % stride == 0) | (iteration == iterations - 1)
        row = np.where(iteration == iterations - 1, len(kept) - 1, iteration // stride)
        history[row[keep], first : first + per_trial] = rows[keep]

    if mode == codes.MAP_GIVEN:  # the base map in torch, on the positions before each call
        for block in blocks:
            given = spec.base(torch.from_numpy(x)).contiguous().numpy()
            for trial in range(trials):
                call(trial, block, given)
    else:
        used = thread_count(threads, trials, slots * runs, particles, iterations)
        empty = np.zeros((0, 0, 0))
        _in_threads(used, trials, blocks, lambda trial, block: call(trial, block, empty))
    _record_new_code(built)
    position, velocity, best, cost, best_global = (
        torch.from_numpy(a).view(slots, runs, *a.shape[1:]) for a in (x, v, pbest, pcost, gpos)
    )
    state = swarm.SwarmState(position, velocity, best, cost, best_global, cost.amin(-1))
    return state, torch.from_numpy(history).view(len(kept), slots, runs)


def thread_count(most: int, trials: int, swarms: int, particles: int, iterations: int) -> int:
    """Threads ``run`` uses: at most ``most``, one per trial at most (a trial's swarms share its
    stream), and one per ``EVALUATIONS_PER_THREAD`` evaluations of a call."""
    per_call = (
        swarms
        * particles
        * min(iterations, max(1, EVALUATIONS_PER_CALL // max(swarms // trials * particles, 1)))
    )
    return max(1, min(most, trials, per_call // EVALUATIONS_PER_THREAD))


def _in_threads(
    threads: int,
    trials: int,
    blocks: list[tuple[int, int, bool]],
    work: Callable[[int, tuple[int, int, bool]], None],
) -> None:
    """``work(trial, block)`` for every trial and block of moves, trials in contiguous shares over
    ``threads`` threads (the caller's thread is one of them). A KeyboardInterrupt stops every
    thread after its current call."""
    stop = threading.Event()

    def share(part: int) -> None:
        for trial in range(trials * part // threads, trials * (part + 1) // threads):
            for block in blocks:
                if stop.is_set():
                    return
                work(trial, block)

    futures = [_pool(threads - 1).submit(share, part) for part in range(1, threads)]
    try:
        share(0)
        for future in futures:
            future.result()
    except BaseException:
        stop.set()
        raise
