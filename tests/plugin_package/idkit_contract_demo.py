"""idkit plugins written from the documented contract alone: none subclasses ``idkit.interfaces``.

Complete: ``Pendulum`` (robot), ``MeanAbsoluteError`` and ``made_cost`` (costs; the second is a
factory function), ``RandomSearch`` (estimator), ``Swing`` (excitation). Each has only the required
members, so idkit must supply every optional one (``n_joints``, ``structure()``, ``check_joints``,
``__call__`` of an excitation, ...). Incomplete on purpose: ``Stiff`` (no ``inverse_dynamics``),
``Nameless`` (no ``joint_names``), ``NoCall`` (no ``__call__``).
"""

from __future__ import annotations

import math
import time

import torch

from idkit.estimate import Estimate


class Pendulum:
    """One joint: ``tau = J qdd + g h cos(q) + fv qd``, parameters ``(J, h, fv)``."""

    joint_names = ("q",)
    param_names = ("J", "h", "fv")

    def __init__(self, g: float = 9.81) -> None:
        self.g = g

    def bounds(self):
        return torch.zeros(3, dtype=torch.float64), torch.tensor([2.0, 5.0, 1.0], dtype=torch.float64)

    def nominal_params(self):
        return torch.tensor([0.5, 1.0, 0.2], dtype=torch.float64)

    def inverse_dynamics(self, params, q, qd, qdd):
        if params.shape[-1:] != (3,) or any(x.ndim != 2 or x.shape[1] != 1 for x in (q, qd, qdd)):
            raise ValueError(
                f"Pendulum: params [..., 3] and states [N, 1], got {tuple(params.shape)}, {tuple(q.shape)}"
            )
        features = torch.stack((qdd, self.g * torch.cos(q), qd), dim=-1)  # [N, 1, 3]
        return torch.einsum("snb,...b->...sn", features.to(params), params)


class Stiff:
    """A robot without ``inverse_dynamics``: refused when loaded."""

    joint_names = ("q",)
    param_names = ("k",)

    def bounds(self):
        return torch.zeros(1, dtype=torch.float64), torch.ones(1, dtype=torch.float64)


class Nameless:
    """A robot without ``joint_names``: refused when built."""

    param_names = ("k",)

    def bounds(self):
        return torch.zeros(1, dtype=torch.float64), torch.ones(1, dtype=torch.float64)

    def inverse_dynamics(self, params, q, qd, qdd):
        return params[..., None, :] * q


class MeanAbsoluteError:
    """Mean absolute torque error (relative: divided by the measured torque's magnitude)."""

    def __init__(self, relative: bool = False) -> None:
        self.relative = relative

    def __call__(self, error, measured):
        if measured.shape != error.shape[-2:]:
            raise ValueError(
                f"MeanAbsoluteError: measured {tuple(measured.shape)} != error's {error.shape[-2:]}"
            )
        scale = measured.abs().clamp_min(1e-3) if self.relative else 1.0
        return (error / scale).abs().mean(dim=(-2, -1))


def made_cost(power: float = 2.0) -> object:
    """A factory function returning a cost instance of a class that does not subclass ``Cost``."""

    class Power:
        relative = False

        def __call__(self, error, measured):
            return error.abs().pow(power).mean(dim=(-2, -1))

    return Power()


class NoCall:
    """A cost without ``__call__``: refused when loaded."""

    relative = False


class RandomSearch:
    """The best of ``samples`` uniform draws in the robot's box, in one batched evaluation."""

    def __init__(self, samples: int = 2000) -> None:
        self.samples = samples

    def fit(self, problem):
        start = time.perf_counter()
        problem.check_identifiable()
        lower, upper = (b.to(problem.device, problem.torch_dtype) for b in problem.robot.bounds())
        u = torch.rand(
            self.samples,
            len(lower),
            generator=problem.generator(),
            device=problem.device,
            dtype=problem.torch_dtype,
        )
        candidates = lower + u * (upper - lower)
        best = candidates[problem.evaluate(candidates).argmin()]
        return Estimate(
            estimator="RandomSearch",
            params=dict(zip(problem.robot.param_names, best.tolist(), strict=True)),
            cost=float(problem.evaluate(best)),
            wall_time_s=time.perf_counter() - start,
            details={"samples": self.samples},
        )


class Swing:
    """Every joint swings ``q = amplitude sin(2 pi frequency t)``; the coefficient is the amplitude."""

    def __init__(self, n_joints: int = 1, amplitude: float = 1.0, frequency: float = 0.3) -> None:
        self.n_joints, self.amplitude, self.frequency = n_joints, amplitude, frequency

    def options(self):
        return {"n_joints": self.n_joints, "amplitude": self.amplitude, "frequency": self.frequency}

    def to_vector(self):
        return torch.tensor([self.amplitude], dtype=torch.float64)

    def from_vector(self, vector):
        return Swing(self.n_joints, float(vector[0]), self.frequency)

    def evaluate(self, coefficients, t):
        w = 2 * math.pi * self.frequency
        amplitude = coefficients[..., None, :1].to(t)  # [..., 1, 1]
        phase = (w * t)[:, None].expand(-1, self.n_joints)  # [T, n]
        return amplitude * phase.sin(), amplitude * w * phase.cos(), -amplitude * w**2 * phase.sin()
