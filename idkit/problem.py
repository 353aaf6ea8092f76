"""Measured samples and the identification problem handed to an estimator.

An *identification problem* is one concept with two kinds: the torque :class:`Problem` (a robot's
inverse dynamics against measured torques) and the rollout problem
(:class:`idkit.sim.problem.RolloutProblem`: a simulator rolled out under logged commands against the
measured joint states). Both implement :class:`IdentificationProblem`; an estimator declares the kind
it fits (``Estimator.problem_type``), so that "which task runs this estimator" is a type check.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import torch
from torch import Tensor

from idkit.seeds import check_seed, torch_generator

if TYPE_CHECKING:
    from idkit.interfaces import Cost, Robot

SAMPLE_ARRAYS = ("q", "qd", "qdd", "tau")

DTYPES = {"float64": torch.float64, "float32": torch.float32}


class IdentificationError(ValueError):
    """The data cannot identify the parameters (too few equations, rank deficiency, ...)."""


def resolve_dtype(dtype: str | torch.dtype) -> torch.dtype:
    """Accept ``"float64"``/``"float32"`` (config-friendly) or one of those ``torch.dtype``s."""
    if isinstance(dtype, torch.dtype) and dtype in DTYPES.values():
        return dtype
    if isinstance(dtype, str) and dtype in DTYPES:
        return DTYPES[dtype]
    raise ValueError(f"unknown dtype {dtype!r} (option dtype); use one of {', '.join(DTYPES)}")


def available_devices() -> list[str]:
    """The devices this torch build can compute on here: ``cpu``, then ``cuda:i`` and ``mps`` if present."""
    devices = ["cpu"]
    if torch.cuda.is_available():
        devices += [f"cuda:{i}" for i in range(torch.cuda.device_count())]
    mps = getattr(torch.backends, "mps", None)
    if mps is not None and mps.is_available():
        devices.append("mps")
    return devices


def check_device(device: str | torch.device) -> torch.device:
    """The ``torch.device`` for a ``device`` option, or a ``ValueError`` naming what is available.

    Checked before any tensor moves, so ``device=cuda`` on a machine without CUDA fails with one line
    instead of a traceback from deep inside torch.
    """
    try:
        parsed = torch.device(device)
    except (RuntimeError, TypeError):
        raise ValueError(
            f"device {device!r} is not a torch device name (option device); available here: "
            f"{', '.join(available_devices())}"
        ) from None
    if parsed.type == "cuda":
        if not torch.cuda.is_available():
            build = f"CUDA {torch.version.cuda}" if torch.version.cuda else "a CPU-only build"
            raise ValueError(
                f"device {device!r} requested but CUDA is not available (torch.cuda.is_available() "
                f"is False; torch {torch.__version__} is {build}); available here: "
                f"{', '.join(available_devices())}"
            )
        if parsed.index is not None and parsed.index >= torch.cuda.device_count():
            raise ValueError(
                f"device {device!r} requested but there are {torch.cuda.device_count()} CUDA device(s); "
                f"available here: {', '.join(available_devices())}"
            )
    elif parsed.type != "cpu" and str(parsed) not in available_devices():
        try:
            torch.empty(0, device=parsed)
        except (RuntimeError, AssertionError):
            raise ValueError(
                f"device {device!r} requested but this torch build cannot use it; available here: "
                f"{', '.join(available_devices())}"
            ) from None
    return parsed


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
class Recorded:
    """Another recording an estimator names (a payload's reference), read for it by whoever read the
    problem's samples — a study reads it exactly as the ``data=`` files (the resolved cut-off, torque
    delay, log topics, effort scale), so that its rows and the data's are made alike.

    Attributes:
        samples: its samples ``[N', n]``, torques in joint torque.
        about: how it was read, for the estimator's ``details`` (``preprocessed``, ``preprocess``,
            ``delay``).
    """

    samples: Samples
    about: Mapping[str, Any] = field(default_factory=dict)


class ParameterSpace(Protocol):
    """What every problem's ``robot`` tells: the names of the parameters (or unknowns) a fit sets."""

    @property
    def param_names(self) -> tuple[str, ...]: ...

    @property
    def n_joints(self) -> int: ...


@runtime_checkable
class IdentificationProblem(Protocol):
    """What an estimator and the conformance suite may use of any problem, whatever its kind.

    Attributes:
        robot: what is identified (``param_names``: the estimate's keys, in order).
        samples: the measurements (their type is the kind's: ``Samples``, a ``RobotLog``).
        cost: the criterion (``None``: the estimator's own).
        seed: every random draw of a fit derives from it (:meth:`generator`).
    """

    robot: ParameterSpace
    samples: Any
    cost: Cost | None
    seed: int

    @property
    def n_identifiable(self) -> int:
        """How many values the measurements must determine."""
        ...

    def check_identifiable(self) -> None:
        """Raise :class:`IdentificationError` when the measurements give fewer equations than values."""
        ...

    def evaluate(self, params: Tensor) -> Tensor:
        """The problem's cost ``[...]`` at ``params[..., P]``."""
        ...

    def generator(self) -> torch.Generator:
        """A fresh generator whose whole state comes from ``seed``."""
        ...

    def head(self, n: int) -> IdentificationProblem:
        """The same problem on its first ``n`` samples."""
        ...


@dataclass(frozen=True)
class Problem(IdentificationProblem):
    """Everything an estimator needs: robot, samples, cost, seed and where to compute.

    ``cost`` may be ``None`` for estimators that fix their own criterion (the least-squares family).
    ``recordings``: the other recordings the estimator names (``Estimator.files_needed``), by path,
    read as the samples were: an estimator reads no file. Frozen, so that the samples moved to
    ``device``/``dtype`` can be cached; derive variants with ``dataclasses.replace``.
    """

    robot: Robot
    samples: Samples
    cost: Cost | None = None
    seed: int = 0
    device: str = "cpu"
    dtype: str | torch.dtype = "float64"
    recordings: Mapping[str, Recorded] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.samples.n_joints != self.robot.n_joints:
            raise ValueError(
                f"samples have {self.samples.n_joints} joints but robot "
                f"{type(self.robot).__name__} has {self.robot.n_joints} ({', '.join(self.robot.joint_names)})"
            )
        object.__setattr__(self, "seed", check_seed(self.seed))
        resolve_dtype(self.dtype)
        check_device(self.device)

    @property
    def n_identifiable(self) -> int:
        """How many parameters the data must determine: the robot's base parameters ``B`` if it
        declares them, else all ``P`` physical parameters (an upper bound)."""
        return len(self.robot.base_param_names) or self.robot.n_params

    def check_identifiable(self) -> None:
        """Raise ``IdentificationError`` if the samples give fewer equations than parameters.

        Every sample gives one equation per joint, so ``N · n`` equations must be at least the
        ``n_identifiable`` parameters. With fewer, any estimator can drive its cost to about zero
        with an arbitrary estimate (the least-squares family would meet a rank-deficient system;
        PSO and Adam would return a random point of the solution set), so every estimator calls this
        at the top of ``fit``. It checks counts only: whether the trajectory excites every base
        parameter is the rank test of ``idkit.estimators.linear.observation``.
        """
        n_samples, n_joints = self.samples.n_samples, self.samples.n_joints
        equations, needed = n_samples * n_joints, self.n_identifiable
        if equations < needed:
            kind = "base parameters" if self.robot.base_param_names else "parameters"
            raise IdentificationError(
                f"robot {type(self.robot).__name__}: {n_samples} sample{'s' * (n_samples != 1)} × "
                f"{n_joints} joint{'s' * (n_joints != 1)} = {equations} equations < {needed} {kind}; "
                f"give at least {math.ceil(needed / n_joints)} samples"
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

    def base_regressor(self) -> Tensor:
        """The robot's base regressor of the samples, ``[N n, B]`` (rows sample-major), computed once:
        least-squares estimators, ``pcls`` and a refit with other bounds all start from it, and it
        is the costliest step of a linear fit on a long recording."""
        return self._base_regressor

    @cached_property
    def _base_regressor(self) -> Tensor:
        s = self.tensors()
        return self.robot.regressor(s.q, s.qd, s.qdd).reshape(-1, len(self.robot.base_param_names))

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
        """A fresh generator on the problem's device whose whole state comes from ``seed``."""
        return torch_generator(self.seed, self.device)

    def head(self, n: int) -> Problem:
        """The same problem on its first ``n`` samples (``recordings`` kept)."""
        if not 1 <= n <= self.samples.n_samples:
            raise ValueError(f"head({n}) of a problem of {self.samples.n_samples} samples")
        s = self.samples
        return replace(self, samples=Samples(s.q[:n], s.qd[:n], s.qdd[:n], s.tau[:n]))
