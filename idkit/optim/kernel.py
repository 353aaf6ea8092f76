"""The fast swarm kernel: PSO moves of one trial's swarms as machine code, compiled by numba.

Why: an eager PyTorch move of a paper-sized swarm (20 particles × 4 parameters × a 3 × 10 error
matrix) is ~120 tensor ops of a few microseconds of dispatch each, while the work is a few thousand
flops. Here a whole block of moves is one call of loops that LLVM compiles for this CPU — through
numba, so no C compiler is needed on the user's machine (``idkit.optim.fast`` imports this module
with numba's cache pointed at idkit's checked cache directory; ``docs/speed.md`` has the
measurements behind the choice).

What one call does, for the swarms ``[first, first + count)`` of one trial: ``moves`` times, draw
the move's uniform numbers from the trial's generator (``rng.random()``: numpy's bit generator,
through numba's documented support for ``np.random.Generator`` arguments), evaluate every
particle (base parameters, error ``E = offset + alpha · linear``, the product of the slot's
factors), update the personal and global bests and move the particles (velocity, boundary rule);
then, if ``last``, one more evaluation. The same numbers in the same order as the eager engine
(``idkit.optim.swarm``), the same operations in the same order, IEEE arithmetic (no fast-math):
the two engines agree to rounding.

Array conventions (float64 unless said): positions ``x``, velocities ``v``, personal bests
``pbest`` ``[S, K, P]``; ``pcost`` ``[S, K]``; ``gpos`` ``[S, P]``; per slot ``linear[L, B, M]``
and ``offset[L, M]`` with ``M = joints × samples`` joint-major; ``slot_of[S]`` (int64);
``codes``/``params`` ``[L, F]`` (int64 factor codes, ``0`` = none, and their parameters). Inside,
an error matrix is ``e[M, K]``: particles innermost, so every loop over particles vectorises.
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
    MAP_IDENTITY,
    MAP_MODE,
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

# numba binds a function's disk cache when it is decorated: point it at idkit's checked directory
# (``cache.kernel_folder``: owner-only, damaged files removed) for these functions only.
#: The kernel cache's folder and manifest, keyed by this file's and the calling convention's source.
FOLDER, MANIFEST = cache.prepared(
    "kernel", cache.digest(Path(__file__).read_bytes() + Path(codes.__file__).read_bytes())
)
_previous_cache_dir = numba.core.config.CACHE_DIR
numba.core.config.CACHE_DIR = str(FOLDER)

jit = njit(cache=True, nogil=True, error_model="numpy")


@jit
def _larger(current: float, value: float) -> float:
    """The running maximum, NaN-propagating as ``torch.amax``."""
    if current == current and not value <= current:
        return value
    return current


@jit
def _base_params(x, s, mode, tape, constants, outputs, given, registers, alpha):  # noqa: ANN001, ANN202
    """``alpha[B, K]``: the base parameters of swarm ``s``'s positions ``x[s]``."""
    particles, count = x.shape[1], alpha.shape[0]
    if mode == MAP_IDENTITY:
        for b in range(count):
            for k in range(particles):
                alpha[b, k] = x[s, k, b]
        return
    if mode == MAP_GIVEN:
        for b in range(count):
            for k in range(particles):
                alpha[b, k] = given[s, k, b]
        return
    for row in range(tape.shape[0]):
        op, out, a, b = tape[row, 0], tape[row, 1], tape[row, 2], tape[row, 3]
        for k in range(particles):
            if op == OP_X:
                registers[out, k] = x[s, k, a]
            elif op == OP_CONST:
                registers[out, k] = constants[row]
            elif op == OP_ADD:
                registers[out, k] = registers[a, k] + registers[b, k]
            elif op == OP_SUB:
                registers[out, k] = registers[a, k] - registers[b, k]
            elif op == OP_MUL:
                registers[out, k] = registers[a, k] * registers[b, k]
            elif op == OP_DIV:
                registers[out, k] = registers[a, k] / registers[b, k]
            elif op == OP_NEG:
                registers[out, k] = -registers[a, k]
            elif op == OP_SIN:
                registers[out, k] = math.sin(registers[a, k])
            elif op == OP_COS:
                registers[out, k] = math.cos(registers[a, k])
            elif op == OP_SQRT:
                registers[out, k] = math.sqrt(registers[a, k])
            else:  # OP_SQUARE
                registers[out, k] = registers[a, k] * registers[a, k]
    for b in range(count):
        for k in range(particles):
            alpha[b, k] = registers[outputs[b], k]


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
def _factor(code, parameter, e, joints, out, squares):  # noqa: ANN001, ANN202
    """``out[K]``: factor ``code`` of each particle's error matrix ``e[M, K]`` (joint-major rows)."""
    entries, particles = e.shape
    samples = entries // joints
    if code == FRO:
        for k in range(particles):
            out[k] = 0.0
        for m in range(entries):
            for k in range(particles):
                out[k] += e[m, k] * e[m, k]
        for k in range(particles):
            out[k] = math.sqrt(out[k])
    elif code == SPECTRAL:
        for k in range(particles):
            out[k] = _spectral3(e, k, samples)
    elif code == COLUMN_SUM or code == ROW_SUM or code == ROW_SQUARES:
        outer, inner = (samples, joints) if code == COLUMN_SUM else (joints, samples)
        for k in range(particles):
            out[k] = -math.inf
        for o in range(outer):
            for k in range(particles):
                squares[k] = 0.0
            for i in range(inner):
                m = i * samples + o if code == COLUMN_SUM else o * samples + i
                for k in range(particles):
                    squares[k] += e[m, k] * e[m, k] if code == ROW_SQUARES else abs(e[m, k])
            for k in range(particles):
                out[k] = _larger(out[k], squares[k])
    elif code == MAX_ABS:
        for k in range(particles):
            out[k] = -math.inf
        for m in range(entries):
            for k in range(particles):
                out[k] = _larger(out[k], abs(e[m, k]))
    elif code == HUBER:
        for k in range(particles):
            out[k] = 0.0
        for m in range(entries):
            for k in range(particles):
                a = abs(e[m, k])
                inner = a if a < parameter else parameter
                out[k] += inner * (a - 0.5 * inner)
        for k in range(particles):
            out[k] /= entries
    else:  # TRIMMED: the parameter is the number of smallest squares kept
        keep = int(parameter)
        column = squares[:entries]
        for k in range(particles):
            for m in range(entries):
                column[m] = e[m, k] * e[m, k]
            ordered = np.sort(column)  # NaN sorts last: checked below, never trimmed away
            total = 0.0
            for m in range(keep):
                total += ordered[m]
            out[k] = math.nan if ordered[entries - 1] != ordered[entries - 1] else total / keep


@jit
def _evaluate(s, x, pbest, pcost, gpos, linear, offset, slot_of, codes, params, joints, alpha, e, values, squares):  # noqa: ANN001, ANN202, E501
    """Cost of every particle of swarm ``s``; personal bests where strictly lower; the swarm's best
    (the first particle with the lowest personal best) into ``gpos[s]``. Returns its cost."""
    particles, dimension = x.shape[1], x.shape[2]
    slot = slot_of[s]
    entries, count = offset.shape[1], alpha.shape[0]
    for m in range(entries):  # E = offset + alpha · linear, summed in the eager engine's order
        for k in range(particles):
            e[m, k] = offset[slot, m] + alpha[0, k] * linear[slot, 0, m]
        for b in range(1, count):
            for k in range(particles):
                e[m, k] += alpha[b, k] * linear[slot, b, m]
    for k in range(particles):
        values[0, k] = 1.0
    for f in range(codes.shape[1]):
        if codes[slot, f] == 0:
            break
        _factor(codes[slot, f], params[slot, f], e, joints, values[1], squares)
        for k in range(particles):
            values[0, k] = values[1, k] if f == 0 else values[0, k] * values[1, k]
    for k in range(particles):
        if values[0, k] < pcost[s, k]:  # strictly; NaN never is
            pcost[s, k] = values[0, k]
            for p in range(dimension):
                pbest[s, k, p] = x[s, k, p]
    best, low = 0, pcost[s, 0]
    for k in range(1, particles):
        if pcost[s, k] < low:
            best, low = k, pcost[s, k]
    for p in range(dimension):
        gpos[s, p] = pbest[s, best, p]
    return low


@jit
def _move(s, weight, r1, r2, u3, x, v, pbest, gpos, lower, upper, c1, c2, vmax, boundary, per_particle):  # noqa: ANN001, ANN202, E501
    """Move swarm ``s`` with inertia ``weight`` and its uniform numbers ``r1``, ``r2`` (``u3`` for
    the random wall rule), each ``[K, P or 1]``, then apply the boundary rule: ``swarm.step``."""
    particles, dimension = x.shape[1], x.shape[2]
    for k in range(particles):
        for p in range(dimension):
            w = 0 if per_particle else p
            position = x[s, k, p]
            velocity = v[s, k, p] * weight + (c1 * r1[k, w]) * (pbest[s, k, p] - position)
            velocity = velocity + (c2 * r2[k, w]) * (gpos[s, p] - position)
            velocity = -vmax[p] if velocity < -vmax[p] else velocity
            velocity = vmax[p] if velocity > vmax[p] else velocity
            moved = position + velocity
            low, high = lower[p], upper[p]
            if boundary == CLAMP:
                clamped = low if moved < low else moved
                clamped = high if clamped > high else clamped
                v[s, k, p] = velocity * (1.0 if clamped == moved else 0.0)
                x[s, k, p] = clamped
            elif boundary == REFLECT:
                # t = (x − lower) mod 2·width (as torch.remainder), folded onto the box
                width = high - low
                t = moved - low
                if not (t >= -2 * width and t < 2 * width):
                    t = np.fmod(t, 2 * width)
                if t < 0:
                    t = t + 2 * width
                folded = width - t
                x[s, k, p] = high - abs(folded)
                v[s, k, p] = velocity * ((1.0 if folded > 0 else 0.0) - (1.0 if folded < 0 else 0.0))
            else:  # RANDOM: between the previous position and the wall it crossed
                u = u3[k, w]
                if moved < low:
                    x[s, k, p], v[s, k, p] = low + (position - low) * u, 0.0
                elif moved > high:
                    x[s, k, p], v[s, k, p] = high - (high - position) * u, 0.0
                else:
                    x[s, k, p], v[s, k, p] = moved, velocity


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
    entries, base = offset.shape[1], linear.shape[1]
    c1, c2, limit = constants[C1], constants[C2], constants[VELOCITY_LIMIT]
    boundary, per_particle, mode = flags[BOUNDARY], flags[PER_PARTICLE], flags[MAP_MODE]
    width = 1 if per_particle else dimension
    kinds = 3 if boundary == RANDOM else 2
    random = np.empty((kinds, count, particles, width))
    vmax = np.empty(dimension)
    for p in range(dimension):
        vmax[p] = limit * (upper[p] - lower[p]) if limit > 0 else math.inf
    registers = np.empty((max(tape.shape[0], 1), particles))
    alpha = np.empty((base, particles))
    e = np.empty((entries, particles))
    values = np.empty((2, particles))
    squares = np.empty(max(entries, particles))
    moves = weights.shape[0]
    for m in range(moves + (1 if last else 0)):
        moving = m < moves
        if moving:
            for kind in range(kinds):
                for c in range(count):
                    for k in range(particles):
                        for w in range(width):
                            random[kind, c, k, w] = rng.random()
        for s in range(first, first + count):
            _base_params(x, s, mode, tape, tape_constants, outputs, given, registers, alpha)
            history[m, s - first] = _evaluate(
                s, x, pbest, pcost, gpos, linear, offset, slot_of, codes, params, joints, alpha, e, values, squares
            )
            if moving:
                c = s - first
                _move(
                    s,
                    weights[m],
                    random[0, c],
                    random[1, c],
                    random[kinds - 1, c],
                    x,
                    v,
                    pbest,
                    gpos,
                    lower,
                    upper,
                    c1,
                    c2,
                    vmax,
                    boundary,
                    per_particle,
                )


numba.core.config.CACHE_DIR = _previous_cache_dir
