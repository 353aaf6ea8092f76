"""A torque fit's run folder as the rollout's start (idkit.sim.from_run) and the bounds of its
zero-start passive terms (idkit.sim.passive_bounds)."""

from __future__ import annotations

import json
import warnings
from functools import partial

import mujoco
import numpy as np
import pytest

from idkit.data.commands import RobotLog
from idkit.notes import Note
from idkit.sim.from_run import check_motor_driven, is_run_folder, read_torque_run
from idkit.sim.model import load_model
from idkit.sim.passive_bounds import caps, derived_bounds, rms_acceleration
from idkit.studies.build import build

#: The study's robot builder, as the rollout study passes it.
ROBOT = partial(build, "robot")

#: A pendulum (a 2 kg point-like ball 0.5 m below a hinge) and a second hinge below it, no actuators.
ARM = """<mujoco><worldbody><body><joint name="a" axis="0 1 0" damping="0.4" frictionloss="0.2"/>
<geom type="sphere" size="0.01" pos="0 0 -0.5" mass="2"/>
<body pos="0 0 -0.5"><joint name="b" axis="0 1 0"/><geom type="sphere" size="0.01" pos="0 0 -0.25" mass="1"/>
</body></body></worldbody></mujoco>"""
SERVO = ARM.replace(
    "</mujoco>", '<actuator><position joint="b" kp="10"/><motor joint="a"/></actuator></mujoco>'
)


def _run_folder(path, mjcf=ARM, scale=None, task="single"):
    path.mkdir()
    result = {
        "task": task,
        "config": {"robot": {"_name_": "urdf", "effort_scale": scale}, "recording": {"topic": None}},
        "payload": {"joint_names": ["a", "b"], "estimate": {"params": {"a.offset": 0.25, "a.fc": 0.2}}},
    }
    (path / "result.json").write_text(json.dumps(result))
    if mjcf is not None:
        (path / "identified.xml").write_text(mjcf)
    return path


def _log(n=400, torque=(1.0, 0.5)):
    t = np.arange(n) * 0.005
    q = np.column_stack([0.5 * np.sin(t), 0.3 * np.sin(2 * t)])
    qd = np.column_stack([0.5 * np.cos(t), 0.6 * np.cos(2 * t)])
    tau = np.column_stack([torque[0] * np.sin(3 * t), torque[1] * np.cos(t)])
    return RobotLog(t, q, qd, t, tau, ("a", "b"), ("a.ctrl", "b.ctrl"), "<log>")


def test_a_run_folder_gives_its_model_scale_and_offsets(tmp_path):
    folder = _run_folder(tmp_path / "run", scale=[2.0, 3.0])
    assert is_run_folder(folder) and not is_run_folder(ARM)
    run = read_torque_run(folder, ROBOT)
    assert run.joint_names == ("a", "b")
    np.testing.assert_array_equal(run.effort_scale, [2.0, 3.0])
    np.testing.assert_array_equal(run.offsets, [0.25, 0.0])
    assert run.mjcf == ARM


def test_logged_torques_are_unit_scale_and_bad_folders_are_refused(tmp_path):
    assert read_torque_run(_run_folder(tmp_path / "torques"), ROBOT).effort_scale.tolist() == [1.0, 1.0]
    with pytest.raises(ValueError, match="not a run folder"):
        read_torque_run(tmp_path, ROBOT)
    with pytest.raises(ValueError, match="not a torque fit's result"):
        read_torque_run(_run_folder(tmp_path / "rollout", task="rollout"), ROBOT)
    with pytest.raises(ValueError, match="effort_scale"):
        read_torque_run(_run_folder(tmp_path / "negative", scale=[1.0, -1.0]), ROBOT)


def test_a_servo_driven_joint_is_refused_and_a_motors_gear_divides_the_torque(tmp_path):
    servo = load_model(SERVO)
    check_motor_driven(servo, ("a",), "<log>")
    with pytest.raises(ValueError, match="joint b is driven by a servo"):
        check_motor_driven(servo, ("a", "b"), "<log>")
    geared = ARM.replace(
        "</mujoco>", '<actuator><motor joint="a" gear="4"/><motor joint="b"/></actuator></mujoco>'
    )
    folder = _run_folder(tmp_path / "geared", mjcf=geared)
    t = np.arange(10) * 0.01
    np.savez(folder / "log.npz", t=t, q=np.zeros((10, 2)), qd=np.zeros((10, 2)), tau=np.ones((10, 2)))
    sim = load_model(geared)
    log = read_torque_run(folder, ROBOT).reader(sim)(folder / "log.npz")
    np.testing.assert_allclose(log.commands[0], [(1.0 - 0.25) / 4, 1.0])


def test_armature_cap_is_rms_torque_over_rms_acceleration_in_closed_form():
    log = _log()
    t = log.t
    # qd = (0.5 cos t, 0.6 cos 2t): accelerations (-0.5 sin t, -1.2 sin 2t)
    exact = np.sqrt(np.mean(np.column_stack([0.5 * np.sin(t), 1.2 * np.sin(2 * t)]) ** 2, axis=0))
    np.testing.assert_allclose(rms_acceleration(log), exact, rtol=5e-3)
    tau = np.sqrt(np.mean(log.commands**2, axis=0))
    np.testing.assert_allclose(caps(log, "armature"), tau / rms_acceleration(log))


def test_zero_starts_get_derived_bounds_with_a_note_and_positive_starts_keep_theirs():
    sim = load_model(
        ARM.replace("<worldbody>", "<worldbody>").replace(
            "</mujoco>", "<actuator><motor joint='a'/><motor joint='b'/></actuator></mujoco>"
        )
    )
    log = _log()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        bounds = derived_bounds(
            sim, log, ("a", "b"), ["armature", "damping", "frictionloss"], {"b.armature": [0, 9]}
        )
    notes = [str(w.message) for w in caught if issubclass(w.category, Note)]
    assert len(notes) == 3 and all("\n" not in n for n in notes)
    tau_rms = np.sqrt(np.mean(log.commands**2, axis=0))
    qd_rms = np.sqrt(np.mean(log.qd**2, axis=0))
    assert bounds["b.armature"] == [0, 9]  # given: kept
    assert bounds["a.armature"][1] == pytest.approx(tau_rms[0] / rms_acceleration(log)[0])
    assert bounds["b.damping"][1] == pytest.approx(tau_rms[1] / qd_rms[1])
    assert bounds["b.frictionloss"][1] == pytest.approx(tau_rms[1])
    assert "a.damping" not in bounds and "a.frictionloss" not in bounds  # 0.4 and 0.2: box × start
    np.testing.assert_allclose(caps(log, "bias"), 0.1 * tau_rms)


def test_the_run_folders_model_loads_with_one_motor_per_joint(tmp_path):
    run = read_torque_run(_run_folder(tmp_path / "run"), ROBOT)
    sim = load_model(run.mjcf)
    assert sim.model.nu == 2
    assert all(sim.model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT for a in range(2))


def test_the_simulator_and_its_identified_xml_have_no_contacts(tmp_path):
    from idkit.sim.export import identified_xml
    from idkit.sim.quantities import select_unknowns

    run = read_torque_run(_run_folder(tmp_path / "run"), ROBOT)
    with pytest.warns(Note, match="contacts disabled"):
        sim = run.model()
    assert sim.model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    unknowns = select_unknowns(sim, ("a",), ["damping"])
    written = mujoco.MjModel.from_xml_string(identified_xml(sim, unknowns, np.array([0.7])))
    assert written.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    assert written.dof_damping[0] == pytest.approx(0.7)
