"""Each moving body's geometry as a bounding ellipsoid and box, in the frame of its inertial parameters.

What the plausibility options of the conic program need (:mod:`idkit.conic.plausible`): a body's
mass must lie inside its geometry, which Wensing, Kim & Slotine's bound ``tr(J Q4) ≥ 0`` states for
an ellipsoid (:mod:`idkit.robots.bounding`), and a report checks its centre of mass against the box.

Which geometry: per link, its URDF ``<collision>`` elements, or its ``<visual>`` ones where no
collision element is usable; a MuJoCo body's colliding geoms (``contype`` or ``conaffinity`` set),
or all its geoms where none collides. A body gathers its own link's and those of every link welded
to it, each through its fixed-joint placement and ``<origin>`` (MuJoCo: the compiled geom poses,
meshes as MuJoCo recentred them). The frame is the body frame of the standard parameters: a URDF
body's child link frame; the MuJoCo body frame moved to the joint's ``pos``
(:mod:`idkit.robots.mjcf`).

Never an error for geometry the dynamics do not need: a mesh that is not found or not read (a
``.dae``, a ``package://`` path without its folder in ``package_dirs``), an unknown or malformed
shape, is left out and named in ``missing``; a body left with nothing has no bound (``None``). A
folder in ``package_dirs`` that does not exist is refused (a typo would silently drop every mesh).

Geometry is trusted only where it can hold the link: a body whose CAD mass would make its geometry's
bounding ellipsoid denser than :data:`MAX_DENSITY` (a 1 cm box standing in for a wrist, a marker
sphere) is a *placeholder*, not the link's shape: it bounds nothing, and is named in
``placeholders``. Density, not the CAD inertia: shipped inertias are often placeholders themselves
(the KUKA's 0.3 kg flange has a 0.41 m radius of gyration inside an 8 cm cylinder), and there the
geometry is the better witness of the body.
"""

from __future__ import annotations

import os
import weakref
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from idkit.interfaces import Robot
from idkit.robots.bounding import Solid, ellipsoid_bound, minimum_volume_ellipsoid, thickened
from idkit.robots.meshes import MeshError, checked_package_dirs, mesh_file, mesh_vertices
from idkit.robots.mjcf import MJCFRobot, compile_mjcf, import_mujoco
from idkit.robots.urdf import URDFRobot
from idkit.robots.urdf_frames import link_placement
from idkit.robots.urdf_model import read_urdf_text, rpy_matrix


@dataclass(frozen=True)
class BodyGeometry:
    """One moving body's geometry, in its body frame (m).

    Attributes:
        ellipsoid_centre: ``c[3]``.
        ellipsoid_shape: ``Q[3, 3]``: ``x`` is inside iff ``(x − c)ᵀ Q (x − c) ≤ 1``; the minimum-volume
            ellipsoid of all the body's solids (exact for one primitive; within 2.2 % of the
            minimum volume where a curved solid enters as a circumscribing polyhedron).
        box_lo, box_hi: ``[3]`` the axis-aligned bounding box of the solids.
        sources: what was bounded, one phrase each (``"lwr_1_link collision sphere"``), and a note
            when flat geometry was thickened.
        missing: the body's geometry that was left out, ``"<link>: <what> (<why>)"``.
    """

    ellipsoid_centre: np.ndarray
    ellipsoid_shape: np.ndarray
    box_lo: np.ndarray
    box_hi: np.ndarray
    sources: tuple[str, ...]
    missing: tuple[str, ...]

    def q4(self) -> np.ndarray:
        """``Q4[4, 4]`` with ``tr(J Q4) ≥ 0`` iff a pseudo-inertia ``J ⪰ 0`` has its mass in the ellipsoid."""
        return ellipsoid_bound(self.ellipsoid_centre, self.ellipsoid_shape)

    def in_ellipsoid(self, point: np.ndarray) -> bool:
        offset = np.asarray(point, dtype=np.float64) - self.ellipsoid_centre
        return bool(offset @ self.ellipsoid_shape @ offset <= 1.0)

    def in_box(self, point: np.ndarray) -> bool:
        point = np.asarray(point, dtype=np.float64)
        return bool(np.all(point >= self.box_lo) and np.all(point <= self.box_hi))

    def size(self) -> float:
        """The bounding box's largest edge (m), to name a placeholder by."""
        return float((self.box_hi - self.box_lo).max())

    def volume(self) -> float:
        """The bounding ellipsoid's volume (m³)."""
        return float(4 / 3 * np.pi / np.sqrt(np.linalg.det(self.ellipsoid_shape)))


@dataclass(frozen=True)
class RobotGeometry:
    """Every moving body's geometry (:func:`body_geometry`).

    Attributes:
        bodies: body link name → its :class:`BodyGeometry`, or ``None`` when none of its links has
            usable geometry or what it has is a placeholder; in the robot's body order.
        missing: all geometry left out, ``"<link>: <what> (<why>)"``.
        placeholders: body link name → why its geometry bounds nothing (far smaller than its CAD
            inertia: module doc).
    """

    bodies: dict[str, BodyGeometry | None]
    missing: tuple[str, ...]
    placeholders: dict[str, str] = field(default_factory=dict)

    def bounded_by(self) -> dict[str, str]:
        """Per body, by name: what bounds it (``"collision sphere, collision cylinder"``), or why nothing
        does (``"nothing: no usable geometry"``, ``"nothing: a placeholder …"``)."""
        out = {}
        for name, geometry in self.bodies.items():
            if geometry is not None:
                out[name] = ", ".join(_without_link(name, source) for source in geometry.sources)
            elif name in self.placeholders:
                out[name] = f"nothing: {self.placeholders[name]}"
            else:
                out[name] = "nothing: no usable geometry"
        return out

    def summary(self) -> str:
        """One line for a report: which bodies are bounded by what, which are not and why, what was
        left out."""
        bounded = self.bounded_by()
        count = sum(geometry is not None for geometry in self.bodies.values())
        parts = [f"geometry bounds {count} of {len(self.bodies)} bodies"]
        if count:
            parts.append(
                "bounded: "
                + ", ".join(f"{name} ({bounded[name]})" for name, g in self.bodies.items() if g is not None)
            )
        if self.placeholders:
            parts.append(
                "placeholder geometry, not used: "
                + ", ".join(f"{name} ({why})" for name, why in self.placeholders.items())
            )
        without = [n for n, g in self.bodies.items() if g is None and n not in self.placeholders]
        if without:
            parts.append(f"no usable geometry on {', '.join(without)}")
        if self.missing:
            parts.append(f"left out: {'; '.join(self.missing)}")
        return "; ".join(parts)


def _without_link(link: str, source: str) -> str:
    """``"lwr_1_link collision sphere"`` → ``"collision sphere"`` (the body's own link)."""
    return source.removeprefix(f"{link} ")


class _Unusable(ValueError):
    """One geometry element that is left out (the message says why)."""


#: Per body link: ``(label, solid)`` of each usable geometry, and what was left out of it.
_Found = dict[str, tuple[list[tuple[str, Solid]], list[str]]]


#: Per robot (weakly held) and ``package_dirs``: what :func:`body_geometry` built. A body of several
#: solids costs a few hundred Newton steps; the estimator, its report and the CLI ask again.
_BUILT: weakref.WeakKeyDictionary[Robot, dict[tuple[str, ...], RobotGeometry]] = weakref.WeakKeyDictionary()


def body_geometry(
    robot: Robot, package_dirs: Sequence[str | os.PathLike[str]] | None = None
) -> RobotGeometry:
    """The bounding ellipsoid and box of each moving body of a ``urdf`` or ``mjcf`` robot (built once
    per robot and ``package_dirs``; the files are not read again).

    Args:
        robot: a :class:`~idkit.robots.urdf.URDFRobot` or :class:`~idkit.robots.mjcf.MJCFRobot`.
        package_dirs: folders holding the packages that URDF ``package://`` mesh paths name
            (``None``: the robot's own ``package_dirs`` option).

    Raises:
        ValueError: any other robot (it has no geometry to read), or a ``package_dirs`` entry that is
            not an existing folder.
    """
    if not isinstance(robot, URDFRobot):
        raise ValueError(f"geometry: needs a urdf or mjcf robot, got {type(robot).__name__}")
    if package_dirs is None:
        package_dirs = tuple(getattr(robot, "package_dirs", ()) or ())
    built = _BUILT.setdefault(robot, {})
    key = tuple(str(d) for d in package_dirs)
    if key not in built:
        built[key] = _build(robot, list(checked_package_dirs(package_dirs, "geometry")))
    return built[key]


#: Geometry is a placeholder when the link's CAD mass would make its bounding ellipsoid denser than
#: this (kg/m³: osmium, the densest element, is 22,590): a real shape holds its own link's mass with
#: room to spare (the ellipsoid is larger than the solid, a link hollower than a metal block), a 1 cm
#: box on a 0.5 kg wrist would be 180,000 kg/m³.
MAX_DENSITY = 22_600.0


def _build(robot: URDFRobot, package_dirs: list[Path]) -> RobotGeometry:
    found = _mjcf_solids(robot) if isinstance(robot, MJCFRobot) else _urdf_solids(robot, package_dirs)
    nominal = robot.nominal_params().double().numpy()
    cad = {link: nominal[10 * i : 10 * i + 10] for i, link in enumerate(robot.link_names)}
    bodies: dict[str, BodyGeometry | None] = {}
    placeholders: dict[str, str] = {}
    missing: list[str] = []
    for link, (solids, lost) in found.items():
        try:
            bodies[link] = _bound(solids, tuple(lost)) if solids else None
        except ValueError as error:
            lost.append(f"{link}: {', '.join(label for label, _ in solids)} ({error})")
            bodies[link] = None
        missing += lost
        geometry = bodies[link]
        mass = cad[link][0] if link in cad else 0.0
        if geometry is not None and mass > MAX_DENSITY * geometry.volume():
            what = ", ".join(_without_link(link, source) for source in geometry.sources)
            placeholders[link] = (
                f"{what} of {100 * geometry.size():.3g} cm, far smaller than a body of its CAD mass "
                f"{mass:.3g} kg can be"
            )
            bodies[link] = None
    return RobotGeometry(bodies, tuple(missing), placeholders)


def _bound(found: list[tuple[str, Solid]], missing: tuple[str, ...]) -> BodyGeometry:
    """The bounds of a body's solids (``ValueError``: they make a single point)."""
    labels = tuple(label for label, _ in found)
    exact = found[0][1].exact_ellipsoid() if len(found) == 1 else None
    if exact is not None:
        centre, shape = exact
    else:
        points, pad = thickened(np.concatenate([solid.points() for _, solid in found]))
        centre, shape = minimum_volume_ellipsoid(points)
        if pad:
            labels += (f"flat geometry thickened to ±{pad * 1e3:.3g} mm",)
    boxes = [solid.bounds() for _, solid in found]
    lo, hi = np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)
    for array in (centre, shape, lo, hi):
        array.flags.writeable = False  # shared by every caller (cached)
    return BodyGeometry(centre, shape, lo, hi, labels, missing)


# ------------------------------------------------------------------------------------------- URDF
def _urdf_solids(robot: URDFRobot, package_dirs: list[Path]) -> _Found:
    data, label = read_urdf_text(robot.urdf)
    base = Path(label).resolve().parent if label != "<URDF text>" else None
    links = {link.get("name"): link for link in ET.fromstring(data).findall("link")}
    found: _Found = {}
    for body in robot.tree.bodies:
        solids, lost = found.setdefault(body.link, ([], []))
        for name in (body.link, *body.welded):
            placement = link_placement(robot.tree, robot.urdf, name)
            for role in ("collision", "visual"):  # visual only where no collision element is usable
                usable = []
                for element in links[name].findall(role):
                    what = f"{role} {_shape_name(element)}"
                    try:
                        pose = (placement.rotation, placement.translation)
                        solid = _urdf_solid(element, *pose, base, package_dirs)
                    except _Unusable as error:
                        lost.append(f"{name}: {what} ({error})")
                        continue
                    usable.append((f"{name} {what}", solid))
                solids += usable
                if usable:
                    break
    return found


def _shape_name(element: ET.Element) -> str:
    shape = element.find("geometry/*")
    if shape is None:
        return "without a shape"
    return f"mesh {shape.get('filename', '')}" if shape.tag == "mesh" else shape.tag


def _numbers(element: ET.Element, attribute: str, count: int, default: str | None = None) -> np.ndarray:
    text = element.get(attribute, default)
    if text is None:
        raise _Unusable(f"no {attribute}")
    try:
        values = np.array([float(v) for v in text.split()], dtype=np.float64)
    except ValueError:
        raise _Unusable(f"{attribute}={text!r} is not numeric") from None
    if values.shape != (count,) or not np.isfinite(values).all():
        raise _Unusable(f"{attribute}={text!r} is not {count} finite number{'s' * (count > 1)}")
    return values


def _urdf_solid(
    element: ET.Element,
    rotation: np.ndarray,
    translation: np.ndarray,
    base: Path | None,
    package_dirs: list[Path],
) -> Solid:
    """The solid of a ``<collision>`` or ``<visual>`` on a link placed at ``(rotation, translation)`` in
    its body frame (mesh paths relative to ``base``, the URDF's folder)."""
    origin = element.find("origin")
    xyz = _numbers(origin, "xyz", 3, "0 0 0") if origin is not None else np.zeros(3)
    rpy = _numbers(origin, "rpy", 3, "0 0 0") if origin is not None else np.zeros(3)
    shape = element.find("geometry/*")
    if shape is None:
        raise _Unusable("no shape in <geometry>")
    pose = rotation @ rpy_matrix(rpy), rotation @ xyz + translation
    if shape.tag == "mesh":
        scale = shape.get("scale", "1 1 1")
        factors = _numbers(shape, "scale", 1 if len(scale.split()) == 1 else 3, "1 1 1")
        vertices = _mesh(shape.get("filename", ""), base, package_dirs) * factors
        return Solid("mesh", np.zeros(0), *pose, vertices)
    if shape.tag == "box":
        size = _numbers(shape, "size", 3) / 2
    elif shape.tag == "sphere":
        size = _numbers(shape, "radius", 1)
    elif shape.tag in ("cylinder", "capsule"):
        size = np.array([_numbers(shape, "radius", 1)[0], _numbers(shape, "length", 1)[0] / 2])
    else:
        raise _Unusable(f"<{shape.tag}> is not a URDF shape (box, cylinder, sphere, mesh)")
    if (size < 0).any():
        raise _Unusable("a negative size")
    return Solid(shape.tag, size, *pose)


def _mesh(filename: str, base: Path | None, package_dirs: list[Path]) -> np.ndarray:
    """``[n, 3]`` the vertices of the mesh file ``filename`` names."""
    path = mesh_file(filename, base, package_dirs)
    if path is None:
        hint = ": give robot.package_dirs" if filename.startswith("package://") else ""
        raise _Unusable("not found" + hint)
    try:
        return mesh_vertices(path)
    except MeshError as error:
        raise _Unusable(str(error)) from None


# ------------------------------------------------------------------------------------------- MJCF
def _mjcf_solids(robot: MJCFRobot) -> _Found:
    """The geoms of each body's MuJoCo bodies, posed as compiled (``mj_kinematics`` at ``qpos0``)."""
    mujoco = import_mujoco()
    read = robot.mujoco_model
    model = compile_mjcf(read.text, read.source, read.tree.source)
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    owner = np.zeros(model.nbody, dtype=int)  # the jointed MuJoCo body each one moves with (0: world)
    for b in range(1, model.nbody):  # parents first
        owner[b] = b if model.body_jntnum[b] else owner[model.body_parentid[b]]
    found: _Found = {}
    for body, anchor in zip(robot.tree.bodies, read.anchors, strict=True):
        solids, lost = found.setdefault(body.link, ([], []))
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body.link)
        frame = data.xmat[b].reshape(3, 3)
        origin = data.xpos[b] + frame @ anchor
        for carrier in np.flatnonzero(owner == b):  # welded bodies may be unnamed
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, carrier) or f"body #{carrier}"
            geoms = np.flatnonzero(model.geom_bodyid == carrier)
            colliding = [g for g in geoms if model.geom_contype[g] or model.geom_conaffinity[g]]
            for g in colliding or geoms:
                rotation = frame.T @ data.geom_xmat[g].reshape(3, 3)
                translation = frame.T @ (data.geom_xpos[g] - origin)
                kind = mujoco.mjtGeom(int(model.geom_type[g])).name.removeprefix("mjGEOM_").lower()
                what = f"geom {mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or '#' + str(g)} {kind}"
                try:
                    solids.append((f"{name} {what}", _mjcf_solid(model, int(g), kind, rotation, translation)))
                except _Unusable as error:
                    lost.append(f"{name}: {what} ({error})")
    return found


def _mjcf_solid(model: Any, g: int, kind: str, rotation: np.ndarray, translation: np.ndarray) -> Solid:
    size = np.asarray(model.geom_size[g], dtype=np.float64)
    if kind in ("box", "ellipsoid"):
        return Solid(kind, size, rotation, translation)
    if kind == "sphere":
        return Solid(kind, size[:1], rotation, translation)
    if kind in ("capsule", "cylinder"):
        return Solid(kind, size[:2], rotation, translation)
    if kind == "mesh":
        mesh = int(model.geom_dataid[g])
        start, count = int(model.mesh_vertadr[mesh]), int(model.mesh_vertnum[mesh])
        vertices = np.asarray(model.mesh_vert[start : start + count], dtype=np.float64)
        return Solid("mesh", np.zeros(0), rotation, translation, vertices)
    if kind == "hfield":  # x, y half-extents; elevation above, base below the geom frame's origin
        rx, ry, top, bottom = np.asarray(model.hfield_size[int(model.geom_dataid[g])], dtype=np.float64)
        centre = translation + rotation @ np.array([0.0, 0.0, (top - bottom) / 2])
        return Solid("box", np.array([rx, ry, (top + bottom) / 2]), rotation, centre)
    raise _Unusable("not a solid idkit bounds")  # an SDF plugin (planes are static in MuJoCo)
