"""Will a batch fit in memory? Estimated before anything is allocated, refused in one line if not.

Why: a size option of ``1e9`` (``runs``, ``particles``, ``starts``) otherwise reaches the allocator
and ends in a many-line traceback — or, just under the machine's memory, in swapping. The estimates
below are the largest arrays a batched search allocates, in bytes; a batch is refused when they
exceed ``SHARE`` of the machine's physical memory, with the estimate and the machine's memory.
"""

from __future__ import annotations

import math
import os

#: Most cost evaluations one search may plan per cost and trial (``runs × particles × iterations``,
#: ``starts × steps``): about a minute of one core on the fast kernel, many on the eager engine. A
#: bigger request is refused when the estimator is built, rather than running for hours unasked.
MAX_EVALUATIONS = 10**9
#: Most rows a search's history keeps per run (``history_stride``).
HISTORY_ROWS = 1000
#: The share of physical memory one batch may plan to use.
SHARE = 0.8
#: Bytes per float64.
FLOAT = 8


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


def machine_memory() -> int | None:
    """Physical memory in bytes, or ``None`` where the system does not say (then nothing is refused)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        pass
    try:  # Windows
        import ctypes

        class Status(ctypes.Structure):
            _fields_ = [("length", ctypes.c_ulong), ("load", ctypes.c_ulong)] + [
                (name, ctypes.c_ulonglong)
                for name in (
                    "total",
                    "free",
                    "page_total",
                    "page_free",
                    "virtual_total",
                    "virtual_free",
                    "extended",
                )
            ]

        status = Status()
        status.length = ctypes.sizeof(Status)
        if ctypes.windll.kernel32.GlobalMemoryStatusEx(ctypes.byref(status)):  # type: ignore[attr-defined]
            return int(status.total)
    except Exception:
        pass
    return None


def swarm_bytes(swarms: int, runs: int, particles: int, dimension: int, history_rows: int) -> int:
    """A batch of ``swarms × runs`` swarms: positions, velocities, personal bests and the initial
    draw (``[S, R, K, D]`` each), personal best costs, and the history ``[rows, S, R]``."""
    members = swarms * runs
    return FLOAT * (members * particles * (4 * dimension + 1) + history_rows * members)


def error_bytes(evaluations: int, entries: int, copies: int = 4) -> int:
    """The error tensors of one eager move: ``evaluations`` error matrices of ``entries`` entries,
    ``copies`` of them alive at once (the error, its absolute value, squares, sums)."""
    return FLOAT * evaluations * entries * copies


def describe(size: float) -> str:
    """``size`` bytes in readable units."""
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if size < 1000 or unit == "PB":
            return f"{size:.3g} {unit}"
        size /= 1000
    return f"{size:.3g} PB"


def check_memory(who: str, needed: int, what: str) -> None:
    """Refuse (``ValueError``, one line) when ``needed`` bytes exceed ``SHARE`` of this machine's memory.

    Args:
        who: the estimator or task (``"pso"``), for the message.
        needed: the estimate in bytes.
        what: the sizes it comes from, in words.
    """
    memory = machine_memory()
    if memory is not None and needed > SHARE * memory:
        raise ValueError(
            f"{who}: {what} need about {describe(needed)} of memory; this machine has "
            f"{describe(memory)}; lower the sizes (or fit the trials in smaller chunks)"
        )
