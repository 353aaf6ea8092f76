"""Sampling instants of the simulated scenarios.

The excitation trajectories themselves are plugins (``idkit.excitations``: ``paper`` is eq. (39),
``fourier`` a finite Fourier series; see ``idkit.excitation``). Whether eq. (39) observes the
bounds (38) is checked by ``idkit.verify.bounds`` (it does not).
"""

from __future__ import annotations

import torch
from torch import Tensor


def sample_times(n_samples: int, t_end: float = 10.0) -> Tensor:
    """Sampling instants ``t[N] = t_end · (1, 2, …, N) / N`` (float64) within ``0 < t <= t_end``.

    A uniform sampling period ``t_end / N`` ending at ``t_end`` (10 samples of eq. (39) → t = 1,
    2, …, 10 s; 20 samples → t = 0.5, 1, …, 10 s), as a logger clocked at ``N / t_end`` Hz
    records. ``t = 0`` is left out on purpose: every sine-sum trajectory has ``qdd(0) = 0``
    exactly, and a zero component cannot carry multiplicative noise (an "outlier" drawn there
    would vanish). The paper does not state its sampling instants.
    """
    if n_samples < 1:
        raise ValueError(f"sample_times: n_samples must be >= 1, got {n_samples}")
    if not t_end > 0:
        raise ValueError(f"sample_times: t_end must be > 0, got {t_end}")
    return t_end * torch.arange(1, n_samples + 1, dtype=torch.float64) / n_samples
