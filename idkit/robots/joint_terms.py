"""The joint terms a model file records: friction and the values idkit wrote beside it.

``robot=urdf`` (and ``robot=mjcf``) start every friction and offset parameter at 0, so a model
written by an identification (``identified.urdf``, ``identified.xml``) is read back without
them. Estimators that take the arm as known — the payload fit subtracts the arm's torques — need
them as written:

* URDF: ``<dynamics damping="fv" friction="fc">`` of each moving joint, and the ``key=value``
  pairs of the joint's ``<!-- idkit: ... -->`` comment (``fs``, ``offset``, ``stribeck_velocity``
  and whatever else :mod:`idkit.robots.urdf_export` records there);
* MJCF: each joint's ``frictionloss`` (``fc``) and ``damping`` (``fv``), and the
  ``<custom><numeric name="idkit:<parameter>">`` values of :mod:`idkit.robots.mjcf_export`.

Values are keyed by parameter name, ``<joint>.<key>`` (``lwr_0_joint.fc``), the names of
:class:`~idkit.robots.urdf.URDFRobot`'s parameters.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from typing import Any

from idkit.robots.urdf_model import read_urdf_text

#: The marker of idkit's comments (URDF) and numerics (MJCF).
MARK = "idkit:"
_PAIR = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)=([-+0-9.eE]+|[-+]?inf|nan)")


def recorded_joint_terms(robot: Any) -> dict[str, float]:
    """``{parameter name: value}`` of the joint terms ``robot``'s model file records (module doc).

    Args:
        robot: a ``urdf`` or ``mjcf`` robot (``source_format``, ``joint_names``, its file).
    """
    if getattr(robot, "source_format", "urdf") == "mjcf":
        return _mjcf_terms(robot)
    return _urdf_terms(robot.urdf, robot.joint_names)


def _urdf_terms(urdf: str, joint_names: tuple[str, ...]) -> dict[str, float]:
    data, label = read_urdf_text(urdf)

    def number(text: str | None, what: str) -> float:
        """``text`` as a float, or a one-line ``ValueError`` naming the file, joint and attribute."""
        try:
            return float(text or "")
        except ValueError:
            raise ValueError(f"urdf ({label}): {what} is {text!r}, not a number") from None

    root = ET.fromstring(data, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    joints = {joint.get("name", ""): joint for joint in root.findall("joint")}
    out: dict[str, float] = {}
    for name in joint_names:
        joint = joints[name]
        dynamics = joint.find("dynamics")
        if dynamics is not None:
            for attribute, key in (("friction", "fc"), ("damping", "fv")):
                if dynamics.get(attribute) is not None:
                    what = f"joint {name!r}: <dynamics {attribute}>"
                    out[f"{name}.{key}"] = number(dynamics.get(attribute), what)
        for child in joint:
            text = idkit_comment(child)
            if text is not None:
                out.update(
                    {
                        f"{name}.{key}": number(value, f"joint {name!r}: {key} of its {MARK} comment")
                        for key, value in comment_pairs(text).items()
                    }
                )
    return out


def idkit_comment(element: ET.Element[Any]) -> str | None:
    """The text of ``element`` if it is an ``idkit:`` comment (XML parsed with its comments kept)."""
    text = element.text or ""
    return text if element.tag is ET.Comment and text.strip().startswith(MARK) else None


def comment_pairs(text: str) -> dict[str, str]:
    """The ``key=number`` pairs of an ``idkit:`` comment, values as written."""
    return dict(_PAIR.findall(text))


def _mjcf_terms(robot: Any) -> dict[str, float]:
    model = robot.mujoco_model
    out: dict[str, float] = {}
    for name, fc, fv in zip(robot.joint_names, model.frictionloss, model.damping, strict=True):
        out[f"{name}.fc"], out[f"{name}.fv"] = float(fc), float(fv)
    for numeric in ET.fromstring(model.text.encode("utf-8")).iter("numeric"):
        label = numeric.get("name") or ""
        if label.startswith(MARK) and numeric.get("data"):
            out[label[len(MARK) :]] = float(numeric.get("data", "").split()[0])
    return out
