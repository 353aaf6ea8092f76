"""``fourier``: a finite Fourier series per joint (Swevers, Ganseman, Bayo Tükel, De Schutter &
Van Brussel 1997), the usual parameterisation of optimal excitation trajectories.

With ``w_f = 2π / period`` and harmonics ``k = 1..K``::

    q_j(t)   = offset_j + sum_k  a_jk / (k w_f) sin(k w_f t) - b_jk / (k w_f) cos(k w_f t)
    qd_j(t)  =            sum_k  a_jk cos(k w_f t) + b_jk sin(k w_f t)
    qdd_j(t) =            sum_k -a_jk k w_f sin(k w_f t) + b_jk k w_f cos(k w_f t)

``a``, ``b`` are velocity amplitudes (rad/s or m/s). Every term has period ``period``, so the motion
is periodic: it starts and ends in the same state, can be repeated and averaged, and its
derivatives are exact. Without coefficients the series is idkit's deterministic default for any
robot: first-harmonic amplitude 0.5 (rad or m), term ``k`` of amplitude ``0.5 / k`` and phase
``phi_jk = 2π·frac(j·k·GOLDEN)`` (``q_j = sum_k (0.5/k) sin(k w_f t + phi_jk)``): a decaying
spectrum, and joints that move differently without a random draw.

``rest=True`` makes every period start and end at rest (``qd = qdd = 0`` at ``t = 0, period, 2·period…``,
exactly: no window, no finite difference) by two linear constraints per joint::

    qd_j(0)  = sum_k a_jk       = 0   →   a_jK = -sum_{k<K} a_jk
    qdd_j(0) = w_f sum_k k b_jk = 0   →   b_j1 = -sum_{k>1} k b_jk

The last harmonic's ``a`` and the first harmonic's ``b`` are thereby computed from the others
(whatever is given for them is replaced), so the constraint is applied in ``evaluate`` and the
stored coefficients satisfy it. Both are linear in the coefficients of one joint, so scaling a
joint's ``a``, ``b`` (``idkit.excitation.feasible``) keeps it at rest. The whole period stays
informative (a window fading the motion in and out would spend time near rest); the motion stays
periodic, so it can be repeated. ``harmonics >= 2`` (one harmonic at rest is no motion).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor

from idkit.excitation.sines import amplitude_caps, as_matrix, offset_box
from idkit.interfaces import Excitation
from idkit.limits import MotionLimits
from idkit.options import positive_number

#: ``(sqrt(5) - 1) / 2``: phases ``2π·frac(j·k·GOLDEN)`` are spread out and differ between joints.
GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0

#: Amplitude (rad or m) of the first harmonic of the default series.
DEFAULT_AMPLITUDE = 0.5


class FourierExcitation(Excitation):
    """Finite Fourier series per joint (module docstring for the formula and the default).

    Coefficient vector ``[C = n + 2 n K]``: ``offset[n]``, then ``a[n, K]`` and ``b[n, K]`` row by row.

    Args:
        n_joints: number of joints ``n``.
        harmonics: number of harmonics ``K``.
        period: fundamental period in seconds (base frequency ``1 / period`` Hz).
        offset: ``[n]`` constant terms (default 0).
        a, b: ``[n][K]`` velocity amplitudes of the cosine and sine velocity terms; give both or
            neither (neither: the default golden-ratio series).
        rest: start and end every period at rest (module docstring): ``a[:, K-1]`` and ``b[:, 0]``
            are computed from the other coefficients.
    """

    def __init__(
        self,
        n_joints: int = 1,
        harmonics: int = 5,
        period: float = 10.0,
        offset: Sequence[float] | None = None,
        a: Sequence[Sequence[float]] | None = None,
        b: Sequence[Sequence[float]] | None = None,
        rest: bool = False,
    ) -> None:
        self.n_joints = n_joints
        self.harmonics = harmonics
        self.period = period
        self.offset = offset
        self.a = a
        self.b = b
        self.rest = rest
        if not isinstance(rest, bool):
            raise ValueError(f"fourier excitation: rest must be true or false, got {rest!r}")
        for name, value in (("n_joints", n_joints), ("harmonics", harmonics)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"fourier excitation: {name} must be an integer >= 1, got {value!r}")
        if not positive_number(period):
            raise ValueError(
                f"fourier excitation: period must be a finite number > 0 (seconds), got {period!r}"
            )
        if rest and harmonics < 2:
            raise ValueError(
                "fourier excitation: rest=true needs harmonics >= 2 (one harmonic at rest is still)"
            )
        if (a is None) != (b is None):
            raise ValueError("fourier excitation: give both a and b, or neither (the default series)")
        shape = (n_joints, harmonics)
        k = torch.arange(1, harmonics + 1, dtype=torch.float64)
        self._omega = 2.0 * math.pi / period * k  # [K]
        if a is None or b is None:  # both, as checked above
            j = torch.arange(1, n_joints + 1, dtype=torch.float64)[:, None]
            phase = 2.0 * math.pi * torch.frac(j * k * GOLDEN)  # [n, K]
            self._a = DEFAULT_AMPLITUDE * self._omega[0] * torch.cos(phase)
            self._b = -DEFAULT_AMPLITUDE * self._omega[0] * torch.sin(phase)
        else:
            self._a = as_matrix(a, shape, "fourier excitation: a")
            self._b = as_matrix(b, shape, "fourier excitation: b")
        self._a, self._b = self._at_rest(self._a, self._b)
        self._offset = (
            torch.zeros(n_joints, dtype=torch.float64)
            if offset is None
            else as_matrix(offset, (n_joints,), "fourier excitation: offset")
        )

    def options(self) -> dict[str, Any]:
        return {
            "n_joints": self.n_joints,
            "harmonics": self.harmonics,
            "period": float(self.period),
            "offset": self._offset.tolist(),
            "a": self._a.tolist(),
            "b": self._b.tolist(),
            "rest": self.rest,
        }

    def to_vector(self) -> Tensor:
        return torch.cat((self._offset, self._a.flatten(), self._b.flatten()))

    def from_vector(self, vector: Tensor) -> FourierExcitation:
        offset, a, b = self._split(torch.as_tensor(vector, dtype=torch.float64).detach().cpu())
        return FourierExcitation(
            self.n_joints, self.harmonics, self.period, offset.tolist(), a.tolist(), b.tolist(), self.rest
        )

    def _split(self, coefficients: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        n, k = self.n_joints, self.harmonics
        if coefficients.shape[-1:] != (n + 2 * n * k,):
            raise ValueError(
                f"fourier excitation: coefficients must be [..., {n + 2 * n * k}] (offset, a, b), got "
                f"shape {tuple(coefficients.shape)}"
            )
        a, b = coefficients[..., n:].unflatten(-1, (2, n, k)).unbind(-3)
        return (coefficients[..., :n], *self._at_rest(a, b))

    def _at_rest(self, a: Tensor, b: Tensor) -> tuple[Tensor, Tensor]:
        """``a, b [..., n, K]`` with ``a[..., K-1]`` and ``b[..., 0]`` set so that ``qd(0) = qdd(0) = 0``
        (unchanged without ``rest``). A function of the other coefficients only, hence idempotent
        bit for bit: a stored member evaluates to exactly what was stored."""
        if not self.rest:
            return a, b
        k = torch.arange(2, self.harmonics + 1, dtype=b.dtype, device=b.device)
        last_a = -a[..., :-1].sum(-1, keepdim=True)
        first_b = -(b[..., 1:] * k).sum(-1, keepdim=True)
        return torch.cat((a[..., :-1], last_a), -1), torch.cat((first_b, b[..., 1:]), -1)

    def evaluate(self, coefficients: Tensor, t: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        offset, a, b = self._split(coefficients.to(t))
        omega = self._omega.to(t)  # [K]
        angle = t[:, None] * omega  # [T, K]
        basis = torch.cat((torch.sin(angle), torch.cos(angle)), dim=-1)  # [T, 2K]
        # Weights of (sin, cos) for q, qd, qdd: [..., 3, n, 2K]; then one matrix product for all.
        weights = torch.stack(
            (
                torch.cat((a / omega, -b / omega), dim=-1),
                torch.cat((b, a), dim=-1),
                torch.cat((-a * omega, b * omega), dim=-1),
            ),
            dim=-3,
        )
        motion = (weights.reshape(-1, basis.shape[-1]) @ basis.T).reshape(*weights.shape[:-1], -1)
        q, qd, qdd = motion.transpose(-1, -2).unbind(-3)  # each [..., T, n]
        return offset[..., None, :] + q, qd, qdd

    def coefficient_joints(self) -> tuple[Tensor, Tensor]:
        n, k = self.n_joints, self.harmonics
        joints = torch.arange(n)
        return torch.cat((joints, joints.repeat_interleave(k).repeat(2))), torch.arange(n + 2 * n * k) < n

    def coefficient_box(self, limits: MotionLimits) -> tuple[Tensor, Tensor]:
        self.check_joints(limits.joint_names, "the motion-limit box")
        low, high = offset_box(limits)
        omega = self._omega.expand(self.n_joints, -1)
        cap = (amplitude_caps(limits, omega) * omega).flatten()  # a, b are velocity amplitudes
        return torch.cat((low, -cap, -cap)), torch.cat((high, cap, cap))
