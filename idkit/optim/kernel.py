"""The fast swarm kernel: PSO moves of one trial's swarms as machine code, compiled by numba.

Why: an eager PyTorch move of a paper-sized swarm (20 particles × 4 parameters × a 3 × 10 error
matrix) is ~120 tensor ops of a few microseconds of dispatch each, while the work is a few thousand
flops. Here a whole block of moves is one call of loops that LLVM compiles for this CPU — through
numba, so no C compiler is needed on the user's machine (this module points numba's cache at
idkit's checked cache directory, ``idkit.optim.cache``; ``docs/speed.md`` has the measurements
behind the choice of numba over a C extension).

What one call does, for the swarms ``[first, first + count)`` of one trial, ``moves`` times:
evaluate every particle (base parameters, error ``E = offset + alpha · linear``, the product of
the slot's factors; the swarms of one slot side by side, ``TILE`` particles at a time), update the
personal and global bests, draw the move's uniform numbers from the trial's generator
(``rng.random()``: numpy's bit generator, through numba's documented support for
``np.random.Generator`` arguments) and move the particles (velocity, boundary rule); then, if
``last``, one more evaluation. The same numbers in the same order as the eager engine
(``idkit.optim.swarm``), the same operations in the same order, IEEE arithmetic (no fast-math):
the two engines agree to rounding.

Array conventions (float64 unless said): positions ``x``, velocities ``v``, personal bests
``pbest`` ``[S, K, P]``; ``pcost`` ``[S, K]``; ``gpos`` ``[S, P]``; per slot ``linear[L, B, M]``
and ``offset[L, M]`` with ``M = joints × samples`` joint-major; ``slot_of[S]`` (int64);
``codes``/``params`` ``[L, F]`` (int64 factor codes, ``0`` = none, and their parameters; the codes
and array layouts are ``idkit.optim.codes``). Inside, an error matrix is ``e[M, n]`` for a tile of
``n`` particles, particles innermost and C-contiguous, so every loop over them vectorises.
"""

from __future__ import annotations

import math
from pathlib import Path

import numba.core.config
import numpy as np
from numba import njit

from idkit.optim import cache, codes
from idkit.optim.codes import (
    BOUNDARY,
    C1,
    C2,
    CLAMP,
    COLUMN_SUM,
    FRO,
    HUBER,
    MAP_GIVEN,
    MAP_MODE,
    MAP_TAPE,
    MAX_ABS,
    OP_ADD,
    OP_CONST,
    OP_COS,
    OP_DIV,
    OP_MUL,
    OP_NEG,
    OP_SIN,
    OP_SQRT,
    OP_SUB,
    OP_X,
    PER_PARTICLE,
    RANDOM,
    REFLECT,
    ROW_SQUARES,
    ROW_SUM,
    SPECTRAL,
    VELOCITY_LIMIT,
)

#: The kernel cache's folder and manifest (``cache.prepared``: owner-only, damaged files removed),
#: keyed by this file's and the calling convention's source. numba binds a function's disk cache
#: when it is decorated, so its cache directory points there while these functions are defined,
#: and only then.
FOLDER, MANIFEST = cache.prepared(
    "kernel", cache.digest(Path(__file__).read_bytes() + Path(codes.__file__).read_bytes())
)
_previous_cache_dir = numba.core.config.CACHE_DIR
numba.core.config.CACHE_DIR = str(FOLDER)

jit = njit(cache=True, nogil=True, error_model="numpy")

#: Particles evaluated together (the swarms of one slot side by side): long loops for the vector
#: units, while the error matrix stays in the cache (30 entries × 256 × 8 B = 60 kB).
TILE = 256


@jit
def _larger(current: float, value: float) -> float:
    """The running maximum, NaN-propagating as ``torch.amax``."""
    if current == current and not value <= current:
        return value
    return current


@jit
def _base_params(points, mode, tape, constants, outputs, registers, alpha):  # noqa: ANN001, ANN202
    """``alpha[B, n]``: the base parameters of ``points[n, P]`` — the points themselves (a base-space
    search, or base parameters given by the caller), or the tape run one operation at a time over
    all points (the dispatch outside the loops, so every loop vectorises)."""
    count, n = alpha.shape
    if mode != MAP_TAPE:
        for b in range(count):
            for k in range(n):
                alpha[b, k] = points[k, b]
        return
    for row in range(tape.shape[0]):
        op, out, a, b = tape[row, 0], tape[row, 1], tape[row, 2], tape[row, 3]
        target, left, right = registers[out, :n], registers[a, :n], registers[b, :n]
        if op == OP_X:
            for k in range(n):
                target[k] = points[k, a]
        elif op == OP_CONST:
            target[:] = constants[row]
        elif op == OP_ADD:
            for k in range(n):
                target[k] = left[k] + right[k]
        elif op == OP_SUB:
            for k in range(n):
                target[k] = left[k] - right[k]
        elif op == OP_MUL:
            for k in range(n):
                target[k] = left[k] * right[k]
        elif op == OP_DIV:
            for k in range(n):
                target[k] = left[k] / right[k]
        elif op == OP_NEG:
            for k in range(n):
                target[k] = -left[k]
        elif op == OP_SIN:
            for k in range(n):
                target[k] = math.sin(left[k])
        elif op == OP_COS:
            for k in range(n):
                target[k] = math.cos(left[k])
        elif op == OP_SQRT:
            for k in range(n):
                target[k] = math.sqrt(left[k])
        else:  # OP_SQUARE
            for k in range(n):
                target[k] = left[k] * left[k]
    for b in range(count):
        alpha[b, :] = registers[outputs[b], :n]


@jit
def _errors(alpha, linear, offset, e):  # noqa: ANN001, ANN202
    """``e[M, n] = offset[M] + alpha[B, n] · linear[B, M]``, summed in the eager engine's order
    (``offset``, then each base parameter's term in turn), four terms per pass over a row so the
    row stays in registers (a missing fifth, sixth… term adds ``0 · alpha``, which changes nothing
    of a finite sum)."""
    count, n = alpha.shape
    for m in range(offset.shape[0]):
        row = e[m]
        for k in range(n):
            row[k] = offset[m]
        for b in range(0, count, 4):
            last = count - 1
            w0 = linear[b, m]
            w1 = linear[b + 1, m] if b + 1 <= last else 0.0
            w2 = linear[b + 2, m] if b + 2 <= last else 0.0
            w3 = linear[b + 3, m] if b + 3 <= last else 0.0
            a0, a1, a2, a3 = (
                alpha[b],
                alpha[min(b + 1, last)],
                alpha[min(b + 2, last)],
                alpha[min(b + 3, last)],
            )
            for k in range(n):
                row[k] = row[k] + a0[k] * w0 + a1[k] * w1 + a2[k] * w2 + a3[k] * w3


@jit
def _spectral3(e, k: int, samples: int) -> float:  # noqa: ANN001
    """Largest singular value of the 3 × N matrix of particle ``k``: Smith's closed form for the top
    eigenvalue of its Gram matrix, as ``idkit.optim.fused.spectral_norm_3``."""
    g00 = g11 = g22 = g01 = g12 = g20 = 0.0
    for j in range(samples):
        a, b, c = e[j, k], e[samples + j, k], e[2 * samples + j, k]
        g00 += a * a
        g11 += b * b
        g22 += c * c
        g01 += a * b
        g12 += b * c
        g20 += c * a
    q = (g00 + g11 + g22) / 3
    x, y, z = g00 - q, g11 - q, g22 - q
    off = g01 * g01 + g20 * g20 + g12 * g12
    p = math.sqrt((x * x + y * y + z * z + 2 * off) / 6)
    det = x * (y * z - g12 * g12) - g01 * (g01 * z - g12 * g20) + g20 * (g01 * g12 - y * g20)
    if not p > 0:
        top = q
    else:
        r = det / (2 * p * p * p)
        r = -1.0 if r < -1.0 else (1.0 if r > 1.0 else r)
        top = q + 2 * p * math.cos(math.acos(r) / 3)
    return math.sqrt(top) if top > 0 else (top if top != top else 0.0)


@jit
def _factor(code, parameter, e, joints, out, sums):  # noqa: ANN001, ANN202
    """``out[K]``: factor ``code`` of each particle's error matrix ``e[M, K]`` (joint-major rows);
    ``sums`` is scratch of at least ``max(M, K)``. Every loop over particles is innermost."""
    entries, particles = e.shape
    samples = entries // joints
    row = sums[:particles]
    if code == FRO:
        out[:] = 0.0
        for m in range(entries):
            for k in range(particles):
                out[k] += e[m, k] * e[m, k]
        for k in range(particles):
            out[k] = math.sqrt(out[k])
    elif code == SPECTRAL:
        for k in range(particles):
            out[k] = _spectral3(e, k, samples)
    elif code == COLUMN_SUM:  # the largest column (sample) absolute sum
        out[:] = -math.inf
        for j in range(samples):
            row[:] = 0.0
            for i in range(joints):
                for k in range(particles):
                    row[k] += abs(e[i * samples + j, k])
            for k in range(particles):
                out[k] = _larger(out[k], row[k])
    elif code == ROW_SUM:  # the largest row (joint) absolute sum
        out[:] = -math.inf
        for i in range(joints):
            row[:] = 0.0
            for j in range(samples):
                for k in range(particles):
                    row[k] += abs(e[i * samples + j, k])
            for k in range(particles):
                out[k] = _larger(out[k], row[k])
    elif code == ROW_SQUARES:  # the largest row square sum
        out[:] = -math.inf
        for i in range(joints):
            row[:] = 0.0
            for j in range(samples):
                for k in range(particles):
                    row[k] += e[i * samples + j, k] * e[i * samples + j, k]
            for k in range(particles):
                out[k] = _larger(out[k], row[k])
    elif code == MAX_ABS:
        out[:] = -math.inf
        for m in range(entries):
            for k in range(particles):
                out[k] = _larger(out[k], abs(e[m, k]))
    elif code == HUBER:  # as idkit.costs.reductions.huber_mean
        out[:] = 0.0
        for m in range(entries):
            for k in range(particles):
                a = abs(e[m, k])
                inner = a if a < parameter else parameter
                out[k] += inner * (a - 0.5 * inner)
        for k in range(particles):
            out[k] /= entries
    else:  # TRIMMED: the parameter is the number of smallest squares kept
        keep = int(parameter)
        column = sums[:entries]
        for k in range(particles):
            for m in range(entries):
                column[m] = e[m, k] * e[m, k]
            ordered = np.sort(column)  # NaN sorts last: checked below, never trimmed away
            total = 0.0
            for m in range(keep):
                total += ordered[m]
            out[k] = math.nan if ordered[entries - 1] != ordered[entries - 1] else total / keep


@jit
def _evaluate(
    x,
    first,
    count,
    pbest,
    pcost,
    gpos,
    history,
    linear,
    offset,
    slot_of,
    codes,
    params,
    joints,
    mode,
    tape,
    constants,
    outputs,
    given,
    work,
):  # noqa: ANN001, ANN202
    """Evaluate swarms ``[first, first + count)``: personal bests where strictly lower, each swarm's
    best (the first particle with the lowest personal best) into ``gpos`` and its cost into
    ``history[s − first]``. Swarms of one slot are evaluated side by side, up to ``TILE`` particles
    at a time: long loops for the vector units, an error matrix that stays in the cache."""
    particles, dimension = x.shape[1], x.shape[2]
    entries, count_base = offset.shape[1], linear.shape[1]
    per_tile = max(1, TILE // particles)  # swarms per tile (a swarm larger than TILE: one alone)
    s = first
    while s < first + count:
        slot, stop = slot_of[s], min(s + per_tile, first + count)
        while stop > s + 1 and slot_of[stop - 1] != slot:
            stop -= 1
        n = (stop - s) * particles
        source = x[s:stop] if mode != MAP_GIVEN else given[s:stop]
        points = source.reshape((n, source.shape[2]))
        # the work arrays as C-contiguous [rows, n] (a slice [:, :n] would not be, and its loops
        # would not vectorise)
        registers = work[0][: max(tape.shape[0], 1) * n].reshape((max(tape.shape[0], 1), n))
        alpha = work[1][: count_base * n].reshape((count_base, n))
        e = work[2][: entries * n].reshape((entries, n))
        cost, value = work[3][:n], work[3][n : 2 * n]
        _base_params(points, mode, tape, constants, outputs, registers, alpha)
        _errors(alpha, linear[slot], offset[slot], e)
        for f in range(codes.shape[1]):
            if codes[slot, f] == 0:
                break
            _factor(codes[slot, f], params[slot, f], e, joints, cost if f == 0 else value, work[4])
            if f > 0:
                for k in range(n):
                    cost[k] = cost[k] * value[k]
        for t in range(s, stop):
            base = (t - s) * particles
            for k in range(particles):
                if cost[base + k] < pcost[t, k]:  # strictly; NaN never is
                    pcost[t, k] = cost[base + k]
                    for p in range(dimension):
                        pbest[t, k, p] = x[t, k, p]
            best, low = 0, pcost[t, 0]
            for k in range(1, particles):
                if pcost[t, k] < low:
                    best, low = k, pcost[t, k]
            for p in range(dimension):
                gpos[t, p] = pbest[t, best, p]
            history[t - first] = low
        s = stop


@jit
def _move(xs, vs, best, gbest, r1, r2, u3, weight, box, boundary, per_particle, dimension, scratch):  # noqa: ANN001, ANN202
    """Move a tile of swarms (their positions ``xs``, velocities ``vs``, personal bests ``best``
    and each coordinate's swarm best ``gbest``, flat ``[n]``) with inertia ``weight`` and uniform
    numbers ``r1``, ``r2`` (``u3`` for random walls), flat ``[n]`` (``[n / P]`` per particle), then
    apply the boundary rule: what ``swarm.step`` does, operation by operation, in flat loops.

    ``box``: per coordinate ``[c1, c2, lower, upper, width, v_max]``, rows ``[6, ≥ n]``."""
    n = xs.shape[0]
    lower, upper, width, vmax = box[2], box[3], box[4], box[5]
    scaled1, scaled2, moved = scratch[0], scratch[1], scratch[2]
    if per_particle:  # one number per particle: spread over its coordinates
        for k in range(n // dimension):
            for p in range(dimension):
                scaled1[k * dimension + p] = r1[k]
                scaled2[k * dimension + p] = r2[k]
        r1, r2 = scaled1[:n], scaled2[:n]
    for i in range(n):
        velocity = vs[i] * weight + (box[0, i] * r1[i]) * (best[i] - xs[i])
        velocity = velocity + (box[1, i] * r2[i]) * (gbest[i] - xs[i])
        velocity = -vmax[i] if velocity < -vmax[i] else velocity
        velocity = vmax[i] if velocity > vmax[i] else velocity
        vs[i] = velocity
        moved[i] = xs[i] + velocity
    if boundary == CLAMP:
        for i in range(n):
            low = lower[i] if moved[i] < lower[i] else moved[i]
            clamped = upper[i] if low > upper[i] else low
            vs[i] = vs[i] * (1.0 if clamped == moved[i] else 0.0)
            xs[i] = clamped
    elif boundary == REFLECT:
        # t = (x − lower) mod 2·width, as torch.remainder: t itself on [0, 2 width), t + 2 width on
        # [−2 width, 0) (exact); farther out (rare) the full remainder. Then folded onto the box.
        far = False
        for i in range(n):
            moved[i] = moved[i] - lower[i]
            far |= not (moved[i] >= -2 * width[i] and moved[i] < 2 * width[i])
        if far:
            for i in range(n):
                if not (moved[i] >= -2 * width[i] and moved[i] < 2 * width[i]):
                    moved[i] = np.fmod(moved[i], 2 * width[i])
        for i in range(n):
            t = moved[i] + 2 * width[i] if moved[i] < 0 else moved[i]
            folded = width[i] - t
            xs[i] = upper[i] - abs(folded)
            vs[i] = vs[i] * ((1.0 if folded > 0 else 0.0) - (1.0 if folded < 0 else 0.0))
    else:  # RANDOM: between the previous position and the wall it crossed
        for i in range(n):
            u = u3[i // dimension] if per_particle else u3[i]
            out_low, out_high = moved[i] < lower[i], moved[i] > upper[i]
            position = lower[i] + (xs[i] - lower[i]) * u if out_low else moved[i]
            xs[i] = upper[i] - (upper[i] - xs[i]) * u if out_high else position
            vs[i] = 0.0 if out_low or out_high else vs[i]


@jit
def run_trial(  # noqa: ANN201, PLR0913
    rng,  # noqa: ANN001
    first,  # noqa: ANN001
    count,  # noqa: ANN001
    weights,  # noqa: ANN001
    last,  # noqa: ANN001
    history,  # noqa: ANN001
    x,  # noqa: ANN001
    v,  # noqa: ANN001
    pbest,  # noqa: ANN001
    pcost,  # noqa: ANN001
    gpos,  # noqa: ANN001
    linear,  # noqa: ANN001
    offset,  # noqa: ANN001
    slot_of,  # noqa: ANN001
    codes,  # noqa: ANN001
    params,  # noqa: ANN001
    joints,  # noqa: ANN001
    lower,  # noqa: ANN001
    upper,  # noqa: ANN001
    constants,  # noqa: ANN001
    flags,  # noqa: ANN001
    tape,  # noqa: ANN001
    tape_constants,  # noqa: ANN001
    outputs,  # noqa: ANN001
    given,  # noqa: ANN001
):
    """``len(weights)`` moves of swarms ``[first, first + count)`` (one trial: they draw from ``rng``),
    then one more evaluation if ``last``. Evaluation ``m`` of the call writes each swarm's best cost
    to ``history[m, s - first]``.

    ``constants``: ``[c1, c2, velocity limit as a fraction of the box width (0: none)]``;
    ``flags``: ``[boundary rule, per-particle numbers (0/1), base-map mode]``. A move draws, in
    order, ``r1`` for every swarm, then ``r2``, then (random walls) ``u3``, each ``[count, K, P]``
    (``[count, K, 1]`` per particle), swarm-major: the eager engine's blocks.
    """
    particles, dimension = x.shape[1], x.shape[2]
    entries, base, coordinates = offset.shape[1], linear.shape[1], particles * dimension
    limit = constants[VELOCITY_LIMIT]
    boundary, per_particle, mode = flags[BOUNDARY], flags[PER_PARTICLE], flags[MAP_MODE]
    width = 1 if per_particle else dimension
    kinds = 3 if boundary == RANDOM else 2
    block = count * particles * width
    random = np.empty(kinds * block)
    per_tile = max(TILE // particles, 1)  # swarms moved (and evaluated) together
    span = per_tile * coordinates
    box = np.empty((6, span))  # c1, c2, the box and the velocity limit of every coordinate of a tile
    for i in range(span):
        p = i % dimension
        box[0, i], box[1, i], box[2, i], box[3, i] = constants[C1], constants[C2], lower[p], upper[p]
        box[4, i] = upper[p] - lower[p]
        box[5, i] = limit * box[4, i] if limit > 0 else math.inf
    scratch = np.empty((4, span))  # scaled numbers, moved positions, the swarms' bests per coordinate
    tile = per_tile * particles
    # flat work arrays for a tile of particles (``_evaluate`` shapes them per tile): registers of
    # the base-map tape, base parameters, error matrix, costs, per-factor sums
    work = (
        np.empty(max(tape.shape[0], 1) * tile),
        np.empty(base * tile),
        np.empty(entries * tile),
        np.empty(2 * tile),
        np.empty(max(entries, tile)),
    )
    moves = weights.shape[0]
    for m in range(moves + (1 if last else 0)):
        _evaluate(
            x, first, count, pbest, pcost, gpos, history[m], linear, offset, slot_of, codes, params, joints,
            mode, tape, tape_constants, outputs, given, work,
        )  # fmt: skip
        if m == moves:
            break
        for i in range(kinds * block):
            random[i] = rng.random()
        for s in range(first, first + count, per_tile):
            stop = min(s + per_tile, first + count)
            n, gbest = (stop - s) * coordinates, scratch[3]
            for t in range(s, stop):
                for k in range(particles):
                    start = ((t - s) * particles + k) * dimension
                    gbest[start : start + dimension] = gpos[t]
            c0, c1 = (s - first) * particles * width, (stop - first) * particles * width
            _move(
                x[s:stop].reshape(n), v[s:stop].reshape(n), pbest[s:stop].reshape(n), gbest[:n],
                random[c0:c1], random[block + c0 : block + c1],
                random[(kinds - 1) * block + c0 : (kinds - 1) * block + c1],
                weights[m], box, boundary, per_particle, dimension, scratch,
            )  # fmt: skip


numba.core.config.CACHE_DIR = _previous_cache_dir
