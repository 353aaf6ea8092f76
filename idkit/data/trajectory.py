"""Excitation trajectories as sums of sines, with exact derivatives.

Both trajectories here are ``q_j(t) = c_j + sum_k A_jk sin(w_jk t + phi_jk)``, so velocity and
acceleration follow in closed form (``A w cos``, ``-A w² sin``) — no finite differences, hence
no differentiation noise in the "clean" samples.

* ``paper_trajectory``: eq. (39), the PSO-planned trajectory of the paper's cylindrical robot.
* ``fourier_excitation``: a deterministic finite Fourier series for any ``n``-joint robot, the
  default ``Robot.excitation`` so every robot plugin can be simulated.

Whether eq. (39) observes the bounds (38) is checked by ``idkit.verify.bounds`` (it does not).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

#: Eq. (39): per joint (theta1, d2, d3) the terms ``(amplitude, angular frequency rad/s)`` and the offset.
PAPER_TERMS: tuple[tuple[tuple[tuple[float, float], ...], float], ...] = (
    (((0.43, 2.2), (0.23, 1.8), (-3.4, 0.06)), -0.36),
    (((1.0, 0.1), (-0.3, 0.07), (0.35, 1.3)), -0.014),
    (((0.1, 0.1), (-0.1, 2.7), (0.06, 0.14)), 0.26),
)


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


def sine_sum(
    t: Tensor, amplitude: Tensor, omega: Tensor, phase: Tensor, offset: Tensor
) -> tuple[Tensor, Tensor, Tensor]:
    """Evaluate ``q_j(t) = offset_j + sum_k amplitude_jk sin(omega_jk t + phase_jk)`` and derivatives.

    Args:
        t: times ``[N]``.
        amplitude, omega, phase: ``[n, K]`` — K sine terms per joint.
        offset: ``[n]``.

    Returns:
        ``(q, qd, qdd)``, each ``[N, n]``, on ``t``'s device and dtype.
    """
    like = {"device": t.device, "dtype": t.dtype}
    amplitude, omega, phase, offset = (x.to(**like) for x in (amplitude, omega, phase, offset))
    angle = t[:, None, None] * omega + phase  # [N, n, K]
    sin, cos = torch.sin(angle), torch.cos(angle)
    q = offset + (amplitude * sin).sum(-1)
    qd = (amplitude * omega * cos).sum(-1)
    qdd = -(amplitude * omega.square() * sin).sum(-1)
    return q, qd, qdd


def paper_trajectory(t: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Eq. (39) for the cylindrical robot: ``(q, qd, qdd)``, each ``[N, 3]`` (theta1, d2, d3).

    Args:
        t: times ``[N]`` in seconds; the paper uses ``0 <= t <= 10``.
    """
    amplitude = torch.tensor([[a for a, _ in terms] for terms, _ in PAPER_TERMS], dtype=torch.float64)
    omega = torch.tensor([[w for _, w in terms] for terms, _ in PAPER_TERMS], dtype=torch.float64)
    offset = torch.tensor([c for _, c in PAPER_TERMS], dtype=torch.float64)
    return sine_sum(t, amplitude, omega, torch.zeros_like(amplitude), offset)


#: ``(sqrt(5) - 1) / 2``: phases ``2π·frac(j·k·GOLDEN)`` are spread out and differ between joints.
GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


def fourier_excitation(
    t: Tensor,
    n_joints: int,
    amplitude: float = 0.5,
    period: float = 10.0,
    harmonics: int = 5,
) -> tuple[Tensor, Tensor, Tensor]:
    """Deterministic finite Fourier series excitation for any ``n``-joint robot.

    Joint ``j`` (1-based) follows ``q_j(t) = sum_{k=1..K} (amplitude / k) sin(k w_f t + phi_jk)``
    with ``w_f = 2π / period`` and ``phi_jk = 2π·frac(j·k·GOLDEN)``. One period spans the default
    10 s window, so the motion is periodic (the usual choice for identification, Swevers et al.
    1997); ``amplitude / k`` keeps the spectrum decaying; the golden-ratio phases make the joints'
    motions different without any random draw. With the defaults the sums of the term
    amplitudes bound ``|q| <= 1.14``, ``|qd| <= 1.57`` and ``|qdd| <= 2.96`` (rad or m, per s,
    per s²) — moderate for typical arms. Robots with tighter limits override ``Robot.excitation``.

    Args:
        t: times ``[N]``.
        n_joints: number of joints ``n``.
        amplitude: amplitude of the first harmonic (rad or m).
        period: fundamental period in seconds.
        harmonics: number of harmonics ``K``.

    Returns:
        ``(q, qd, qdd)``, each ``[N, n]``, on ``t``'s device and dtype.
    """
    if n_joints < 1 or harmonics < 1 or not period > 0:
        raise ValueError(
            f"fourier_excitation: need n_joints >= 1, harmonics >= 1, period > 0; got "
            f"{n_joints}, {harmonics}, {period}"
        )
    k = torch.arange(1, harmonics + 1, dtype=torch.float64)  # [K]
    j = torch.arange(1, n_joints + 1, dtype=torch.float64)[:, None]  # [n, 1]
    amp = (amplitude / k).expand(n_joints, harmonics)
    omega = (2.0 * math.pi / period * k).expand(n_joints, harmonics)
    phase = 2.0 * math.pi * torch.frac(j * k * GOLDEN)
    return sine_sum(t, amp, omega, phase, torch.zeros(n_joints, dtype=torch.float64))
