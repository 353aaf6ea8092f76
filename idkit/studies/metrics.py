"""Parameter-error metrics shared by single runs, the paper tables and the robustness study.

Definitions (the ``result.json`` contract and the robustness tables use exactly these):

* relative error of parameter ``k``: ``(p̂_k − p_k) / |p_k|`` — signed, so a table shows whether a
  method over- or under-estimates; undefined (``None``/NaN) where ``p_k = 0``.
* parameter error of one estimate: the mean absolute relative error over the ``P`` parameters,
  ``mean_k |p̂_k − p_k| / |p_k|`` (0.05 = the parameters are off by 5 % on average). A mean rather
  than a norm so that the number reads as a percentage whatever ``P`` is, and each parameter
  counts equally whatever its unit.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np


def relative_errors(estimate: Mapping[str, float], truth: Mapping[str, float]) -> dict[str, float | None]:
    """Signed relative error per parameter name (``None`` where the true value is 0)."""
    return {
        name: (float(estimate[name]) - value) / abs(value) if value != 0 else None
        for name, value in truth.items()
        if name in estimate
    }


def mean_abs_relative_error(relative: Mapping[str, float | None]) -> float | None:
    """Mean of ``|relative error|`` over the parameters where it is defined."""
    values = [abs(v) for v in relative.values() if v is not None and math.isfinite(v)]
    return sum(values) / len(values) if values else None


def parameter_error(estimates: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Mean absolute relative error ``[...]`` of estimates ``[..., P]`` against truth ``[P]``.

    Non-finite estimates give ``inf`` (a failed fit loses every comparison instead of vanishing).
    """
    estimates = np.asarray(estimates, dtype=float)
    truth = np.asarray(truth, dtype=float)
    nonzero = truth != 0
    rel = np.abs(estimates[..., nonzero] - truth[nonzero]) / np.abs(truth[nonzero])
    err = rel.mean(axis=-1)
    return np.where(np.isfinite(err), err, np.inf)
