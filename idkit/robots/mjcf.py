"""MuJoCo models (MJCF) as idkit robots: the URDF robot's kinematic tree, read through ``mujoco``.

``robot=mjcf robot.mjcf=arm.xml`` identifies a MuJoCo model exactly as ``robot=urdf`` identifies a
URDF: :class:`MJCFRobot` is a :class:`~idkit.robots.urdf.URDFRobot` whose
:class:`~idkit.robots.urdf_model.KinematicTree` comes from the *compiled* ``MjModel`` (what
``mj_inverse`` simulates: defaults, ``<frame>`` elements, ``inertiafromgeom`` and the other compiler
options applied) instead of a URDF, so the same batched Newton–Euler pass, regressor and base
parameters run on it.

Mapping (MuJoCo → tree): a body with one ``hinge`` or ``slide`` joint is a tree body named after
the MuJoCo body (``<body>.m`` …) and its joint; a body without a joint is welded to its parent
(merged into the moving body it hangs on, dropped when it hangs on the world). idkit's body frame
is the MuJoCo body frame moved to the joint's ``pos`` (a hinge's axis passes through it; a slide
joint's ``pos`` plays no role), and a joint's ``ref`` (the ``qpos`` at which the body is in its
modelled pose) is folded into the constant placement, so idkit's ``q`` is MuJoCo's ``qpos``.
Gravity is the model's ``<option gravity>`` (along −z). ``range`` gives the position limits,
``actuatorfrcrange`` the effort limit (the smaller bound's magnitude); MJCF has no velocity limit.

Refused with one line naming the element, because ``mj_inverse`` would then add forces the tree
does not model: ``free``/``ball`` joints, two joints in one body, unnamed joints or bodies,
equality constraints, tendons with stiffness, damping, friction loss, armature or limits, joint
stiffness, gravity compensation, fluid forces (``density`` / ``viscosity``), flexes, gravity not
along −z, and a joint ``armature`` unless ``armature=True`` models it. Joint ``damping`` and
``frictionloss`` are what ``friction=true``'s ``fv`` and ``fc`` model (their a-priori value is 0, as
for a URDF; ``armature`` is the a-priori value of ``<joint>.armature``); contacts and
joint-limit forces are not modelled (measured data have none inside the limits).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from idkit.registry import PluginLoadError
from idkit.robots.drives import Friction
from idkit.robots.inertia import standard_parameters
from idkit.robots.model_checks import check_model
from idkit.robots.model_xml import model_text
from idkit.robots.urdf import URDFRobot
from idkit.robots.urdf_model import Body, KinematicTree, LinkInertial, model_file
from idkit.seeds import Seed

#: What to install when ``mujoco`` is missing.
INSTALL = "pip install robot-idkit[mjcf]"


def import_mujoco() -> Any:
    """The ``mujoco`` module, or a one-line error saying how to install it (an optional extra)."""
    try:
        import mujoco
    except ImportError:
        raise PluginLoadError(f"mjcf: MuJoCo models need the mujoco package: {INSTALL}") from None
    return mujoco


@dataclass(frozen=True)
class MJCFModel:
    """A MuJoCo model read into idkit's tree.

    Attributes:
        tree: the moving bodies, parents first (link = MuJoCo body name, joint = joint name).
        gravity: magnitude of the model's gravity along −z (0 when disabled).
        anchors: ``[nb, 3]`` each tree body's joint ``pos`` in its MuJoCo body frame: idkit's body
            frame is the MuJoCo one moved there (same orientation), which the writer undoes.
        damping, frictionloss, armature: ``[nb]`` the joints' MuJoCo viscous and Coulomb friction
            and reflected rotor inertia.
        source: the model's file path, or ``None`` for MJCF text.
        text: the MJCF text that was read.
    """

    tree: KinematicTree
    gravity: float
    anchors: np.ndarray
    damping: np.ndarray
    frictionloss: np.ndarray
    armature: np.ndarray
    source: Path | None
    text: str


def read_mjcf_text(mjcf: str | os.PathLike) -> tuple[str, Path | None, str]:
    """``(text, path or None, label)`` of MJCF text (starts with ``<``), a file path or a shipped asset.

    Raises:
        FileNotFoundError: no such file.
        ValueError: a directory, not UTF-8 XML, a DTD (:mod:`idkit.robots.model_xml`), or not an MJCF
            file (a URDF is pointed to ``robot=urdf``).
    """
    if isinstance(mjcf, str) and mjcf.lstrip().startswith("<"):
        text, path, label = model_text(mjcf.encode("utf-8"), "<MJCF text>", "mjcf"), None, "<MJCF text>"
    else:
        path = model_file(mjcf, "mjcf", ".xml")
        text, label = model_text(path.read_bytes(), str(path), "mjcf"), str(path)
    try:
        tag = ET.fromstring(text.encode("utf-8")).tag
    except ET.ParseError as error:
        raise ValueError(f"mjcf: {label} is not valid XML: {error}") from None
    if tag == "robot":
        raise ValueError(f"mjcf: {label} is a URDF (<robot>): use robot=urdf robot.urdf={label}")
    if tag != "mujoco":
        raise ValueError(f"mjcf: {label}: root element is <{tag}>, expected <mujoco>")
    return text, path, label


def compile_mjcf(text: str, path: Path | None, label: str) -> Any:
    """The compiled ``MjModel``; MuJoCo's refusal becomes a one-line ``ValueError``."""
    mujoco = import_mujoco()
    try:
        if path is not None:  # from the file, so that includes and assets resolve next to it
            return mujoco.MjModel.from_xml_path(str(path))
        return mujoco.MjModel.from_xml_string(text)
    except ValueError as error:
        message = " ".join(str(error).split())
        raise ValueError(f"mjcf: MuJoCo cannot load {label}: {message}") from None


def read_mjcf(mjcf: str | os.PathLike) -> MJCFModel:
    """Read MJCF text or a file into an :class:`MJCFModel` (see the module doc for the mapping).

    Raises:
        PluginLoadError: ``mujoco`` is not installed.
        FileNotFoundError, ValueError: no such file, not MJCF, MuJoCo refuses it, or it holds
            something the tree does not model (the message names the element).
    """
    text, path, label = read_mjcf_text(mjcf)
    model = compile_mjcf(text, path, label)
    return model_from_mujoco(model, label, text, path)


def _name(mujoco: Any, model: Any, kind: Any, index: int) -> str:
    return mujoco.mj_id2name(model, kind, index) or ""


def _refuse_unmodelled(mujoco: Any, model: Any, label: str) -> None:
    """Raise for anything that adds forces the tree does not model (module doc), naming it."""
    obj = mujoco.mjtObj

    def named(kind: Any, index: int, what: str) -> str:
        return repr(_name(mujoco, model, kind, index) or f"#{index}") + f" ({what})"

    if model.neq:
        equalities = [mujoco.mjtEq(int(t)).name.removeprefix("mjEQ_").lower() for t in model.eq_type]
        listed = ", ".join(named(obj.mjOBJ_EQUALITY, i, equalities[i]) for i in range(model.neq))
        raise ValueError(f"mjcf: {label}: equality constraints are not supported: {listed}")
    for i in range(model.ntendon):
        terms = {
            "stiffness": model.tendon_stiffness[i],
            "damping": model.tendon_damping[i],
            "frictionloss": model.tendon_frictionloss[i],
            "armature": model.tendon_armature[i] if hasattr(model, "tendon_armature") else 0.0,
            "limited": float(model.tendon_limited[i]),
        }
        coupling = [k for k, v in terms.items() if np.any(np.asarray(v) != 0)]
        if coupling:
            raise ValueError(
                f"mjcf: {label}: tendon {named(obj.mjOBJ_TENDON, i, ', '.join(coupling))} couples joints: "
                "tendon forces are not supported"
            )
    if model.nflex:
        raise ValueError(f"mjcf: {label}: flexes (deformable bodies) are not supported")
    if model.opt.density != 0 or model.opt.viscosity != 0:
        raise ValueError(
            f"mjcf: {label}: fluid forces (option density={model.opt.density:g}, "
            f"viscosity={model.opt.viscosity:g}) are not supported"
        )
    for b in np.flatnonzero(model.body_gravcomp):
        raise ValueError(
            f"mjcf: {label}: body {_name(mujoco, model, obj.mjOBJ_BODY, int(b))!r} has gravcomp="
            f"{model.body_gravcomp[b]:g}: gravity compensation is not supported"
        )
    for j in range(model.njnt):
        _refuse_joint(mujoco, model, label, j)
    gravity = np.asarray(model.opt.gravity, dtype=np.float64)
    if gravity[0] != 0 or gravity[1] != 0 or gravity[2] > 0:
        raise ValueError(
            f"mjcf: {label}: option gravity={' '.join(f'{g:g}' for g in gravity)}: only gravity along -z "
            "is supported"
        )


def _refuse_joint(mujoco: Any, model: Any, label: str, j: int) -> None:
    """Raise for joint ``j`` unless it is a named hinge or slide joint of a named body, without a spring."""
    obj = mujoco.mjtObj
    kinds = {int(mujoco.mjtJoint.mjJNT_FREE): "free", int(mujoco.mjtJoint.mjJNT_BALL): "ball"}
    name = _name(mujoco, model, obj.mjOBJ_JOINT, j)
    body = _name(mujoco, model, obj.mjOBJ_BODY, int(model.jnt_bodyid[j]))
    where = f"joint {name or '#' + str(j)!r} (body {body!r})"
    if int(model.jnt_type[j]) in kinds:
        raise ValueError(
            f"mjcf: {label}: {where} is a {kinds[int(model.jnt_type[j])]} joint: only hinge and "
            "slide joints are supported (fixed-base trees)"
        )
    if not name:
        raise ValueError(f"mjcf: {label}: {where} has no name: joints are matched to data by name")
    if not body:
        raise ValueError(
            f"mjcf: {label}: the body of joint {name!r} has no name: parameters are named after it"
        )
    if model.jnt_stiffness[j] != 0:
        raise ValueError(
            f"mjcf: {label}: {where} has stiffness={model.jnt_stiffness[j]:g}: joint springs are not "
            "supported"
        )


def _matrix(mujoco: Any, quaternion: np.ndarray) -> np.ndarray:
    out = np.empty(9)
    mujoco.mju_quat2Mat(out, np.asarray(quaternion, dtype=np.float64))
    return out.reshape(3, 3)


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` about the unit ``axis`` (Rodrigues), ``[3, 3]``."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * k @ k


def model_from_mujoco(model: Any, label: str, text: str, source: Path | None) -> MJCFModel:
    """The tree of a compiled ``MjModel`` (bodies are stored parents first, as the tree needs).

    A MuJoCo body ``b`` hangs on its owner (the nearest moving body at or above it, or the world);
    ``frames[b]`` is its frame's ``(R, p)`` in the owner's idkit frame at ``q = 0``.
    """
    mujoco = import_mujoco()
    _refuse_unmodelled(mujoco, model, label)
    obj = mujoco.mjtObj
    hinge = int(mujoco.mjtJoint.mjJNT_HINGE)
    frames: dict[int, tuple[int, np.ndarray, np.ndarray]] = {0: (-1, np.eye(3), np.zeros(3))}
    bodies: list[Body] = []
    inertials: list[np.ndarray] = []
    welded: list[list[str]] = []
    anchors, damping, frictionloss, armature = [], [], [], []
    links: list[LinkInertial] = []
    for b in range(1, model.nbody):
        name = _name(mujoco, model, obj.mjOBJ_BODY, b)
        principal = _matrix(mujoco, model.body_iquat[b])
        own_inertia = principal @ np.diag(model.body_inertia[b]) @ principal.T
        links.append(LinkInertial(name, float(model.body_mass[b]), np.array(model.body_ipos[b]), own_inertia))
        owner, rot_parent, pos_parent = frames[int(model.body_parentid[b])]
        rot = rot_parent @ _matrix(mujoco, model.body_quat[b])  # MuJoCo body frame in the owner frame
        pos = rot_parent @ model.body_pos[b] + pos_parent
        if model.body_jntnum[b] > 1:
            joints = [
                _name(mujoco, model, obj.mjOBJ_JOINT, j)
                for j in range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b])
            ]
            raise ValueError(
                f"mjcf: {label}: body {name!r} has {len(joints)} joints ({', '.join(joints)}): one joint per "
                "body is supported (nest a body per joint)"
            )
        if model.body_jntnum[b] == 1:
            j = int(model.body_jntadr[b])
            axis = np.asarray(model.jnt_axis[j], dtype=np.float64)
            axis = axis / np.linalg.norm(axis)
            ref = float(model.qpos0[model.jnt_qposadr[j]])
            revolute = int(model.jnt_type[j]) == hinge
            anchor = np.asarray(model.jnt_pos[j], dtype=np.float64) if revolute else np.zeros(3)
            # qpos = ref is the modelled pose: the constant placement turns (or slides) by -ref.
            placement = rot @ _axis_rotation(axis, -ref) if revolute else rot
            origin = pos + rot @ anchor if revolute else pos - ref * (rot @ axis)
            bodies.append(_body(mujoco, model, j, owner, placement, origin, axis, revolute, name))
            inertials.append(np.zeros(10))
            welded.append([])
            anchors.append(anchor)
            damping.append(float(model.dof_damping[model.jnt_dofadr[j]]))
            frictionloss.append(float(model.dof_frictionloss[model.jnt_dofadr[j]]))
            armature.append(float(model.dof_armature[model.jnt_dofadr[j]]))
            owner, rot, pos = len(bodies) - 1, np.eye(3), -anchor
        elif owner >= 0:
            welded[owner].append(name)
        frames[b] = (owner, rot, pos)
        if owner >= 0 and model.body_mass[b] > 0:
            inertia = rot @ own_inertia @ rot.T
            inertials[owner] += standard_parameters(
                float(model.body_mass[b]), rot @ model.body_ipos[b] + pos, inertia
            )
    if not bodies:
        raise ValueError(f"mjcf: {label} has no hinge or slide joint")
    bodies = [
        _replace(b, inertial, tuple(w)) for b, inertial, w in zip(bodies, inertials, welded, strict=True)
    ]
    gravity = (
        0.0 if model.opt.disableflags & int(mujoco.mjtDisableBit.mjDSBL_GRAVITY) else -model.opt.gravity[2]
    )
    tree = KinematicTree(
        bytes(model.names).split(b"\0", 1)[0].decode(), "world", tuple(bodies), label, tuple(links)
    )
    check_model(tree)
    return MJCFModel(
        tree,
        float(gravity),
        np.array(anchors).reshape(-1, 3),
        np.array(damping),
        np.array(frictionloss),
        np.array(armature),
        source,
        text,
    )


def _body(
    mujoco: Any,
    model: Any,
    j: int,
    parent: int,
    rotation: np.ndarray,
    translation: np.ndarray,
    axis: np.ndarray,
    revolute: bool,
    link: str,
) -> Body:
    """The tree :class:`Body` of joint ``j`` (inertial filled in later)."""
    limits = None
    if model.jnt_limited[j]:
        low, high = (float(v) for v in model.jnt_range[j])
        limits = (low, high) if high > low else None
    effort = None
    if model.jnt_actfrclimited[j]:
        low, high = (float(v) for v in model.jnt_actfrcrange[j])
        effort = min(-low, high) if min(-low, high) > 0 else None
    return Body(
        _name(mujoco, model, mujoco.mjtObj.mjOBJ_JOINT, j),
        link,
        "revolute" if revolute else "prismatic",
        parent,
        rotation,
        translation,
        axis,
        np.zeros(10),
        limits,
        effort=effort,
    )


def _replace(body: Body, inertial: np.ndarray, welded: tuple[str, ...]) -> Body:
    return replace(body, inertial=inertial, welded=welded)


class MJCFRobot(URDFRobot):
    """A MuJoCo model (MJCF) identified like a URDF: the same tree, parameters and options.

    Args:
        mjcf: an MJCF file path, MJCF text, or the name of an MJCF shipped in ``idkit/robots/assets``
            (default ``arm``: two hinges and a slide). Read with ``mujoco``: ``pip install
            robot-idkit[mjcf]``.
        friction, offset, stribeck_velocity, effort_scale: as for :class:`~idkit.robots.urdf.URDFRobot`
            (``fc`` is MuJoCo's ``frictionloss``, ``fv`` its ``damping``).
        sigmoid_steepness, sigmoid_shift, coulomb_velocity: as for :class:`~idkit.robots.urdf.URDFRobot`.
        armature: as for :class:`~idkit.robots.urdf.URDFRobot`; the a-priori value is the joint's
            MuJoCo ``armature``. A model with a non-zero ``armature`` needs ``armature=True``:
            ``mj_inverse`` adds ``armature · q̈``, which the model would otherwise lack.
        n_states, tolerance, seed: as for :class:`~idkit.robots.urdf.URDFRobot`.
        max_coulomb, max_viscous, max_offset, max_armature, steepness_range, max_shift: as for
            :class:`~idkit.robots.urdf.URDFRobot`.

    Gravity is the model's ``<option gravity>`` (``self.gravity``, m/s² along −z). Parameters are
    named after the MuJoCo bodies and joints: ``<body>.m … <body>.Izz``,
    ``<joint>.fc``, ``<joint>.fv``, ``<joint>.armature``; the inertia is about idkit's body frame (the
    MuJoCo body frame moved to the joint's ``pos``). ``mujoco_model`` keeps what the writer needs
    (:mod:`idkit.robots.mjcf_export`).
    """

    source_format: ClassVar[str] = "mjcf"

    def __init__(
        self,
        mjcf: str = "arm",
        friction: Friction = False,
        offset: bool = False,
        n_states: int = 200,
        tolerance: float = 1e-8,
        seed: Seed = 0,
        max_coulomb: float = 10.0,
        max_viscous: float = 10.0,
        max_offset: float = 10.0,
        stribeck_velocity: float | Sequence[float] | None = None,
        armature: bool = False,
        effort_scale: Sequence[float] | None = None,
        max_armature: float = 10.0,
        sigmoid_steepness: float | Sequence[float] = 10.0,
        sigmoid_shift: float | Sequence[float] = 0.0,
        steepness_range: tuple[float, float] = (1.0, 100.0),
        max_shift: float = 0.2,
        coulomb_velocity: float | Sequence[float] | str | None = None,
    ) -> None:
        self.mjcf = mjcf
        self.mujoco_model = read_mjcf(mjcf)
        joints = self.mujoco_model.tree.joint_names
        armatures = zip(joints, self.mujoco_model.armature, strict=True)
        with_rotors = [f"{joint} ({value:g})" for joint, value in armatures if value]
        if with_rotors and not armature:
            raise ValueError(
                f"mjcf: {self.mujoco_model.tree.source}: joints with armature: {', '.join(with_rotors)}; "
                "identify it with robot.armature=true (mj_inverse adds armature · q̈), or set it to 0"
            )
        super().__init__(
            mjcf,
            friction=friction,
            offset=offset,
            gravity=self.mujoco_model.gravity,
            n_states=n_states,
            tolerance=tolerance,
            seed=seed,
            max_coulomb=max_coulomb,
            max_viscous=max_viscous,
            max_offset=max_offset,
            stribeck_velocity=stribeck_velocity,
            armature=armature,
            effort_scale=effort_scale,
            max_armature=max_armature,
            sigmoid_steepness=sigmoid_steepness,
            sigmoid_shift=sigmoid_shift,
            steepness_range=steepness_range,
            max_shift=max_shift,
            coulomb_velocity=coulomb_velocity,
        )

    def _read_tree(self) -> KinematicTree:
        return self.mujoco_model.tree

    def _a_priori_armatures(self) -> dict[str, float]:
        """The joints' MuJoCo ``armature``."""
        return dict(zip(self.joint_names, self.mujoco_model.armature.tolist(), strict=True))
