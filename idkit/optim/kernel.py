"""The fast swarm kernel: PSO moves of one trial's swarms as machine code, compiled by numba.

Why: an eager PyTorch move of a paper-sized swarm (20 particles × 4 parameters × a 3 × 10 error
matrix) is ~120 tensor ops, each paying torch's dispatch, while the work is a few thousand flops
(``docs/speed.md`` times both). Here a whole block of moves is one call of loops that LLVM compiles
for this CPU — through numba, so no C compiler is needed on the user's machine (this module points
numba's cache at idkit's checked cache directory, ``idkit.optim.cache``; ``docs/speed.md`` has the
measurements behind the choice of numba over a C extension).

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
from numba import carray, njit, types
from numba.extending import intrinsic

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

#: Particles side by side in a trimmed mean's selection (``_trimmed_mean``): vector-wide passes
#: over a scratch ``[M, LANES]`` that stays small for long recordings.
LANES = 64
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
def _base_params(points, first, n, mode, tape, constants, outputs, registers, alpha):  # noqa: ANN001, ANN202
    """``alpha[B, :n]``: the base parameters of points ``points[first : first + n]`` — the points
    themselves (a base-space search, or base parameters given by the caller), or the tape run one
    operation at a time over all points (the dispatch outside the loops, so every loop vectorises)."""
    count = alpha.shape[0]
    points = points[first : first + n]
    if mode != MAP_TAPE:
        for b in range(count):
            for k in range(n):
                alpha[b, k] = points[k, b]
        return
    for row in range(tape.shape[0]):
        op, out, a, b = tape[row, 0], tape[row, 1], tape[row, 2], tape[row, 3]
        if op == OP_X:
            for k in range(n):
                registers[out, k] = points[k, a]
        elif op == OP_CONST:
            value = constants[row]
            for k in range(n):
                registers[out, k] = value
        elif op == OP_ADD:
            for k in range(n):
                registers[out, k] = registers[a, k] + registers[b, k]
        elif op == OP_SUB:
            for k in range(n):
                registers[out, k] = registers[a, k] - registers[b, k]
        elif op == OP_MUL:
            for k in range(n):
                registers[out, k] = registers[a, k] * registers[b, k]
        elif op == OP_DIV:
            for k in range(n):
                registers[out, k] = registers[a, k] / registers[b, k]
        elif op == OP_NEG:
            for k in range(n):
                registers[out, k] = -registers[a, k]
        elif op == OP_SIN:
            for k in range(n):
                registers[out, k] = math.sin(registers[a, k])
        elif op == OP_COS:
            for k in range(n):
                registers[out, k] = math.cos(registers[a, k])
        elif op == OP_SQRT:
            for k in range(n):
                registers[out, k] = math.sqrt(registers[a, k])
        else:  # OP_SQUARE
            for k in range(n):
                registers[out, k] = registers[a, k] * registers[a, k]
    for b in range(count):
        source = outputs[b]
        for k in range(n):
            alpha[b, k] = registers[source, k]


@jit
def _errors(alpha, linear, offset, slot, n, e):  # noqa: ANN001, ANN202
    """``e[M, :n] = offset[slot] + alpha[B, :n] · linear[slot]``, summed in the eager engine's order
    (``offset``, then each base parameter's term in turn), four terms per pass over a row so the
    row stays in registers (a missing fifth, sixth… term adds ``0 · alpha``, which changes nothing
    of a finite sum)."""
    count, last = alpha.shape[0], alpha.shape[0] - 1
    for m in range(offset.shape[1]):
        for b in range(0, count, 4):
            w0 = linear[slot, b, m]
            w1 = linear[slot, b + 1, m] if b + 1 <= last else 0.0
            w2 = linear[slot, b + 2, m] if b + 2 <= last else 0.0
            w3 = linear[slot, b + 3, m] if b + 3 <= last else 0.0
            i1, i2, i3 = min(b + 1, last), min(b + 2, last), min(b + 3, last)
            if b == 0:
                start = offset[slot, m]
                for k in range(n):
                    e[m, k] = (
                        start + alpha[0, k] * w0 + alpha[i1, k] * w1 + alpha[i2, k] * w2 + alpha[i3, k] * w3
                    )
            else:
                for k in range(n):
                    e[m, k] = (
                        e[m, k] + alpha[b, k] * w0 + alpha[i1, k] * w1 + alpha[i2, k] * w2 + alpha[i3, k] * w3
                    )


@jit
def _spectral3(e, n: int, samples: int, gram, out) -> None:  # noqa: ANN001
    """``out[:n]``: the largest singular value of each particle's 3 × N matrix in ``e[3N, :n]``:
    Smith's closed form for the top eigenvalue of its Gram matrix, as
    ``idkit.optim.fused.spectral_norm_3``. The Gram matrices are summed for all particles at once
    (``gram[6, ≥ n]``, particles innermost, so the loop vectorises), each in sample order."""
    g00, g11, g22, g01, g12, g20 = gram[0], gram[1], gram[2], gram[3], gram[4], gram[5]
    for k in range(n):
        g00[k] = g11[k] = g22[k] = g01[k] = g12[k] = g20[k] = 0.0
    for j in range(samples):
        first, second, third = e[j], e[samples + j], e[2 * samples + j]
        for k in range(n):
            a, b, c = first[k], second[k], third[k]
            g00[k] += a * a
            g11[k] += b * b
            g22[k] += c * c
            g01[k] += a * b
            g12[k] += b * c
            g20[k] += c * a
    for k in range(n):
        q = (g00[k] + g11[k] + g22[k]) / 3
        x, y, z = g00[k] - q, g11[k] - q, g22[k] - q
        off = g01[k] * g01[k] + g20[k] * g20[k] + g12[k] * g12[k]
        p = math.sqrt((x * x + y * y + z * z + 2 * off) / 6)
        det = (
            x * (y * z - g12[k] * g12[k])
            - g01[k] * (g01[k] * z - g12[k] * g20[k])
            + g20[k] * (g01[k] * g12[k] - y * g20[k])
        )
        if not p > 0:
            top = q
        else:
            r = det / (2 * p * p * p)
            r = -1.0 if r < -1.0 else (1.0 if r > 1.0 else r)
            top = q + 2 * p * math.cos(math.acos(r) / 3)
        out[k] = math.sqrt(top) if top > 0 else (top if top != top else 0.0)


@jit
def _factor(code, parameter, e, n, joints, out, work, squares):  # noqa: ANN001, ANN202
    """``out[:n]``: factor ``code`` of each particle's error matrix ``e[M, :n]`` (joint-major rows);
    ``work`` (``[6, ≥ n]``) and ``squares`` (``[M, LANES]``) are scratch. Every loop over particles
    is innermost."""
    entries = e.shape[0]
    samples = entries // joints
    row = work[0]
    if code == FRO:
        for k in range(n):
            out[k] = 0.0
        for m in range(entries):
            for k in range(n):
                out[k] += e[m, k] * e[m, k]
        for k in range(n):
            out[k] = math.sqrt(out[k])
    elif code == SPECTRAL:
        _spectral3(e, n, samples, work, out)
    elif code == COLUMN_SUM:  # the largest column (sample) absolute sum
        for k in range(n):
            out[k] = -math.inf
        for j in range(samples):
            for k in range(n):
                row[k] = 0.0
            for i in range(joints):
                for k in range(n):
                    row[k] += abs(e[i * samples + j, k])
            for k in range(n):
                out[k] = _larger(out[k], row[k])
    elif code == ROW_SUM:  # the largest row (joint) absolute sum
        for k in range(n):
            out[k] = -math.inf
        for i in range(joints):
            for k in range(n):
                row[k] = 0.0
            for j in range(samples):
                for k in range(n):
                    row[k] += abs(e[i * samples + j, k])
            for k in range(n):
                out[k] = _larger(out[k], row[k])
    elif code == ROW_SQUARES:  # the largest row square sum
        for k in range(n):
            out[k] = -math.inf
        for i in range(joints):
            for k in range(n):
                row[k] = 0.0
            for j in range(samples):
                for k in range(n):
                    row[k] += e[i * samples + j, k] * e[i * samples + j, k]
            for k in range(n):
                out[k] = _larger(out[k], row[k])
    elif code == MAX_ABS:
        for k in range(n):
            out[k] = -math.inf
        for m in range(entries):
            for k in range(n):
                out[k] = _larger(out[k], abs(e[m, k]))
    elif code == HUBER:  # as idkit.costs.reductions.huber_mean
        for k in range(n):
            out[k] = 0.0
        for m in range(entries):
            for k in range(n):
                a = abs(e[m, k])
                inner = a if a < parameter else parameter
                out[k] += inner * (a - 0.5 * inner)
        for k in range(n):
            out[k] /= entries
    else:  # TRIMMED: the parameter is the number of smallest squares kept
        keep = int(parameter)
        for group in range(0, n, LANES):
            _trimmed_mean(e, group, min(LANES, n - group), keep, squares, work, out)


@jit
def _trimmed_mean(e, first, width, keep, squares, work, out):  # noqa: ANN001, ANN202
    """``out[first : first + width]``: the mean of the ``keep`` smallest squares of each particle's
    entries ``e[M, first : first + width]`` (NaN if one is NaN: NaN is never trimmed away), the
    particles side by side in ``squares[M, ≥ width]`` so that every pass vectorises.

    A selection, not a sort: whichever of the kept or the dropped entries are fewer are moved to one
    end, one extreme per pass (``_select``). A trimmed mean drops a few entries, so this is a few
    passes instead of a sort of every entry (``docs/speed.md``); the kept entries are summed in
    their own order, a rounding difference from sorted order that ``torch.topk`` has too.
    ``work[0:4]``: each particle's extreme, its index, whether its entries are all numbers, its sum.
    """
    entries = e.shape[0]
    extreme, index, finite, total = work[0], work[1], work[2], work[3]
    for w in range(width):
        finite[w] = 1.0
    for m in range(entries):
        source, target = e[m, first:], squares[m]
        for w in range(width):
            target[w] = source[w] * source[w]
            finite[w] = finite[w] if target[w] == target[w] else 0.0
    if keep <= entries - keep:  # move the kept (smallest) to the front
        for j in range(keep):
            _select(squares, width, j, j + 1, entries, True, extreme, index)
    else:  # move the dropped (largest) to the back
        for j in range(entries - 1, keep - 1, -1):
            _select(squares, width, j, 0, j, False, extreme, index)
    for w in range(width):
        total[w] = 0.0
    for m in range(keep):
        row = squares[m]
        for w in range(width):
            total[w] += row[w]
    for w in range(width):
        out[first + w] = total[w] / keep if finite[w] else math.nan


@jit
def _select(squares, width, j, start, stop, smallest, extreme, index):  # noqa: ANN001, ANN202
    """One pass of the selection, for each particle (column of ``squares``): swap row ``j`` with the
    first row of ``[start, stop)`` holding a smaller (``smallest``) or larger value than every
    other there and than row ``j``'s, if any (``extreme``, ``index``: scratch ``[≥ width]``)."""
    end = squares[j]
    for w in range(width):
        extreme[w], index[w] = end[w], j
    for m in range(start, stop):
        row = squares[m]
        if smallest:
            for w in range(width):
                better = row[w] < extreme[w]
                extreme[w] = row[w] if better else extreme[w]
                index[w] = m if better else index[w]
        else:
            for w in range(width):
                better = row[w] > extreme[w]
                extreme[w] = row[w] if better else extreme[w]
                index[w] = m if better else index[w]
    for w in range(width):
        squares[int(index[w]), w] = end[w]
        end[w] = extreme[w]


@jit
def _evaluate(
    points,
    x,
    first,
    count,
    pbest,
    pcost,
    gpos,
    history,
    move,
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
    registers,
    alpha,
    e,
    cost,
    work,
    squares,
):  # noqa: ANN001, ANN202
    """Evaluate swarms ``[first, first + count)`` (their points are rows of ``points``: the positions,
    or the base parameters given by the caller): personal bests where strictly lower, each swarm's
    best (the first particle with the lowest personal best) into ``gpos`` and its cost into
    ``history[move, s − first]``. Swarms of one slot are evaluated side by side, up to ``TILE``
    particles at a time: long loops for the vector units, an error matrix that stays in the cache.
    The work arrays (``registers``, ``alpha``, ``e``, ``cost``, ``work``) are ``[rows, ≥ tile]``; only their
    first ``n`` columns are used, indexed without slicing (a slice would cost a reference count
    per use, more than a small tile's arithmetic)."""
    particles, dimension = x.shape[1], x.shape[2]
    per_tile = max(1, TILE // particles)  # swarms per tile (a swarm larger than TILE: one alone)
    s = first
    while s < first + count:
        slot, stop = slot_of[s], min(s + per_tile, first + count)
        while stop > s + 1 and slot_of[stop - 1] != slot:
            stop -= 1
        n = (stop - s) * particles
        _base_params(points, s * particles, n, mode, tape, constants, outputs, registers, alpha)
        _errors(alpha, linear, offset, slot, n, e)
        for f in range(codes.shape[1]):
            if codes[slot, f] == 0:
                break
            _factor(codes[slot, f], params[slot, f], e, n, joints, cost[min(f, 1)], work, squares)
            if f > 0:
                for k in range(n):
                    cost[0, k] = cost[0, k] * cost[1, k]
        for t in range(s, stop):
            costs = cost[0, (t - s) * particles :]
            for k in range(particles):
                if costs[k] < pcost[t, k]:  # strictly; NaN never is
                    pcost[t, k] = costs[k]
                    for p in range(dimension):
                        pbest[t, k, p] = x[t, k, p]
            best, low = 0, pcost[t, 0]
            for k in range(1, particles):
                if pcost[t, k] < low:
                    best, low = k, pcost[t, k]
            for p in range(dimension):
                gpos[t, p] = pbest[t, best, p]
            history[move, t - first] = low
        s = stop


@jit
def _move(xs, vs, best, gbest, r1, r2, u3, weight, box, boundary, per_particle, dimension, scratch):  # noqa: ANN001, ANN202
    """Move a tile of swarms (their positions ``xs``, velocities ``vs``, personal bests ``best``
    and each coordinate's swarm best ``gbest``, flat ``[n]``) with inertia ``weight`` and uniform
    numbers ``r1``, ``r2`` (``u3`` for random walls), flat ``[n]`` (``[n / P]`` per particle), then
    apply the boundary rule: what ``swarm.step`` does, operation by operation, in flat loops (indexed
    by the loop counter alone, so that they vectorise).

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

    The loop of moves (``_moves``) runs on views without reference counts (``_unowned``), so the
    slices it takes per tile cost no atomic operations, and its loops index by their counter alone
    (a computed index is checked for wrapping around, which keeps a loop from vectorising).
    """
    swarms, particles, dimension = x.shape[0], x.shape[1], x.shape[2]
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
    scratch = np.empty((4, span))  # spread numbers, moved positions, the swarms' bests per coordinate
    tile = per_tile * particles
    # the points evaluated, one row per particle: positions, or the base parameters given
    if mode == MAP_GIVEN:
        points = given.reshape((given.shape[0] * given.shape[1], given.shape[2]))
    else:
        points = x.reshape((swarms * particles, dimension))
    # work arrays for a tile of particles: registers of the base-map tape, base parameters, error
    # matrix, costs (the product and one factor), per-factor sums
    registers = np.empty((max(tape.shape[0], 1), tile))
    alpha = np.empty((base, tile))
    e = np.empty((entries, tile))
    cost = np.empty((2, tile))
    work = np.empty((6, tile))
    squares = np.empty((entries, LANES))
    flat_x, flat_v, flat_best = x.reshape(x.size), v.reshape(v.size), pbest.reshape(pbest.size)
    u = _unowned
    _moves(
        rng, first, count, weights, last, u(history), u(x), u(pbest), u(pcost), u(gpos), u(linear), u(offset),
        u(slot_of), u(codes), u(params), joints, mode, u(tape), u(tape_constants), u(outputs), u(points),
        u(registers), u(alpha), u(e), u(cost), u(work), u(squares), u(random), u(box), u(scratch), u(flat_x),
        u(flat_v), u(flat_best), boundary, per_particle, kinds, block, per_tile, width,
    )  # fmt: skip


@jit
def _moves(
    rng, first, count, weights, last, history, x, pbest, pcost, gpos, linear, offset, slot_of, codes, params,
    joints, mode, tape, tape_constants, outputs, points, registers, alpha, e, cost, work, squares, random,
    box, scratch, flat_x, flat_v, flat_best, boundary, per_particle, kinds, block, per_tile, width,
):  # fmt: skip  # noqa: ANN001, ANN202
    """The loop of ``run_trial``, on views that carry no reference count (``_unowned``)."""
    particles, dimension = x.shape[1], x.shape[2]
    coordinates = particles * dimension
    gbest = scratch[3]
    moves = weights.shape[0]
    for m in range(moves + (1 if last else 0)):
        _evaluate(
            points, x, first, count, pbest, pcost, gpos, history, m, linear, offset, slot_of, codes, params,
            joints, mode, tape, tape_constants, outputs, registers, alpha, e, cost, work, squares,
        )  # fmt: skip
        if m == moves:
            break
        for i in range(kinds * block):
            random[i] = rng.random()
        for s in range(first, first + count, per_tile):
            stop = min(s + per_tile, first + count)
            n = (stop - s) * coordinates
            for t in range(s, stop):
                for k in range(particles):
                    # a view per particle: indexed by the loop counter alone, no index wraps around
                    target = gbest[((t - s) * particles + k) * dimension :]
                    for p in range(dimension):
                        target[p] = gpos[t, p]
            c0, c1, at = (s - first) * particles * width, (stop - first) * particles * width, s * coordinates
            _move(
                flat_x[at : at + n], flat_v[at : at + n], flat_best[at : at + n], gbest[:n], random[c0:c1],
                random[block + c0 : block + c1], random[(kinds - 1) * block + c0 : (kinds - 1) * block + c1],
                weights[m], box, boundary, per_particle, dimension, scratch,
            )  # fmt: skip


@intrinsic
def _data_pointer(context, array):  # noqa: ANN001, ANN202
    """The data pointer of a C-contiguous ``array`` typed ``CPointer(dtype)``, as ``numba.carray``
    takes it (any other layout is a typing error: ``carray`` reads its data as C-contiguous)."""
    if not isinstance(array, types.Array) or array.layout != "C":
        return None

    def generate(codegen, builder, signature, arguments):  # noqa: ANN001, ANN202
        return codegen.make_array(signature.args[0])(codegen, builder, arguments[0]).data

    return types.CPointer(array.dtype)(array), generate


@jit
def _unowned(array):  # noqa: ANN001, ANN202
    """A view of ``array`` without a reference count (``numba.carray`` over its data). Every array
    passed to a compiled function is reference-counted on entry and exit — atomic operations, which
    cost a one-run fit a quarter of its kernel time —, a view without one only a null test. The
    caller keeps ``array`` alive while the view is used."""
    return carray(_data_pointer(array), array.shape)


numba.core.config.CACHE_DIR = _previous_cache_dir
