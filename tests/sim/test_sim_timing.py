"""The sample-time convention (idkit.sim.timing), checked against MuJoCo itself.

A log written from a MuJoCo run — ``ctrl[k]`` applied from ``t_k``, the state at ``t_k`` the one before
step ``k`` — must give a zero error at the truth; a delay must equal MuJoCo's own actuator delay (its
history buffer, linear interpolation); an off-grid log must be read between the simulator's rows.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from mujoco import rollout

from idkit.data.commands import RobotLog
from idkit.sim.export import identified_xml, start_state
from idkit.sim.model import load_model
from idkit.sim.problem import RolloutProblem, SimRobot
from idkit.sim.quantities import select_unknowns
from idkit.sim.segments import split
from idkit.sim.timing import held_averages, readout
from idkit.testing import rollout_cases as cases


@pytest.fixture(scope="module")
def arm7_log() -> RobotLog:
    return cases.case_b().fit


def _problem(case_model: str, log: RobotLog, params, start=None, segment=0.5) -> RolloutProblem:
    sim = load_model(case_model)
    bounds = {"command_delay": [0.0, 0.02]} if "command_delay" in params else None
    unknowns = select_unknowns(sim, log.joint_names, params, start=start, bounds=bounds)
    return RolloutProblem(SimRobot(sim, unknowns, log.joint_names), log, segment=segment, threads=1)


@pytest.mark.parametrize("segment", [None, 0.5, 0.1])
def test_a_fit_at_the_truth_has_zero_error(arm7_log, segment):
    """MuJoCo's sensor row k is computed before step k, its state row k after: the log pairs the state
    at t_k with the command from t_k, and the simulator reproduces it exactly, in any segments."""
    problem = _problem(
        cases.ARM7,
        arm7_log,
        ["armature", "damping", "frictionloss", "kp", "kv", "command_delay"],
        segment=segment,
    )
    truth = problem.robot.unknowns.vector("start")
    simulator = problem.simulator()
    try:
        error = problem.error(truth[None], simulator)
    finally:
        simulator.close()
    assert np.abs(error).max() == 0.0
    assert error.shape == (1, 14, arm7_log.n_samples)


def test_mujocos_own_sensor_rows_are_the_states_at_the_step_start():
    """The fact the convention rests on: rollout's sensor row k equals state row k - 1 (step k's start)."""
    text = cases.ARM5.replace("</mujoco>", '<sensor><jointpos joint="joint1"/></sensor></mujoco>')
    model = mujoco.MjModel.from_xml_string(text)
    data = mujoco.MjData(model)
    initial = np.empty(mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_FULLPHYSICS))
    mujoco.mj_getState(model, data, initial, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    state, sensor = rollout.rollout(model, data, initial, np.ones((5, 5)))
    assert sensor[0, 0, 0] == initial[1]
    np.testing.assert_array_equal(sensor[0, 1:, 0], state[0, :-1, 1])


def test_a_wrong_value_is_seen(arm7_log):
    problem = _problem(cases.ARM7, arm7_log, ["damping"], segment=0.5)
    values = problem.robot.unknowns.vector("start") * 1.05
    simulator = problem.simulator()
    try:
        error = problem.error(values[None], simulator)
    finally:
        simulator.close()
    assert np.abs(error).max() > 100.0  # in channel scales: a millionth of the spread on a clean log


def test_the_delay_is_mujocos_actuator_delay(arm7_log):
    """A fitted delay written into identified.xml (actuator delay, linear history) reproduces idkit's
    rollout once the buffer holds the first command (start_state)."""
    delay = 0.0073  # 3.65 steps: between two samples
    problem = _problem(
        cases.ARM7, arm7_log, ["damping", "command_delay"], start={"command_delay": delay}, segment=None
    )
    values = problem.robot.unknowns.vector("start")
    simulator = problem.simulator()
    try:
        q, qd = simulator.predict(values[None])
    finally:
        simulator.close()
    sim = load_model(identified_xml(problem.robot.sim, problem.robot.unknowns, values))
    assert sim.model.actuator_delay == pytest.approx(np.full(sim.model.nu, delay))
    log = arm7_log
    state = start_state(sim, log.joint_names, log.q[0], log.qd[0], log.commands[0])
    rows, _ = rollout.rollout(sim.model, mujoco.MjData(sim.model), state, log.commands[:-1])
    np.testing.assert_allclose(rows[0, :, 1:8], q[0, 1:], atol=1e-10)
    np.testing.assert_allclose(rows[0, :, 8:15], qd[0, 1:], atol=1e-8)


def test_held_averages_on_and_off_the_grid():
    times = np.arange(5) * 0.01
    values = np.arange(5.0)[:, None] ** 2
    on_grid = held_averages(times, values, np.array([0.0]), 5, 0.01)[0, :, 0]
    np.testing.assert_array_equal(on_grid, values[:, 0])  # the commands themselves, bit for bit
    half = held_averages(times, values, np.array([0.005]), 3, 0.01)[0, :, 0]
    np.testing.assert_allclose(half, [0.5, 2.5, 6.5])  # half of each of two held commands
    before, after = held_averages(times, values, np.array([-0.02, 0.05]), 2, 0.01)[:, :, 0]
    np.testing.assert_array_equal(before, [0.0, 0.0])  # the first command, held before the log
    np.testing.assert_array_equal(after, [16.0, 16.0])  # the last, held after it


def test_a_log_off_the_simulators_grid_is_interpolated():
    """The arm simulated at 1 ms and logged every 3 ms from 1.5 ms on: the 2 ms model reads its rows
    between steps, and its prediction matches the 1 ms run to the integration error."""
    fine = cases.ARM5.replace('timestep="0.002"', 'timestep="0.001"')
    t_fine = np.arange(3001) * 0.001
    ctrl = np.column_stack([np.sin(2 * np.pi * f * t_fine) for f in (0.5, 0.7, 0.4, 0.9, 0.6)])
    q, qd = cases.simulate(fine, ctrl)
    rows = np.arange(0, 3001, 3)  # 3 ms apart: every 1.5 steps of the 2 ms model
    joints = tuple(f"joint{i}" for i in range(1, 6))
    names = tuple(f"act{i}.ctrl" for i in range(1, 6))
    log = RobotLog(t_fine[rows], q[rows], qd[rows], t_fine, ctrl, joints, names, "1 ms run")
    view = readout(log.t, 0, 11, 0.002)
    np.testing.assert_array_equal(view.lower, [-1, 0, 2, 3, 5, 6, 8, 9, 11, 12, 14])
    np.testing.assert_allclose(view.fraction, [0, 0.5, 0, 0.5, 0, 0.5, 0, 0.5, 0, 0.5, 0])
    problem = _problem(cases.ARM5, log, ["armature"], segment=0.5)
    simulator = problem.simulator()
    try:
        error = problem.error(problem.robot.unknowns.vector("start")[None], simulator)[0]
    finally:
        simulator.close()
    spread = np.abs(np.hstack([q, qd])).max(axis=0)
    scaled = np.abs(error) * problem.scales()[:, None] / spread[:, None]
    assert scaled.max() < 2e-3  # 2 ms vs 1 ms integration: small; a wrong row would be ~1e-1


def test_segments_cover_every_sample_once():
    t = np.r_[np.arange(100) * 0.01, 5.0 + np.arange(60) * 0.01]  # a gap after 1 s
    segments = split(t, 0.3)
    covered = np.concatenate([np.arange(a, b) for a, b in segments])
    np.testing.assert_array_equal(covered, np.arange(t.size))
    assert all(not (a < 100 <= b - 1) for a, b in segments)  # none spans the gap
    assert split(t, None) == [(0, 100), (100, 160)]
    with pytest.raises(ValueError, match="positive"):
        split(t, 0.0)


def test_a_urdf_goes_through_mujocos_import_and_gets_a_motor_per_joint():
    from urdf_cases import TREE_URDF

    sim = load_model(TREE_URDF)
    assert sim.joint_names() == ("j1", "j2", "j3", "j4")
    assert sim.actuator_names() == ("j1", "j2", "j3", "j4")
    t = np.arange(300) * sim.timestep
    ctrl = 0.2 * np.column_stack([np.sin(2 * np.pi * f * t) for f in (1.0, 1.3, 0.7, 1.9)])
    text = identified_xml(
        sim,
        select_unknowns(sim, sim.joint_names(), ["j1.damping"], bounds={"damping": [0, 1]}),
        np.array([0.3]),
    )
    q, qd = cases.simulate(text, ctrl)
    log = RobotLog(t, q, qd, t, ctrl, sim.joint_names(), [f"{j}.ctrl" for j in sim.joint_names()], "urdf run")
    unknowns = select_unknowns(
        sim, log.joint_names, ["j1.damping"], start={"damping": 0.3}, bounds={"damping": [0, 1]}
    )
    problem = RolloutProblem(SimRobot(sim, unknowns, log.joint_names), log, threads=1)
    simulator = problem.simulator()
    try:
        assert np.abs(problem.error(np.array([[0.3]]), simulator)).max() < 1e-6  # MJCF's 6 digits
        assert np.abs(problem.error(np.array([[0.0]]), simulator)).max() > 10.0
    finally:
        simulator.close()
