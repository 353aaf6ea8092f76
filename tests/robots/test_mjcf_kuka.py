"""Issue 17's MJCF judgement on the real KUKA LWR4+ recordings (skips when they are absent): the KUKA
as MuJoCo converts its URDF, ``robot=mjcf`` with pcls and the CAD prior, trained on measurements_1,
predicts the held-out measurements_3 within 5.5 %, and so does the written identified.xml under
``mujoco.mj_inverse``."""

from __future__ import annotations

import numpy as np
import pytest

from idkit.reports import single as single_report
from idkit.robots.mjcf_export import urdf_to_mjcf
from idkit.studies import single

mujoco = pytest.importorskip("mujoco")


def mj_inverse_error(path: str, recording) -> tuple[float, float]:
    """‖E‖/‖T‖ of ``mj_inverse`` on the file's model over a recording, without and with the torque
    offsets the file carries as ``<numeric name="idkit:<joint>.offset">`` (a sensor bias, which
    ``mj_inverse`` cannot add; 0 when absent). Contacts are off: the converted arm's collision
    geoms overlap."""
    model = mujoco.MjModel.from_xml_path(path)
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    data = mujoco.MjData(model)
    predicted = []
    for q, qd, qdd in zip(
        recording["positions"], recording["velocities"], recording["accelerations"], strict=True
    ):
        data.qpos[:], data.qvel[:], data.qacc[:] = q, qd, qdd
        mujoco.mj_inverse(model, data)
        predicted.append(data.qfrc_inverse.copy())
    predicted = np.stack(predicted)
    joints = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(model.njnt)]
    names = {mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_NUMERIC, k) for k in range(model.nnumeric)}
    offsets = np.array(
        [model.numeric(f"idkit:{j}.offset").data[0] if f"idkit:{j}.offset" in names else 0.0 for j in joints]
    )
    measured = recording["torques"]
    return tuple(  # type: ignore[return-value]
        float(np.linalg.norm(p - measured) / np.linalg.norm(measured))
        for p in (predicted, predicted + offsets)
    )


@pytest.mark.kuka
def test_kuka_as_mjcf_pcls_prior_predicts_measurements_3(kuka_dir, tmp_path):
    with pytest.warns(UserWarning, match="collision mesh"):
        (tmp_path / "kuka.xml").write_text(urdf_to_mjcf(kuka_dir / "kuka_lwr4.urdf"))
    robot = {"_name_": "mjcf", "mjcf": str(tmp_path / "kuka.xml"), "friction": True, "offset": True}
    result = single.run(
        robot=robot,
        estimator={"_name_": "pcls", "prior_weight": 300.0},
        cost=None,
        data=str(kuka_dir / "measurements_1.npz"),
        validate=[str(kuka_dir / "measurements_3.npz")],
    )
    held_out = result.validation[0].scores.rel_all
    written = single_report.write(result, tmp_path / "run", plots=False)
    alone, with_offsets = mj_inverse_error(
        written["identified_mjcf"], np.load(kuka_dir / "measurements_3.npz")
    )
    assert held_out <= 0.055
    assert with_offsets <= 0.055
    assert abs(with_offsets - held_out) < 0.002  # the same model, up to MuJoCo's low-speed friction
    assert alone > with_offsets  # the offsets are part of the identified model
