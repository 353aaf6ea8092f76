"""Multiple shooting: a long log as segments, each simulated from the logged state at its start.

An open-loop rollout of a whole log drifts away from the measurement (an unstable or lightly damped
arm amplifies any error), and then the error says little about the parameters. Segments of a few
tenths of a second, each restarted from the logged state at its first sample, keep every rollout
near the measured trajectory. A segment ``(start, stop)`` predicts samples ``start .. stop - 1`` (its
first sample is its initial state, predicted exactly when that state is the logged one), and the next
segment starts at ``stop``, so every sample is predicted once. A segment never spans a gap in the log's
times (a step over ``GAP`` of the median step) nor an excluded row (a driver's stalled repeat,
:mod:`idkit.data.artefacts`): a new one starts after it, and excluded rows are predicted by none.
"""

from __future__ import annotations

import numpy as np

#: A step between logged samples longer than this many median steps is a gap.
GAP = 5.0


def split(t: np.ndarray, length: float | None, excluded: np.ndarray | None = None) -> list[tuple[int, int]]:
    """``(start, stop)`` sample indices (``stop`` excluded) of segments about ``length`` seconds long
    (``None``: one per stretch between gaps), equal in sample count within a stretch; rows marked in
    ``excluded[N]`` end a stretch and belong to no segment.

    Raises:
        ValueError: ``length`` not positive, or a stretch of fewer than 2 samples.
    """
    if length is not None and not length > 0:
        raise ValueError(
            f"segment must be a positive number of seconds (or null: whole stretches), got {length}"
        )
    segments: list[tuple[int, int]] = []
    for first, stop in stretches(t, excluded):
        if stop - first < 2:
            continue  # a lone sample between two gaps predicts nothing
        count = 1 if length is None else max(1, int(round((t[stop - 1] - t[first]) / length)))
        count = min(count, (stop - first) // 2)
        bounds = np.round(np.linspace(first, stop, count + 1)).astype(int)
        segments += [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    if not segments:
        raise ValueError("the log has no two consecutive samples to simulate between")
    return segments


def stretches(t: np.ndarray, excluded: np.ndarray | None = None) -> list[tuple[int, int]]:
    """``(first, stop)`` of each run of kept samples between gaps (a step over ``GAP`` median steps)
    and excluded rows."""
    steps = np.diff(t)
    cut = np.zeros(t.size, dtype=bool)  # cut[i]: a new stretch starts at i
    cut[1:] = steps > GAP * np.median(steps)
    keep = np.ones(t.size, dtype=bool) if excluded is None else ~np.asarray(excluded, dtype=bool)
    out: list[tuple[int, int]] = []
    first: int | None = None
    for i in range(t.size):
        if first is not None and (cut[i] or not keep[i]):
            out.append((first, i))
            first = None
        if first is None and keep[i]:
            first = i
    if first is not None:
        out.append((first, t.size))
    return out
