"""The MuJoCo model a rollout identification simulates: an MJCF file, or a URDF through MuJoCo's import.

Unlike ``robot=mjcf`` (:mod:`idkit.robots.mjcf`, the inverse-dynamics view of the same file) nothing is
refused here that MuJoCo simulates: joint stiffness, friction loss, contacts, equality constraints,
actuator dynamics are all part of the rollout. The model's own ``<option timestep>`` and integrator
are the simulator's. A model without actuators (what MuJoCo's URDF import gives) gets one ``<motor>``
per hinge or slide joint, named after the joint, so that torque commands (``<joint>.ctrl``) drive it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from idkit.robots.mjcf import import_mujoco
from idkit.robots.model_xml import model_text
from idkit.robots.urdf_model import model_file

#: The setting that names the model, for messages.
OPTION = "rollout.model"
#: MuJoCo's ``mjtJoint`` values of the joints a log can hold (one position and one velocity each).
HINGE, SLIDE = 3, 2


@dataclass(frozen=True)
class SimModel:
    """A MuJoCo model held as its spec (to write ``identified.xml``) and compiled once.

    Attributes:
        spec: the ``MjSpec`` the model was compiled from (never modified: copies are).
        model: the compiled ``MjModel``.
        label: where it came from, for messages.
        folder: the directory relative asset paths resolve in (``None`` for text).
    """

    spec: Any
    model: Any
    label: str
    folder: Path | None

    @property
    def timestep(self) -> float:
        return float(self.model.opt.timestep)

    def joint_names(self) -> tuple[str, ...]:
        """The hinge and slide joints, in the model's order."""
        return tuple(
            self.model.joint(j).name
            for j in range(self.model.njnt)
            if self.model.jnt_type[j] in (HINGE, SLIDE)
        )

    def actuator_names(self) -> tuple[str, ...]:
        return tuple(self.model.actuator(a).name for a in range(self.model.nu))

    def joint_id(self, name: str) -> int:
        mujoco = import_mujoco()
        index = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if index < 0 or self.model.jnt_type[index] not in (HINGE, SLIDE):
            raise ValueError(
                f"{self.label}: no hinge or slide joint {name!r}; its joints: {', '.join(self.joint_names())}"
            )
        return int(index)

    def actuated_joint(self, actuator: int) -> int | None:
        """The joint actuator ``actuator`` drives directly, or ``None`` (a tendon, site, body)."""
        mujoco = import_mujoco()
        if self.model.actuator_trntype[actuator] != mujoco.mjtTrn.mjTRN_JOINT:
            return None
        return int(self.model.actuator_trnid[actuator, 0])

    def copy_spec(self) -> Any:
        """A copy of the spec, with asset folders absolute so that the written XML loads anywhere."""
        spec = self.spec.copy()
        if self.folder is not None:
            for attribute in ("meshdir", "texturedir"):
                value = getattr(spec, attribute, None)
                if value is not None and not Path(value).is_absolute():
                    setattr(spec, attribute, str(self.folder / value))
        return spec

    def state_size(self) -> int:
        mujoco = import_mujoco()
        return int(mujoco.mj_stateSize(self.model, mujoco.mjtState.mjSTATE_FULLPHYSICS))


def load_model(source: str | os.PathLike) -> SimModel:
    """The model of an MJCF file or text (``<mujoco>``), or of a URDF file or text (``<robot>``).

    Raises:
        FileNotFoundError: no such file.
        ValueError: not UTF-8 XML, a DTD (:mod:`idkit.robots.model_xml`), neither MJCF nor URDF,
            MuJoCo refuses it (its message, on one line), or it has no hinge or slide joint.
    """
    mujoco = import_mujoco()
    text, path, label = _read(source)
    if "<robot" in text[:2000] and "<mujoco" not in text[:200]:
        from idkit.robots.mjcf_export import urdf_to_mjcf

        text, path = urdf_to_mjcf(path if path is not None else text), None
    try:
        spec = mujoco.MjSpec.from_file(str(path)) if path is not None else mujoco.MjSpec.from_string(text)
        if not spec.actuators:
            _add_motors(spec, mujoco)
        model = spec.compile()
    except ValueError as error:
        raise ValueError(f"{label}: MuJoCo cannot load it: {' '.join(str(error).split())}") from None
    loaded = SimModel(spec, model, label, path.resolve().parent if path is not None else None)
    if not loaded.joint_names():
        raise ValueError(f"{label}: no hinge or slide joint to identify")
    return loaded


def _read(source: str | os.PathLike) -> tuple[str, Path | None, str]:
    """``(text, path or None, label)``, under every model loader's XML policy
    (:mod:`idkit.robots.model_xml`)."""
    if isinstance(source, str) and source.lstrip().startswith("<"):
        return model_text(source.encode("utf-8"), "<model text>", OPTION), None, "<model text>"
    path = Path(source)
    suffix = path.suffix.lower() if path.suffix.lower() in (".xml", ".urdf") else ".xml"
    path = model_file(source, OPTION, suffix, formats="MJCF or URDF")
    return model_text(path.read_bytes(), str(path), OPTION), path, str(path)


def _add_motors(spec: Any, mujoco: Any) -> None:
    """One ``<motor>`` (gear 1, unlimited) per hinge or slide joint, named after it."""
    for joint in spec.joints:
        if joint.type in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE):
            spec.add_actuator(name=joint.name, target=joint.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)


def logged_state(
    sim: SimModel, joints: tuple[str, ...], q: np.ndarray, qd: np.ndarray, time: float = 0.0
) -> np.ndarray:
    """The ``mjSTATE_FULLPHYSICS`` vector with ``joints`` at ``q``, ``qd`` (``[n]`` each), every other
    state at the model's initial one (``qpos0``, at rest, no activation)."""
    mujoco = import_mujoco()
    data = mujoco.MjData(sim.model)
    data.time = time
    for j, name in enumerate(joints):
        index = sim.joint_id(name)
        data.qpos[sim.model.jnt_qposadr[index]] = q[j]
        data.qvel[sim.model.jnt_dofadr[index]] = qd[j]
    state = np.empty(sim.state_size())
    mujoco.mj_getState(sim.model, data, state, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    return state
