"""A deliberate torch thread count for the estimators.

torch's default intra-op pool uses every core. On a small problem (a few hundred particles × a
3 × 10 error matrix) each op is a few microseconds of work, and waking a second thread costs more
than it saves: a paper-sized PSO fit was erratic and much slower with the default pool
(docs/speed.md). Large batches (thousands of runs) do gain from two threads. So the
estimators take a ``threads`` option, resolve it with ``resolve_threads`` and run inside
``torch_threads``; the count used is recorded in ``Estimate.details["threads"]``.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

import torch

#: Elements per iteration (particles × parameters-sized work, see ``resolve_threads``) above which
#: a second thread pays for itself, on the 2-core development machine (``bench/estimators.py``).
MULTITHREAD_WORK = 2_000_000


def resolve_threads(threads: int | None, work: int) -> int:
    """The intra-op thread count to use: ``threads`` if given, else 1 for small work, else all cores.

    Args:
        threads: explicit count (``>= 1``) or ``None`` for the size-based default.
        work: a measure of the per-op tensor size (e.g. elements of the error tensor per iteration).
    """
    if threads is not None:
        if int(threads) < 1:
            raise ValueError(f"threads must be >= 1 or None, got {threads}")
        return int(threads)
    if work < MULTITHREAD_WORK:
        return 1
    return available_cores()


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity where the OS has one, else all)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0)) or 1
    return os.cpu_count() or 1


@contextmanager
def torch_threads(threads: int) -> Iterator[int]:
    """Run the block with ``torch.set_num_threads(threads)`` and restore the previous count after."""
    previous = torch.get_num_threads()
    if threads != previous:
        torch.set_num_threads(threads)
    try:
        yield threads
    finally:
        if torch.get_num_threads() != previous:
            torch.set_num_threads(previous)
