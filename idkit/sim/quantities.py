"""The model's named settable quantities, and the unknowns a rollout identification fits.

A quantity is a number of the compiled model, named ``<element>.<kind>``:

* per hinge or slide joint: ``armature`` (reflected rotor inertia), ``damping`` (viscous),
  ``frictionloss`` (dry friction), ``stiffness`` (spring);
* per actuator: ``kp`` (a position servo's gain: ``gainprm[0] = kp``, ``biasprm[1] = -kp``), ``kv``
  (a velocity servo's gain, ``gainprm[0] = kv``, ``biasprm[2] = -kv``; or a position servo's damping
  ``biasprm[2] = -kv`` where the model gives it one), ``gear`` (the transmission ratio
  ``gear[0]``) and ``bias`` (a constant force ``biasprm[0]``);
* ``delay``: seconds by which the logged states trail the commands (:mod:`idkit.sim.timing`).

``params`` names the unknowns: a kind (``damping``: one unknown per joint in scope, or per actuator
driving one) or a quantity's name (``j1.damping``). A kind listed in ``shared`` is one unknown for
all its elements, named after the kind. Each unknown has a start (the model's value unless given)
and bounds (given, or ``box`` times the start). Optimisers search in *coordinates*: ``log(value)``
where the lower bound is positive (a factor counts the same at any size), ``value / (upper − lower)``
otherwise.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from idkit.sim.model import SimModel

JOINT_KINDS = ("armature", "damping", "frictionloss", "stiffness")
ACTUATOR_KINDS = ("kp", "kv", "gear", "bias")
DELAY = "delay"
KINDS = (*JOINT_KINDS, *ACTUATOR_KINDS, DELAY)
#: Kinds whose change needs ``mj_setConst`` (constants MuJoCo derives from the mass matrix at qpos0).
MASS_KINDS = ("armature",)
#: Default search box of ``delay`` (s) when no bounds are given.
DELAY_BOUNDS = (0.0, 0.05)
#: MuJoCo's gain and bias types read here (``mjtGain``/``mjtBias``).
_FIXED, _NONE, _AFFINE = 0, 0, 1


def servo_kind(model: Any, actuator: int) -> str:
    """``"position"``, ``"velocity"`` or ``"other"``: what the actuator's compiled gains make it."""
    gain, bias = model.actuator_gainprm[actuator], model.actuator_biasprm[actuator]
    if (
        model.actuator_gaintype[actuator] != _FIXED
        or model.actuator_biastype[actuator] != _AFFINE
        or gain[0] == 0
    ):
        return "other"
    if bias[1] == -gain[0]:
        return "position"
    if bias[1] == 0 and bias[2] == -gain[0]:
        return "velocity"
    return "other"


def _dof_field(model: Any, kind: str) -> np.ndarray:
    return {
        "armature": model.dof_armature,
        "damping": model.dof_damping,
        "frictionloss": model.dof_frictionloss,
    }[kind]


def _read(sim: SimModel, kind: str, target: int) -> float:
    m = sim.model
    if kind == "stiffness":
        return float(m.jnt_stiffness[target])
    if kind in JOINT_KINDS:
        return float(_dof_field(m, kind)[m.jnt_dofadr[target]])
    if kind == "kp":
        return float(m.actuator_gainprm[target, 0])
    if kind == "kv":
        return float(-m.actuator_biasprm[target, 2])
    if kind == "gear":
        return float(m.actuator_gear[target, 0])
    return float(m.actuator_biasprm[target, 0])


def set_quantity(model: Any, kind: str, target: int, value: float) -> None:
    """Write one quantity into a compiled ``MjModel`` (call ``mj_setConst`` after a ``MASS_KINDS`` one)."""
    if kind == "stiffness":
        model.jnt_stiffness[target] = value
    elif kind in JOINT_KINDS:
        _dof_field(model, kind)[model.jnt_dofadr[target]] = value
    elif kind == "kp":
        model.actuator_gainprm[target, 0] = value
        model.actuator_biasprm[target, 1] = -value
    elif kind == "kv":
        if servo_kind(model, target) == "velocity":
            model.actuator_gainprm[target, 0] = value
        model.actuator_biasprm[target, 2] = -value
    elif kind == "gear":
        model.actuator_gear[target, 0] = value
    elif kind == "bias":
        model.actuator_biastype[target] = _AFFINE
        model.actuator_biasprm[target, 0] = value
    else:
        raise ValueError(f"{kind!r} is not a model quantity")


def write_quantity(spec: Any, sim: SimModel, kind: str, target: int, value: float) -> None:
    """Write one quantity into an ``MjSpec`` (the element named as in the compiled model)."""
    m = sim.model
    if kind in JOINT_KINDS:
        joint = spec.joint(m.joint(target).name)
        if kind in ("damping", "stiffness"):  # MuJoCo 4 keeps polynomial coefficients beside the value
            current = np.array(getattr(joint, kind), dtype=np.float64).reshape(-1)
            current[0] = value
            setattr(joint, kind, current)
        else:
            setattr(joint, kind, value)
        return
    actuator = spec.actuator(m.actuator(target).name)
    gain, bias = np.array(actuator.gainprm), np.array(actuator.biasprm)
    if kind == "kp":
        gain[0], bias[1] = value, -value
    elif kind == "kv":
        if servo_kind(m, target) == "velocity":
            gain[0] = value
        bias[2] = -value
    elif kind == "gear":
        gear = np.array(actuator.gear)
        gear[0] = value
        actuator.gear = gear
    elif kind == "bias":
        import mujoco

        actuator.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        bias[0] = value
    actuator.gainprm, actuator.biasprm = gain, bias


@dataclass(frozen=True)
class Unknown:
    """One fitted number: a quantity (or a kind shared by several elements) with its start and bounds.

    Attributes:
        name: ``<element>.<kind>``, the kind for a shared one, or ``delay``.
        kind: one of ``KINDS``.
        targets: the joint or actuator indices it sets (``()`` for ``delay``).
        start, lower, upper: the start value and the search bounds.
    """

    name: str
    kind: str
    targets: tuple[int, ...]
    start: float
    lower: float
    upper: float

    @property
    def logarithmic(self) -> bool:
        """Whether the optimisers' coordinate is ``log(value)`` (a positive lower bound)."""
        return self.lower > 0


@dataclass(frozen=True)
class Unknowns:
    """The unknowns of a fit, in order, and their coordinates (module docstring)."""

    items: tuple[Unknown, ...]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(u.name for u in self.items)

    def __len__(self) -> int:
        return len(self.items)

    def vector(self, attribute: str) -> np.ndarray:
        return np.array([getattr(u, attribute) for u in self.items], dtype=np.float64)

    @property
    def delay_index(self) -> int | None:
        return next((i for i, u in enumerate(self.items) if u.kind == DELAY), None)

    @property
    def needs_set_const(self) -> bool:
        return any(u.kind in MASS_KINDS for u in self.items)

    def _split(self) -> tuple[np.ndarray, np.ndarray]:
        log = np.array([u.logarithmic for u in self.items])
        width = self.vector("upper") - self.vector("lower")
        return log, width

    def to_coordinates(self, values: np.ndarray) -> np.ndarray:
        """Coordinates ``[..., P]`` of values ``[..., P]``."""
        log, width = self._split()
        values = np.asarray(values, dtype=np.float64)
        return np.where(log, np.log(np.where(log, values, 1.0)), values / width)

    def from_coordinates(self, z: np.ndarray) -> np.ndarray:
        """Values ``[..., P]`` of coordinates ``[..., P]``."""
        log, width = self._split()
        z = np.asarray(z, dtype=np.float64)
        return np.where(log, np.exp(np.where(log, z, 0.0)), z * width)

    def coordinate_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.to_coordinates(self.vector("lower")), self.to_coordinates(self.vector("upper"))

    def joints(self, sim: SimModel) -> list[int | None]:
        """The model joint each unknown belongs to (its own, or the one its actuator drives); ``None``
        for ``delay``, a shared unknown, and an actuator that drives no joint directly."""
        out: list[int | None] = []
        for unknown in self.items:
            if len(unknown.targets) != 1:
                out.append(None)
            elif unknown.kind in JOINT_KINDS:
                out.append(unknown.targets[0])
            else:
                out.append(sim.actuated_joint(unknown.targets[0]))
        return out

    def apply(self, model: Any, values: np.ndarray) -> None:
        """Write ``values[P]`` into a compiled model (every quantity but ``delay``)."""
        for unknown, value in zip(self.items, values, strict=True):
            for target in unknown.targets:
                set_quantity(model, unknown.kind, target, float(value))

    def write(self, spec: Any, sim: SimModel, values: np.ndarray) -> None:
        """Write ``values[P]`` into an ``MjSpec`` (every quantity but ``delay``)."""
        for unknown, value in zip(self.items, values, strict=True):
            for target in unknown.targets:
                write_quantity(spec, sim, unknown.kind, target, float(value))


def _elements(sim: SimModel, kind: str, joints: Sequence[str]) -> list[tuple[str, int]]:
    """``(element name, index)`` of every element of ``kind`` in scope (the joints and their actuators)."""
    ids = [sim.joint_id(j) for j in joints]
    if kind in JOINT_KINDS:
        return [(name, index) for name, index in zip(joints, ids, strict=True)]
    found = []
    for a in range(sim.model.nu):
        joint = sim.actuated_joint(a)
        if joint is None or joint not in ids:
            continue
        servo = servo_kind(sim.model, a)
        if (
            (kind == "kp" and servo == "position")
            or (
                kind == "kv"
                and (servo == "velocity" or (servo == "position" and sim.model.actuator_biasprm[a, 2] != 0))
            )
            or kind in ("gear", "bias")
        ):
            found.append((sim.model.actuator(a).name, a))
    return found


def _lookup(table: Mapping[str, Any], name: str, kind: str) -> Any:
    return table[name] if name in table else table.get(kind)


def select_unknowns(
    sim: SimModel,
    joints: Sequence[str],
    params: Sequence[str],
    shared: Sequence[str] = (),
    bounds: Mapping[str, Sequence[float]] | None = None,
    start: Mapping[str, float] | None = None,
    box: Sequence[float] = (0.1, 10.0),
) -> Unknowns:
    """The unknowns ``params`` names (module docstring), with starts and bounds.

    Args:
        sim: the model.
        joints: the joints in scope (their quantities, and those of the actuators driving them).
        params: kinds and/or quantity names, in the order the unknowns are listed.
        shared: kinds fitted as one value for all their elements.
        bounds: ``{name or kind: [lower, upper]}``; a name beats its kind.
        start: ``{name or kind: value}``; default the model's value (``delay``: 0).
        box: ``(a, b)``: bounds ``[a·start, b·start]`` of an unknown without given bounds.

    Raises:
        ValueError: an unknown kind or name, a kind with no element in scope, a quantity listed twice,
            a start outside its bounds, bounds that are not ``lower < upper``, or an unknown whose
            start is not positive and has no bounds — each naming it.
    """
    bounds, start = dict(bounds or {}), dict(start or {})
    if len(box) != 2 or not 0 < box[0] < 1 < box[1]:
        raise ValueError(f"box must be (a, b) with 0 < a < 1 < b, got {list(box)}")
    for kind in shared:
        if kind not in KINDS or kind == DELAY:
            raise ValueError(
                f"shared: {kind!r} is not a kind of several elements; kinds: {', '.join(KINDS[:-1])}"
            )
    items: list[Unknown] = []
    seen: dict[tuple[str, int], str] = {}
    for entry in params:
        for name, kind, targets in _expand(sim, entry, joints, shared):
            for target in targets:
                if (kind, target) in seen:
                    raise ValueError(f"params: {name} repeats {seen[(kind, target)]} (listed twice?)")
                seen[(kind, target)] = name
            items.append(_unknown(sim, name, kind, targets, bounds, start, box))
    if not items:
        raise ValueError("params: no unknowns to identify")
    known = {u.name for u in items} | {u.kind for u in items}
    for option, table in (("bounds", bounds), ("start", start)):
        stray = sorted(set(table) - known)
        if stray:
            raise ValueError(
                f"{option}: {', '.join(stray)} name(s) no unknown; the unknowns: "
                + ", ".join(u.name for u in items)
            )
    return Unknowns(tuple(items))


def _expand(
    sim: SimModel, entry: str, joints: Sequence[str], shared: Sequence[str]
) -> list[tuple[str, str, tuple[int, ...]]]:
    """``(name, kind, targets)`` of one ``params`` entry."""
    if entry == DELAY:
        return [(DELAY, DELAY, ())]
    if entry in KINDS:
        elements = _elements(sim, entry, joints)
        if not elements:
            raise ValueError(
                f"params: no element of kind {entry!r} among the joints {', '.join(joints)} "
                "and their actuators"
            )
        if entry in shared:
            return [(entry, entry, tuple(index for _, index in elements))]
        return [(f"{name}.{entry}", entry, (index,)) for name, index in elements]
    element, _, kind = entry.rpartition(".")
    if kind not in KINDS or not element:
        raise ValueError(f"params: {entry!r} is neither a kind ({', '.join(KINDS)}) nor <element>.<kind>")
    scope = [j for j in sim.joint_names()]
    match = [index for name, index in _elements(sim, kind, scope) if name == element]
    if not match:
        raise ValueError(
            f"params: the model has no {kind} named {entry!r} (an element of that kind named {element!r})"
        )
    return [(entry, kind, (match[0],))]


def _unknown(
    sim: SimModel,
    name: str,
    kind: str,
    targets: tuple[int, ...],
    bounds: Mapping[str, Sequence[float]],
    start: Mapping[str, float],
    box: Sequence[float],
) -> Unknown:
    model_value = 0.0 if kind == DELAY else float(np.mean([_read(sim, kind, t) for t in targets]))
    given = _lookup(start, name, kind)
    value = model_value if given is None else float(given)
    limits = _lookup(bounds, name, kind)
    if limits is None:
        if kind == DELAY:
            limits = DELAY_BOUNDS
        elif value > 0:
            limits = (box[0] * value, box[1] * value)
        else:
            origin = "its start" if given is not None else "the model's value"
            raise ValueError(
                f"{name} starts at {value:g} ({origin}): give its bounds ({name}: [lower, upper] in bounds) "
                "or a positive start"
            )
    if len(limits) != 2:
        raise ValueError(f"bounds of {name} must be [lower, upper], got {list(limits)}")
    lower, upper = (float(x) for x in limits)
    if not (np.isfinite(lower) and np.isfinite(upper) and lower < upper):
        raise ValueError(f"bounds of {name} must be finite with lower < upper, got [{lower:g}, {upper:g}]")
    if not lower <= value <= upper:
        raise ValueError(f"{name}: start {value:g} is outside its bounds [{lower:g}, {upper:g}]")
    if kind != DELAY and kind != "bias" and lower < 0:
        raise ValueError(f"bounds of {name}: a {kind} is not negative, got lower bound {lower:g}")
    return Unknown(name, kind, targets, value, lower, upper)
