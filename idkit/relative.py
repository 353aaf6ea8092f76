"""The relative error of eq. (27), with an explicit policy for near-zero measured torques (core:
used by relative costs, the least-squares family and plugins alike).

Dividing by a measured torque that is zero or tiny turns a relative cost into ``inf``/``NaN`` or
lets one sample dominate it. idkit's policy: an entry ``T_ij`` with ``|T_ij| < floor · RMS_i``
(RMS of joint i's measured torques) is replaced by ``±floor · RMS_i`` (its own sign, ``+`` for an
exact zero), and a ``RelativeFloorWarning`` says how many entries were floored. A joint whose
measured torques are all zero has no relative error at all: that is a ``ValueError``.
"""

from __future__ import annotations

import warnings

import torch
from torch import Tensor

DEFAULT_FLOOR = 1e-3


class RelativeFloorWarning(UserWarning):
    """Some measured torques were too small to divide by and were floored."""


def relative_denominator(measured: Tensor, floor: float = DEFAULT_FLOOR) -> Tensor:
    """Denominators ``[n, N]`` for the relative error of ``measured[n, N]`` (joints × samples)."""
    if floor < 0:
        raise ValueError(f"relative floor must be >= 0, got {floor}")
    rms = measured.square().mean(dim=-1, keepdim=True).sqrt()
    dead = (rms == 0).flatten()
    if dead.any():
        joints = dead.nonzero().flatten().tolist()
        raise ValueError(f"relative error undefined: measured torques of joint(s) {joints} are all zero")
    limit = floor * rms
    small = measured.abs() < limit
    if floor > 0 and bool(small.any()):
        warnings.warn(
            f"{int(small.sum())} measured torque(s) below {floor:g} x their joint's RMS were "
            "floored for the relative error (see idkit.relative)",
            RelativeFloorWarning,
            stacklevel=3,
        )
        sign = torch.where(measured < 0, -1.0, 1.0).to(measured)
        return torch.where(small, sign * limit, measured)
    if floor == 0 and bool((measured == 0).any()):
        raise ValueError("relative error undefined: a measured torque is exactly zero and floor=0")
    return measured


def relative_error(error: Tensor, measured: Tensor, floor: float = DEFAULT_FLOOR) -> Tensor:
    """``E_rel[..., n, N] = error / T`` (eq. 27) under the near-zero policy above."""
    if measured.shape != error.shape[-2:]:
        raise ValueError(
            f"relative error: measured torques must be [n, N] = {tuple(error.shape[-2:])} like the "
            f"error's last two dimensions, got {tuple(measured.shape)}"
        )
    return error / relative_denominator(measured, floor)
