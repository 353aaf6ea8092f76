"""The flow torque fit → run folder → ``rollout.model=<run folder>`` with the logged efforts as commands."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest

from idkit.studies.rollout import run

#: Two hinges under motors; the truth's armature and damping are what the "torque fit" lacks.
ARM = """<mujoco><option timestep="0.002"/><worldbody>
<body><joint name="a" axis="0 1 0" armature="{a0}" damping="{d0}" frictionloss="0.05"/>
<geom type="capsule" fromto="0 0 0 0 0 -0.4" size="0.03" mass="1.5"/>
<body pos="0 0 -0.4"><joint name="b" axis="0 1 0" armature="{a1}" damping="{d1}" frictionloss="0.02"/>
<geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.02" mass="0.7"/></body></body></worldbody>
<actuator><motor name="a" joint="a"/><motor name="b" joint="b"/></actuator></mujoco>"""
TRUTH = {"a.armature": 0.04, "b.armature": 0.015, "a.damping": 0.3, "b.damping": 0.08}
SCALE, OFFSET = np.array([2.0, 4.0]), np.array([0.2, -0.05])


def _log(seed: int, seconds: float = 4.0) -> np.ndarray:
    """``[N, 7]``: t, q, qd and the logged efforts (torque + offset) / scale, at 200 Hz."""
    model = mujoco.MjModel.from_xml_string(ARM.format(a0=0.04, a1=0.015, d0=0.3, d1=0.08))
    data = mujoco.MjData(model)
    rng = np.random.default_rng(seed)
    freq, phase = rng.uniform(0.3, 1.5, (3, 2)), rng.uniform(0, 2 * np.pi, (3, 2))
    rows, k = [], 0
    for i in range(int(seconds / 0.005)):
        t = i * 0.005
        torque = np.array([3.0, 0.8]) * np.sin(2 * np.pi * freq * t + phase).sum(axis=0) / 3
        torque += [
            0.0,
            0.7 * 9.81 * 0.15 * np.sin(data.qpos[0] + data.qpos[1]),
        ]  # a little help against gravity
        rows.append([t, *data.qpos, *data.qvel, *((torque + OFFSET) / SCALE)])
        data.ctrl[:] = torque
        while k * model.opt.timestep < t + 0.005 - 1e-12:
            mujoco.mj_step(model, data)
            k += 1
    return np.array(rows)


def _csv(path, rows):
    header = "t,a.q,b.q,a.qd,b.qd,a.tau,b.tau"
    np.savetxt(path, rows, delimiter=",", header=header, comments="", fmt="%.17g")
    return path


@pytest.mark.slow
def test_a_torque_runs_folder_refines_the_missing_armature_and_damping(tmp_path):
    folder = tmp_path / "torque_run"
    folder.mkdir()
    (folder / "identified.xml").write_text(ARM.format(a0=0, a1=0, d0=0, d1=0))
    result = {
        "task": "single",
        "config": {"robot": {"_name_": "mjcf", "effort_scale": SCALE.tolist()}},
        "payload": {
            "joint_names": ["a", "b"],
            "estimate": {"params": {"a.offset": OFFSET[0], "b.offset": OFFSET[1]}},
        },
    }
    (folder / "result.json").write_text(json.dumps(result))
    train = _csv(tmp_path / "train.csv", _log(0))
    with pytest.warns(UserWarning, match="bounds from the model and log"):
        found = run(str(folder), str(train), params=["armature", "damping"], seed=0)
    for name, truth in TRUTH.items():
        assert found.estimate.params[name] == pytest.approx(truth, rel=0.02), name
    assert found.mjcf is not None
    written = mujoco.MjModel.from_xml_string(found.mjcf)
    assert written.dof_armature[0] == pytest.approx(TRUTH["a.armature"], rel=0.02)
