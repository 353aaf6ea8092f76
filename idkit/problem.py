"""Measured samples and the identification problem handed to an estimator."""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from typing import TYPE_CHECKING

import torch
from torch import Tensor

if TYPE_CHECKING:
    from idkit.interfaces import Cost, Robot

SAMPLE_ARRAYS = ("q", "qd", "qdd", "tau")

DTYPES = {"float64": torch.float64, "float32": torch.float32}


def resolve_dtype(dtype: str | torch.dtype) -> torch.dtype:
    """Accept ``"float64"``/``"float32"`` (config-friendly) or a ``torch.dtype``."""
    if isinstance(dtype, torch.dtype):
        return dtype
    try:
        return DTYPES[dtype]
    except KeyError:
        raise ValueError(f"unknown dtype {dtype!r}; use one of {', '.join(DTYPES)}") from None


def _check_finite(name: str, array: Tensor) -> None:
    bad = ~torch.isfinite(array)
    if bad.any():
        sample, joint = (int(i) for i in bad.nonzero()[0])
        raise ValueError(
            f"samples: array {name!r} has a non-finite value ({array[sample, joint].item()}) "
            f"at sample {sample}, joint {joint} ({int(bad.sum())} non-finite entries in all)"
        )


@dataclass(frozen=True)
class Samples:
    """N measured samples of an n-joint robot: ``q, qd, qdd, tau``, each ``[N, n]``.

    Validated on construction: 2-D, equal shapes, finite — the error names the array and the sample,
    because a NaN that reaches an optimiser surfaces far from its cause.
    """

    q: Tensor
    qd: Tensor
    qdd: Tensor
    tau: Tensor

    def __post_init__(self) -> None:
        shape = None
        for name in SAMPLE_ARRAYS:
            value = getattr(self, name)
            if not isinstance(value, Tensor):
                value = torch.as_tensor(value, dtype=torch.float64)
                object.__setattr__(self, name, value)
            if value.ndim != 2:
                raise ValueError(
                    f"samples: array {name!r} must be 2-D [N samples, n joints], got shape "
                    f"{tuple(value.shape)}"
                )
            if shape is None:
                shape = value.shape
            elif value.shape != shape:
                raise ValueError(
                    f"samples: array {name!r} has shape {tuple(value.shape)} but 'q' has "
                    f"{tuple(shape)}; all four arrays must be [N samples, n joints]"
                )
            if not value.is_floating_point():
                object.__setattr__(self, name, value.to(torch.float64))
            _check_finite(name, getattr(self, name))

    @property
    def n_samples(self) -> int:
        return self.q.shape[0]

    @property
    def n_joints(self) -> int:
        return self.q.shape[1]

    def to(self, device: str | torch.device | None = None, dtype: torch.dtype | None = None) -> Samples:
        return replace(self, **{k: getattr(self, k).to(device=device, dtype=dtype) for k in SAMPLE_ARRAYS})

    def measured_matrix(self) -> Tensor:
        """Measured torques ``T[n, N]`` in the paper's joints × samples layout (eq. 25)."""
        return self.tau.T


@dataclass(frozen=True)
class Problem:
    """Everything an estimator needs: robot, samples, cost, seed and where to compute.

    ``cost`` may be ``None`` for estimators that fix their own criterion (the least-squares family).
    Frozen, so that the samples moved to ``device``/``dtype`` can be cached; derive variants with
    ``dataclasses.replace``.
    """

    robot: Robot
    samples: Samples
    cost: Cost | None = None
    seed: int = 0
    device: str = "cpu"
    dtype: str | torch.dtype = "float64"

    def __post_init__(self) -> None:
        if self.samples.n_joints != self.robot.n_joints:
            raise ValueError(
                f"samples have {self.samples.n_joints} joints but robot "
                f"{type(self.robot).__name__} has {self.robot.n_joints} ({', '.join(self.robot.joint_names)})"
            )

    @property
    def torch_dtype(self) -> torch.dtype:
        return resolve_dtype(self.dtype)

    def tensors(self) -> Samples:
        """The samples on the problem's device and dtype (converted once, then cached)."""
        return self._tensors

    @cached_property
    def _tensors(self) -> Samples:
        return self.samples.to(device=self.device, dtype=self.torch_dtype)

    def error(self, params: Tensor) -> Tensor:
        """Torque error ``E[..., n, N] = measured - predicted`` (eqs. 5-6) for ``params[..., P]``."""
        s = self.tensors()
        predicted = self.robot.inverse_dynamics(params, s.q, s.qd, s.qdd)
        return (s.tau - predicted).transpose(-1, -2)

    def evaluate(self, params: Tensor) -> Tensor:
        """The problem's cost ``[...]`` at physical parameters ``params[..., P]``."""
        if self.cost is None:
            raise ValueError("this problem has no cost to evaluate (Problem.cost is None)")
        return self.cost(self.error(params), self.tensors().measured_matrix())

    def generator(self) -> torch.Generator:
        """A fresh generator seeded from ``seed``, on the problem's device."""
        return torch.Generator(device=self.device).manual_seed(int(self.seed))
