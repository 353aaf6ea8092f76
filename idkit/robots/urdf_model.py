"""Parse a fixed-base URDF into moving bodies with float64 placements and inertials.

Why not pytorch-kinematics' parser: it stores joint origins in float32 (torques then drift by
~1e-6 N·m on a real arm) and keeps no inertial data, which is what dynamics needs. URDF is a small
XML format, so ``xml.etree`` reads it directly in float64.

A *body* is one moving joint (revolute, continuous or prismatic) together with its child link and
every link welded to that link by ``fixed`` joints; those welded inertials are merged into the
body's inertial (e.g. a flange or a tool). Links welded to the root (the KUKA ``box`` and
``lwr_base_link``) never move and are dropped, as pinocchio does. Each body's frame is its
child link's frame, which URDF defines to be the joint frame.

Bodies are listed depth-first from the root (children in document order), so a body's parent
always precedes it; kinematic trees (branches) are therefore supported, not only serial chains.

The tree also keeps every link's own inertial as written, so that
:func:`idkit.robots.model_checks.check_model` (which every reader calls) can name the element at
fault: a repeated name, a negative or non-finite mass, a lower limit above the upper one, an
inertia no rigid body has.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from idkit.robots.inertia import standard_parameters
from idkit.robots.model_checks import check_model
from idkit.robots.model_xml import refuse_dtd

ASSETS = Path(__file__).resolve().parent / "assets"
MOVING = {"revolute": "revolute", "continuous": "revolute", "prismatic": "prismatic"}
UNSUPPORTED = {
    "floating": "a floating base is not supported (fixed-base robots only)",
    "planar": "planar joints are not supported",
}
#: Order of the 10 standard inertial parameters of one body (inertia about the body-frame origin).
INERTIAL_NAMES = ("m", "mcx", "mcy", "mcz", "Ixx", "Ixy", "Ixz", "Iyy", "Iyz", "Izz")


@dataclass(frozen=True)
class Body:
    """One moving joint and the rigid body it carries.

    Attributes:
        joint: URDF joint name.
        link: URDF child link name (the body frame).
        kind: ``"revolute"`` (revolute or continuous) or ``"prismatic"``.
        parent: index of the parent body, ``-1`` when the parent is the fixed root.
        rotation: ``[3, 3]`` orientation of the joint frame in the parent body frame at ``q = 0``.
        translation: ``[3]`` position of the joint frame origin in the parent body frame.
        axis: ``[3]`` unit joint axis in the joint (= body) frame.
        inertial: ``[10]`` standard parameters ``(m, m c, I_xx, I_xy, I_xz, I_yy, I_yz, I_zz)`` with
            the inertia about the body-frame origin, welded links included.
        limits: ``(lower, upper)`` from ``<limit>``, or ``None`` (continuous joints).
        max_velocity: ``velocity`` of ``<limit>`` (rad/s or m/s), or ``None`` when absent or 0.
        welded: links welded to ``link`` by fixed joints, whose inertials are merged into ``inertial``.
        effort: ``<limit effort>`` (N·m or N), or ``None`` when absent or 0.
    """

    joint: str
    link: str
    kind: str
    parent: int
    rotation: np.ndarray
    translation: np.ndarray
    axis: np.ndarray
    inertial: np.ndarray
    limits: tuple[float, float] | None
    max_velocity: float | None = None
    welded: tuple[str, ...] = ()
    effort: float | None = None


@dataclass(frozen=True)
class LinkInertial:
    """One link's own inertial as the model file gives it, before welded links are merged.

    Attributes:
        name: link name.
        mass: kg (0 for a link without an inertial).
        com: ``[3]`` centre of mass in the link frame.
        inertia: ``[3, 3]`` inertia about the centre of mass, in link-frame axes.
    """

    name: str
    mass: float
    com: np.ndarray
    inertia: np.ndarray


@dataclass(frozen=True)
class KinematicTree:
    """The moving bodies of a fixed-base robot, parents before children.

    Attributes:
        name: the robot's name in its file.
        root: the root link.
        bodies: the moving bodies.
        source: where the model was read from (a file path, ``<URDF text>``), for messages.
        links: every link of the file in document order (repeats included), with its own inertial.
        fixed_joints: the names of the fixed joints (merged away in ``bodies``).
    """

    name: str
    root: str
    bodies: tuple[Body, ...]
    source: str
    links: tuple[LinkInertial, ...]
    fixed_joints: tuple[str, ...] = ()

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(b.joint for b in self.bodies)

    @property
    def joint_kinds(self) -> tuple[str, ...]:
        """``"revolute"`` or ``"prismatic"`` per joint: whether its effort is a torque or a force."""
        return tuple(b.kind for b in self.bodies)

    @property
    def link_names(self) -> tuple[str, ...]:
        return tuple(b.link for b in self.bodies)

    @property
    def parents(self) -> tuple[int, ...]:
        return tuple(b.parent for b in self.bodies)


def read_urdf_text(urdf: str | os.PathLike) -> tuple[bytes, str]:
    """The URDF's bytes and a label for error messages.

    ``urdf`` is URDF text (starts with ``<``), a file path, or the name of a URDF shipped in
    ``idkit/robots/assets`` (e.g. ``"cylindrical"``). Text is encoded to UTF-8 bytes and its XML
    declaration's ``encoding`` is rewritten to match, so a declared encoding never disagrees.

    Raises:
        ValueError: the XML declares a DTD (:mod:`idkit.robots.model_xml`, every model loader's policy).
    """
    if isinstance(urdf, str) and urdf.lstrip().startswith("<"):
        text = urdf.lstrip()
        if text.startswith("<?xml"):
            end = text.find("?>")
            text = '<?xml version="1.0" encoding="utf-8"' + text[end:] if end > 0 else text
        data, label = text.encode("utf-8"), "<URDF text>"
    else:
        path = model_file(urdf, "urdf", ".urdf")
        data, label = path.read_bytes(), str(path)
    refuse_dtd(data, label, "urdf")
    return data, label


def model_file(spec: str | os.PathLike, kind: str, suffix: str, formats: str | None = None) -> Path:
    """The model file ``spec`` names: a path, or a model shipped in ``idkit/robots/assets``.

    Args:
        spec: a path, or an asset's name (``"cylindrical"``).
        kind: ``"urdf"`` or ``"mjcf"`` (the option, for messages).
        suffix: the format's file suffix (``".urdf"``, ``".xml"``).
        formats: the formats the option takes, for messages (default ``kind`` in capitals).

    Raises:
        ValueError: ``spec`` is a directory (the message lists the model files in it).
        FileNotFoundError: no such file and no such asset (the message lists the shipped ones).
    """
    path = Path(spec)
    if not path.is_file() and (ASSETS / f"{spec}{suffix}").is_file():
        path = ASSETS / f"{spec}{suffix}"
    if path.is_dir():
        found = sorted(p.name for p in path.glob(f"*{suffix}"))
        inside = f"; {suffix} files in it: {', '.join(found[:5])}{' …' * (len(found) > 5)}" if found else ""
        raise ValueError(f"{kind}: {path} is a directory, not a {kind.upper()} file{inside}")
    if not path.is_file():
        shipped = sorted(p.stem for p in ASSETS.glob(f"*{suffix}"))
        raise FileNotFoundError(
            f"{kind}: {str(spec)!r} is neither {formats or kind.upper()} text, an existing file, nor a "
            f"shipped asset (shipped: {', '.join(shipped) or 'none'})"
        )
    return path


def _floats(element: ET.Element | None, attribute: str, default: tuple[float, ...], where: str) -> np.ndarray:
    if element is None or element.get(attribute) is None:
        return np.array(default, dtype=np.float64)
    try:
        values = np.array([float(v) for v in element.get(attribute, "").split()], dtype=np.float64)
    except ValueError:
        raise ValueError(f"{where}: {attribute}={element.get(attribute)!r} is not numeric") from None
    if not np.isfinite(values).all():
        raise ValueError(f"{where}: {attribute}={element.get(attribute)!r} is not a finite number")
    if values.shape != (len(default),):
        raise ValueError(f"{where}: {attribute} needs {len(default)} numbers, got {element.get(attribute)!r}")
    return values


def rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw: ``R = Rz(yaw) Ry(pitch) Rx(roll)``, ``[3, 3]``."""
    (cr, cp, cy), (sr, sp, sy) = np.cos(rpy), np.sin(rpy)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _origin(element: ET.Element, where: str) -> tuple[np.ndarray, np.ndarray]:
    """The first ``<origin>`` child as ``(R[3, 3], p[3])`` (urdfdom also reads only the first)."""
    origin = element.find("origin")
    xyz = _floats(origin, "xyz", (0.0, 0.0, 0.0), f"{where} <origin>")
    rpy = _floats(origin, "rpy", (0.0, 0.0, 0.0), f"{where} <origin>")
    return rpy_matrix(rpy), xyz


def _link_inertial(link: ET.Element) -> LinkInertial:
    """A link's inertial in its own frame; zeros when it has no ``<inertial>``."""
    name = link.get("name", "")
    where = f"link {name!r}"
    inertial = link.find("inertial")
    if inertial is None:
        return LinkInertial(name, 0.0, np.zeros(3), np.zeros((3, 3)))
    mass = _floats(inertial.find("mass"), "value", (0.0,), f"{where} <mass>")[0]
    rotation, com = _origin(inertial, f"{where} <inertial>")
    element = inertial.find("inertia")
    names = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    xx, xy, xz, yy, yz, zz = (_floats(element, k, (0.0,), f"{where} <inertia>")[0] for k in names)
    inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    return LinkInertial(name, float(mass), com, rotation @ inertia @ rotation.T)


def _moving_body(
    joint: ET.Element, child: str, parent: int, rotation: np.ndarray, translation: np.ndarray
) -> Body:
    """The :class:`Body` a moving joint (to link ``child``) starts (inertial filled in later)."""
    name, kind = joint.get("name", ""), joint.get("type", "")
    axis = _floats(joint.find("axis"), "xyz", (1.0, 0.0, 0.0), f"joint {name!r} <axis>")
    norm = np.linalg.norm(axis)
    if norm < 1e-12:
        raise ValueError(f"joint {name!r} has a zero axis")
    limits = None
    limit = joint.find("limit")
    velocity = _floats(limit, "velocity", (0.0,), f"joint {name!r} <limit>")[0]
    effort = float(_floats(limit, "effort", (0.0,), f"joint {name!r} <limit>")[0])
    if kind != "continuous":
        lo = _floats(limit, "lower", (0.0,), f"joint {name!r} <limit>")[0]
        hi = _floats(limit, "upper", (0.0,), f"joint {name!r} <limit>")[0]
        limits = None if hi == lo else (float(lo), float(hi))  # both absent: 0, 0 (no limit)
    max_velocity = float(velocity) if velocity > 0 else None
    return Body(
        name,
        child,
        MOVING[kind],
        parent,
        rotation,
        translation,
        axis / norm,
        np.zeros(10),
        limits,
        max_velocity=max_velocity,
        effort=effort if effort > 0 else None,
    )


def parse_urdf(urdf: str | os.PathLike) -> KinematicTree:
    """Parse URDF text, a path or a shipped asset name into a checked :class:`KinematicTree`.

    Raises:
        ValueError: malformed XML, a number that is not one (``nan``), a joint of unsupported type
            (``floating``, ``planar``, unknown) or with ``<mimic>``, a zero axis, a link with two
            parents, no unique root, or no moving joint; and whatever
            :func:`~idkit.robots.model_checks.check_model` refuses. The message names the file and
            the offending joint or link.
    """
    data, label = read_urdf_text(urdf)
    try:
        robot = ET.fromstring(data)
    except ET.ParseError as error:
        raise ValueError(f"urdf: {label} is not valid XML: {error}") from None
    try:
        tree = _tree(robot, label)
    except ValueError as error:
        raise ValueError(f"urdf: {label}: {error}") from None
    check_model(tree)
    return tree


def _tree(robot: ET.Element, label: str) -> KinematicTree:
    """The :class:`KinematicTree` of a parsed ``<robot>`` element (``label``: its source)."""
    if robot.tag != "robot":
        raise ValueError(f"root element is <{robot.tag}>, expected <robot>")
    for element in (*robot.findall("link"), *robot.findall("joint")):
        if element.get("name") is None:
            raise ValueError(f"a <{element.tag}> has no name attribute (parameters are named after them)")
    own = [_link_inertial(link) for link in robot.findall("link")]
    inertial_of = {link.name: link for link in own}
    children, root = _joint_graph(robot, [link.get("name", "") for link in robot.findall("link")])
    bodies: list[Body] = []
    inertials: list[np.ndarray] = []
    welded: list[list[str]] = []
    # Depth-first walk. A stack entry is (link, owning body, pose of the link in that body, the
    # Body its moving parent joint starts — or None when it hangs on a fixed joint).
    stack: list[tuple[str, int, np.ndarray, np.ndarray, Body | None]] = [
        (root, -1, np.eye(3), np.zeros(3), None)
    ]
    while stack:
        link, owner, rot, pos, body = stack.pop()
        if body is not None:
            bodies.append(body)
            inertials.append(np.zeros(10))
            welded.append([])
            owner, rot, pos = len(bodies) - 1, np.eye(3), np.zeros(3)
        elif owner >= 0:
            welded[owner].append(link)
        inertial = inertial_of[link]
        if owner >= 0:
            com, inertia = rot @ inertial.com + pos, rot @ inertial.inertia @ rot.T
            inertials[owner] += standard_parameters(inertial.mass, com, inertia)
        pending: list[tuple[str, int, np.ndarray, np.ndarray, Body | None]] = []
        for joint, child in children[link]:
            j_rot, j_pos = _origin(joint, f"joint {joint.get('name')!r}")
            rot_c, pos_c = rot @ j_rot, rot @ j_pos + pos  # joint frame in the owning body frame
            if joint.get("type") == "fixed":
                pending.append((child, owner, rot_c, pos_c, None))
            else:
                pending.append((child, owner, rot_c, pos_c, _moving_body(joint, child, owner, rot_c, pos_c)))
        stack.extend(reversed(pending))  # children in document order
    if not bodies:
        raise ValueError("has no revolute, continuous or prismatic joint")
    bodies = [
        replace(b, inertial=inertial, welded=tuple(w))
        for b, inertial, w in zip(bodies, inertials, welded, strict=True)
    ]
    fixed = tuple(joint.get("name", "") for joint in robot.findall("joint") if joint.get("type") == "fixed")
    return KinematicTree(robot.get("name", ""), root, tuple(bodies), label, tuple(own), fixed)


def _joint_graph(robot: ET.Element, links: list[str]) -> tuple[dict[str, list[tuple[ET.Element, str]]], str]:
    """Each link's joints to its children, with the child link's name, and the root link; every joint
    checked (:func:`_check_joint`) and every link with one parent at most."""
    children: dict[str, list[tuple[ET.Element, str]]] = {name: [] for name in links}
    parent_of: dict[str, str] = {}
    for joint in robot.findall("joint"):
        name = joint.get("name", "")
        _check_joint(joint)
        ends = []
        for role in ("parent", "child"):
            end = joint.find(role)
            link_name = None if end is None else end.get("link")
            if link_name is None or link_name not in children:
                raise ValueError(f"joint {name!r}: {role} link {link_name!r} is not defined")
            ends.append(link_name)
        parent_link, child_link = ends
        if child_link in parent_of:
            raise ValueError(
                f"link {child_link!r} is the child of two joints ({parent_of[child_link]!r}, "
                f"{name!r}): closed loops are not supported"
            )
        parent_of[child_link] = name
        children[parent_link].append((joint, child_link))
    roots = [name for name in children if name not in parent_of]
    if len(roots) != 1:
        raise ValueError(f"expected one root link, found {roots or 'none (a loop)'}")
    return children, roots[0]


def _check_joint(joint: ET.Element) -> None:
    """Refuse a joint idkit does not model: an unsupported or unknown type, a ``<mimic>``."""
    name, kind = joint.get("name", ""), joint.get("type")
    if kind in UNSUPPORTED:
        raise ValueError(f"joint {name!r} has type {kind!r}: {UNSUPPORTED[kind]}")
    if kind not in MOVING and kind != "fixed":
        raise ValueError(
            f"joint {name!r} has unknown type {kind!r} (supported: revolute, continuous, prismatic, fixed)"
        )
    if joint.find("mimic") is not None:
        raise ValueError(f"joint {name!r} has <mimic>: mimic joints are not supported")
