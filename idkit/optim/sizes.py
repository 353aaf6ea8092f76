"""The sizes of a batched search: a cap on its evaluations, a bound on its history, and the bytes
it will allocate (checked by ``idkit.memory.check_memory`` before anything is allocated).

Why: a size option of ``1e9`` (``runs``, ``particles``, ``iterations``, ``starts``) otherwise
reaches the allocator and ends in a many-line traceback, runs for hours unasked, or writes
gigabytes of history. The estimates below are the largest arrays a batched search allocates.
"""

from __future__ import annotations

import math

from idkit.memory import check_memory as check_machine_memory

#: Most cost evaluations one search may plan per cost and trial (``runs × particles × iterations``,
#: ``starts × steps``): about a minute of one core on the fast kernel, many on the eager engine. A
#: bigger request is refused when the estimator is built, rather than running for hours unasked.
MAX_EVALUATIONS = 10**9
#: Most rows a search's history keeps per run (``history_stride``).
HISTORY_ROWS = 1000
#: Bytes per float64.
FLOAT = 8
#: Allocations below this are not checked against the machine's free memory: reading what the
#: system has (``/proc/meminfo``, cgroup files) costs more than a small fit, and a size that small
#: is not what exhausts a machine.
UNCHECKED_BYTES = 1 << 20


def check_evaluations(who: str, sizes: dict[str, int]) -> int:
    """The product of ``sizes`` (evaluations per cost and trial), or ``ValueError`` (one line) above
    ``MAX_EVALUATIONS``; ``sizes`` maps option names to values, e.g. ``{"runs": 10, ...}``."""
    evaluations = math.prod(sizes.values())
    if evaluations > MAX_EVALUATIONS:
        product = " × ".join(sizes)
        values = " × ".join(str(v) for v in sizes.values())
        raise ValueError(
            f"{who}: {product} = {values} = {evaluations:.1e} cost evaluations per cost, above idkit's "
            f"cap of {MAX_EVALUATIONS:.0e} (about a minute of one core on the fast kernel); lower one of them"
        )
    return evaluations


def history_stride(iterations: int) -> int:
    """Keep every ``stride``-th iteration (and the last) so a history has at most ``HISTORY_ROWS``
    rows (+ 1): 1 up to ``HISTORY_ROWS`` iterations."""
    return max(1, math.ceil(iterations / HISTORY_ROWS))


def swarm_bytes(swarms: int, runs: int, particles: int, dimension: int, history_rows: int) -> int:
    """A batch of ``swarms × runs`` swarms: positions, velocities, personal bests and the initial
    draw (``[S, R, K, D]`` each), personal best costs, and the history ``[rows, S, R]``."""
    members = swarms * runs
    return FLOAT * (members * particles * (4 * dimension + 1) + history_rows * members)


def error_bytes(evaluations: int, entries: int, copies: int = 4) -> int:
    """The error tensors of one eager move: ``evaluations`` error matrices of ``entries`` entries,
    ``copies`` of them alive at once (the error, its absolute value, squares, sums)."""
    return FLOAT * evaluations * entries * copies


def check_memory(what: str, needed: float, hint: str = "") -> None:
    """``idkit.memory.check_memory`` for allocations of at least ``UNCHECKED_BYTES``."""
    if needed >= UNCHECKED_BYTES:
        check_machine_memory(what, needed, hint)
