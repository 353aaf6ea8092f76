"""The model's named settable quantities, and the unknowns a rollout identification fits.

A quantity is a number of the compiled model, named ``<element>.<kind>``:

* per hinge or slide joint: ``armature`` (reflected rotor inertia), ``damping`` (viscous),
  ``frictionloss`` (dry friction), ``stiffness`` (spring);
* per actuator: ``kp`` (a position servo's gain: ``gainprm[0] = kp``, ``biasprm[1] = -kp``), ``kv``
  (a velocity servo's gain, ``gainprm[0] = kv``, ``biasprm[2] = -kv``; or a position servo's damping
  ``biasprm[2] = -kv`` where the model gives it one), ``gear`` (the transmission ratio
  ``gear[0]``) and ``bias`` (a constant force ``biasprm[0]``);
* per body moved by a joint in scope: ``inertia``, its mass, centre of mass and rotational inertia as
  10 log-Cholesky coordinates (:mod:`idkit.sim.inertia`: every value is a physical body), named
  ``<body>.inertia.alpha`` … ``<body>.inertia.t3``; ``<body>.inertia`` in ``params`` picks one body;
* ``command_delay``: seconds by which the logged states trail the commands (:mod:`idkit.sim.timing`;
  the former ``delay``, still read with a ``FutureWarning``). Not the torque path's
  ``recording.torque_lag`` (torques behind states, :mod:`idkit.data.delay`).

``params`` names the unknowns: a kind (``damping``: one unknown per joint in scope, or per actuator
driving one) or a quantity's name (``j1.damping``). An actuator's quantity may also be named after the
joint it drives (``j1.kp`` for ``p1.kp``) when no other actuator of that kind drives the joint; in
``params`` that name is kept, in ``bounds`` and ``start`` either name is read. A kind listed in
``shared`` is one unknown for all its elements, named after the kind. Each unknown has a start (the
model's value unless given) and bounds (given, or ``box`` times the start). Optimisers search in
*coordinates*: ``log(value)`` where the lower bound is positive (a factor counts the same at any
size), ``value / (upper − lower)`` otherwise (always for ``bias``, ``command_delay`` and the inertia
coordinates, which are logarithms or lengths already). An inertia's default bounds are ``±ln √10`` on
``alpha`` and ``d`` (a factor 10 on the mass) and ``±2`` radii of gyration on ``s`` and ``t``.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from idkit.robots.inertia import centroidal
from idkit.sim.inertia import COORDINATES, from_mujoco, mujoco_inertial, standard
from idkit.sim.model import SimModel

JOINT_KINDS = ("armature", "damping", "frictionloss", "stiffness")
ACTUATOR_KINDS = ("kp", "kv", "gear", "bias")
DELAY = "command_delay"
#: The former name of ``command_delay``, still read (with a ``FutureWarning``) in params, bounds, start.
OLD_DELAY = "delay"
INERTIA = "inertia"
KINDS = (*JOINT_KINDS, *ACTUATOR_KINDS, INERTIA, DELAY)
#: Kinds whose change needs ``mj_setConst`` (constants MuJoCo derives from the mass matrix at qpos0).
MASS_KINDS = ("armature", INERTIA)
#: Kinds searched in their own units, never in logarithms.
LINEAR_KINDS = ("bias", INERTIA, DELAY)
#: Default search box of ``command_delay`` (s) when no bounds are given.
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


#: An estimate within this fraction of its box (in coordinates) from a bound is on it.
AT_BOUND = 1e-6


@dataclass(frozen=True)
class Unknown:
    """One fitted number: a quantity (or a kind shared by several elements) with its start and bounds.

    Attributes:
        name: ``<element>.<kind>``, the kind for a shared one, or ``command_delay``.
        kind: one of ``KINDS``.
        targets: the joint or actuator indices it sets (``()`` for ``command_delay``).
        start, lower, upper: the start value and the search bounds.
    """

    name: str
    kind: str
    targets: tuple[int, ...]
    start: float
    lower: float
    upper: float
    component: int = 0  #: which of a body's inertia coordinates

    @property
    def logarithmic(self) -> bool:
        """Whether the optimisers' coordinate is ``log(value)`` (a positive lower bound)."""
        return self.lower > 0 and self.kind not in LINEAR_KINDS


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

    def at_bound(self, values: np.ndarray, tolerance: float = AT_BOUND) -> list[str]:
        """The names of the unknowns whose ``values[P]`` lie on a bound: within ``tolerance`` of the
        box's width in the optimisers' coordinates (where a bounded solver stops)."""
        z = self.to_coordinates(values)
        lower, upper = self.coordinate_bounds()
        near = tolerance * (upper - lower)
        on = (z <= lower + near) | (z >= upper - near)
        return [name for name, hit in zip(self.names, on, strict=True) if hit]

    def joints(self, sim: SimModel) -> list[int | None]:
        """The model joint each unknown belongs to (its own, or the one its actuator drives); ``None``
        for ``command_delay``, a body's inertia (it moves every joint above it), a shared unknown, and
        an actuator that drives no joint directly."""
        out: list[int | None] = []
        for unknown in self.items:
            if len(unknown.targets) != 1 or unknown.kind == INERTIA:
                out.append(None)
            elif unknown.kind in JOINT_KINDS:
                out.append(unknown.targets[0])
            else:
                out.append(sim.actuated_joint(unknown.targets[0]))
        return out

    def apply(self, model: Any, values: np.ndarray) -> None:
        """Write ``values[P]`` into a compiled model (every quantity but ``command_delay``)."""
        for unknown, value in zip(self.items, values, strict=True):
            if unknown.kind != INERTIA:
                for target in unknown.targets:
                    set_quantity(model, unknown.kind, target, float(value))
        for body, theta in self.inertias(values).items():
            mass, ipos, moments, iquat = mujoco_inertial(theta)
            model.body_mass[body], model.body_ipos[body] = mass, ipos
            model.body_inertia[body], model.body_iquat[body] = moments, iquat

    def write(self, spec: Any, sim: SimModel, values: np.ndarray) -> None:
        """Write ``values[P]`` into an ``MjSpec`` (every quantity but ``command_delay``)."""
        for unknown, value in zip(self.items, values, strict=True):
            if unknown.kind != INERTIA:
                for target in unknown.targets:
                    write_quantity(spec, sim, unknown.kind, target, float(value))
        inertias = self.inertias(values)
        if inertias:
            import mujoco

            spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_AUTO
        for body, theta in inertias.items():
            mass, ipos, moments, iquat = mujoco_inertial(theta)
            element = spec.body(sim.model.body(body).name)
            element.mass, element.ipos, element.inertia, element.iquat = mass, ipos, moments, iquat
            element.fullinertia = np.full(6, np.nan)
            element.explicitinertial = True

    def inertias(self, values: np.ndarray) -> dict[int, np.ndarray]:
        """``{body: θ[10]}`` of the fitted bodies at ``values[P]``."""
        out: dict[int, np.ndarray] = {}
        for unknown, value in zip(self.items, values, strict=True):
            if unknown.kind == INERTIA:
                out.setdefault(unknown.targets[0], np.zeros(10))[unknown.component] = value
        return out

    def bodies(self, sim: SimModel, values: np.ndarray) -> dict[str, dict[str, Any]]:
        """Each fitted body's mass, centre of mass and inertia about it (3 × 3) at ``values[P]``."""
        out = {}
        for body, theta in self.inertias(values).items():
            mass, com, about_com = centroidal(standard(theta))
            out[sim.model.body(body).name] = {
                "mass": mass,
                "com": com.tolist(),
                "inertia": about_com.tolist(),
            }
        return out


def _elements(sim: SimModel, kind: str, joints: Sequence[str]) -> list[tuple[str, int]]:
    """``(element name, index)`` of every element of ``kind`` in scope (the joints and their actuators)."""
    ids = [sim.joint_id(j) for j in joints]
    if kind in JOINT_KINDS:
        return [(name, index) for name, index in zip(joints, ids, strict=True)]
    if kind == INERTIA:
        bodies = dict.fromkeys(int(sim.model.jnt_bodyid[j]) for j in ids)
        return [(sim.model.body(b).name, b) for b in bodies]
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


def _lookup(table: Mapping[str, Any], names: Sequence[str], kind: str) -> Any:
    """The entry of the first of ``names`` in ``table``, else the kind's."""
    return next((table[n] for n in names if n in table), table.get(kind))


def _joint_alias(sim: SimModel, kind: str, actuator: int) -> str | None:
    """``<joint>.<kind>`` for an actuator quantity when it is the only one of its kind on that joint."""
    joint = sim.actuated_joint(actuator)
    if joint is None:
        return None
    name = sim.model.joint(joint).name
    same = [index for _, index in _elements(sim, kind, [name])]
    return f"{name}.{kind}" if same == [actuator] else None


def _aliases(sim: SimModel, name: str, kind: str, targets: tuple[int, ...]) -> list[str]:
    """The other names an unknown answers to in ``bounds`` and ``start`` (module docstring)."""
    if kind not in ACTUATOR_KINDS or len(targets) != 1:
        return []
    canonical = f"{sim.model.actuator(targets[0]).name}.{kind}"
    alias = _joint_alias(sim, kind, targets[0])
    return [n for n in (canonical, alias) if n is not None and n != name]


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
        start: ``{name or kind: value}``; default the model's value (``command_delay``: 0).
        box: ``(a, b)``: bounds ``[a·start, b·start]`` of an unknown without given bounds.

    Raises:
        ValueError: an unknown kind or name, a kind with no element in scope, a quantity listed twice,
            a start outside its bounds, bounds that are not ``lower < upper``, or an unknown whose
            start is not positive and has no bounds — each naming it.
    """
    params, bounds, start = _renamed(params, bounds, start)
    if len(box) != 2 or not 0 < box[0] < 1 < box[1]:
        raise ValueError(f"box must be (a, b) with 0 < a < 1 < b, got {list(box)}")
    for kind in shared:
        if kind not in KINDS or kind in (DELAY, INERTIA):
            raise ValueError(
                f"shared: {kind!r} is not a kind of several elements; kinds: {', '.join(KINDS[:-1])}"
            )
    items: list[Unknown] = []
    seen: dict[tuple[str, int, int], str] = {}
    known: set[str] = set()
    for entry in params:
        for name, kind, targets, component in _expand(sim, entry, joints, shared):
            for target in targets:
                if (kind, target, component) in seen:
                    raise ValueError(
                        f"params: {name} repeats {seen[(kind, target, component)]} (listed twice?)"
                    )
                seen[(kind, target, component)] = name
            names = [name, *_aliases(sim, name, kind, targets)]
            items.append(_unknown(sim, names, kind, targets, bounds, start, box, component))
            known |= {*names, kind}
    if not items:
        raise ValueError("params: no unknowns to identify")
    for option, table in (("bounds", bounds), ("start", start)):
        stray = sorted(set(table) - known)
        if stray:
            raise ValueError(
                f"{option}: {', '.join(stray)} name(s) no unknown; the unknowns: "
                + ", ".join(u.name for u in items)
            )
    return Unknowns(tuple(items))


def _renamed(
    params: Sequence[str], bounds: Mapping[str, Sequence[float]] | None, start: Mapping[str, float] | None
) -> tuple[list[str], dict[str, Sequence[float]], dict[str, float]]:
    """``params``, ``bounds`` and ``start`` with the deprecated ``delay`` read as ``command_delay``."""
    bounds, start = dict(bounds or {}), dict(start or {})
    if OLD_DELAY not in (*params, *bounds, *start):
        return list(params), bounds, start
    warnings.warn(
        f"rollout: {OLD_DELAY!r} is now called {DELAY!r} (seconds by which the logged states trail the "
        f"commands; not recording.torque_lag, the torques' lag behind the states): {OLD_DELAY!r} still "
        "works but is deprecated",
        FutureWarning,
        stacklevel=3,
    )
    if DELAY in bounds and OLD_DELAY in bounds or DELAY in start and OLD_DELAY in start:
        raise ValueError(f"give {DELAY} once (both {DELAY!r} and its old name {OLD_DELAY!r} are set)")
    bounds = {DELAY if k == OLD_DELAY else k: v for k, v in bounds.items()}
    start = {DELAY if k == OLD_DELAY else k: v for k, v in start.items()}
    return [DELAY if p == OLD_DELAY else p for p in params], bounds, start


def _expand(
    sim: SimModel, entry: str, joints: Sequence[str], shared: Sequence[str]
) -> list[tuple[str, str, tuple[int, ...], int]]:
    """``(name, kind, targets, component)`` of each unknown one ``params`` entry names."""
    if entry == DELAY:
        return [(DELAY, DELAY, (), 0)]
    if entry in KINDS:
        elements = _elements(sim, entry, joints)
        if not elements:
            raise ValueError(
                f"params: no element of kind {entry!r} among the joints {', '.join(joints)} "
                "and their actuators"
            )
        if entry in shared:
            return [(entry, entry, tuple(index for _, index in elements), 0)]
        return [unknown for name, index in elements for unknown in _named(name, entry, index)]
    element, _, kind = entry.rpartition(".")
    if kind not in KINDS or not element:
        raise ValueError(f"params: {entry!r} is neither a kind ({', '.join(KINDS)}) nor <element>.<kind>")
    scope = list(sim.joint_names())
    match = [index for name, index in _elements(sim, kind, scope) if name == element]
    if not match and kind in ACTUATOR_KINDS:
        match = [index for _, index in _elements(sim, kind, scope) if _joint_alias(sim, kind, index) == entry]
    if not match:
        raise ValueError(
            f"params: the model has no {kind} named {entry!r} (an element of that kind named {element!r})"
        )
    if kind == INERTIA:
        return _named(element, kind, match[0])
    return [(entry, kind, (match[0],), 0)]


def _named(element: str, kind: str, index: int) -> list[tuple[str, str, tuple[int, ...], int]]:
    """The unknowns of one element: one, or a body's ten inertia coordinates."""
    if kind == INERTIA:
        return [(f"{element}.{kind}.{c}", kind, (index,), i) for i, c in enumerate(COORDINATES)]
    return [(f"{element}.{kind}", kind, (index,), 0)]


def _unknown(
    sim: SimModel,
    names: Sequence[str],
    kind: str,
    targets: tuple[int, ...],
    bounds: Mapping[str, Sequence[float]],
    start: Mapping[str, float],
    box: Sequence[float],
    component: int = 0,
) -> Unknown:
    name = names[0]
    if kind == INERTIA:
        return _inertia_unknown(sim, name, targets[0], component, bounds, start)
    model_value = 0.0 if kind == DELAY else float(np.mean([_read(sim, kind, t) for t in targets]))
    given = _lookup(start, names, kind)
    value = model_value if given is None else float(given)
    limits = _lookup(bounds, names, kind)
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


def _inertia_unknown(
    sim: SimModel, name: str, body: int, component: int, bounds: Mapping[str, Any], start: Mapping[str, float]
) -> Unknown:
    """One inertia coordinate of ``body``: its start (the model's body, unless given) and bounds."""
    m = sim.model
    theta = from_mujoco(m.body_mass[body], m.body_ipos[body], m.body_inertia[body], m.body_iquat[body])
    value = float(start.get(name, theta[component]))
    limits = bounds.get(name)
    if limits is None:
        gyration = float(np.sqrt(m.body_inertia[body].sum() / max(m.body_mass[body], 1e-300)))
        reach = max(gyration, float(np.linalg.norm(m.body_ipos[body])), 1e-3)
        half = 0.5 * np.log(10.0) if component < 4 else 2.0 * reach
        limits = (value - half, value + half)
    lower, upper = (float(x) for x in limits)
    if not (np.isfinite(lower) and np.isfinite(upper) and lower < upper and lower <= value <= upper):
        raise ValueError(
            f"{name}: start {value:g} and bounds [{lower:g}, {upper:g}] must be finite, in order"
        )
    return Unknown(name, INERTIA, (body,), value, lower, upper, component)
