"""Drives: the joint-space terms between what a robot records and its rigid-body torques.

For every joint ``j`` the model is::

    k_j · effort_j = τ_rigid,j(q, q̇, q̈) + friction_j(q̇_j) + Ia_j q̈_j + offset_j

* ``k`` (``effort_scale``) turns the recorded effort into joint torque, e.g. gear ratio × torque
  constant when the controller logs motor current. It scales the *measured* torques where a
  recording enters a study, so every estimator, every reported error (N·m) and the identified model
  are in joint torque;
* ``Ia`` (``armature``) is the rotor inertia reflected through the gear (``I_rotor · N²``);
* the friction model is one of ``FRICTION_MODELS``: Coulomb + viscous ``fc sign(q̇) + fv q̇`` (with
  an optional low-speed term ``fs exp(−(q̇/v_s)²) sign(q̇)``), asymmetric Coulomb ``fc_pos [q̇ > 0] −
  fc_neg [q̇ < 0] + fv q̇``, or the sigmoid model of Gaz et al. (RA-L 2019) plus viscous friction::

      φ1 / (1 + exp(−φ2 (q̇ + φ3))) − φ1 / (1 + exp(−φ2 φ3)) + fv q̇

  whose steepness ``φ2`` and shift ``φ3`` enter nonlinearly (*shape* parameters: no regressor
  column; linear estimators keep them at their reference value, :mod:`idkit.estimators.varpro`
  searches them);
* ``offset`` is a constant torque (a sensor bias).

**Coulomb friction near zero speed.** ``sign(q̇)`` jumps by ``2 fc`` where the velocity crosses
zero, and a measured velocity at rest is noise around zero: a model of a joint at rest then predicts
``±fc`` at random (on a real arm's point-to-point motion the wrist's predicted torque flipped by
±2.3 N·m for 12 s). With a velocity scale ``v_c`` (``coulomb_scales``) every ``sign(q̇)`` of the
Coulomb terms becomes ``tanh(q̇ / v_c)``: the same saturation above a few ``v_c``, zero friction
predicted at rest (the middle of the static band ``±fc``), and still one linear coefficient per
joint. ``idkit.studies.coulomb`` chooses ``v_c`` by cross-validation on the training recording.

Each term is one group of per-joint parameters ``<joint>.<suffix>``, every term linear in its
coefficient except the shape parameters, so a :class:`DriveModel` hands the robot regressor columns
(``[N, n, D]``, diagonal per joint) and the exact torques for any batch of parameter sets.

The armature has no URDF field. Convention (read by :func:`read_armatures`, written by
:mod:`idkit.robots.urdf_export`): a ROS ``<transmission>`` of the joint whose ``<actuator>`` carries
``<mechanicalReduction>N</mechanicalReduction>`` and ``<rotor_inertia>I</rotor_inertia>`` (kg·m², on
the motor side) means ``Ia = I · N²``; either element may also sit directly in the transmission (the
older format). A URDF without them has armature 0 a priori.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import torch
from torch import Tensor

from idkit.robots.urdf_model import read_urdf_text

#: The ``friction`` option: ``False`` (none), ``True`` (Coulomb + viscous), or a named model.
Friction = bool | Literal["asymmetric", "sigmoid"]
FRICTION_MODELS: dict[object, tuple[str, ...]] = {
    False: (),
    True: ("fc", "fv"),
    "asymmetric": ("fc_pos", "fc_neg", "fv"),
    "sigmoid": ("phi1", "fv", "phi2", "phi3"),
}
#: The sigmoid friction Gaz et al. (RA-L 2019) identified on a Franka Emika Panda, joints 1–7: a
#: realistic 7-joint reference for simulations (``phi1`` N·m, ``phi2`` s/rad, ``phi3`` rad/s).
GAZ_PANDA_FRICTION: dict[str, tuple[float, ...]] = {
    "phi1": (0.54615, 0.87224, 0.64068, 1.2794, 0.83904, 0.30301, 0.56489),
    "phi2": (5.1181, 9.0657, 10.136, 5.5903, 8.3469, 17.133, 10.336),
    "phi3": (0.039533, 0.025882, -0.04607, 0.036194, 0.026226, -0.021047, 0.0035526),
}
#: Suffixes of the parameters that are physically ``≥ 0`` (pcls constrains them).
NONNEGATIVE = ("fc", "fv", "fc_pos", "fc_neg", "phi1", "armature")


@dataclass(frozen=True)
class Term:
    """One per-joint parameter group ``<joint>.<suffix>``: its search box and kind.

    Attributes:
        suffix: the parameter-name suffix.
        lower, upper: search box of each joint's coefficient.
        shape: a nonlinear shape parameter (no regressor column).
    """

    suffix: str
    lower: float
    upper: float
    shape: bool = False

    @property
    def nonnegative(self) -> bool:
        """Physically ``≥ 0`` (``NONNEGATIVE``)."""
        return self.suffix in NONNEGATIVE


@dataclass(frozen=True)
class Boxes:
    """Search-box widths of the drive parameters (their a-priori value is 0, shapes excepted).

    Attributes:
        coulomb: ``fc``, ``fc_pos``, ``fc_neg``, ``φ1`` in ``[0, coulomb]`` (N·m); ``fs`` in ``±coulomb``.
        viscous: ``fv`` in ``[0, viscous]`` (N·m·s/rad).
        offset: ``offset`` in ``±offset`` (N·m).
        armature: ``Ia`` in ``[0, armature]`` (kg·m²).
        steepness: ``φ2`` in ``[steepness[0], steepness[1]]`` (s/rad).
        shift: ``φ3`` in ``±shift`` (rad/s).
    """

    coulomb: float = 10.0
    viscous: float = 10.0
    offset: float = 10.0
    armature: float = 10.0
    steepness: tuple[float, float] = (1.0, 100.0)
    shift: float = 0.2


def sigmoid_friction(qd: Tensor, steepness: Tensor, shift: Tensor) -> Tensor:
    """Gaz et al.'s friction per unit ``φ1``: ``σ(φ2 (q̇ + φ3)) − σ(φ2 φ3)``, zero at rest.

    Args:
        qd: joint velocities ``[N, n]``.
        steepness, shift: ``φ2``, ``φ3`` broadcasting against ``qd`` (e.g. ``[..., 1, n]``).

    Returns:
        ``[..., N, n]``.
    """
    return torch.sigmoid(steepness * (qd + shift)) - torch.sigmoid(steepness * shift)


def coulomb_sign(qd: Tensor, scales: np.ndarray | None) -> Tensor:
    """``sign(q̇)``, or ``tanh(q̇ / v_c)`` with per-joint velocity scales ``v_c[n] > 0`` (module doc);
    ``qd[..., N, n]``."""
    if scales is None:
        return torch.sign(qd)
    return torch.tanh(qd / torch.as_tensor(scales, dtype=qd.dtype, device=qd.device))


def float_array(value: float | Sequence[float]) -> np.ndarray:
    """One number or a sequence of them (a list, a tuple, a config's list) as floats ``[k]``; non-numbers
    raise numpy's ``ValueError``/``TypeError``, for the caller to word."""
    items = list(value) if isinstance(value, Iterable) and not isinstance(value, (str, bytes)) else value
    return np.atleast_1d(np.asarray(items, dtype=np.float64))


def per_joint(value: float | Sequence[float], joints: Sequence[str], option: str, who: str) -> np.ndarray:
    """A per-joint option as ``[n]`` finite floats (one value is broadcast), or a one-line ``ValueError``."""
    array = float_array(value)
    if array.size == 1:
        array = np.full(len(joints), array[0])
    if array.shape != (len(joints),) or not np.isfinite(array).all():
        raise ValueError(
            f"{who}: {option}={value!r} needs one finite value or {len(joints)} of them "
            f"(joints: {', '.join(joints)})"
        )
    return array


def with_drive_values(
    param_names: Sequence[str], joints: Sequence[str], params: Tensor, values: Mapping[str, Sequence[float]]
) -> Tensor:
    """A copy of ``params[P]`` with ``<joint>.<suffix>`` set to ``values[suffix][j]`` for joint ``j``.

    A sequence longer than the robot's joints gives its first values (e.g. the Panda's friction on
    a 4-joint arm); a suffix the robot lacks is a ``KeyError`` naming the parameter.
    """
    out = params.clone()
    index = {name: k for k, name in enumerate(param_names)}
    for suffix, numbers in values.items():
        for joint, number in zip(joints, numbers, strict=False):
            name = f"{joint}.{suffix}"
            if name not in index:
                raise KeyError(f"the robot has no parameter {name!r}")
            out[index[name]] = float(number)
    return out


def check_effort_scale(value: Sequence[float] | None, joints: Sequence[str], who: str) -> np.ndarray | None:
    """``effort_scale`` as ``[n]`` factors ``k > 0``, or ``None``; a one-line ``ValueError`` otherwise."""
    if value is None:
        return None
    values = list(value) if not isinstance(value, (str, bytes)) and hasattr(value, "__len__") else [value]
    if len(values) != len(joints):
        raise ValueError(
            f"{who}: effort_scale has {len(values)} value(s) but the robot has {len(joints)} joints "
            f"({', '.join(joints)}); give one factor k > 0 per joint (joint torque = k × recorded effort)"
        )
    scale = np.asarray(values, dtype=np.float64)
    bad = [j for j, k in enumerate(scale) if not (math.isfinite(k) and k > 0)]
    if bad:
        j = bad[0]
        raise ValueError(
            f"{who}: effort_scale[{j}] = {scale[j]:g} for joint {joints[j]} must be a finite factor > 0 "
            "(joint torque = k × recorded effort)"
        )
    return scale


def read_armatures(urdf: str) -> dict[str, float]:
    """A-priori armature ``I_rotor · N²`` per joint from the URDF's transmissions (module doc).

    Joints without a transmission carrying ``<rotor_inertia>`` are absent. Raises a one-line
    ``ValueError`` naming the transmission for a non-numeric, negative or non-finite value, a
    rotor inertia in a transmission that drives several joints, or a second transmission giving one
    joint a rotor inertia.
    """
    data, label = read_urdf_text(urdf)
    root = ET.fromstring(data)
    out: dict[str, float] = {}
    for transmission in root.findall("transmission"):
        name = transmission.get("name", "?")
        actuators = transmission.findall("actuator")
        inertia = _child_number(transmission, actuators, "rotor_inertia", name, label)
        if inertia is None:
            continue
        joints = [joint.get("name") for joint in transmission.findall("joint")]
        if len(joints) != 1 or len(actuators) > 1 or not joints[0]:
            raise ValueError(
                f"urdf ({label}): transmission {name!r} has a <rotor_inertia> but drives {len(joints)} "
                f"joint(s) with {len(actuators)} actuator(s); an armature needs one joint and one actuator"
            )
        if joints[0] in out:  # which of the two is the joint's rotor cannot be known
            raise ValueError(
                f"urdf ({label}): transmission {name!r} gives joint {joints[0]!r} a <rotor_inertia>, and an "
                "earlier transmission gives it one too; keep one transmission per joint"
            )
        reduction = _child_number(transmission, actuators, "mechanicalReduction", name, label)
        out[joints[0]] = inertia * (1.0 if reduction is None else reduction) ** 2
    return out


def _child_number(
    transmission: ET.Element, actuators: list[ET.Element], tag: str, name: str, label: str
) -> float | None:
    """The number in ``<tag>`` of the (single) actuator, else of the transmission itself."""
    for parent in (*actuators, transmission):
        element = parent.find(tag)
        if element is not None:
            try:
                value = float((element.text or "").strip())
            except ValueError:
                value = math.nan
            if not math.isfinite(value) or value < 0 or (tag == "mechanicalReduction" and value == 0):
                raise ValueError(
                    f"urdf ({label}): transmission {name!r} has <{tag}>{element.text}</{tag}>; "
                    "it must be a finite number >= 0 (a reduction != 0)"
                )
            return value
    return None


#: The robot options that set each sigmoid shape's reference value and its search box.
SHAPE_OPTIONS = {"phi2": ("sigmoid_steepness", "steepness_range"), "phi3": ("sigmoid_shift", "max_shift")}


def _listed(values: np.ndarray) -> str:
    """One value if all joints share it, else the list: as the user most likely wrote it."""
    values = np.asarray(values, dtype=float)
    if np.all(values == values[0]):
        return f"{values[0]:g}"
    return "[" + ", ".join(f"{v:g}" for v in values) + "]"


class DriveModel:
    """The drive terms of an ``n``-joint robot: parameter names, boxes, regressor columns, torques.

    Args:
        joints: joint names ``[n]``.
        friction: a key of ``FRICTION_MODELS``.
        armature: add ``<joint>.armature``.
        offset: add ``<joint>.offset``.
        stribeck_scales: ``v_s`` per joint ``[n]`` (adds ``<joint>.fs``; ``friction=True`` only), or ``None``.
        coulomb_scales: ``v_c`` per joint ``[n]``: Coulomb terms use ``tanh(q̇ / v_c)`` instead of
            ``sign(q̇)`` (module doc; ``friction=True`` or ``"asymmetric"``), or ``None``.
        armature_prior: a-priori armature per joint ``[n]`` (``nominal``), default 0.
        shape_prior: reference ``(φ2[n], φ3[n])`` of the sigmoid model (its ``nominal``).
        boxes: search boxes.
        who: prefix of error messages.

    Parameters are term-major, ``D = n × terms``: every joint's value of the first term, then of the
    next one (friction, then armature, then offset), e.g. ``j1.fc, j2.fc, j1.fv, j2.fv``.
    """

    def __init__(
        self,
        joints: Sequence[str],
        friction: Friction = False,
        armature: bool = False,
        offset: bool = False,
        stribeck_scales: np.ndarray | None = None,
        armature_prior: np.ndarray | None = None,
        shape_prior: tuple[np.ndarray, np.ndarray] | None = None,
        boxes: Boxes = Boxes(),
        who: str = "urdf",
        coulomb_scales: np.ndarray | None = None,
    ) -> None:
        key = friction if isinstance(friction, bool) else str(friction)
        if key not in FRICTION_MODELS:
            raise ValueError(
                f"{who}: friction={friction!r} is not a friction model; use true (Coulomb + viscous), "
                "false, 'asymmetric' or 'sigmoid'"
            )
        if stribeck_scales is not None and key is not True:
            raise ValueError(
                f"{who}: stribeck_velocity needs friction=true (Coulomb + viscous), got {friction!r}"
            )
        if coulomb_scales is not None and key not in (True, "asymmetric"):
            raise ValueError(
                f"{who}: coulomb_velocity smooths a Coulomb term: it needs friction=true or 'asymmetric', "
                f"got {friction!r}"
            )
        self.joints = tuple(joints)
        n = len(self.joints)
        self.stribeck_scales = stribeck_scales
        self.coulomb_scales = coulomb_scales
        lo, hi = boxes.steepness
        if not 0 < lo < hi:
            raise ValueError(
                f"{who}: the sigmoid steepness range must be 0 < low < high, got {boxes.steepness}"
            )
        catalogue = {
            "fc": Term("fc", 0.0, boxes.coulomb),
            "fv": Term("fv", 0.0, boxes.viscous),
            "fs": Term("fs", -boxes.coulomb, boxes.coulomb),
            "fc_pos": Term("fc_pos", 0.0, boxes.coulomb),
            "fc_neg": Term("fc_neg", 0.0, boxes.coulomb),
            "phi1": Term("phi1", 0.0, boxes.coulomb),
            "phi2": Term("phi2", lo, hi, shape=True),
            "phi3": Term("phi3", -boxes.shift, boxes.shift, shape=True),
            "armature": Term("armature", 0.0, boxes.armature),
            "offset": Term("offset", -boxes.offset, boxes.offset),
        }
        suffixes = list(FRICTION_MODELS[key]) + (["fs"] if stribeck_scales is not None else [])
        suffixes += (["armature"] if armature else []) + (["offset"] if offset else [])
        self.terms = tuple(catalogue[s] for s in suffixes)
        self.names = tuple(f"{j}.{t.suffix}" for t in self.terms for j in self.joints)
        prior = {
            "armature": np.zeros(n) if armature_prior is None else armature_prior,
            "phi2": np.full(n, 10.0) if shape_prior is None else shape_prior[0],
            "phi3": np.zeros(n) if shape_prior is None else shape_prior[1],
        }
        self._nominal = np.concatenate([np.zeros(0)] + [prior.get(t.suffix, np.zeros(n)) for t in self.terms])
        for t in self.terms:
            if t.shape and ((prior[t.suffix] < t.lower) | (prior[t.suffix] > t.upper)).any():
                given, box = SHAPE_OPTIONS[t.suffix]
                raise ValueError(
                    f"{who}: {given}={_listed(prior[t.suffix])} (the reference sigmoid {t.suffix}) leaves "
                    f"its search box [{t.lower:g}, {t.upper:g}] ({box}); give {given} inside it, or widen "
                    f"{box}"
                )

    @property
    def size(self) -> int:
        """``D``: how many drive parameters."""
        return len(self.names)

    @property
    def suffixes(self) -> tuple[str, ...]:
        return tuple(t.suffix for t in self.terms)

    def nominal(self) -> np.ndarray:
        """A-priori values ``[D]``: 0, the reference sigmoid shape, the URDF's armature."""
        return self._nominal.copy()

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Search box ``(lower[D], upper[D])``."""
        n = len(self.joints)
        lower = np.concatenate([np.zeros(0)] + [np.full(n, t.lower) for t in self.terms])
        upper = np.concatenate([np.zeros(0)] + [np.full(n, t.upper) for t in self.terms])
        return lower, upper

    def names_where(self, keep: Callable[[Term], bool]) -> tuple[str, ...]:
        """Parameter names of the terms for which ``keep(term)`` holds, in order."""
        return tuple(f"{j}.{t.suffix}" for t in self.terms if keep(t) for j in self.joints)

    def _split(self, params: Tensor) -> dict[str, Tensor]:
        """``params[..., D]`` → ``{suffix: [..., 1, n]}`` (ready to broadcast over samples)."""
        n = len(self.joints)
        return {t.suffix: params[..., None, k * n : (k + 1) * n] for k, t in enumerate(self.terms)}

    def features(self, qd: Tensor, qdd: Tensor, shape: dict[str, Tensor] | None = None) -> dict[str, Tensor]:
        """Torque per unit coefficient of every linear term, ``{suffix: [..., N, n]}``.

        ``shape``: ``{"phi2", "phi3"}`` broadcasting against ``qd`` (default: the reference shape).
        """
        out: dict[str, Tensor] = {}
        for term in self.terms:
            s = term.suffix
            if s == "fc":
                out[s] = coulomb_sign(qd, self.coulomb_scales)
            elif s == "fv":
                out[s] = qd
            elif s == "fs":
                scale = torch.as_tensor(self.stribeck_scales, dtype=qd.dtype, device=qd.device)
                out[s] = torch.exp(-((qd / scale) ** 2)) * coulomb_sign(qd, self.coulomb_scales)
            elif s == "fc_pos":
                smooth = self.coulomb_scales is not None
                out[s] = (1 + coulomb_sign(qd, self.coulomb_scales)) / 2 if smooth else (qd > 0).to(qd.dtype)
            elif s == "fc_neg":
                smooth = self.coulomb_scales is not None
                out[s] = (
                    -(1 - coulomb_sign(qd, self.coulomb_scales)) / 2 if smooth else -(qd < 0).to(qd.dtype)
                )
            elif s == "phi1":
                if shape is None:
                    shape = self._split(torch.as_tensor(self._nominal, dtype=qd.dtype, device=qd.device))
                out[s] = sigmoid_friction(qd, shape["phi2"], shape["phi3"])
            elif s == "armature":
                out[s] = qdd
            elif s == "offset":
                out[s] = torch.ones_like(qd)
        return out

    def columns(self, qd: Tensor, qdd: Tensor) -> Tensor:
        """Regressor block ``[N, n, D]`` at the reference shape (shape parameters: zero columns)."""
        features = self.features(qd, qdd)
        zero = torch.zeros_like(qd)
        blocks = [torch.diag_embed(features.get(t.suffix, zero)) for t in self.terms]
        return torch.cat([qd.new_zeros((*qd.shape, 0)), *blocks], dim=-1)

    def torque(self, params: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
        """Exact drive torques ``[..., N, n]`` of ``params[..., D]`` (shape parameters included)."""
        split = self._split(params)
        features = self.features(qd, qdd, split if "phi2" in split else None)
        tau = torch.zeros(params.shape[:-1] + qd.shape, dtype=qd.dtype, device=qd.device)
        for suffix, feature in features.items():
            tau = tau + split[suffix] * feature
        return tau
