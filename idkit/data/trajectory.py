"""Excitation trajectories as sums of sines, with exact derivatives.

Both trajectories here are ``q_j(t) = c_j + sum_k A_jk sin(w_jk t + phi_jk)``, so velocity and
acceleration follow in closed form (``A w cos``, ``-A w² sin``) — no finite differences, hence
no differentiation noise in the "clean" samples.

* ``paper_trajectory``: eq. (39), the PSO-planned trajectory of the paper's cylindrical robot.
* ``fourier_excitation``: a deterministic finite Fourier series for any ``n``-joint robot, the
  default ``Robot.excitation`` so every robot plugin can be simulated.

``check_bounds`` compares a trajectory with a box such as eq. (38) and *reports* every excursion
(it never clips): eq. (39) does leave eq. (38) — ``d2`` starts at −0.014 m, for example.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import torch
from torch import Tensor

#: Eq. (39): per joint (theta1, d2, d3) the terms ``(amplitude, angular frequency rad/s)`` and the offset.
PAPER_TERMS: tuple[tuple[tuple[tuple[float, float], ...], float], ...] = (
    (((0.43, 2.2), (0.23, 1.8), (-3.4, 0.06)), -0.36),
    (((1.0, 0.1), (-0.3, 0.07), (0.35, 1.3)), -0.014),
    (((0.1, 0.1), (-0.1, 2.7), (0.06, 0.14)), 0.26),
)

#: Eq. (38): the physical box the planned trajectory should observe, ``name -> (lower, upper)``.
PAPER_BOUNDS: dict[str, tuple[float, float]] = {
    "theta1": (-math.pi, math.pi),
    "theta1_d": (-4.0, 4.0),
    "theta1_dd": (-3.0, 3.0),
    "d2": (0.0, 1.0),
    "d2_d": (-2.0, 2.0),
    "d2_dd": (-2.0, 2.0),
    "d3": (0.0, 1.0),
    "d3_d": (-1.5, 1.5),
    "d3_dd": (-1.0, 1.0),
}

PAPER_JOINTS = ("theta1", "d2", "d3")


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


@dataclass(frozen=True)
class BoundViolation:
    """One variable leaving one side of its box.

    Attributes:
        variable: e.g. ``"d2"`` or ``"theta1_dd"``.
        side: ``"lower"`` or ``"upper"``.
        limit: the bound that is crossed.
        worst: the most extreme value beyond it, reached at ``t_worst``.
        excess: ``|worst - limit|``, how far it goes beyond the bound.
        intervals: ``(t_first, t_last)`` of each run of consecutive grid times outside the bound.
        fraction: share of the grid times outside the bound.
    """

    variable: str
    side: str
    limit: float
    worst: float
    excess: float
    t_worst: float
    intervals: tuple[tuple[float, float], ...]
    fraction: float

    def __str__(self) -> str:
        spans = ", ".join(f"[{a:.3f}, {b:.3f}]" for a, b in self.intervals)
        sign = "<" if self.side == "lower" else ">"
        return (
            f"{self.variable} {sign} {self.limit:g} (worst {self.worst:.4g} at t={self.t_worst:.3f} s, "
            f"beyond by {self.excess:.3g}; {100 * self.fraction:.1f} % of the time, t in {spans} s)"
        )


def _runs(t: Tensor, outside: Tensor) -> tuple[tuple[float, float], ...]:
    """``(t_first, t_last)`` of each run of ``True`` in ``outside[N]``."""
    flags = torch.cat((outside.new_zeros(1), outside, outside.new_zeros(1))).to(torch.int8)
    edges = flags.diff()  # +1 where a run starts, -1 one past where it ends
    starts = (edges == 1).nonzero().flatten().tolist()
    ends = ((edges == -1).nonzero().flatten() - 1).tolist()
    return tuple((float(t[a]), float(t[b])) for a, b in zip(starts, ends, strict=True))


def check_bounds(
    t: Tensor,
    q: Tensor,
    qd: Tensor,
    qdd: Tensor,
    bounds: Mapping[str, tuple[float, float]] = PAPER_BOUNDS,
    joint_names: tuple[str, ...] = PAPER_JOINTS,
) -> list[BoundViolation]:
    """Every excursion of a trajectory outside a box such as eq. (38), none hidden or clipped.

    Args:
        t: times ``[N]``, ascending (use a dense grid, e.g. ``torch.linspace(0, 10, 10001)``:
            the report resolves crossing times to the grid spacing).
        q, qd, qdd: ``[N, n]``.
        bounds: ``"<joint>"``, ``"<joint>_d"``, ``"<joint>_dd"`` -> ``(lower, upper)``; variables
            without an entry are not checked.
        joint_names: the ``n`` joint names used to build those keys.

    Returns:
        One ``BoundViolation`` per (variable, side) that is crossed, in the order of ``bounds``;
        an empty list when the trajectory stays inside.
    """
    series = {}
    for j, joint in enumerate(joint_names):
        for suffix, x in (("", q), ("_d", qd), ("_dd", qdd)):
            series[joint + suffix] = x[:, j]
    unknown = set(bounds) - set(series)
    if unknown:
        raise ValueError(f"check_bounds: no variable named {sorted(unknown)}; known: {sorted(series)}")
    t = t.detach().cpu().double()
    found = []
    for name, (lower, upper) in bounds.items():
        x = series[name].detach().cpu().double()
        for side, limit, outside in (("lower", lower, x < lower), ("upper", upper, x > upper)):
            if not outside.any():
                continue
            i = int(x.argmin() if side == "lower" else x.argmax())
            found.append(
                BoundViolation(
                    variable=name,
                    side=side,
                    limit=float(limit),
                    worst=float(x[i]),
                    excess=abs(float(x[i]) - limit),
                    t_worst=float(t[i]),
                    intervals=_runs(t, outside),
                    fraction=float(outside.double().mean()),
                )
            )
    return found


def format_violations(violations: list[BoundViolation]) -> str:
    """Readable report, one line per violation (``"within bounds"`` when there is none)."""
    if not violations:
        return "within bounds"
    return "\n".join(str(v) for v in violations)


def paper_bounds_report(n_points: int = 10001, t_end: float = 10.0) -> list[BoundViolation]:
    """Where eq. (39) leaves eq. (38) on a dense grid of ``n_points`` over ``0 <= t <= t_end``."""
    t = torch.linspace(0.0, t_end, n_points, dtype=torch.float64)
    return check_bounds(t, *paper_trajectory(t))
