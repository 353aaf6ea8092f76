"""Write the identified model back as a URDF (``identified.urdf``).

The source URDF of a ``urdf`` robot is copied element for element (comments, visuals, collisions,
limits, transmissions, plugins stay as they are); only these change:

* each moving body's link gets a new ``<inertial>`` from its standard parameters ``(m, h, I_O)``:
  ``<origin xyz = c = h/m rpy = 0>``, ``<mass m>`` and the inertia about the centre of mass in the
  link frame, ``I_c = I_O − m (|c|² 1 − c cᵀ)`` (parallel-axis theorem backwards);
* links welded to a body by ``fixed`` joints lose their ``<inertial>``: the parser merged them into
  the body, and the identification cannot separate them again;
* with friction, each joint's ``<dynamics damping="fv" friction="fc">`` (other attributes kept);
  URDF's friction is symmetric Coulomb, so the asymmetric model writes the mean ``(fc_pos +
  fc_neg)/2`` and the sigmoid model its saturated half-range ``phi1/2`` there; the exact terms URDF
  has no field for (Stribeck ``fs``, ``fc_pos``/``fc_neg``, ``phi1..phi3``, torque ``offset``) go
  into an XML comment in the joint, so they are not lost;
* with armature, the joint's ``<transmission>`` gets ``<rotor_inertia>Ia / N²</rotor_inertia>`` in its
  ``<actuator>`` (``N`` its ``<mechanicalReduction>``, kept; 1 when absent): the convention
  :func:`idkit.robots.drives.read_armatures` reads back. A joint without a transmission gets a
  ``SimpleTransmission`` named ``<joint>_idkit_drive``. A merged (unidentifiable) armature is written
  at its a-priori value with a comment saying so.
* with a payload (``estimator=payload``), a ``<link name="payload">`` carrying its inertial and a
  ``fixed`` joint ``payload_joint`` from the link it was identified on (``payload_2`` … when the
  names are taken); the body's own ``<inertial>`` keeps the arm's part. ``robot=urdf`` reading the
  file back merges the payload into the body again, as it merges every welded link.

A mass ``≤ 0`` cannot be written (the centre of mass is undefined) and raises; a pseudo-inertia that
is not positive semidefinite is written with a warning (many simulators reject it): project the
estimate first with :func:`idkit.conic.program.nearest_consistent`.
"""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import torch
from torch import Tensor

from idkit.robots.inertia import centroidal, frame_change, min_pseudo_inertia_eigenvalues, pseudo_inertia
from idkit.robots.joint_terms import comment_pairs, idkit_comment
from idkit.robots.urdf import URDFRobot
from idkit.robots.urdf_frames import link_placement
from idkit.robots.urdf_model import INERTIAL_NAMES, read_urdf_text

#: An element or a comment (``ET.Comment``): what :func:`_append` places.
_Child = TypeVar("_Child", bound="ET.Element[Any]")


def parameter_vector(
    robot: URDFRobot, params: Tensor | Mapping[str, float], writer: str = "urdf export"
) -> np.ndarray:
    """``params`` (``[P]`` or name → value) as a float64 ``[P]`` array; ``writer`` prefixes errors."""
    if isinstance(params, Mapping):
        missing = [name for name in robot.param_names if name not in params]
        if missing:
            raise ValueError(f"{writer}: parameters missing: {', '.join(missing[:5])}")
        return np.array([float(params[name]) for name in robot.param_names])
    values = torch.as_tensor(params, dtype=torch.float64).detach().cpu().numpy()
    if values.shape != (robot.n_params,):
        raise ValueError(f"{writer}: params must be [{robot.n_params}], got {values.shape}")
    return values


def _number(x: float) -> str:
    return repr(float(x))


def identified_urdf(
    robot: URDFRobot, params: Tensor | Mapping[str, float], payload: Mapping[str, Any] | None = None
) -> str:
    """The source URDF of ``robot`` with the identified ``params`` (``[P]`` or name → value) written in.

    Args:
        robot: a ``urdf`` robot.
        params: its parameters; with ``payload``, the payload is merged into its body's.
        payload: a payload fit's ``details["payload"]`` (``link`` and ``standard``: its 10 standard
            parameters in that link's frame): written as its own link (module doc), and taken out
            of the body's parameters, so that reading the file back merges it in again.

    Raises:
        ValueError: wrong parameter shape or names, or a link mass ``≤ 0`` (naming the link).
    """
    values = parameter_vector(robot, params)
    data, _ = read_urdf_text(robot.urdf)
    root = ET.fromstring(data, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    links = {link.get("name", ""): link for link in root.findall("link")}
    joints = {joint.get("name", ""): joint for joint in root.findall("joint")}
    carried = _payload_parameters(robot, payload)
    if carried is not None:  # a copy: ``values`` may share memory with the caller's tensor
        values = values.copy()
        values[10 * carried.body : 10 * carried.body + 10] -= carried.transform @ carried.standard
    for i, body in enumerate(robot.tree.bodies):
        if not values[10 * i] > 0:
            raise ValueError(
                f"urdf export: link {body.link!r} has mass {values[10 * i]:.6g} <= 0; a URDF needs a "
                "positive mass (project with idkit.conic.program.nearest_consistent)"
            )
    inertials = torch.as_tensor(values[: 10 * len(robot.link_names)]).reshape(-1, 10)
    eigenvalues = min_pseudo_inertia_eigenvalues(robot, torch.as_tensor(values))
    scale = pseudo_inertia(inertials).abs().amax((-2, -1))
    bad = [
        f"{b.link} ({float(e):.3g})"
        for b, e, s in zip(robot.tree.bodies, eigenvalues, scale, strict=True)
        if e < -1e-12 * s
    ]  # round-off of an exactly singular (thin rod, point mass) body is fine
    if bad:
        warnings.warn(
            f"urdf export: pseudo-inertia not positive semidefinite for {', '.join(bad)}; simulators may "
            "reject these inertials (project with idkit.conic.program.nearest_consistent)",
            stacklevel=2,
        )
    for i, body in enumerate(robot.tree.bodies):
        _set_inertial(links[body.link], *centroidal(values[10 * i : 10 * i + 10]))
        for name in body.welded:
            for inertial in links[name].findall("inertial"):
                links[name].remove(inertial)
    _write_joint_terms(robot, values, joints)
    _write_armatures(robot, values, root)
    if carried is not None:
        _add_payload(root, links, carried)
    return '<?xml version="1.0" encoding="utf-8"?>\n' + _prolog(data) + ET.tostring(root, encoding="unicode")


@dataclass(frozen=True)
class _Payload:
    """A payload to write: on ``link`` (frame), carried by moving body ``body``; ``standard[10]`` in
    the link's frame, ``transform`` to the body frame (:func:`idkit.robots.inertia.frame_change`)."""

    link: str
    body: int
    standard: np.ndarray
    transform: np.ndarray


def _payload_parameters(robot: URDFRobot, payload: Mapping[str, Any] | None) -> _Payload | None:
    """The payload block's parameters and placement, or ``None`` (no block, or a mass ``<= 0``)."""
    if not payload:
        return None
    if not isinstance(payload, Mapping) or not {"link", "standard"} <= set(payload):
        raise ValueError("urdf export: a payload needs 'link' and 'standard' (estimator=payload's block)")
    standard = np.array([float(payload["standard"][name]) for name in INERTIAL_NAMES])
    if not standard[0] > 0:
        warnings.warn(
            f"urdf export: the payload on {payload['link']!r} has mass {standard[0]:.3g} kg: not written",
            stacklevel=3,
        )
        return None
    placed = link_placement(robot.tree, robot.urdf, str(payload["link"]))
    return _Payload(placed.link, placed.body, standard, frame_change(placed.rotation, placed.translation))


def _add_payload(root: ET.Element, links: dict[str, ET.Element], payload: _Payload) -> None:
    """``<link name="payload">`` with the payload's inertial and a ``fixed`` joint from its link (the
    names get a numeric suffix if the file already uses them)."""
    taken = set(links) | {joint.get("name") for joint in root.findall("joint")}
    name, k = "payload", 1
    while name in taken or f"{name}_joint" in taken:
        k += 1
        name = f"payload_{k}"
    if len(root):
        root[-1].tail = "\n  "
    comment = ET.Comment(f" idkit: payload identified on {payload.link} (estimator=payload) ")
    comment.tail = "\n  "
    link = ET.Element("link", name=name)
    link.text = "\n    "
    link.tail = "\n  "
    _set_inertial(link, *centroidal(payload.standard))
    joint = ET.Element("joint", name=f"{name}_joint", type="fixed")
    joint.text = "\n    "
    joint.tail = "\n"
    for tag, attributes in (
        ("origin", {"xyz": "0 0 0", "rpy": "0 0 0"}),
        ("parent", {"link": payload.link}),
        ("child", {"link": name}),
    ):
        ET.SubElement(joint, tag, attributes).tail = "\n    "
    joint[-1].tail = "\n  "
    root.extend([comment, link, joint])


def _prolog(data: bytes) -> str:
    """What precedes ``<robot`` in the source (comments, not the XML declaration)."""
    text = data.decode("utf-8", errors="replace")
    head = text[: text.find("<robot")]
    if head.lstrip().startswith("<?xml"):
        head = head[head.find("?>") + 2 :]
    return head.lstrip("\r\n")


def _set_inertial(link: ET.Element, mass: float, com: np.ndarray, inertia: np.ndarray) -> None:
    for old in link.findall("inertial"):
        link.remove(old)
    indent = (link.text or "\n    ") if (link.text or "").strip() == "" else "\n    "
    inertial = ET.Element("inertial")
    inertial.text = indent + "  "
    origin = ET.SubElement(inertial, "origin", xyz=" ".join(map(_number, com)), rpy="0 0 0")
    origin.tail = indent + "  "
    ET.SubElement(inertial, "mass", value=_number(mass)).tail = indent + "  "
    (xx, xy, xz), (_, yy, yz), (_, _, zz) = inertia
    names = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    values = map(_number, (xx, xy, xz, yy, yz, zz))
    element = ET.SubElement(inertial, "inertia", dict(zip(names, values, strict=True)))
    element.tail = indent
    inertial.tail = indent
    link.insert(0, inertial)
    if len(link) == 1:
        link.text, inertial.tail = indent, indent[:-2] if indent.endswith("  ") else indent


#: Drive terms URDF has no field for: written into a comment in the joint.
COMMENT_TERMS = ("fs", "fc_pos", "fc_neg", "phi1", "phi2", "phi3", "offset")


def _coulomb(value: dict[str, float]) -> float:
    """URDF's symmetric Coulomb friction for each friction model (module doc)."""
    if "fc" in value:
        return value["fc"]
    if "fc_pos" in value:
        return (value["fc_pos"] + value["fc_neg"]) / 2
    return value["phi1"] / 2


def _write_joint_terms(robot: URDFRobot, values: np.ndarray, joints: dict[str, ET.Element]) -> None:
    """Friction into ``<dynamics>``; the terms without a URDF field into a comment in the joint."""
    index = {name: k for k, name in enumerate(robot.param_names)}
    for j, name in enumerate(robot.joint_names):
        joint = joints[name]
        value = {s: float(values[index[f"{name}.{s}"]]) for s in robot.drives.suffixes}
        if robot.friction:
            dynamics = joint.find("dynamics")
            if dynamics is None:
                dynamics = ET.SubElement(joint, "dynamics")
                dynamics.tail = "\n  "
            dynamics.set("damping", _number(value["fv"]))
            dynamics.set("friction", _number(_coulomb(value)))
        keys = [key for key in COMMENT_TERMS if f"{name}.{key}" in index]
        extra = {key: _number(values[index[f"{name}.{key}"]]) for key in keys}
        if robot.stribeck_scales is not None:
            extra["stribeck_velocity"] = _number(robot.stribeck_scales[j])
        if robot.coulomb_scales is not None:  # tanh(q̇ / v_c), not sign(q̇): no URDF field
            extra["coulomb_velocity"] = _number(robot.coulomb_scales[j])
        if extra:
            extra = {**_take_own_comments(joint), **extra}  # the source's record, updated
            comment = ET.Comment(f" idkit: {' '.join(f'{k}={v}' for k, v in extra.items())} (no URDF field) ")
            if len(joint):
                comment.tail, joint[-1].tail = joint[-1].tail, "\n    "
            joint.append(comment)


def _write_armatures(robot: URDFRobot, values: np.ndarray, root: ET.Element) -> None:
    """``<rotor_inertia>`` of each joint's transmission (module doc; ``read_armatures`` reads it)."""
    index = {name: k for k, name in enumerate(robot.param_names)}
    single = {}
    for transmission in root.findall("transmission"):
        names = [joint.get("name") for joint in transmission.findall("joint")]
        if len(names) == 1 and len(transmission.findall("actuator")) <= 1:
            single[names[0]] = transmission
    for joint in robot.joint_names:
        key = f"{joint}.armature"
        if key not in index:
            continue
        transmission = single.get(joint) or _new_transmission(root, joint)
        actuator = transmission.find("actuator")
        if actuator is None:
            actuator = _append(transmission, ET.Element("actuator", name=f"{joint}_motor"))
        reduction = actuator.find("mechanicalReduction")
        if reduction is None:
            reduction = transmission.find("mechanicalReduction")
        ratio = 1.0 if reduction is None else float((reduction.text or "1").strip())
        rotor = actuator.find("rotor_inertia")
        if rotor is None:
            rotor = transmission.find("rotor_inertia")
        if rotor is None:
            rotor = _append(actuator, ET.Element("rotor_inertia"))
        rotor.text = _number(values[index[key]] / ratio**2)
        if key in robot.a_priori_params:
            note = f" idkit: the armature of {joint} merges with the link inertia (not identifiable); "
            _append(transmission, ET.Comment(note + "rotor_inertia is its a-priori value "))


def _append(parent: ET.Element, child: _Child) -> _Child:
    """Append ``child`` indented like its siblings (a pretty-printed source stays pretty)."""
    if len(parent):
        child.tail, parent[-1].tail = parent[-1].tail, parent.text
    else:
        child.tail, parent.text = parent.tail, (parent.tail or "") + "  "
    parent.append(child)
    return child


def _new_transmission(root: ET.Element, joint: str) -> ET.Element:
    """A ``SimpleTransmission`` of ``joint`` with one actuator of reduction 1 (its rotor inertia 0)."""
    transmission = ET.Element("transmission", name=f"{joint}_idkit_drive")
    ET.SubElement(transmission, "type").text = "transmission_interface/SimpleTransmission"
    ET.SubElement(transmission, "joint", name=joint)
    actuator = ET.SubElement(transmission, "actuator", name=f"{joint}_motor")
    ET.SubElement(actuator, "mechanicalReduction").text = "1"
    ET.SubElement(actuator, "rotor_inertia").text = "0"
    ET.indent(transmission, space="  ", level=1)
    return _append(root, transmission)


def _take_own_comments(joint: ET.Element) -> dict[str, str]:
    """Remove the joint's ``idkit:`` comments (an identified.urdf identified again) and return their
    ``key=value`` pairs, so that terms this fit does not hold are kept."""
    pairs: dict[str, str] = {}
    for child in list(joint):
        text = idkit_comment(child)
        if text is not None:
            pairs.update(comment_pairs(text))
            siblings = list(joint)
            if child is siblings[-1] and len(siblings) > 1:
                siblings[-2].tail = child.tail  # keep the closing tag's indentation
            joint.remove(child)
    return pairs


def write_identified_urdf(
    robot: URDFRobot,
    params: Tensor | Mapping[str, float],
    path: str | Path = "identified.urdf",
    payload: Mapping[str, Any] | None = None,
) -> Path:
    """Write :func:`identified_urdf` to ``path`` (UTF-8) and return the path."""
    path = Path(path)
    path.write_text(identified_urdf(robot, params, payload), encoding="utf-8")
    return path
