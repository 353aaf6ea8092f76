"""A compiled PSO loop for costs with a declared norm structure (the ``"native"`` engine).

Why: an eager PyTorch step of a paper-sized swarm (20 particles × 4 parameters × a 3 × 10 error
matrix) is ~25 tensor ops of a few microseconds of dispatch each; the work itself is a few
thousand flops. JAX peers compile the whole loop (XLA) and win small swarms by 10×. This module
compiles plain C with the host's C compiler (``cc``/``gcc``, ``-O3 -march=native``, IEEE
arithmetic) the first time it is needed, caches the shared library on disk (``IDKIT_CACHE_DIR`` or
``~/.cache/idkit``, keyed by the source's hash and the host, so later processes only load it) and
calls it through ``ctypes``.

The C step does, for every swarm of the batch, what ``swarm.step`` + ``Objective.__call__`` do in
torch: evaluate ``E = T/d − alpha · Yᵀ/d`` and the product of its norms for every particle,
update personal and global bests, then move the particles (velocity, boundary rule). The robot's
map from search positions to base parameters is traced and written in C where it is an
elementwise formula (``idkit.estimators.base_map``); then whole blocks of moves run in one call.
Otherwise the map stays in torch and the kernel is called once per move. Random numbers come from
the same pre-drawn blocks as the eager engine, so a seed gives the same numbers to both; the
trajectories agree to rounding, and the kernel gives identical numbers on every call and for any
thread count (swarms are split over threads, each swarm on one).

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
from functools import cache
from pathlib import Path

import torch
from torch import Tensor

from idkit.estimators import swarm
from idkit.estimators.base_map import identity_source, map_source
from idkit.estimators.objective import Objective
from idkit.interfaces import Robot

#: Norm name (``idkit.costs.norms.NORMS``) -> code in the C source.
NORM_CODES = {"fro": 1, "2": 2, "1": 3, "inf": 4, "max_row_sq": 5, "max_abs": 6}
#: Most norms one cost may multiply (the paper's f6 has three).
MAX_NORMS = 4
BOUNDARY_CODES = {"clamp": 0, "reflect": 1, "random": 2}
#: Compiler flags: optimised, vectorised for this CPU, IEEE arithmetic (no fast-math, no FMA
#: contraction, so the kernel rounds like the eager engine's separate multiplies and adds).
#: Particles per thread below which the kernel does not start another thread.
PARTICLES_PER_THREAD = 2_000
FLAGS = ("-O3", "-march=native", "-ffp-contract=off", "-fno-fast-math", "-fPIC", "-shared", "-pthread")

SOURCE = r"""
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define MAX_THREADS 64

/*BASE_MAP*/

static double spectral3(const double *e, int64_t N) {
    /* Largest singular value of e[3, N]: Smith's closed form for the top eigenvalue of e e^T. */
    double g[3][3] = {{0}};
    for (int i = 0; i < 3; i++)
        for (int k = i; k < 3; k++) {
            double acc = 0;
            for (int64_t j = 0; j < N; j++) acc += e[i * N + j] * e[k * N + j];
            g[i][k] = g[k][i] = acc;
        }
    double q = (g[0][0] + g[1][1] + g[2][2]) / 3;
    double x = g[0][0] - q, y = g[1][1] - q, z = g[2][2] - q;
    double off = g[0][1] * g[0][1] + g[0][2] * g[0][2] + g[1][2] * g[1][2];
    double p = sqrt((x * x + y * y + z * z + 2 * off) / 6);
    if (!(p > 0)) return sqrt(q > 0 ? q : 0);
    double det = x * (y * z - g[1][2] * g[1][2]) - g[0][1] * (g[0][1] * z - g[1][2] * g[0][2])
               + g[0][2] * (g[0][1] * g[1][2] - y * g[0][2]);
    double r = det / (2 * p * p * p);
    r = r < -1 ? -1 : (r > 1 ? 1 : r);
    double top = q + 2 * p * cos(acos(r) / 3);
    return sqrt(top > 0 ? top : 0);
}

static double norm(int code, const double *e, int64_t n, int64_t N) {
    double best = 0, a;
    switch (code) {
    case 1: /* Frobenius */
        a = 0;
        for (int64_t m = 0; m < n * N; m++) a += e[m] * e[m];
        return sqrt(a);
    case 2: /* spectral, n == 3 */
        return spectral3(e, N);
    case 3: /* largest column (sample) absolute sum */
        for (int64_t j = 0; j < N; j++) {
            a = 0;
            for (int64_t i = 0; i < n; i++) a += fabs(e[i * N + j]);
            if (a > best) best = a;
        }
        return best;
    case 4: /* largest row (joint) absolute sum */
        for (int64_t i = 0; i < n; i++) {
            a = 0;
            for (int64_t j = 0; j < N; j++) a += fabs(e[i * N + j]);
            if (a > best) best = a;
        }
        return best;
    case 5: /* largest row square sum */
        for (int64_t i = 0; i < n; i++) {
            a = 0;
            for (int64_t j = 0; j < N; j++) a += e[i * N + j] * e[i * N + j];
            if (a > best) best = a;
        }
        return best;
    case 6: /* largest absolute entry */
        for (int64_t m = 0; m < n * N; m++)
            if (fabs(e[m]) > best) best = fabs(e[m]);
        return best;
    }
    return NAN;
}

/* Python-style remainder (sign of the divisor), as torch.remainder. */
static double remainder_(double a, double b) {
    double r = fmod(a, b);
    if (r != 0 && ((r < 0) != (b < 0))) r += b;
    return r;
}

/* What stays fixed over a run: sizes, samples, state buffers. Shapes: S swarms x K particles x P.
   alpha[S,K,B] (base parameters of x); linear[L,B,M]; offset[L,M]; slot_of[S] in [0,L);
   codes[L,max_norms] (0 = none); x, v, pbest [S,K,P]; pcost [S,K]; gpos [S,P]. */
typedef struct {
    int64_t S, K, P, B, n, N;
    const double *alpha, *linear, *offset;
    const int64_t *slot_of;
    const int32_t *codes;
    int64_t max_norms;
    double *x, *v, *pbest, *pcost, *gpos;
    int64_t per_particle;
    const double *lower, *upper;
    int64_t boundary;
    double velocity_limit;
    int64_t use_map; /* 1: alpha = base_map(x) here; 0: alpha is given (computed by torch) */
} Batch;

/* Swarms [s0, s1): evaluate x, update personal bests, write each swarm's best into gcost; then,
   if move, move its particles. Swarms are independent, so any split gives the same numbers. */
static int64_t swarm_range(const Batch *batch, int64_t s0, int64_t s1, double *gcost, int64_t move,
                           double w, const double *r1, const double *r2, const double *u3)
{
    int64_t K = batch->K, P = batch->P, B = batch->B, n = batch->n, N = batch->N;
    const double *alpha = batch->alpha, *linear = batch->linear, *offset = batch->offset;
    const int64_t *slot_of = batch->slot_of;
    const int32_t *codes = batch->codes;
    int64_t max_norms = batch->max_norms, per_particle = batch->per_particle, boundary = batch->boundary;
    double *x = batch->x, *v = batch->v, *pbest = batch->pbest, *pcost = batch->pcost, *gpos = batch->gpos;
    const double *lower = batch->lower, *upper = batch->upper;
    double velocity_limit = batch->velocity_limit;
    int64_t M = n * N;
    double *e = (double *)malloc(sizeof(double) * (size_t)(M + B));
    if (!e) return -1;
    double *mapped = e + M;
    for (int64_t s = s0; s < s1; s++) {
        int64_t l = slot_of[s];
        const double *lin = linear + l * B * M, *off = offset + l * M;
        const int32_t *code = codes + l * max_norms;
        for (int64_t k = 0; k < K; k++) {
            const double *a = alpha + (s * K + k) * B;
            if (batch->use_map) {
                base_map(x + (s * K + k) * P, mapped);
                a = mapped;
            }
            memcpy(e, off, sizeof(double) * (size_t)M);
            for (int64_t b = 0; b < B; b++) {
                double ab = a[b];
                const double *row = lin + b * M;
                for (int64_t m = 0; m < M; m++) e[m] += ab * row[m];
            }
            double cost = 1;
            for (int64_t c = 0; c < max_norms && code[c]; c++) cost *= norm(code[c], e, n, N);
            double *pc = pcost + s * K + k;
            if (cost < *pc) { /* strictly better; NaN never is */
                *pc = cost;
                memcpy(pbest + (s * K + k) * P, x + (s * K + k) * P, sizeof(double) * (size_t)P);
            }
        }
        /* global best: first particle with the smallest personal best (NaN propagates, as torch.min) */
        int64_t arg = 0;
        double low = pcost[s * K];
        for (int64_t k = 1; k < K; k++) {
            double c = pcost[s * K + k];
            if (low != low) break;
            if (c < low || c != c) { low = c; arg = k; }
        }
        gcost[s] = low;
        memcpy(gpos + s * P, pbest + (s * K + arg) * P, sizeof(double) * (size_t)P);
        if (!move) continue;
        for (int64_t k = 0; k < K; k++)
            for (int64_t p = 0; p < P; p++) {
                int64_t i = (s * K + k) * P + p, ri = per_particle ? s * K + k : i;
                double xi = x[i];
                double vel = v[i] * w + r1[ri] * (pbest[i] - xi);
                vel = vel + r2[ri] * (gpos[s * P + p] - xi);
                double lo = lower[p], hi = upper[p];
                if (velocity_limit > 0) {
                    double vmax = velocity_limit * (hi - lo);
                    vel = vel < -vmax ? -vmax : (vel > vmax ? vmax : vel);
                }
                double pos = xi + vel;
                if (boundary == 0) {
                    double c = pos < lo ? lo : (pos > hi ? hi : pos);
                    if (c != pos) vel = 0;
                    pos = c;
                } else if (boundary == 1) {
                    double width = hi - lo;
                    double t = pos - lo; /* fmod(t, 2 width) is t itself inside [0, 2 width) */
                    double folded = width - (t >= 0 && t < 2 * width ? t : remainder_(t, 2 * width));
                    pos = hi - fabs(folded);
                    vel = folded > 0 ? vel : (folded < 0 ? -vel : 0 * vel);
                } else {
                    double u = u3[ri];
                    int out_low = pos < lo, out_high = pos > hi;
                    if (out_low) pos = lo + (xi - lo) * u;
                    if (out_high) pos = hi - (hi - xi) * u;
                    if (out_low || out_high) vel = 0;
                }
                x[i] = pos;
                v[i] = vel;
            }
    }
    free(e);
    return 0;
}

/* `count` moves of swarms [s0, s1) (needs use_map): move m evaluates x into history[m], then moves
   with weights[m] and the random numbers block[m] = [draws][S][K][P'] (r1, r2, u3). */
static int64_t moves_range(const Batch *batch, int64_t s0, int64_t s1, double *history, int64_t count,
                           const double *weights, const double *block, int64_t draws)
{
    int64_t stride = batch->S * batch->K * (batch->per_particle ? 1 : batch->P);
    for (int64_t m = 0; m < count; m++) {
        const double *r = block + m * draws * stride;
        int64_t status = swarm_range(batch, s0, s1, history + m * batch->S, 1, weights[m], r, r + stride,
                                     draws > 2 ? r + 2 * stride : NULL);
        if (status) return status;
    }
    return 0;
}

typedef struct {
    const Batch *batch;
    int64_t s0, s1, move;
    double *gcost, w;
    const double *r1, *r2, *u3;
    int64_t count; /* > 0: moves_range over `count` moves with weights and block */
    const double *weights, *block;
    int64_t draws, status;
} Part;

static void *run_part(void *arg) {
    Part *p = (Part *)arg;
    if (p->count > 0)
        p->status = moves_range(p->batch, p->s0, p->s1, p->gcost, p->count, p->weights, p->block, p->draws);
    else
        p->status = swarm_range(p->batch, p->s0, p->s1, p->gcost, p->move, p->w, p->r1, p->r2, p->u3);
    return NULL;
}

static int64_t run_parts(Part *parts, int64_t threads) {
    pthread_t ids[MAX_THREADS];
    int started[MAX_THREADS] = {0};
    for (int64_t t = 1; t < threads; t++)
        started[t] = pthread_create(&ids[t], NULL, run_part, &parts[t]) == 0;
    run_part(&parts[0]);
    int64_t status = parts[0].status;
    for (int64_t t = 1; t < threads; t++) {
        if (started[t]) pthread_join(ids[t], NULL);
        else run_part(&parts[t]); /* could not start a thread: do its share here */
        if (parts[t].status) status = parts[t].status;
    }
    return status;
}

static int64_t clamp_threads(const Batch *batch, int64_t threads) {
    if (threads > MAX_THREADS) threads = MAX_THREADS;
    if (threads > batch->S) threads = batch->S;
    return threads < 1 ? 1 : threads;
}

/* One evaluation (+ move) of all swarms, split over `threads` threads (contiguous swarm ranges). */
int64_t idkit_pso_step(const Batch *batch, double *gcost, int64_t move, double w,
                       const double *r1, const double *r2, const double *u3, int64_t threads)
{
    threads = clamp_threads(batch, threads);
    Part parts[MAX_THREADS];
    for (int64_t t = 0; t < threads; t++) {
        int64_t s0 = batch->S * t / threads, s1 = batch->S * (t + 1) / threads;
        Part part = {batch, s0, s1, move, gcost, w, r1, r2, u3, 0, NULL, NULL, 0, 0};
        parts[t] = part;
    }
    return run_parts(parts, threads);
}

/* `count` moves of all swarms in one call (the base map is in C: nothing to do in between). */
int64_t idkit_pso_moves(const Batch *batch, double *history, int64_t count, const double *weights,
                        const double *block, int64_t draws, int64_t threads)
{
    threads = clamp_threads(batch, threads);
    Part parts[MAX_THREADS];
    for (int64_t t = 0; t < threads; t++) {
        int64_t s0 = batch->S * t / threads, s1 = batch->S * (t + 1) / threads;
        Part part = {batch, s0, s1, 1, history, 0, NULL, NULL, NULL, count, weights, block, draws, 0};
        parts[t] = part;
    }
    return run_parts(parts, threads);
}
"""


def cache_dir() -> Path:
    """Where compiled kernels live: ``IDKIT_CACHE_DIR`` or ``~/.cache/idkit``, then ``native/``."""
    root = os.environ.get("IDKIT_CACHE_DIR") or Path.home() / ".cache" / "idkit"
    return Path(root) / "native"


def _compiler() -> str | None:
    for name in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if name and shutil.which(name):
            return name
    return None


#: The base map of a kernel that reads base parameters computed by torch.
NO_MAP = "static void base_map(const double *x, double *alpha) { (void)x; (void)alpha; }\n"


@cache
def kernel(base_map: str = NO_MAP) -> tuple[ctypes.CDLL | None, str, float]:
    """``(library or None, how it was obtained or why not, seconds spent compiling in this process)``.

    Compiled once per machine and base map (``idkit.estimators.base_map``; cached on disk), loaded
    once per process.
    """
    source = SOURCE.replace("/*BASE_MAP*/", base_map)
    # -march=native makes the library specific to this CPU: the key names the host too.
    key = "\n".join((source, *FLAGS, sys.platform, platform.machine(), platform.node()))
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
                c_file.write_text(source)
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
    batch, ptr, i64 = ctypes.POINTER(_Batch), ctypes.c_void_p, ctypes.c_int64
    signatures = {
        "idkit_pso_step": [batch, ptr, i64, ctypes.c_double, ptr, ptr, ptr, i64],
        "idkit_pso_moves": [batch, ptr, i64, ptr, ptr, i64, i64],
    }
    for name, argtypes in signatures.items():
        function = getattr(library, name)
        function.restype, function.argtypes = i64, argtypes
    return library, how, spent


class _Batch(ctypes.Structure):
    """The C ``Batch`` struct (same field order)."""

    _fields_ = [
        *((name, ctypes.c_int64) for name in ("S", "K", "P", "B", "n", "N")),
        *((name, ctypes.c_void_p) for name in ("alpha", "linear", "offset", "slot_of", "codes")),
        ("max_norms", ctypes.c_int64),
        *((name, ctypes.c_void_p) for name in ("x", "v", "pbest", "pcost", "gpos")),
        ("per_particle", ctypes.c_int64),
        ("lower", ctypes.c_void_p),
        ("upper", ctypes.c_void_p),
        ("boundary", ctypes.c_int64),
        ("velocity_limit", ctypes.c_double),
        ("use_map", ctypes.c_int64),
    ]


class NativeStep:
    """The kernel bound to one batch of swarms: fixed tensors and the state buffers, set once.

    Args:
        linear: ``[L, B, M]`` (``-Yᵀ/d`` per slot), ``offset``: ``[L, 1, M]`` (``T/d``).
        slot_of: ``[S]`` slot of each swarm. ``norms``: per slot, its norm names.
        shape: ``(n, N)`` of the error matrix. ``lower``, ``upper``: the box ``[P]``.
        state: ``(x, v, pbest, pcost, gpos)``, contiguous float64 ``[S, K, P]`` ×3, ``[S, K]``,
            ``[S, P]``, updated in place by every call (a personal best improves where the cost is
            strictly lower, so start ``pcost`` at ``inf``).
        threads: split the swarms over this many threads (results do not depend on it).
        base_map: C source of the robot's base map (``idkit.estimators.base_map``): the kernel
            then computes the base parameters itself and ``moves`` runs many moves per call;
            ``None``: every call is given the base parameters.
    """

    def __init__(
        self,
        linear: Tensor,
        offset: Tensor,
        slot_of: Tensor,
        norms: list[tuple[str, ...]],
        shape: tuple[int, int],
        lower: Tensor,
        upper: Tensor,
        rules: swarm.SwarmRules,
        state: tuple[Tensor, ...],
        threads: int = 1,
        base_map: str | None = None,
    ) -> None:
        library, _, _ = kernel(base_map or NO_MAP)
        if library is None:
            raise RuntimeError("the native PSO kernel is unavailable")
        self.function = library.idkit_pso_step
        self.many = library.idkit_pso_moves
        codes = torch.zeros((len(norms), MAX_NORMS), dtype=torch.int32)
        for slot, names in enumerate(norms):
            codes[slot, : len(names)] = torch.tensor([NORM_CODES[name] for name in names], dtype=torch.int32)
        fixed = {
            "linear": linear.contiguous(),
            "offset": offset.reshape(offset.shape[0], -1).contiguous(),
            "slot_of": slot_of.to(torch.int64).contiguous(),
            "codes": codes,
            "lower": lower.contiguous(),
            "upper": upper.contiguous(),
            **dict(zip(("x", "v", "pbest", "pcost", "gpos"), state, strict=True)),
        }
        if any(not t.is_contiguous() for t in state):
            raise ValueError("native PSO kernel: state buffers must be contiguous")
        self.keep = fixed  # the struct holds raw pointers: keep the tensors alive
        x = state[0]
        self.batch = _Batch(
            *x.shape,
            linear.shape[1],
            *shape,
            None,
            *(fixed[name].data_ptr() for name in ("linear", "offset", "slot_of", "codes")),
            MAX_NORMS,
            *(t.data_ptr() for t in state),
            int(rules.per_particle),
            fixed["lower"].data_ptr(),
            fixed["upper"].data_ptr(),
            BOUNDARY_CODES[rules.boundary],
            float(rules.velocity_limit or 0.0),
            int(base_map is not None),
        )
        self.pointer = ctypes.byref(self.batch)
        # A thread pays only for enough particles (thread start ~20 µs vs ~0.1 µs per particle).
        self.threads = max(1, min(int(threads), x.shape[0] * x.shape[1] // PARTICLES_PER_THREAD))

    def __call__(
        self, alpha: Tensor, best: Tensor, move: tuple[float, Tensor, Tensor, Tensor | None] | None
    ) -> None:
        """Evaluate ``alpha[S, K, B]`` (the base parameters of ``x``), update bests, then move.

        Each swarm's best cost goes to ``best[S]`` (contiguous, e.g. a row of the history);
        ``move`` is ``(w, c1·r1, c2·r2, u)`` (``u`` for the random boundary rule) or ``None`` for
        the last evaluation.
        """
        alpha = alpha.contiguous()  # kept alive in this frame during the call
        self.batch.alpha = alpha.data_ptr()
        if move is None:
            status = self.function(self.pointer, best.data_ptr(), 0, 0.0, None, None, None, self.threads)
        else:
            w, r1, r2, u3 = move
            status = self.function(
                self.pointer,
                best.data_ptr(),
                1,
                w,
                r1.data_ptr(),
                r2.data_ptr(),
                None if u3 is None else u3.data_ptr(),
                self.threads,
            )
        if status != 0:
            raise MemoryError("native PSO kernel: out of memory for one error matrix")

    def moves(self, history: Tensor, weights: Tensor, block: Tensor) -> None:
        """``count`` moves in one call (needs ``base_map``): evaluate into ``history[count, S]``, move.

        ``weights[count]`` are the inertias, ``block[count, draws, S, K, P']`` the scaled random
        numbers of ``Draws.blocks``.
        """
        count = block.shape[0]
        status = self.many(
            self.pointer,
            history.data_ptr(),
            count,
            weights.data_ptr(),
            block.data_ptr(),
            block.shape[1],
            self.threads,
        )
        if status != 0:
            raise MemoryError("native PSO kernel: out of memory for one error matrix")


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

    Every cost of ``objective`` must have a fast structure and the objective must use the
    regressor, on the CPU in float64 (``supports``).
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
    step = NativeStep(
        objective.linear,
        objective.offset,
        torch.arange(slots).repeat_interleave(runs),
        [objective.structures[s % count].norms for s in range(slots)],
        objective.shape,
        lower,
        upper,
        rules,
        state,
        threads,
        base_map,
    )
    history = torch.empty((iterations, slots * runs), dtype=x.dtype)
    if base_map is not None:  # whole blocks of moves per call, nothing in torch in between
        shape, scale = swarm.move_shape(batch_shape, particles, lower, rules)
        weights = torch.tensor([rules.weight(m) for m in range(iterations - 1)], dtype=torch.float64)
        done = 0
        for block in uniform.blocks(shape, scale, iterations - 1):
            count = block.shape[0]
            step.moves(history[done : done + count], weights[done : done + count], block.contiguous())
            done += count
    else:
        numbers = swarm.move_draws(uniform, batch_shape, particles, iterations, lower, rules)
        for move, random in enumerate(numbers):  # random numbers are contiguous slices of a block
            scaled = (rules.weight(move), random[0], random[1], random[2] if len(random) > 2 else None)
            step(objective.base(x), history[move], scaled)
    step(objective.base(x) if base_map is None else x, history[-1], None)
    x, v, pbest, pcost, gpos = (t.view(slots, runs, *t.shape[1:]) for t in state)
    final = swarm.SwarmState(x, v, pbest, pcost, gpos, history[-1].view(slots, runs))
    return final, history.view(iterations, slots, runs)


def supports(objective: Objective) -> str | None:
    """``None`` if the kernel can run ``objective``, else the reason it cannot (for ``details``)."""
    if objective.lower.device.type != "cpu" or objective.lower.dtype != torch.float64:
        return "the native kernel runs float64 on the CPU"
    if not objective.use_regressor:
        return "the native kernel needs the regressor (use_regressor)"
    for cost, structure in zip(objective.costs, objective.structures, strict=True):
        if structure is None or len(structure.norms) > MAX_NORMS:
            return f"cost {type(cost).__name__} declares no norm structure the kernel knows"
        if "2" in structure.norms and objective.shape[0] != 3:
            return "the native kernel's spectral norm is for 3 joints only"
    library, how, _ = kernel(robot_map(objective) or NO_MAP)
    return None if library is not None else how
