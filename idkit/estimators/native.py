"""A compiled PSO loop for costs with a declared norm structure (the ``"native"`` engine).

Why: an eager PyTorch step of a paper-sized swarm (20 particles × 4 parameters × a 3 × 10 error
matrix) is ~25 tensor ops of a few microseconds of dispatch each; the work itself is a few
thousand flops. JAX peers compile the whole loop (XLA) and win small swarms by 10×. This module
compiles plain C (``pso_kernel.c`` beside it) with the host's C compiler (``cc``/``gcc``, ``-O3
-march=native``, IEEE arithmetic) the first time it is needed, caches the shared library on disk
(``IDKIT_CACHE_DIR`` or ``~/.cache/idkit``, keyed by the source's hash and the host, so later
processes only load it) and calls it through ``ctypes``.

One call runs whole PSO runs: for every swarm it does what ``swarm.step`` +
``Objective.__call__`` do in torch — evaluate ``E = T/d − alpha · Yᵀ/d`` and the product of its
norms for every particle, update personal and global bests, move the particles (velocity,
boundary rule) — and it draws the random numbers itself: numpy's SFC64 and
``Generator.random(dtype=float32)`` written in C, continuing each trial's stream (``swarm.Uniform``)
from its state and handing the state back, so both engines see the same numbers and leave the
streams in the same place. The trajectories agree to rounding; the kernel gives identical numbers
on every call and for any thread count (trials are split over threads: a trial's draws interleave
across its swarms).

The source is compiled per problem size (``Sizes``: the error matrix ``n × N``, the base
parameters, the search dimension, as ``#define``s, so loops unroll and vectorise) and per base
map: the robot's map from search positions to base parameters is traced and written in C where it
is an elementwise formula (``idkit.estimators.base_map``), and then a whole run is one call.
Otherwise the map stays in torch and the kernel is called once per move with the base parameters.
Particles are evaluated four at a time as the lanes of a vector (the error matrix, its norms, the
spectral norm's closed form); what bounds an evaluation is measured in ``docs/speed.md``.

Norms (``NORM_CODES``): the paper's six, and ``"huber"`` and ``"trimmed"`` with one parameter each
(``NormStructure.parameters``, aligned with ``norms``).

When no compiler is available (or compiling fails) ``kernel()`` returns ``None`` with the reason,
and the estimator takes the eager engine and says so in ``details["engine_build"]``.
"""

from __future__ import annotations

import contextlib
import ctypes
import hashlib
import inspect
import os
import pickle
import platform
import shutil
import subprocess
import sys
import tempfile
import time
import weakref
from collections.abc import Sequence
from functools import cache, lru_cache
from importlib import resources
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch
from torch import Tensor

from idkit.estimators import swarm
from idkit.estimators.base_map import identity_source, map_source
from idkit.estimators.objective import Objective, factor_parameters
from idkit.interfaces import Cost, NormStructure, Robot

#: Norm name (``idkit.costs.norms.NORMS``) -> code in the C source.
NORM_CODES = {"fro": 1, "2": 2, "1": 3, "inf": 4, "max_row_sq": 5, "max_abs": 6, "huber": 7, "trimmed": 8}
#: Most norms one cost may multiply (the paper's f6 has three).
MAX_NORMS = 4
BOUNDARY_CODES = {"clamp": 0, "reflect": 1, "random": 2}
#: Compiler flags: optimised, vectorised for this CPU, IEEE arithmetic (no fast-math, no FMA
#: contraction, so the kernel rounds like the eager engine's separate multiplies and adds).
#: ``-fno-math-errno`` and ``-fno-trapping-math`` change no result: they let ``sqrt`` and the
#: selects of the boundary rules vectorise (no errno to set, no floating-point traps to keep).
FLAGS = (
    "-O3",
    "-march=native",
    "-ffp-contract=off",
    "-fno-fast-math",
    "-fno-math-errno",
    "-fno-trapping-math",
    "-fPIC",
    "-shared",
    "-pthread",
)
#: Cost evaluations per thread below which a call does not start another thread (a thread costs
#: ~50 µs to start and join; an evaluation well under 0.1 µs).
EVALUATIONS_PER_THREAD = 20_000


#: The C source's ``MAX_THREADS``.
MAX_THREADS = 64


def thread_count(most: int, trials: int, evaluations: int) -> int:
    """Threads a kernel call uses: at most ``most``, one per trial at most (a trial's draws
    interleave across its swarms), and one per ``EVALUATIONS_PER_THREAD`` evaluations."""
    return max(1, min(most, MAX_THREADS, trials, evaluations // EVALUATIONS_PER_THREAD))


def call_threads(objective: Objective, swarms: int, particles: int, iterations: int, most: int) -> int:
    """Threads each kernel call of ``run`` uses on ``swarms`` swarms (for ``details["threads"]``):
    a call runs whole runs where the base map is in C, one move where it stays in torch."""
    moves_per_call = iterations if robot_map(objective) is not None else 1
    return thread_count(most, len(objective.trials), swarms * particles * moves_per_call)


#: The kernel's C source (package data), compiled behind a generated prefix (``source``).
KERNEL_FILE = "pso_kernel.c"


class Sizes(NamedTuple):
    """What a kernel is compiled for: the error matrix ``joints × samples``, ``base`` parameters
    and the search ``dimension``."""

    joints: int
    samples: int
    base: int
    dimension: int


#: The paper's cylindrical robot: 3 joints × 10 samples, 4 base parameters, 4 search dimensions.
PAPER_SIZES = Sizes(3, 10, 4, 4)


def sizes_of(objective: Objective) -> Sizes:
    """The kernel sizes of an objective that uses the regressor."""
    n, samples = objective.shape
    return Sizes(n, samples, objective.linear.shape[1], objective.dimension)


def source(sizes: Sizes, base_map: str | None) -> str:
    """C source of the kernel for ``sizes`` and a base map (``None``: the caller gives alpha)."""
    defines = {
        "NJ": sizes.joints,
        "NS": sizes.samples,
        "NB": sizes.base,
        "NP": sizes.dimension,
        "MAX_NORMS": MAX_NORMS,
        "USE_MAP": int(base_map is not None),
    }
    prefix = "".join(f"#define {name} {value}\n" for name, value in defines.items())
    body = resources.files("idkit.estimators").joinpath(KERNEL_FILE).read_text()
    return f"{prefix}#include <math.h>\n{base_map or ''}\n{body}"


def cache_dir() -> Path:
    """Where compiled kernels live: ``IDKIT_CACHE_DIR`` or ``~/.cache/idkit``, then ``native/``."""
    root = os.environ.get("IDKIT_CACHE_DIR") or Path.home() / ".cache" / "idkit"
    return Path(root) / "native"


def _compiler() -> str | None:
    for name in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if name and shutil.which(name):
            return name
    return None


@cache
def kernel(sizes: Sizes = PAPER_SIZES, base_map: str | None = None) -> tuple[ctypes.CDLL | None, str, float]:
    """``(library or None, how it was obtained or why not, seconds spent compiling in this process)``.

    Compiled once per machine, ``sizes`` and base map (``idkit.estimators.base_map``; ``None``:
    the base parameters come from torch), cached on disk, loaded once per process.
    """
    try:
        text = source(sizes, base_map)
    except OSError as error:
        return None, f"the kernel source is missing from the installation: {error}", 0.0
    # -march=native makes the library specific to this CPU: the key names the host too.
    key = "\n".join((text, *FLAGS, sys.platform, platform.machine(), platform.node()))
    digest = hashlib.sha256(key.encode()).hexdigest()[:16]
    path = cache_dir() / f"pso_step-{digest}.so"
    spent = 0.0
    how = "cached"
    if not path.exists():
        compiler = _compiler()
        if compiler is None:
            return None, "no C compiler found (set CC)", 0.0
        started = time.perf_counter()
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryDirectory(dir=path.parent) as tmp:
                c_file = Path(tmp) / "pso_step.c"
                c_file.write_text(text)
                built = Path(tmp) / path.name
                portable = tuple(f for f in FLAGS if f != "-march=native")
                for flags in (FLAGS, portable):  # a compiler without -march=native gets the second
                    command = [compiler, *flags, str(c_file), "-o", str(built), "-lm"]
                    done = subprocess.run(command, capture_output=True, timeout=120)
                    if done.returncode == 0:
                        break
                done.check_returncode()
                os.replace(built, path)  # atomic: parallel processes never load half a file
        except (OSError, subprocess.SubprocessError) as error:
            detail = getattr(error, "stderr", b"") or b""
            return None, f"compiling the kernel failed: {error} {detail.decode(errors='replace')[:200]}", 0.0
        spent = time.perf_counter() - started
        how = f"compiled with {compiler}"
    library = ctypes.CDLL(str(path))
    ptr, i64 = ctypes.c_void_p, ctypes.c_int64
    library.idkit_pso_run.restype = i64
    library.idkit_pso_run.argtypes = [ctypes.POINTER(_Batch), ptr, i64, ptr, i64, i64]
    library.idkit_uniform.restype = None
    library.idkit_uniform.argtypes = [ptr, i64, ptr]
    return library, how, spent


class _Batch(ctypes.Structure):
    """The C ``Batch`` struct (same field order)."""

    _fields_ = [
        *((name, ctypes.c_int64) for name in ("S", "T", "K")),
        *((name, ctypes.c_void_p) for name in ("linear", "offset", "slot_of", "codes", "params")),
        *((name, ctypes.c_void_p) for name in ("x", "v", "pbest", "pcost", "gpos", "lower", "upper")),
        *((name, ctypes.c_double) for name in ("c1", "c2", "velocity_limit")),
        *((name, ctypes.c_int64) for name in ("boundary", "per_particle")),
        ("streams", ctypes.c_void_p),
        ("alpha", ctypes.c_void_p),
    ]


def norm_codes(structures: Sequence[NormStructure]) -> tuple[Tensor, Tensor]:
    """Per slot, the kernel's norm codes ``[L, MAX_NORMS]`` (int32, 0 = none) and their parameters
    ``[L, MAX_NORMS]`` (checked by ``objective.factor_parameters``: 0.0 for a matrix norm).

    Raises:
        ValueError: a factor the kernel does not know, too many factors, or a bad parameter.
    """
    codes = torch.zeros((len(structures), MAX_NORMS), dtype=torch.int32)
    params = torch.zeros((len(structures), MAX_NORMS), dtype=torch.float64)
    for slot, structure in enumerate(structures):
        names = tuple(structure.norms)
        if not names:
            raise ValueError("norm structure without factors: the kernel needs at least one")
        if len(names) > MAX_NORMS:
            raise ValueError(f"norm structure {names}: the kernel takes at most {MAX_NORMS} factors")
        unknown = [name for name in names if name not in NORM_CODES]
        if unknown:
            raise ValueError(f"the native kernel has no code for {', '.join(unknown)}")
        values = factor_parameters(names, structure.parameters)
        for c, (name, value) in enumerate(zip(names, values, strict=True)):
            codes[slot, c], params[slot, c] = NORM_CODES[name], value
    return codes, params


class NativeStep:
    """The kernel bound to one batch of swarms: fixed tensors, state buffers and streams, set once.

    Args:
        linear: ``[L, B, M]`` (``-Yᵀ/d`` per slot), ``offset``: ``[L, 1, M]`` (``T/d``).
        slot_of: ``[S]`` slot of each swarm. ``structures``: per slot, its ``NormStructure``.
        sizes: what the kernel is compiled for. ``lower``, ``upper``: the box ``[P]``.
        rules: the update rule.
        state: ``(x, v, pbest, pcost, gpos)``, contiguous float64 ``[S, K, P]`` ×3, ``[S, K]``,
            ``[S, P]``, updated in place by every call (a personal best improves where the cost is
            strictly lower, so start ``pcost`` at ``inf``).
        streams: ``[T, 6]`` uint64 (``swarm.Draws.bit_states``), advanced in place: trial ``t``
            owns swarms ``[t S/T, (t + 1) S/T)`` and draws its numbers from row ``t``.
        threads: split the trials over up to this many threads (results do not depend on it).
        base_map: C source of the robot's base map (``idkit.estimators.base_map``): the kernel
            then computes the base parameters itself; ``None``: every call is given them.
    """

    def __init__(
        self,
        linear: Tensor,
        offset: Tensor,
        slot_of: Tensor,
        structures: Sequence[NormStructure],
        sizes: Sizes,
        lower: Tensor,
        upper: Tensor,
        rules: swarm.SwarmRules,
        state: tuple[Tensor, ...],
        streams: np.ndarray,
        threads: int = 1,
        base_map: str | None = None,
    ) -> None:
        library, how, _ = kernel(sizes, base_map)
        if library is None:
            raise RuntimeError(f"the native PSO kernel is unavailable: {how}")
        self.function = library.idkit_pso_run
        if any(not t.is_contiguous() for t in state):
            raise ValueError("native PSO kernel: state buffers must be contiguous")
        tensors = (linear, offset, lower, upper, *state)
        if any(t.dtype != torch.float64 or t.device.type != "cpu" for t in tensors):
            raise ValueError("native PSO kernel: tensors must be float64 on the CPU")
        x = state[0]
        if linear.shape[1:] != (sizes.base, sizes.joints * sizes.samples) or x.shape[-1] != sizes.dimension:
            raise ValueError(
                f"native PSO kernel compiled for {sizes}: linear {tuple(linear.shape)} and positions "
                f"{tuple(x.shape)} do not fit"
            )
        if streams.dtype != np.uint64 or streams.shape[1:] != (6,) or not streams.flags.c_contiguous:
            raise ValueError(f"native PSO kernel: streams must be uint64 [T, 6], got {streams.shape}")
        if x.shape[0] % streams.shape[0]:
            raise ValueError(
                f"native PSO kernel: {x.shape[0]} swarms do not split evenly into {streams.shape[0]} trials"
            )
        codes, params = norm_codes(structures)
        fixed = {
            "linear": linear.contiguous(),
            "offset": offset.reshape(offset.shape[0], -1).contiguous(),
            "slot_of": slot_of.to(torch.int64).contiguous(),
            "codes": codes,
            "params": params,
            **dict(zip(("x", "v", "pbest", "pcost", "gpos"), state, strict=True)),
            "lower": lower.contiguous(),
            "upper": upper.contiguous(),
        }
        self.keep = (fixed, streams)  # the struct holds raw pointers: keep the arrays alive
        self.batch = _Batch(
            x.shape[0],
            streams.shape[0],
            x.shape[1],
            *(tensor.data_ptr() for tensor in fixed.values()),
            rules.c1,
            rules.c2,
            float(rules.velocity_limit or 0.0),
            BOUNDARY_CODES[rules.boundary],
            int(rules.per_particle),
            streams.ctypes.data,
            None,
        )
        self.pointer = ctypes.byref(self.batch)
        self.uses_map = base_map is not None
        self.threads = max(1, int(threads))

    def __call__(self, history: Tensor, weights: Tensor, last: bool, alpha: Tensor | None = None) -> None:
        """``len(weights)`` moves (inertias ``weights``), then one more evaluation if ``last``.

        Each evaluation writes every swarm's best cost into a row of ``history[moves + last, S]``
        (contiguous float64). ``alpha[S, K, B]``: the base parameters of ``x``, needed (and only
        allowed) without a base map in C, where a call makes at most one move.
        """
        moves, last = weights.shape[0], int(last)
        if (alpha is None) == (not self.uses_map) or (alpha is not None and moves > 1):
            raise ValueError("native PSO kernel: alpha comes with each move exactly when the map is not in C")
        if history.shape != (moves + last, self.batch.S) or not history.is_contiguous():
            raise ValueError(
                f"native PSO kernel: history must be contiguous [{moves + last}, {self.batch.S}], "
                f"got {tuple(history.shape)}"
            )
        weights = weights.to(torch.float64).contiguous()
        if alpha is not None:
            alpha = alpha.contiguous()  # kept alive in this frame during the call
            self.batch.alpha = alpha.data_ptr()
        evaluations = self.batch.S * self.batch.K * (moves + last)
        threads = thread_count(self.threads, self.batch.T, evaluations)
        status = self.function(self.pointer, history.data_ptr(), moves, weights.data_ptr(), last, threads)
        if status != 0:
            raise MemoryError("native PSO kernel: out of memory for a thread's working buffers")


#: Base maps translated to C, per robot object: ``id -> (weak reference, source or None, seconds)``.
_MAPS: dict[int, tuple[weakref.ref, str | None, float]] = {}


def _map_file(robot: Robot, dimension: int) -> Path | None:
    """Disk-cache file of a robot's translated map: keyed by its pickled state and its code."""
    try:
        state = pickle.dumps(robot)
        code = inspect.getsource(type(robot))
    except Exception:  # not picklable, or no source: trace in every process
        return None
    key = hashlib.sha256(
        b"\n".join((state, code.encode(), str(dimension).encode(), torch.__version__.encode()))
    )
    return cache_dir() / "maps" / f"{key.hexdigest()[:16]}.c"


def robot_map(objective: Objective) -> str | None:
    """C source of the objective's search-to-base map, or ``None`` (the torch map is used).

    Tracing (``idkit.estimators.base_map``) imports torch's tracer, seconds the first time in a
    process, so its result is cached on disk beside the kernels (an empty file: not translatable)
    and in memory per robot object.
    """
    dimension = objective.lower.shape[-1]
    if objective.space == "base":
        return identity_source(dimension)
    robot = objective.problem.robot
    known = _MAPS.get(id(robot))
    if known is not None and known[0]() is robot:
        return known[1]
    started = time.perf_counter()
    file = _map_file(robot, dimension)
    if file is not None and file.exists():
        source = file.read_text() or None
    else:
        source = map_source(robot, dimension)
        if file is not None:
            with contextlib.suppress(OSError):  # a read-only cache only costs the next process a trace
                file.parent.mkdir(parents=True, exist_ok=True)
                temporary = file.with_suffix(f".{os.getpid()}.tmp")
                temporary.write_text(source or "")
                os.replace(temporary, file)
    with contextlib.suppress(TypeError):  # a robot that is not weak-referenceable is traced again
        _MAPS[id(robot)] = (weakref.ref(robot), source, time.perf_counter() - started)
    return source


def map_seconds(objective: Objective) -> float:
    """Seconds this process spent obtaining the objective's base map (tracing or reading the cache)."""
    known = _MAPS.get(id(objective.problem.robot))
    return 0.0 if known is None else known[2]


def build(objective: Objective) -> tuple[ctypes.CDLL | None, str, float]:
    """``kernel`` for this objective's sizes and base map."""
    return kernel(sizes_of(objective), robot_map(objective))


@lru_cache(maxsize=64)
def _inertias(rules: swarm.SwarmRules, moves: int) -> Tensor:
    """``rules.weight`` of every move ``[moves]`` (cached: 300 Python calls cost a tenth of a run)."""
    return torch.tensor([rules.weight(m) for m in range(moves)], dtype=torch.float64)


def run(
    objective: Objective,
    batch_shape: tuple[int, int],
    particles: int,
    iterations: int,
    rules: swarm.SwarmRules,
    uniform: swarm.Draws,
    threads: int = 1,
) -> tuple[swarm.SwarmState, Tensor]:
    """``swarm.run`` on the kernel: same draws, same update, same history ``[iterations, S, R]``.

    Every cost of ``objective`` must have a structure the kernel knows and the objective must use
    the regressor, on the CPU in float64 (``supports``); ``uniform`` has one numpy stream per
    trial of the objective, left where the eager engine would leave it.
    """
    if particles < 1 or iterations < 1:
        raise ValueError(f"need particles >= 1 and iterations >= 1, got {particles}, {iterations}")
    slots, runs = batch_shape
    lower, upper = objective.lower, objective.upper
    dimension = lower.shape[-1]
    count = len(objective.costs)
    base_map = robot_map(objective)
    u = uniform.draw((slots, runs, particles, dimension))
    x = (lower + (upper - lower) * u).reshape(slots * runs, particles, dimension).contiguous()
    state = (
        x,
        torch.zeros_like(x),
        x.clone(),
        torch.full(x.shape[:2], torch.inf, dtype=x.dtype),
        torch.empty((slots * runs, dimension), dtype=x.dtype),
    )
    streams = uniform.bit_states()
    step = NativeStep(
        objective.linear,
        objective.offset,
        torch.arange(slots).repeat_interleave(runs),
        [objective.structures[s % count] for s in range(slots)],
        sizes_of(objective),
        lower,
        upper,
        rules,
        state,
        streams,
        threads,
        base_map,
    )
    history = torch.empty((iterations, slots * runs), dtype=x.dtype)
    weights = _inertias(rules, iterations - 1)
    if base_map is not None:  # the whole run in one call
        step(history, weights, last=True)
    else:  # the base map in torch: one call per move, given the base parameters of x
        for move in range(iterations - 1):
            step(history[move : move + 1], weights[move : move + 1], False, objective.base(x))
        step(history[iterations - 1 :], weights[:0], True, objective.base(x))
    uniform.set_bit_states(streams)
    x, v, pbest, pcost, gpos = (t.view(slots, runs, *t.shape[1:]) for t in state)
    final = swarm.SwarmState(x, v, pbest, pcost, gpos, history[-1].view(slots, runs))
    return final, history.view(iterations, slots, runs)


def cost_refusal(cost: Cost, structure: NormStructure | None) -> str | None:
    """Why the kernel cannot run ``cost`` (its ``fast_structure``) whatever the problem, or ``None``.

    A cost without a structure runs eager, calling the cost; one whose factors the kernel has no
    code for (``NORM_CODES``) runs eager fused (``Objective``'s ``NormProducts``).
    """
    name = type(cost).__name__
    if structure is None:
        return f"{name}: the cost declares no norm structure (Cost.structure)"
    try:
        norm_codes([structure])
    except ValueError as error:
        return f"{name}: {error} (eager engine, fused)"
    return None


def supports(objective: Objective) -> str | None:
    """``None`` if the kernel can run ``objective``, else the reason it cannot (for ``details``)."""
    if objective.lower.device.type != "cpu" or objective.lower.dtype != torch.float64:
        return "the native kernel runs float64 on the CPU"
    if not objective.use_regressor:
        return "the native kernel needs the regressor (use_regressor)"
    for cost, structure in zip(objective.costs, objective.structures, strict=True):
        refusal = cost_refusal(cost, structure)
        if refusal is not None:
            return refusal
        if "2" in structure.norms and objective.shape[0] != 3:
            return "the native kernel's spectral norm is for 3 joints only"
    library, how, _ = build(objective)
    return None if library is not None else how
