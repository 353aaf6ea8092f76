"""Where a URDF link sits on the moving body it is welded to (a flange, a tool mount).

The URDF reader merges links welded by ``fixed`` joints into their moving body and keeps only
their names (``Body.welded``). A payload is often best reported in such a link's frame — the
flange frame that libfranka's ``setLoad`` and UR's ``set_target_payload`` take — so this module
composes the fixed joints' ``<origin>`` from the body's link down to the welded one.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from idkit.robots.urdf_model import KinematicTree, read_urdf_text, rpy_matrix


@dataclass(frozen=True)
class LinkPlacement:
    """A link's frame in the frame of the moving body that carries it.

    Attributes:
        link: the link's name.
        body: index of the moving body in ``tree.bodies``.
        rotation: ``[3, 3]`` orientation of the link frame in the body frame.
        translation: ``[3]`` origin of the link frame in the body frame (m).
    """

    link: str
    body: int
    rotation: np.ndarray
    translation: np.ndarray


def _origin(joint: ET.Element) -> tuple[np.ndarray, np.ndarray]:
    """A joint's first ``<origin>`` as ``(R, p)`` (the file was checked by the reader already)."""
    origin = joint.find("origin")
    xyz = (origin.get("xyz") if origin is not None else None) or "0 0 0"
    rpy = (origin.get("rpy") if origin is not None else None) or "0 0 0"
    return rpy_matrix(np.array([float(v) for v in rpy.split()])), np.array([float(v) for v in xyz.split()])


def _link(joint: ET.Element, role: str) -> str:
    """The link a joint's ``<parent>`` or ``<child>`` (``role``) names ("" if none: checked by the reader)."""
    end = joint.find(role)
    return "" if end is None else end.get("link", "")


def link_placement(tree: KinematicTree, urdf: str, link: str) -> LinkPlacement:
    """The placement of ``link`` (a moving body's link or one welded to it) in its body's frame.

    Args:
        tree: the robot's tree (``URDFRobot.tree``), read from ``urdf``.
        urdf: the URDF the tree was read from (path, text or shipped name).
        link: a link name.

    Raises:
        ValueError: ``link`` is not in the tree, or is welded to the fixed root (it never moves).
    """
    bodies = {body.link: i for i, body in enumerate(tree.bodies)}
    if link in bodies:
        return LinkPlacement(link, bodies[link], np.eye(3), np.zeros(3))
    if link not in {own.name for own in tree.links}:
        raise ValueError(f"{tree.source} has no link {link!r}")
    data, _ = read_urdf_text(urdf)
    parent_joint = {_link(joint, "child"): joint for joint in ET.fromstring(data).findall("joint")}
    chain, current = [], link
    while current not in bodies:
        joint = parent_joint.get(current)
        if joint is None or joint.get("type") != "fixed":
            raise ValueError(f"link {link!r} of {tree.source} never moves (it is the root or welded to it)")
        chain.append(joint)
        current = _link(joint, "parent")
    rotation, translation = np.eye(3), np.zeros(3)
    for joint in reversed(chain):  # from the body's link down to ``link``
        r, p = _origin(joint)
        rotation, translation = rotation @ r, rotation @ p + translation
    return LinkPlacement(link, bodies[current], rotation, translation)
