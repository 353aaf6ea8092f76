"""Held-out validation (idkit.sim.validation): traces against MuJoCo run directly, the default mode,
and a perfect model scoring the log's noise level."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from idkit.data.commands import RobotLog
from idkit.sim.model import load_model
from idkit.sim.problem import SimRobot
from idkit.sim.quantities import select_unknowns
from idkit.sim.validation import WITHIN, default_mode, held_out, score
from idkit.testing import rollout_cases as cases
from idkit.testing.rollout_cases import corrupt, simulate

MOTORS = cases.ARM5.split('<body name="link3"')[0] + (
    "</body></body></worldbody><actuator>"
    '<motor name="act1" joint="joint1"/><motor name="act2" joint="joint2"/></actuator></mujoco>'
)
SERVOS = MOTORS.replace(
    '<motor name="act1" joint="joint1"/><motor name="act2" joint="joint2"/>',
    '<position name="act1" joint="joint1" kp="40" kv="4"/>'
    '<position name="act2" joint="joint2" kp="30" kv="3"/>',
)
TRUTH = {"joint1.armature": 0.5, "joint2.armature": 0.4, "joint1.damping": 1.0, "joint2.damping": 0.8}


def _log(
    text: str, noise: tuple[float, float] = (0.0, 0.0), glitches: float = 0.0, seed: int = 0
) -> RobotLog:
    t = np.arange(1000) * 0.002
    servo = "position" in text
    a = (0.6, 0.5) if servo else (3.0, 2.0)
    ctrl = np.column_stack([a[0] * np.sin(2 * np.pi * 1.3 * t), a[1] * np.cos(2 * np.pi * 1.9 * t)])
    q, qd = simulate(text, ctrl)
    if noise[0] or glitches:
        q, qd = corrupt(q, qd, noise, glitches, np.random.default_rng(seed))
    names = ("joint1.q_ref", "joint2.q_ref") if servo else ("act1.ctrl", "act2.ctrl")
    return RobotLog(t, q, qd, t, ctrl, ("joint1", "joint2"), names, "held-out log")


def _robot(text: str) -> SimRobot:
    sim = load_model(text)
    unknowns = select_unknowns(sim, ("joint1", "joint2"), ("armature", "damping"))
    return SimRobot(sim, unknowns, ("joint1", "joint2"))


def _direct(text: str, log: RobotLog, first: int, stop: int, values: dict[str, float]) -> np.ndarray:
    """``[stop - first, 2]`` positions of MuJoCo stepped by hand from the logged state at ``first`` under
    the logged commands (the command at ``t_k`` acts from ``t_k``; the state at ``t_k`` is before step k)."""
    model = mujoco.MjModel.from_xml_string(text)
    for name, value in values.items():
        joint, kind = name.split(".")
        getattr(model, f"dof_{kind}")[model.joint(joint).dofadr[0]] = value
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = log.q[first], log.qd[first]
    mujoco.mj_forward(model, data)
    out = [data.qpos.copy()]
    for k in range(first, stop - 1):
        data.ctrl[:] = log.commands[k]
        mujoco.mj_step(model, data)
        out.append(data.qpos.copy())
    return np.array(out)


@pytest.mark.parametrize("text", [MOTORS, SERVOS], ids=["open loop (motors)", "closed loop (servos)"])
def test_segments_and_whole_are_mujocos_own_rollouts_from_the_logged_state(text):
    log = _log(text)
    start = {k: 1.3 * v for k, v in TRUTH.items()}  # not the truth: the trace must still be MuJoCo's
    robot = _robot(text)
    values = np.array([start[n] for n in robot.unknowns.names])
    segments = score(robot, values, log, "segments", 0.5)
    whole = score(robot, values, log, "whole")
    assert segments.segments == 4 and whole.segments == 1
    np.testing.assert_allclose(
        segments.simulated[250:500, :2], _direct(text, log, 250, 500, start), atol=1e-9
    )
    np.testing.assert_allclose(whole.simulated[:, :2], _direct(text, log, 0, 1000, start), atol=1e-9)
    np.testing.assert_array_equal(whole.measured[:, :2], log.q)


def test_default_mode_is_whole_only_when_every_joint_is_held_by_a_position_servo():
    log = _log(MOTORS)
    assert default_mode(load_model(MOTORS), log)[0] == "segments"
    mode, reason = default_mode(_robot(SERVOS), log)
    assert mode == "whole" and "joint1, joint2" in reason
    mixed = SERVOS.replace(
        '<position name="act2" joint="joint2" kp="30" kv="3"/>', '<motor name="act2" joint="joint2"/>'
    )
    mode, reason = default_mode(load_model(mixed), log)
    assert mode == "segments" and reason.startswith("joint2 is not held")
    velocity = MOTORS.replace(
        '<motor name="act1" joint="joint1"/>', '<velocity name="act1" joint="joint1" kv="5"/>'
    )
    assert default_mode(load_model(velocity), log)[0] == "segments"  # a velocity servo lets q drift


@pytest.mark.parametrize("text", [MOTORS, SERVOS], ids=["motors", "servos"])
def test_the_truth_scores_the_noise_level_and_a_wrong_model_does_not(text):
    """Noise (1e-4 rad, 1e-2 rad/s) and 1.5 % glitched rows: at the truth every joint is within noise in
    every mode (the glitches do not count; the start state's noise carried forward is part of what a
    perfect model scores), and the robust error is the noise level (1.4826 × median); 30 % off is not."""
    log, robot = _log(text, (1e-4, 1e-2), 0.015, seed=3), _robot(text)
    truth = np.array([TRUTH[n] for n in robot.unknowns.names])
    records = held_out(robot, {"fitted": truth, "start": 1.3 * truth}, log, 0.5, seed=1)
    modes = {"segments", "whole"} if text is SERVOS else {"segments"}
    assert {r.mode for r in records} == modes and sum(r.default for r in records) == 2
    for record in records:
        ratio = np.array(list(record.ratio.values()))
        if record.values == "fitted":
            assert ratio.max() <= WITHIN and record.verdict == "within noise", record.mode
            assert 0.7 < record.robust[0] / record.noise[0] < 1.6 * record.expected[0] / record.noise[0]
        else:
            assert ratio.max() > 3 * WITHIN and record.verdict.endswith(")")
    segments = next(r for r in records if r.mode == "segments" and r.values == "fitted")
    assert (segments.expected[:2] >= segments.noise[:2]).all()
    assert set(segments.scores()["verdicts"]) == {"joint1", "joint2"}


def test_bad_input_is_named():
    log, robot = _log(MOTORS), _robot(MOTORS)
    with pytest.raises(ValueError, match="mode"):
        score(robot, np.ones(4), log, "open loop")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="3 values for 4 unknowns"):
        score(robot, np.ones(3), log)
    with pytest.raises(ValueError, match="no value for joint2.damping"):
        score(robot, {k: v for k, v in TRUTH.items() if k != "joint2.damping"}, log)
