"""Self-collision of a URDF robot along a motion, with pinocchio and coal (hpp-fcl): optional.

``pip install robot-idkit[collision]`` installs both (PyPI ``pin``, ``coal``); they are imported
only here and only when a check runs. :func:`self_collision` returns a :class:`SelfCollision`
that tests joint trajectories, or a :class:`NotChecked` that says why not (neither installed, the
robot is not a URDF, the URDF has no collision geometry) — a report then says "not checked" and
why, never "no collision".

Which pairs are tested: every pair of collision geometries on two different bodies, except
*adjacent* bodies — a body and its parent, which touch at their joint by construction. A link
without (usable) collision geometry is transparent: its parent and child bodies count as adjacent
(they meet at that link, which the model does not draw). Mesh geometry whose file cannot be found
(``package://`` paths need the package's folder: ``package_dirs``) is left out, and the check says
which links lost geometry. Geometry on links welded to the root (a table, a base) takes part:
an arm hitting its table is a collision.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from idkit.interfaces import Robot


@dataclass(frozen=True)
class NotChecked:
    """Why self-collision was not checked (``reason``, one phrase for a report)."""

    reason: str

    def status(self) -> str:
        return f"not checked ({self.reason})"


@dataclass(frozen=True)
class Contact:
    """Two bodies (link names, sorted) in contact at sample ``index`` of a trajectory."""

    index: int
    first: str
    second: str


def _import_pinocchio() -> Any | None:
    try:
        import pinocchio
    except ImportError:
        return None
    return pinocchio


def _mesh_file(filename: str, base: Path | None, package_dirs: Sequence[Path]) -> Path | None:
    """The mesh file ``filename`` names (absolute, relative to the URDF, ``package://``, ``file://``)."""
    if filename.startswith("package://"):
        relative = filename[len("package://") :]
        package, _, rest = relative.partition("/")
        candidates = [d / package / rest for d in package_dirs] + [d / rest for d in package_dirs]
    elif filename.startswith("file://"):
        candidates = [Path(filename[len("file://") :])]
    else:
        path = Path(filename)
        candidates = [path] if path.is_absolute() or base is None else [base / path]
    return next((c for c in candidates if c.is_file()), None)


def _usable_geometry(root: ET.Element, base: Path | None, package_dirs: Sequence[Path]) -> list[str]:
    """Drop ``<collision>`` elements whose mesh is missing (in place); the links that lost one."""
    lost = []
    for link in root.iter("link"):
        for element in list(link.findall("collision")):
            mesh = element.find("geometry/mesh")
            if mesh is not None and _mesh_file(mesh.get("filename", ""), base, package_dirs) is None:
                link.remove(element)
                lost.append(link.get("name", "?"))
    return sorted(set(lost))


@dataclass
class SelfCollision:
    """Self-collision tests of one URDF robot (built by :func:`self_collision`).

    Attributes:
        joint_names: the robot's joints, in idkit's order (the columns of the trajectories tested).
        pairs: the body pairs tested, by link name.
        incomplete: links whose collision mesh was not found (their geometry is not tested).
    """

    joint_names: tuple[str, ...]
    pairs: list[tuple[str, str]]
    incomplete: list[str]
    _pin: Any = field(repr=False)
    _model: Any = field(repr=False)
    _geometry: Any = field(repr=False)
    _columns: list[tuple[int, int]] = field(repr=False)  # per idkit joint: (pinocchio q index, nq)

    def status(self) -> str:
        missing = f"; without {', '.join(self.incomplete)} (mesh not found)" if self.incomplete else ""
        return f"checked with pinocchio + coal ({len(self.pairs)} body pairs{missing})"

    def _configuration(self, q: np.ndarray) -> np.ndarray:
        config = self._pin.neutral(self._model)
        for value, (index, nq) in zip(q, self._columns, strict=True):
            if nq == 2:  # continuous joint: (cos, sin)
                config[index : index + 2] = (np.cos(value), np.sin(value))
            else:
                config[index] = value
        return config

    def in_contact(self, q: np.ndarray) -> np.ndarray:
        """Whether any tested pair is in contact, per pose of ``q[T, n]``: ``[T]`` bool."""
        pin, model, geometry = self._pin, self._model, self._geometry
        data, geometry_data = model.createData(), pin.GeometryData(geometry)
        poses = np.asarray(q, dtype=np.float64)
        return np.array(
            [
                pin.computeCollisions(model, data, geometry, geometry_data, self._configuration(p), True)
                for p in poses
            ],
            dtype=bool,
        )

    def contacts(self, q: np.ndarray, first_only: bool = False) -> list[Contact]:
        """Every pair in contact at each pose of ``q[T, n]`` (idkit's joint order); with
        ``first_only``, stop at the first pose in contact."""
        pin, model, geometry = self._pin, self._model, self._geometry
        data, geometry_data = model.createData(), pin.GeometryData(geometry)
        found: list[Contact] = []
        for index, pose in enumerate(np.asarray(q, dtype=np.float64)):
            if not pin.computeCollisions(
                model, data, geometry, geometry_data, self._configuration(pose), False
            ):
                continue
            for k, result in enumerate(geometry_data.collisionResults):
                if result.isCollision():
                    pair = geometry.collisionPairs[k]
                    names = sorted((self._link(pair.first), self._link(pair.second)))
                    contact = Contact(index, *names)
                    if contact not in found:
                        found.append(contact)
            if first_only:
                break
        return found

    def _link(self, geometry_index: int) -> str:
        return _link_of(self._model, self._geometry.geometryObjects[geometry_index])


def _link_of(model: Any, geometry_object: Any) -> str:
    """The URDF link a pinocchio geometry belongs to (its parent frame)."""
    return model.frames[geometry_object.parentFrame].name


def self_collision(
    robot: Robot, package_dirs: Sequence[str | os.PathLike[str]] = ()
) -> SelfCollision | NotChecked:
    """A self-collision checker for ``robot``, or why there is none (module docstring).

    Args:
        robot: a URDF robot (``idkit.robots.urdf.URDFRobot``); any other is "not checked".
        package_dirs: folders holding the packages ``package://`` mesh paths name.
    """
    from idkit.robots.urdf import URDFRobot
    from idkit.robots.urdf_model import read_urdf_text

    if not isinstance(robot, URDFRobot):
        return NotChecked(f"{type(robot).__name__} is not a URDF robot")
    pin = _import_pinocchio()
    if pin is None:
        return NotChecked("pinocchio+coal not installed: pip install robot-idkit[collision]")
    text, label = read_urdf_text(robot.urdf)
    base = Path(label).parent if label != "<URDF text>" else None
    root = ET.fromstring(text)
    incomplete = _usable_geometry(root, base, [Path(d) for d in package_dirs])
    if not any(link.find("collision") is not None for link in root.iter("link")):
        lost = f"; meshes not found for {', '.join(incomplete)}" if incomplete else ""
        return NotChecked(f"no collision geometry{lost}")
    xml = ET.tostring(root, encoding="unicode")
    model = pin.buildModelFromXML(xml)
    geometry = pin.buildGeomFromUrdfString(model, xml, pin.GeometryType.COLLISION)
    carriers = {g.parentJoint for g in geometry.geometryObjects}

    def carrying_parent(joint: int) -> int:
        """The nearest ancestor of ``joint`` that carries geometry (the root if none does)."""
        parent = model.parents[joint]
        while parent != 0 and parent not in carriers:
            parent = model.parents[parent]
        return parent

    geometry.addAllCollisionPairs()
    kept = []  # indices, copied: the pair objects are views into a vector that is cleared below
    for pair in geometry.collisionPairs:
        first, second = int(pair.first), int(pair.second)
        a, b = (geometry.geometryObjects[i].parentJoint for i in (first, second))
        if a != b and carrying_parent(a) != b and carrying_parent(b) != a:
            kept.append((first, second))
    geometry.removeAllCollisionPairs()
    for first, second in kept:
        geometry.addCollisionPair(pin.CollisionPair(first, second))
    pin_names = list(model.names)
    columns = []
    for name in robot.joint_names:
        joint = pin_names.index(name)
        columns.append((model.idx_qs[joint], model.nqs[joint]))
    links = [
        (_link_of(model, geometry.geometryObjects[i]), _link_of(model, geometry.geometryObjects[j]))
        for i, j in kept
    ]
    bodies = sorted({(a, b) if a <= b else (b, a) for a, b in links})
    return SelfCollision(tuple(robot.joint_names), bodies, incomplete, pin, model, geometry, columns)
