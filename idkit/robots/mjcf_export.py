"""Write the identified model as MJCF (``identified.xml``), which MuJoCo loads.

The source is the robot's own MJCF (an ``mjcf`` robot), or MuJoCo's conversion of the URDF (a
``urdf`` robot, :func:`urdf_to_mjcf`). It is copied element for element (geoms, actuators, sensors,
defaults, comments and number formatting stay as written; ``<include>`` files are inlined and asset
directories made absolute so that the file loads from any folder); only these change:

* each moving body gets a new ``<inertial pos quat mass diaginertia>``: its standard parameters
  ``(m, h, I_O)`` as the centre of mass ``c = h/m`` and the principal moments and axes of the
  inertia about it, in the MuJoCo body frame (idkit's body frame is that frame moved to the joint's
  ``pos``);
* bodies welded to a moving body (no joint) get a zero ``<inertial>``: the tree merged them into
  the moving body, and the identification cannot separate them again;
* each joint's ``damping`` = ``fv`` and ``frictionloss`` = ``fc``: 0 without ``friction=true`` (the
  fit assumed none; the identified inertials absorbed what friction there was, and MuJoCo would
  otherwise add the source's values on top); ``armature`` when the robot has ``<joint>.armature``
  parameters (rotor inertia; the hook for drive models);
* terms MJCF has no field for (Stribeck ``fs`` and its velocity scale, the torque ``offset`` of a
  biased sensor) go into MuJoCo's user data, ``<custom><numeric name="idkit:<parameter>" data>``
  (``model.numeric("idkit:lwr_0_joint.offset").data``): ``mj_inverse`` does not add them, so a
  re-scoring adds the offset to its torques;
* compiler options that would change the written inertials at load time (``inertiafromgeom="true"``,
  ``boundmass``, ``boundinertia``, ``balanceinertia``, ``settotalmass``) are dropped.

Numbers are written in full precision (``repr``); MuJoCo's own writer keeps 6 significant digits, so
a converted URDF's placements are MuJoCo's 6-digit ones. MuJoCo refuses a body whose inertia is
not physical (mass ≤ 0, a negative principal moment, or one larger than the other two together):
:func:`identified_mjcf` says so in one line naming the bodies (``estimator=pcls`` keeps every body
physical); the written text is loaded by MuJoCo before it is returned.
"""

from __future__ import annotations

import os
import tempfile
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from torch import Tensor

from idkit.robots.inertia import centroidal
from idkit.robots.mjcf import compile_mjcf, import_mujoco
from idkit.robots.urdf import URDFRobot
from idkit.robots.urdf_export import parameter_vector
from idkit.robots.urdf_model import read_urdf_text

#: Prefix of the ``<custom><numeric>`` names holding terms MJCF has no field for.
NUMERIC_PREFIX = "idkit:"
#: Compiler attributes that rescale or recompute inertials when MuJoCo loads the file.
INERTIAL_OPTIONS = ("boundmass", "boundinertia", "balanceinertia", "settotalmass")


def _number(x: float) -> str:
    return repr(float(x))


def _numbers(values: np.ndarray) -> str:
    return " ".join(_number(v) for v in values)


def urdf_to_mjcf(urdf: str | os.PathLike) -> str:
    """MuJoCo's own conversion of a URDF (text, path or shipped asset name) to MJCF text.

    Three things MuJoCo's importer would refuse or do differently are settled first, as idkit reads
    the URDF: only the first ``<origin>`` of an element is kept (urdfdom and pinocchio read only
    that one; MuJoCo refuses a repeat); visual geometry is discarded; a collision mesh whose file is
    not found (``package://`` URIs, a missing file) is left out with a warning naming it, and the
    others get absolute paths. Placements are written with MuJoCo's 6 significant digits.

    Raises:
        PluginLoadError: ``mujoco`` is not installed.
        ValueError: MuJoCo refuses the URDF.
    """
    mujoco = import_mujoco()
    data, label = read_urdf_text(urdf)
    root = ET.fromstring(data)
    folder = Path(label).resolve().parent if label != "<URDF text>" else Path.cwd()
    missing: list[str] = []
    for element in root.iter():
        for extra in element.findall("origin")[1:]:
            element.remove(extra)
    for link in root.findall("link"):
        for visual in link.findall("visual"):
            link.remove(visual)
        for collision in link.findall("collision"):
            mesh = collision.find("geometry/mesh")
            if mesh is None:
                continue
            filename = mesh.get("filename", "")
            path = Path(filename) if Path(filename).is_absolute() else folder / filename
            if "://" in filename or not path.is_file():
                missing.append(filename)
                link.remove(collision)
            else:
                mesh.set("filename", str(path))
    if missing:
        warnings.warn(
            f"mjcf: {len(missing)} collision mesh(es) of {label} not found, left out of the MJCF: "
            f"{', '.join(sorted(set(missing))[:3])}{' …' if len(set(missing)) > 3 else ''}",
            stacklevel=2,
        )
    extension = root.find("mujoco")
    if extension is None:
        extension = ET.SubElement(root, "mujoco")
    compiler = extension.find("compiler")
    if compiler is None:
        compiler = ET.SubElement(extension, "compiler")
    compiler.set("discardvisual", "true")
    compiler.set("strippath", "false")
    try:
        model = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
    except ValueError as error:
        raise ValueError(f"mjcf: MuJoCo cannot convert {label}: {' '.join(str(error).split())}") from None
    with tempfile.TemporaryDirectory() as scratch:  # mj_saveLastXML writes only to a file
        path = Path(scratch) / "converted.xml"
        mujoco.mj_saveLastXML(str(path), model)
        return path.read_text(encoding="utf-8")


def physical_problems(robot: URDFRobot, values: np.ndarray) -> list[str]:
    """``"<body> (why)"`` for each moving body MuJoCo would refuse: mass ≤ 0, or principal moments
    ``A, B, C`` about the centre of mass with one negative or ``A + B < C`` (triangle inequality)."""
    problems = []
    for i, body in enumerate(robot.tree.bodies):
        block = values[10 * i : 10 * i + 10]
        if not block[0] > 0:
            problems.append(f"{body.link} (mass {block[0]:.3g})")
            continue
        moments = np.linalg.eigvalsh(centroidal(block)[2])
        slack = 1e-12 * max(abs(moments).max(), 1e-300)
        if moments[0] < -slack or moments[2] > moments[0] + moments[1] + slack:
            shown = ", ".join(f"{m:.3g}" for m in moments)
            problems.append(f"{body.link} (principal moments {shown})")
    return problems


def _inline_includes(root: ET.Element, folder: Path) -> None:
    """Replace every ``<include file>`` by the children of the included file's root (recursively)."""
    for parent in list(root.iter()):
        for index, child in reversed(list(enumerate(parent))):
            if child.tag != "include":
                continue
            included = ET.parse(folder / child.get("file", "")).getroot()
            _inline_includes(included, folder)
            parent.remove(child)
            for offset, element in enumerate(included):
                parent.insert(index + offset, element)


def _absolute_asset_dirs(root: ET.Element, folder: Path) -> None:
    """Mesh and texture directories as absolute paths, so the file loads from another folder."""
    compilers = root.findall("compiler") or [ET.SubElement(root, "compiler")]
    dirs: dict[str, str] = {}
    for compiler in compilers:
        for key in ("assetdir", "meshdir", "texturedir"):
            if key in compiler.attrib:
                dirs[key] = compiler.attrib.pop(key)
    for key in ("meshdir", "texturedir"):
        compilers[0].set(key, str((folder / dirs.get(key, dirs.get("assetdir", ""))).resolve()))


def _source_root(robot: URDFRobot) -> ET.Element:
    """The MJCF element tree to write into: the robot's MJCF, or MuJoCo's conversion of its URDF."""
    from idkit.robots.mjcf import MJCFRobot

    if isinstance(robot, MJCFRobot):
        model = robot.mujoco_model
        root = ET.fromstring(
            model.text.encode("utf-8"), parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
        )
        if model.source is not None:
            folder = model.source.resolve().parent
            _inline_includes(root, folder)
            _absolute_asset_dirs(root, folder)
        return root
    return ET.fromstring(urdf_to_mjcf(robot.urdf).encode("utf-8"))


def _anchors(robot: URDFRobot) -> np.ndarray:
    """``[nb, 3]`` joint positions in the MuJoCo body frames (0 for a URDF: joint frame = link frame)."""
    from idkit.robots.mjcf import MJCFRobot

    if isinstance(robot, MJCFRobot):
        return robot.mujoco_model.anchors
    return np.zeros((len(robot.tree.bodies), 3))


def _set_inertial(body: ET.Element, mass: float, com: np.ndarray, inertia: np.ndarray) -> None:
    """Replace the body's ``<inertial>`` by ``pos mass diaginertia quat``: the principal moments and
    axes computed here in float64 (MuJoCo diagonalises a ``fullinertia`` itself, 3.2–3.3 only to ~1e-6
    relative)."""
    for old in body.findall("inertial"):
        if old is body[-1] and len(body) > 1:
            body[-2].tail = old.tail  # keep the closing tag's indentation
        body.remove(old)
    moments, axes = np.linalg.eigh(inertia)
    if np.linalg.det(axes) < 0:
        axes[:, 0] = -axes[:, 0]
    quaternion = np.empty(4)
    import_mujoco().mju_mat2Quat(quaternion, axes.flatten())
    inertial = ET.Element(
        "inertial",
        pos=_numbers(com),
        quat=_numbers(quaternion),
        mass=_number(mass),
        diaginertia=_numbers(np.maximum(moments, 0.0)),
    )
    inertial.tail = body.text if (body.text or "").strip() == "" and body.text else "\n"
    body.insert(0, inertial)


def _welded_bodies(body: ET.Element) -> list[ET.Element]:
    """Descendant ``<body>`` elements with no joint, reached without passing a jointed body."""
    found = []
    for child in body:
        if child.tag == "frame":
            found += _welded_bodies(child)
        elif child.tag == "body" and child.find("joint") is None and child.find("freejoint") is None:
            found.append(child)
            found += _welded_bodies(child)
    return found


def _set_numerics(root: ET.Element, values: Mapping[str, float]) -> None:
    """``<custom><numeric name="idkit:<name>" data=value>`` for terms MJCF has no field for (replaced
    when the source already has them, e.g. an identified.xml identified again)."""
    if not values:
        return
    custom = root.find("custom")
    if custom is None:
        custom = ET.SubElement(root, "custom")
    for name, value in values.items():
        for old in custom.findall(f"numeric[@name='{NUMERIC_PREFIX}{name}']"):
            custom.remove(old)
        ET.SubElement(custom, "numeric", name=f"{NUMERIC_PREFIX}{name}", data=_number(value))
    ET.indent(custom, level=1)


def identified_mjcf(robot: URDFRobot, params: Tensor | Mapping[str, float]) -> str:
    """The MJCF of ``robot`` with the identified ``params`` (``[P]`` or name → value) written in.

    Raises:
        ValueError: wrong parameter shape or names; a body MuJoCo would refuse (one line naming
            them); a body or joint of the tree not found in the source; MuJoCo refuses the result.
        PluginLoadError: ``mujoco`` is not installed.
    """
    values = parameter_vector(robot, params, writer="mjcf export")
    bad = physical_problems(robot, values)
    if bad:
        raise ValueError(
            f"mjcf export: MuJoCo refuses non-physical inertials: {'; '.join(bad)} "
            "(estimator=pcls identifies physically consistent ones)"
        )
    root = _source_root(robot)
    bodies = {b.get("name"): b for b in root.iter("body")}
    joints = {j.get("name"): j for j in root.iter("joint")}
    for compiler in root.iter("compiler"):
        for key in INERTIAL_OPTIONS:
            compiler.attrib.pop(key, None)
        if compiler.get("inertiafromgeom") == "true":
            compiler.set("inertiafromgeom", "auto")
    index = {name: k for k, name in enumerate(robot.param_names)}
    for i, (body, anchor) in enumerate(zip(robot.tree.bodies, _anchors(robot), strict=True)):
        element, joint = bodies.get(body.link), joints.get(body.joint)
        if element is None or joint is None:
            raise ValueError(
                f"mjcf export: body {body.link!r} / joint {body.joint!r} not found in the MJCF source "
                "(made by <replicate> or <attach>?)"
            )
        mass, com, inertia = centroidal(values[10 * i : 10 * i + 10])
        _set_inertial(element, mass, com + anchor, inertia)
        for welded in _welded_bodies(element):
            _set_inertial(welded, 0.0, np.zeros(3), np.zeros((3, 3)))
        terms = {"damping": "fv", "frictionloss": "fc", "armature": "armature"}
        for attribute, key in terms.items():
            if f"{body.joint}.{key}" in index:
                joint.set(attribute, _number(values[index[f"{body.joint}.{key}"]]))
            elif key in ("fv", "fc"):  # the fit assumed none: MuJoCo must not add the source's on top
                joint.set(attribute, "0")
    _set_numerics(root, _recorded_terms(robot, values))
    text = ET.tostring(root, encoding="unicode") + "\n"
    compile_mjcf(text, None, "the identified MJCF")  # MuJoCo loads it, or says why not
    return text


def _recorded_terms(robot: URDFRobot, values: np.ndarray) -> dict[str, float]:
    """The values MJCF has no attribute for: Stribeck terms, offsets, and the velocity scales of the
    Stribeck and smoothed Coulomb terms (``frictionloss`` is MuJoCo's own law; the fit's is recorded)."""
    extra = {name: values[k] for k, name in enumerate(robot.param_names) if name.endswith((".fs", ".offset"))}
    for key, attribute in (("stribeck_velocity", "stribeck_scales"), ("coulomb_velocity", "coulomb_scales")):
        scales = getattr(robot, attribute, None)
        if scales is not None:
            extra.update(
                (f"{joint}.{key}", float(v)) for joint, v in zip(robot.joint_names, scales, strict=True)
            )
    return extra


def write_identified_mjcf(
    robot: URDFRobot, params: Tensor | Mapping[str, float], path: str | Path = "identified.xml"
) -> Path:
    """Write :func:`identified_mjcf` to ``path`` (UTF-8) and return the path."""
    path = Path(path)
    path.write_text(identified_mjcf(robot, params), encoding="utf-8")
    return path
