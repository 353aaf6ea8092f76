"""``SimulatorModel``: its rollouts against MuJoCo's own (``mujoco.rollout`` of ``to_mujoco()`` under the
logged commands, from ``mujoco_state``), ``save``'s guarantees, and the library entry's model."""

from __future__ import annotations

import os
import stat
from importlib.resources import files

import numpy as np
import pytest

from idkit.data.commands import read_robot_log
from idkit.examples.make_servo_arm import DECIMATE, TRUTH
from idkit.sim.model import load_model
from idkit.sim.quantities import select_unknowns
from idkit.sim.segments import split
from idkit.sim.simulator_model import SimulatorModel

EXAMPLE = files("idkit.examples") / "servo_arm"
JOINTS = ("j1", "j2", "j3")


def truth_model(delay: float = 0.0) -> SimulatorModel:
    """The shipped arm at its true values (and a command delay)."""
    sim = load_model(str(EXAMPLE / "servo_arm.xml"))
    params = ["armature", "damping", "frictionloss"] + (["command_delay"] if delay else [])
    unknowns = select_unknowns(sim, JOINTS, params, bounds={"command_delay": [0.0, 0.02]} if delay else None)
    return SimulatorModel.of(sim, unknowns, {**TRUTH, "command_delay": delay}, JOINTS)


def direct_rollout(model: SimulatorModel, log, steps: int) -> np.ndarray:
    """``[steps + 1, 3]`` positions from MuJoCo alone: the identified model, its state at the log's first
    sample, each logged command held for the ``DECIMATE`` steps until the next."""
    import mujoco
    from mujoco import rollout

    m = model.to_mujoco()
    state = model.mujoco_state(log.q[0], log.qd[0], log.commands[0])
    controls = np.repeat(log.commands, DECIMATE, axis=0)[:steps]
    out, _ = rollout.rollout(m, mujoco.MjData(m), state, controls)
    qpos = np.vstack([state[1 : 1 + m.nq], out[0][:, 1 : 1 + m.nq]])
    return qpos


@pytest.mark.parametrize("delay", [0.0, 0.003])
def test_simulate_is_mujocos_own_rollout_of_the_saved_model(delay):
    """A whole rollout from the first logged state follows MuJoCo's rollout of ``to_mujoco()`` (its delay
    as the actuators' history buffer) to round-off, at every logged sample; and the logged arm (the
    truth, without delay) is reproduced to its noise."""
    model = truth_model(delay)
    log = read_robot_log(str(EXAMPLE / "train.csv"), JOINTS)
    run = model.simulate(log)
    assert run.segments == 1 and np.array_equal(run.t, log.t)
    steps = DECIMATE * (log.n_samples - 1)
    mujoco_q = direct_rollout(model, log, steps)[::DECIMATE]
    assert np.abs(run.q - mujoco_q).max() < 1e-8
    if not delay:  # the log is this arm's motion with 2e-4 rad of encoder noise
        assert max(q for q, _ in run.rms().values()) < 3e-4


def test_a_delay_changes_the_rollout():
    """The delay is simulated, not dropped: 3 ms late commands move the arm measurably."""
    log = read_robot_log(str(EXAMPLE / "train.csv"), JOINTS)
    assert np.abs(truth_model(0.003).simulate(log).q - truth_model().simulate(log).q).max() > 1e-3


def test_a_horizon_restarts_each_segment_from_the_logged_state():
    log = read_robot_log(str(EXAMPLE / "train.csv"), JOINTS)
    run = truth_model().simulate(log, horizon=0.5)
    segments = split(log.t, 0.5)
    assert run.segments == len(segments) == 8 and np.array_equal(run.t, log.t)
    for start, _ in segments:
        np.testing.assert_allclose(run.q[start], log.q[start], atol=1e-12)
    whole = truth_model().simulate(log)
    assert np.abs(run.q - whole.q)[segments[1][0]].max() > 1e-5  # restarted: not one rollout


def test_commands_alone_start_from_the_given_state():
    """A commands table rolls out from ``initial`` exactly as the log does from the same first state."""
    log = read_robot_log(str(EXAMPLE / "train.csv"), JOINTS)
    model = truth_model()
    table = {"t": log.t, **{name: log.commands[:, k] for k, name in enumerate(log.command_names)}}
    alone = model.simulate(table, initial=(log.q[0], log.qd[0]))
    assert alone.measured_q is None
    np.testing.assert_allclose(alone.q, model.simulate(log).q, atol=1e-12)
    with pytest.raises(ValueError, match="horizon"):
        model.simulate(table, horizon=0.5)
    with pytest.raises(ValueError, match="<joint>.q_ref"):
        model.simulate({"t": log.t, "j1.torque": log.t})
    with pytest.raises(ValueError, match="3 joints"):
        model.simulate(table, initial=([0.0], [0.0]))
    with pytest.raises(ValueError, match="no logged motion"):
        alone.rms()


def test_save_replaces_in_one_step_and_keeps_the_mode(tmp_path):
    model = truth_model()
    path = tmp_path / "identified.xml"
    path.write_text("old")
    os.chmod(path, 0o640)
    model.save(path)
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o640
    assert load_model(str(path)).model.dof_damping.tolist() == [1.6, 1.1, 0.4]
    assert [p.name for p in tmp_path.iterdir()] == ["identified.xml"]  # no temporary left
    with pytest.raises(ValueError, match="use .xml"):
        model.save(tmp_path / "identified.urdf")
    refused = SimulatorModel.of(model.sim, model.unknowns, dict(model.values), mjcf=None, mjcf_problem="no")
    with pytest.raises(ValueError, match="no"):
        refused.save(path)
    assert path.read_text().startswith("<mujoco")  # the earlier file is intact


def test_identify_simulator_returns_the_runs_model(tmp_path):
    """The library entry: a short fit of the shipped arm gives a model whose values, σ and intervals are
    the run's record, whose held-out records are the run's, and whose saved file is the run's."""
    import json

    import idkit

    head = "".join((EXAMPLE / "train.csv").read_text().splitlines(keepends=True)[:251])  # 1 s
    (tmp_path / "train.csv").write_text(head)
    model = idkit.identify_simulator(
        str(EXAMPLE / "servo_arm.xml"),
        str(tmp_path / "train.csv"),
        validate=[str(EXAMPLE / "held_out.csv")],
        out_dir=tmp_path / "run",
        estimator={"_name_": "rollout", "iterations": 0, "polish_iterations": 8},
    )
    record = json.loads((tmp_path / "run" / "result.json").read_text())["payload"]["estimate"]
    assert model.values == record["params"]
    assert model.std == record["details"]["uncertainty"]["std"]
    assert {r.file for r in model.held_out} == {str(EXAMPLE / "held_out.csv")}  # every mode, both values
    assert sum(r.default and r.values == "fitted" for r in model.held_out) == 1  # one verdict
    for name, (low, high) in model.interval95.items():
        assert low <= model.values[name] <= high
    assert model.to_mujoco().nu == 3
    assert isinstance(model, idkit.SimulatorModel)  # the package's lazy name is this class
    assert (tmp_path / "run" / "identified.xml").read_text() == model.mjcf


def test_identify_simulator_refuses_a_folder_it_cannot_write_before_the_fit(tmp_path):
    import idkit
    from idkit.reports.files import FolderError

    (tmp_path / "taken").write_text("a file, not a folder")
    with pytest.raises(FolderError, match="out_dir: .*taken is a file"):
        idkit.identify_simulator(
            str(EXAMPLE / "servo_arm.xml"), str(EXAMPLE / "train.csv"), out_dir=tmp_path / "taken"
        )
