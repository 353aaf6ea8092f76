"""``paper``: the PSO-planned trajectory of the paper's cylindrical robot, eq. (39).

``q_j(t) = offset_j + sum_k amplitude_jk sin(omega_jk t)`` per joint ``(theta1, d2, d3)``, so the
velocity and acceleration follow in closed form (``A w cos``, ``-A w² sin``): no finite
differences, hence no differentiation noise in the "clean" samples. The frequencies are not
harmonics of one base frequency, so the motion is not periodic. The defaults are eq. (39); any
other amplitudes, frequencies and offsets make the same family.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor

from idkit.excitation.sines import amplitude_caps, as_matrix, offset_box
from idkit.interfaces import Excitation
from idkit.limits import MotionLimits

#: Eq. (39), rows theta1, d2, d3: amplitudes, angular frequencies (rad/s) and offsets.
PAPER_AMPLITUDE = ((0.43, 0.23, -3.4), (1.0, -0.3, 0.35), (0.1, -0.1, 0.06))
PAPER_OMEGA = ((2.2, 1.8, 0.06), (0.1, 0.07, 1.3), (0.1, 2.7, 0.14))
PAPER_OFFSET = (-0.36, -0.014, 0.26)


class PaperExcitation(Excitation):
    """Sums of sines with free frequencies; eq. (39) by default.

    Coefficient vector ``[C = n + n K]``: the offsets ``[n]``, then the amplitudes ``[n, K]`` row
    by row. The frequencies are structure, not coefficients.

    Args:
        amplitude: ``[n][K]`` amplitudes (rad or m).
        omega: ``[n][K]`` angular frequencies (rad/s).
        offset: ``[n]`` constant terms (rad or m).
    """

    def __init__(
        self,
        amplitude: Sequence[Sequence[float]] = PAPER_AMPLITUDE,
        omega: Sequence[Sequence[float]] = PAPER_OMEGA,
        offset: Sequence[float] = PAPER_OFFSET,
    ) -> None:
        self.amplitude = amplitude
        self.omega = omega
        self.offset = offset
        n = len(offset)
        self._omega = as_matrix(omega, (n, None), "paper excitation: omega")
        self._amplitude = as_matrix(amplitude, tuple(self._omega.shape), "paper excitation: amplitude")
        self._offset = as_matrix(offset, (n,), "paper excitation: offset")
        self.n_joints = n

    def options(self) -> dict[str, Any]:
        return {
            "amplitude": self._amplitude.tolist(),
            "omega": self._omega.tolist(),
            "offset": self._offset.tolist(),
        }

    def to_vector(self) -> Tensor:
        return torch.cat((self._offset, self._amplitude.flatten()))

    def from_vector(self, vector: Tensor) -> PaperExcitation:
        offset, amplitude = self._split(torch.as_tensor(vector, dtype=torch.float64).detach().cpu())
        return PaperExcitation(amplitude.tolist(), self._omega.tolist(), offset.tolist())

    def _split(self, coefficients: Tensor) -> tuple[Tensor, Tensor]:
        n, size = self.n_joints, self._omega.numel()
        if coefficients.shape[-1:] != (n + size,):
            raise ValueError(
                f"paper excitation: coefficients must be [..., {n + size}] (offsets, then amplitudes), "
                f"got shape {tuple(coefficients.shape)}"
            )
        return coefficients[..., :n], coefficients[..., n:].unflatten(-1, tuple(self._omega.shape))

    def evaluate(self, coefficients: Tensor, t: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        offset, amplitude = self._split(coefficients.to(t))
        offset, amplitude = offset[..., None, :], amplitude[..., None, :, :]  # [..., 1, n], [..., 1, n, K]
        omega = self._omega.to(t)
        angle = t[:, None, None] * omega  # [T, n, K]
        sin, cos = torch.sin(angle), torch.cos(angle)
        q = offset + (amplitude * sin).sum(-1)
        qd = (amplitude * omega * cos).sum(-1)
        qdd = -(amplitude * omega.square() * sin).sum(-1)
        return q, qd, qdd

    def coefficient_joints(self) -> tuple[Tensor, Tensor]:
        n, k = self._omega.shape
        joints = torch.arange(n)
        return torch.cat((joints, joints.repeat_interleave(k))), torch.arange(n + n * k) < n

    def coefficient_box(self, limits: MotionLimits) -> tuple[Tensor, Tensor]:
        self.check_joints(limits.joint_names, "the motion-limit box")
        low, high = offset_box(limits)
        cap = amplitude_caps(limits, self._omega).flatten()
        return torch.cat((low, -cap)), torch.cat((high, cap))
