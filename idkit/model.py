"""``IdentifiedModel``: a robot with identified parameters, the thing a fit gives you to hold.

An ``Estimate`` is a record (parameters by name, the estimator's details). The model puts it back
on its robot, so that it can be used without rebuilding a parameter tensor by name:

* ``predict(q, qd, qdd)``: joint torques, numpy in → numpy out, torch in → torch out, batched over
  any leading dimensions (``[..., n]`` states → ``[..., n]`` torques);
* ``params`` / ``base_params``: values by name with a standard deviation where one exists
  (:class:`Parameters`: its ``note`` says where σ came from and why some have none);
* ``save("identified.urdf" | "identified.xml")``: the robot's own file with the identified values
  written in (:mod:`idkit.robots.urdf_export`, :mod:`idkit.robots.mjcf_export`);
* ``to_pinocchio()`` / ``to_mujoco()``: the same model in those libraries (optional extras).

``idkit.identify`` returns one (with its held-out scores and the run's result); ``RunResult.model``
gives one for any single fit; ``IdentifiedModel(robot, estimate)`` wraps an estimate you hold.
"""

from __future__ import annotations

import functools
import math
import os
import types
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from idkit.estimate import Estimate
from idkit.std_source import describe

if TYPE_CHECKING:
    from torch import Tensor

    from idkit.interfaces import Robot
    from idkit.studies.single import HeldOut, RunResult

Array = TypeVar("Array", "np.ndarray", "Tensor")

#: How each extra a conversion needs is installed (the distribution's name is ``robot-idkit``).
EXTRAS = {"pinocchio": "pinocchio", "mujoco": "mjcf"}

#: A derivative below this fraction of its row's largest counts as zero (numerical base maps
#: carry round-off where a parameter is absent).
_ZERO = 1e-10


class Parameters(Mapping[str, float]):
    """Identified values by name (``model.params["link2.m"]``, a read-only mapping), with a standard
    deviation each where the estimate determines one.

    Attributes:
        std: name → standard deviation; ``None`` where none exists (``note`` says why), ``inf``
            along directions the data do not determine.
        note: where the standard deviations come from, and why some (or all) are ``None``.
    """

    def __init__(self, values: Mapping[str, float], std: Mapping[str, float | None], note: str) -> None:
        self._values = dict(values)
        self.std: Mapping[str, float | None] = types.MappingProxyType(dict(std))
        self.note = note

    def __getitem__(self, name: str) -> float:
        return self._values[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def __repr__(self) -> str:
        return f"Parameters({self._values!r}, std={dict(self.std)!r})"

    def tensor(self) -> Tensor:
        """The values as a float64 tensor ``[K]`` in the robot's order."""
        import torch

        return torch.tensor(list(self._values.values()), dtype=torch.float64)

    def table(self) -> list[tuple[str, float, float | None]]:
        """``(name, value, std)`` rows in the robot's order."""
        return [(name, value, self.std[name]) for name, value in self._values.items()]


class IdentifiedModel:
    """A robot and its identified parameters (module doc).

    Args:
        robot: the robot plugin the parameters belong to (the one the estimator fitted).
        estimate: the fit's ``Estimate`` (``params`` keyed by ``robot.param_names``).
        validation: the fit's held-out scores (``idkit.studies.single.HeldOut``), if any.
        result: the whole run (``idkit.studies.single.RunResult``), if the model came from one.

    Raises:
        ValueError: the estimate lacks a parameter of the robot or has one it does not know.
    """

    def __init__(
        self,
        robot: Robot,
        estimate: Estimate,
        *,
        validation: Sequence[HeldOut] = (),
        result: RunResult | None = None,
    ) -> None:
        names = tuple(robot.param_names)
        missing = [name for name in names if name not in estimate.params]
        extra = [name for name in estimate.params if name not in names]
        if missing or extra:
            raise ValueError(
                f"IdentifiedModel: estimate {estimate.estimator!r} does not match robot "
                f"{type(robot).__name__}: missing {_few(missing)}, unknown {_few(extra)}"
            )
        self.robot = robot
        self.estimate = estimate
        self.validation = tuple(validation)
        self.result = result

    @classmethod
    def from_params(
        cls, robot: Robot, params: Mapping[str, float] | Sequence[float] | Tensor, label: str = "given"
    ) -> IdentifiedModel:
        """A model at given parameters (a map by name, or ``[P]`` in ``robot.param_names`` order), e.g.
        the CAD values or a simulation's truth; it has no standard deviations."""
        if not isinstance(params, Mapping):
            values = np.asarray(params.tolist() if hasattr(params, "tolist") else params, dtype=np.float64)
            if values.shape != (len(robot.param_names),):
                raise ValueError(
                    f"IdentifiedModel.from_params: params must be [{len(robot.param_names)}] "
                    f"({_few(list(robot.param_names))}), got shape {values.shape}"
                )
            params = dict(zip(robot.param_names, values.tolist(), strict=True))
        return cls(robot, Estimate(label, {k: float(v) for k, v in params.items()}, None, 0.0))

    def __repr__(self) -> str:
        held = f", {len(self.validation)} held-out file(s)" if self.validation else ""
        return (
            f"IdentifiedModel({type(self.robot).__name__}, {len(self.robot.joint_names)} joints, "
            f"{len(self.robot.param_names)} parameters, estimator {self.estimate.estimator!r}{held})"
        )

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The joints, in the order of the columns ``predict`` takes and returns."""
        return tuple(self.robot.joint_names)

    @functools.cached_property
    def vector(self) -> Tensor:
        """The physical parameters ``[P]`` (float64, CPU) in ``robot.param_names`` order."""
        import torch

        values = [float(self.estimate.params[name]) for name in self.robot.param_names]
        return torch.tensor(values, dtype=torch.float64)

    # --- prediction ---------------------------------------------------------------------------

    def predict(self, q: Array, qd: Array, qdd: Array) -> Array:
        """Joint torques the model predicts at the states ``q, qd, qdd``, each ``[..., n]``.

        Numpy (or array-like) in → a float64 numpy array out; torch in → a tensor on the input's
        device and (floating) dtype, differentiable (mixed dtypes meet in the wider one, as in torch's
        own arithmetic: float32 with float64 → float64). Any leading dimensions: ``[n]`` → ``[n]``,
        ``[N, n]`` → ``[N, n]``, ``[2, N, n]`` → ``[2, N, n]``. Columns are ``joint_names``.
        The torques are joint torques (with the robot's friction, offsets, rotor inertia): a robot
        whose recordings hold another effort converts those with ``robot.joint_torques``.

        Raises:
            TypeError: numpy and torch mixed, or a non-numeric input.
            ValueError: the three shapes differ, the last dimension is not ``n``, or the tensors are
                on different devices.
        """
        import torch

        states, as_numpy = _as_tensors(q, qd, qdd)
        n = len(self.robot.joint_names)
        shapes = [tuple(x.shape) for x in states]
        if len(set(shapes)) != 1 or not shapes[0] or shapes[0][-1] != n:
            got = ", ".join(f"{name} {shape}" for name, shape in zip(("q", "qd", "qdd"), shapes, strict=True))
            raise ValueError(
                f"predict: q, qd, qdd must have one shape [..., {n}] (joints "
                f"{_few(list(self.joint_names))}), got {got}"
            )
        batch = shapes[0][:-1]
        flat = [x.reshape(-1, n) for x in states]
        params = self.vector.to(device=flat[0].device, dtype=flat[0].dtype)
        if flat[0].shape[0] == 0:
            tau = flat[0].new_zeros((0, n))
        elif as_numpy:
            with torch.no_grad():
                tau = self.robot.inverse_dynamics(params, *flat)
        else:
            tau = self.robot.inverse_dynamics(params, *flat)
        tau = tau.reshape(*batch, n)
        return tau.numpy() if as_numpy else tau  # type: ignore[return-value]  # as_numpy follows Array

    # --- parameters ---------------------------------------------------------------------------

    @functools.cached_property
    def base_params(self) -> Parameters | None:
        """The base parameters (identifiable combinations) by name with their σ, or ``None`` for a
        robot that declares none. Values: the estimate's, else ``robot.base_params`` of ``params``."""
        names = tuple(self.robot.base_param_names)
        if not names:
            return None
        if self.estimate.base_params is not None and set(names) <= set(self.estimate.base_params):
            values = {name: float(self.estimate.base_params[name]) for name in names}
        else:
            computed = self.robot.base_params(self.vector).tolist()
            values = dict(zip(names, map(float, computed), strict=True))
        reported = self._reported_std()
        if reported is None:
            return Parameters(values, dict.fromkeys(names), self._no_std_note())
        std = {name: reported.get(name) for name in names}
        absent = [name for name in names if std[name] is None]
        note = self._std_source() + (f"; none reported for {_few(absent)}" if absent else "")
        return Parameters(values, std, note)

    @functools.cached_property
    def params(self) -> Parameters:
        """The physical parameters by name with their σ where one exists.

        The data determine base parameters (combinations); a physical parameter gets a σ only where
        a base parameter depends on it alone, ``α_j = f(p_k)``: then ``σ(p_k) = σ(α_j) / |f'(p_k)|``
        (the delta method, exact for a linear ``f``). The others are ``None``: they enter only in
        combinations, whose covariance the estimate does not carry.
        """
        values = {name: float(self.estimate.params[name]) for name in self.robot.param_names}
        base = self.base_params
        if self._reported_std() is None or base is None:
            why = self._no_std_note() if base is not None else "no σ: the robot declares no base parameters"
            return Parameters(values, dict.fromkeys(values), why)
        std: dict[str, float | None] = dict.fromkeys(values)
        for k, j, slope in self._alone():
            sigma = base.std.get(self.robot.base_param_names[j])
            if sigma is not None and std[self.robot.param_names[k]] is None:
                std[self.robot.param_names[k]] = sigma / abs(slope) if slope else math.inf
        alone = sum(s is not None for s in std.values())
        note = (
            f"{base.note}; {alone} of {len(values)} physical parameters are a base parameter's only "
            "term (their σ is that parameter's, by the delta method); the others enter only in "
            "combinations and have no σ of their own"
        )
        return Parameters(values, std, note)

    def _alone(self) -> list[tuple[int, int, float]]:
        """``(k, j, ∂α_j/∂p_k)`` for every base parameter ``α_j`` that depends on ``p_k`` alone."""
        import torch

        try:
            jacobian = torch.autograd.functional.jacobian(self.robot.base_params, self.vector)
        except (NotImplementedError, RuntimeError, TypeError):
            return []
        found = []
        for j, row in enumerate(jacobian.abs()):
            top = float(row.max())
            live = (row > _ZERO * top).nonzero().flatten().tolist() if top > 0 else []
            if len(live) == 1:
                found.append((live[0], j, float(jacobian[j, live[0]])))
        return found

    def _reported_std(self) -> dict[str, float] | None:
        """The base-parameter σ the estimator reported (``details["uncertainty"]["std"]``), if any."""
        uncertainty = self.estimate.details.get("uncertainty")
        std = uncertainty.get("std") if isinstance(uncertainty, Mapping) else None
        if not isinstance(std, Mapping):
            return None
        return {str(k): float(v) for k, v in std.items() if v is not None}

    def _std_source(self) -> str:
        """The estimator's own record of its σ method, in :mod:`idkit.std_source`'s words (the same
        sentence ``result.json`` carries as ``std_source``)."""
        uncertainty = self.estimate.details.get("uncertainty")
        method = uncertainty.get("method") if isinstance(uncertainty, Mapping) else None
        return (
            f"{describe(method if isinstance(method, str) else None)} (estimator {self.estimate.estimator!r})"
        )

    def _no_std_note(self) -> str:
        return (
            f"no σ: estimator {self.estimate.estimator!r} reports no uncertainty "
            '(its details have no "uncertainty"; the least-squares family and pcls report one)'
        )

    # --- files and other libraries ------------------------------------------------------------

    def to_urdf(self) -> str:
        """The robot's URDF with the identified values written in (:mod:`idkit.robots.urdf_export`).

        Raises:
            ValueError: the robot was not read from a URDF, or a value cannot be written (mass ≤ 0).
        """
        robot = self._file_robot("urdf")
        from idkit.robots.urdf_export import identified_urdf

        return identified_urdf(robot, self.estimate.params, self.estimate.details.get("payload"))

    def to_mjcf(self) -> str:
        """The robot's MJCF (its own, or MuJoCo's conversion of its URDF) with the identified values
        written in (:mod:`idkit.robots.mjcf_export`); needs the ``mjcf`` extra.

        Raises:
            ValueError: the robot has no URDF/MJCF, or MuJoCo refuses a non-physical inertia.
            PluginLoadError: ``mujoco`` is not installed.
        """
        robot = self._file_robot("mjcf")
        from idkit.robots.mjcf_export import identified_mjcf

        return identified_mjcf(robot, self.estimate.params)

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write ``identified.urdf`` (suffix ``.urdf``) or MJCF (``.xml``/``.mjcf``) to ``path``.

        The text is made in full before the file is opened, and the file replaced in one step
        (:func:`idkit.reports.files.write_text`: a file replaced keeps its mode), so a refused model
        never leaves a half-written (or emptied) file behind.

        Raises:
            ValueError: another suffix, or the writer refuses the model (see ``to_urdf``/``to_mjcf``).
        """
        path = Path(path)
        writers = {".urdf": self.to_urdf, ".xml": self.to_mjcf, ".mjcf": self.to_mjcf}
        suffix = path.suffix.lower()
        if suffix not in writers:
            raise ValueError(
                f"save: {str(path)!r} has suffix {path.suffix or '(none)'!r}; use .urdf (URDF) or .xml (MJCF)"
            )
        text = writers[suffix]()
        from idkit.reports.files import write_text

        return write_text(path, text)

    def to_pinocchio(self) -> Any:
        """A ``pinocchio.Model`` of the identified URDF, its ``armature`` set from the identified rotor
        inertias (``pin.rnea`` adds ``armature · qdd``). Pinocchio's inverse dynamics have no friction
        or offset terms: ``predict`` = ``pin.rnea`` + ``fc sign(qd) + fv qd + offset`` (``model.friction``
        and ``model.damping`` carry ``fc`` and ``fv`` from ``<dynamics>``, as pinocchio reads them).

        Raises:
            ImportError: pinocchio is not installed (names the extra).
            ValueError: the robot was not read from a URDF.
        """
        text = self.to_urdf()
        pin = _import("pinocchio", "to_pinocchio")
        model = pin.buildModelFromXML(text)
        for name in self.robot.joint_names:
            key = f"{name}.armature"
            if key in self.estimate.params:
                joint = model.joints[model.getJointId(name)]
                model.armature[joint.idx_v] = float(self.estimate.params[key])
        return model

    def to_mujoco(self) -> Any:
        """A compiled ``mujoco.MjModel`` of :meth:`to_mjcf` (joint ``damping`` = ``fv``,
        ``frictionloss`` = ``fc``, ``armature``; offsets in its custom numerics).

        Raises:
            ImportError: mujoco is not installed (names the extra).
            ValueError: as :meth:`to_mjcf`.
        """
        mujoco = _import("mujoco", "to_mujoco")
        return mujoco.MjModel.from_xml_string(self.to_mjcf())

    def _file_robot(self, kind: str) -> Any:
        """The robot if it can be written as ``kind`` (``"urdf"`` or ``"mjcf"``), else a ``ValueError``."""
        from idkit.robots.urdf import URDFRobot

        robot = self.robot
        name = type(robot).__name__
        if not isinstance(robot, URDFRobot):
            raise ValueError(
                f"{name} is not read from a URDF or MJCF file, so there is no file to write the "
                "identified values into (robot=urdf or robot=mjcf can be)"
            )
        if kind == "urdf" and robot.source_format != "urdf":
            raise ValueError(f"{name} was read from {robot.source_format.upper()}: save it as .xml (MJCF)")
        return robot


def _few(names: Sequence[str], shown: int = 4) -> str:
    if not names:
        return "none"
    return ", ".join(names[:shown]) + (f", … ({len(names)} in all)" if len(names) > shown else "")


def _import(module: str, method: str) -> Any:
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        extra = EXTRAS[module]
        raise ImportError(
            f"IdentifiedModel.{method} needs {module}: pip install 'robot-idkit[{extra}]'"
        ) from None


def _as_tensors(*arrays: Any) -> tuple[list[Tensor], bool]:
    """The states as tensors, and whether they came as numpy (or array-likes)."""
    import torch

    is_tensor = [isinstance(a, torch.Tensor) for a in arrays]
    if any(is_tensor) and not all(is_tensor):
        kinds = ", ".join(type(a).__name__ for a in arrays)
        raise TypeError(f"predict: q, qd, qdd must be all torch tensors or all numpy arrays, got {kinds}")
    if all(is_tensor):
        out = []
        for a in arrays:
            if a.dtype == torch.bool or a.is_complex():
                raise TypeError(f"predict: states must be real numbers, got dtype {a.dtype}")
            out.append(a if a.is_floating_point() else a.to(torch.float64))
        devices = {str(a.device) for a in out}
        if len(devices) > 1:
            shown = ", ".join(
                f"{name} on {a.device}" for name, a in zip(("q", "qd", "qdd"), out, strict=True)
            )
            raise ValueError(f"predict: q, qd, qdd must be on one device, got {shown}")
        common = functools.reduce(torch.promote_types, (a.dtype for a in out))  # as torch's own arithmetic
        return [a.to(common) for a in out], False
    converted = []
    for a in arrays:
        array = np.asarray(a)
        if array.dtype.kind not in "iuf":
            raise TypeError(f"predict: states must be real numbers, got dtype {array.dtype}")
        converted.append(torch.from_numpy(np.ascontiguousarray(array, dtype=np.float64)))
    return converted, True
