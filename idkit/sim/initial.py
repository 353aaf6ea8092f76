"""The joint state a segment starts from: the logged sample, unless it is a glitch.

A glitched sample (an encoder spike, a dropped packet) at a segment's start would ruin the whole
segment's rollout. So each channel's logged value at the start is compared with a local cubic fitted to
the ``2·WINDOW + 1`` samples around it (refitted without the samples further than ``REJECT`` robust
standard deviations from the first fit); a value further than ``REJECT`` noise levels (or fit residual
scales, whichever is larger) from the cubic is replaced by the cubic's. A noiseless log keeps its exact
samples. The noise of a kept sample stays: the polish fits the initial states with the parameters
(:mod:`idkit.sim.shooting`).
"""

from __future__ import annotations

import numpy as np

WINDOW = 6
REJECT = 3.5


def _local_fit(t: np.ndarray, x: np.ndarray, at: float) -> tuple[np.ndarray, np.ndarray]:
    """Values ``[n]`` at ``at`` of cubics fitted to ``x[m, n]`` at times ``t[m]``, outliers removed, and
    the robust scale ``[n]`` of the kept samples' residuals."""
    u = t - at
    scale = max(float(np.abs(u).max()), 1e-12)
    basis = np.vander(u / scale, min(4, t.size), increasing=True)  # [m, d]
    out, spreads = np.empty(x.shape[1]), np.empty(x.shape[1])
    for j in range(x.shape[1]):
        keep = np.ones(t.size, dtype=bool)
        coef, residual, spread = _cubic(basis, x[:, j], keep)
        new = np.abs(residual) <= REJECT * spread if spread > 0 else keep
        if new.sum() >= basis.shape[1] and not (new == keep).all():
            coef, _, spread = _cubic(basis, x[:, j], new)
        out[j], spreads[j] = coef[0], spread
    return out, spreads


def _cubic(basis: np.ndarray, x: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Coefficients fitted to the kept samples, the residual of every sample, the kept ones' robust scale."""
    coef, *_ = np.linalg.lstsq(basis[keep], x[keep], rcond=None)
    residual = x - basis @ coef
    return coef, residual, 1.4826 * float(np.median(np.abs(residual[keep])))


def robust_states(
    t: np.ndarray, q: np.ndarray, qd: np.ndarray, starts: np.ndarray, noise: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``([S, n], [S, n])`` positions and velocities at samples ``starts`` (module docstring).

    Args:
        t, q, qd: the log.
        starts: the segments' first samples.
        noise: ``[2n]`` the noise level of each position, then velocity, channel.
    """
    states = np.hstack([q, qd])
    out = states[starts].copy()
    for i, s in enumerate(starts):
        window = slice(max(0, s - WINDOW), min(t.size, s + WINDOW + 1))
        fitted, spread = _local_fit(t[window], states[window], t[s])
        glitch = np.abs(out[i] - fitted) > REJECT * np.maximum(noise, spread)
        out[i] = np.where(glitch, fitted, out[i])
    n = q.shape[1]
    return out[:, :n], out[:, n:]
