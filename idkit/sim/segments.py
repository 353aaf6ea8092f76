"""Multiple shooting: a long log as segments, each simulated from the logged state at its start.

An open-loop rollout of a whole log drifts away from the measurement (an unstable or lightly damped
arm amplifies any error), and then the error says little about the parameters. Segments of a few
tenths of a second, each restarted from the logged state at its first sample, keep every rollout
near the measured trajectory. A segment ``(start, stop)`` predicts samples ``start .. stop - 1`` (its
first sample is its initial state, predicted exactly when that state is the logged one), and the next
segment starts at ``stop``, so every sample is predicted once. A segment never spans a gap in the log's
times (a step over ``GAP`` of the median step): a new one starts after it.
"""

from __future__ import annotations

import numpy as np

#: A step between logged samples longer than this many median steps is a gap.
GAP = 5.0


def split(t: np.ndarray, length: float | None) -> list[tuple[int, int]]:
    """``(start, stop)`` sample indices (``stop`` excluded) of segments about ``length`` seconds long
    (``None``: one per stretch between gaps), equal in sample count within a stretch.

    Raises:
        ValueError: ``length`` not positive, or a stretch of fewer than 2 samples.
    """
    if length is not None and not length > 0:
        raise ValueError(
            f"segment must be a positive number of seconds (or null: whole stretches), got {length}"
        )
    steps = np.diff(t)
    cuts = np.flatnonzero(steps > GAP * np.median(steps))
    edges = [0, *(int(c) + 1 for c in cuts), t.size]
    segments: list[tuple[int, int]] = []
    for first, stop in zip(edges[:-1], edges[1:], strict=True):
        if stop - first < 2:
            continue  # a lone sample between two gaps predicts nothing
        count = 1 if length is None else max(1, int(round((t[stop - 1] - t[first]) / length)))
        count = min(count, (stop - first) // 2)
        bounds = np.round(np.linspace(first, stop, count + 1)).astype(int)
        segments += [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    if not segments:
        raise ValueError("the log has no two consecutive samples to simulate between")
    return segments
