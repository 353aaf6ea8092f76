"""Logs of commands and joint states (idkit.data.commands) and which command drives which actuator."""

from __future__ import annotations

import numpy as np
import pytest
from bag_cases import Stream, write_ros1, write_ros2

from idkit.data.commands import RobotLog, read_robot_log, save_robot_log
from idkit.sim.drive import match_commands
from idkit.sim.model import load_model
from idkit.testing import rollout_cases as cases


@pytest.fixture(scope="module")
def arm7():
    return cases.case_b().fit


def _streams(log: RobotLog, joints: list[str]) -> list[Stream]:
    stamps = 1_700_000_000_000_000_000 + np.round(log.t * 1e9).astype(np.int64)
    n = len(joints)
    states = Stream("/joint_states", stamps, joints, position=log.q, velocity=log.qd)
    commands = Stream("/commands", stamps, joints, position=log.commands[:, :n], velocity=log.commands[:, n:])
    return [states, commands]


def test_csv_round_trip(tmp_path, arm7):
    path = save_robot_log(arm7, tmp_path / "run.csv")
    read = read_robot_log(path)
    for name in ("t", "q", "qd", "command_t", "commands"):
        np.testing.assert_array_equal(getattr(read, name), getattr(arm7, name))
    assert read.command_names == arm7.command_names
    assert read_robot_log(path, joints=["j3", "j1"]).joint_names == ("j3", "j1")


@pytest.mark.parametrize("writer", ["ros2", "ros1"])
def test_a_bag_reads_as_the_csv(tmp_path, arm7, writer):
    """Joints in another order every other message, an extra joint and topic: the same log as the CSV."""
    joints = list(arm7.joint_names)
    if writer == "ros2":
        path = write_ros2(tmp_path / "run", _streams(arm7, joints))
    else:
        path = write_ros1(tmp_path / "run.bag", _streams(arm7, joints))
    read = read_robot_log(path, joints=joints, command_topic="/commands")
    np.testing.assert_allclose(read.t, arm7.t, atol=1e-12)
    np.testing.assert_allclose(read.command_t, arm7.t, atol=1e-12)
    np.testing.assert_array_equal(read.q, arm7.q)
    np.testing.assert_array_equal(read.qd, arm7.qd)
    order = [read.command_names.index(name) for name in arm7.command_names]
    np.testing.assert_array_equal(read.commands[:, order], arm7.commands)
    assert read.joint_names == tuple(joints)


def test_a_bag_needs_its_command_topic(tmp_path, arm7):
    path = write_ros2(tmp_path / "run", _streams(arm7, list(arm7.joint_names)))
    with pytest.raises(ValueError, match="command_topic"):
        read_robot_log(path)
    with pytest.raises(ValueError, match="no topic '/nope'"):
        read_robot_log(path, command_topic="/nope")


@pytest.mark.parametrize(
    ("header", "message"),
    [
        ("t,j1.q,j1.qd", "no command columns"),
        ("t,j1.q,j1.qd,ctrl1", "name the command columns"),
        ("t,q1,qd1,j1.ctrl", "name the joints"),
        ("t,j1.q,j1.ctrl", "qd"),
    ],
)
def test_csv_without_what_a_rollout_needs_is_refused(tmp_path, header, message):
    path = tmp_path / "bad.csv"
    columns = header.count(",") + 1
    path.write_text(header + "\n" + "\n".join(",".join([str(k)] * columns) for k in range(3)) + "\n")
    with pytest.raises(ValueError, match=message):
        read_robot_log(path)


def test_commands_drive_actuators_by_name_or_by_their_joints_servo(arm7):
    sim = load_model(cases.ARM7)
    drive = match_commands(sim, arm7)
    assert drive.describe(sim, arm7)["p3"] == "j3.q_ref"
    assert drive.describe(sim, arm7)["v3"] == "j3.qd_ref"
    renamed = RobotLog(
        arm7.t,
        arm7.q,
        arm7.qd,
        arm7.t,
        arm7.commands[:, :7],
        arm7.joint_names,
        [f"j{i}.q_ref" for i in range(1, 8)],
    )
    with pytest.raises(ValueError, match="no command for actuator 'v1'.*j1.qd_ref"):
        match_commands(sim, renamed)


def test_a_log_must_be_ordered_and_finite(arm7):
    with pytest.raises(ValueError, match="increase strictly"):
        RobotLog(arm7.t[::-1], arm7.q, arm7.qd, arm7.t, arm7.commands, arm7.joint_names, arm7.command_names)
    q = arm7.q.copy()
    q[5, 2] = np.nan
    with pytest.raises(ValueError, match="non-finite value at sample 5"):
        RobotLog(arm7.t, q, arm7.qd, arm7.t, arm7.commands, arm7.joint_names, arm7.command_names)


def test_state_and_command_times_are_checked_by_the_torque_paths_check(arm7):
    """One timestamp check for every reader (idkit.data.raw.check_increasing): the same words."""
    from idkit.data.raw import Recording

    t = arm7.t.copy()
    t[4] = t[3]
    with pytest.raises(ValueError, match=r"^<log>: state times must increase strictly; t\[4\] = "):
        RobotLog(t, arm7.q, arm7.qd, arm7.t, arm7.commands, arm7.joint_names, arm7.command_names)
    with pytest.raises(ValueError, match=r"command times must increase strictly; command_t\[4\]"):
        RobotLog(arm7.t, arm7.q, arm7.qd, t, arm7.commands, arm7.joint_names, arm7.command_names)
    with pytest.raises(ValueError, match=r"^x: timestamps must increase strictly; t\[4\] = "):
        Recording(t, arm7.q, arm7.q, source="x")


def test_a_bag_whose_only_joint_state_topic_is_the_commands_is_refused(tmp_path, arm7):
    """The states cannot be the commands' topic: the one topic chooser of idkit.data.logs says so."""
    path = write_ros2(tmp_path / "run", _streams(arm7, list(arm7.joint_names))[1:])
    with pytest.raises(
        ValueError, match=r"no sensor_msgs/JointState topic besides /commands; name it with state_topic"
    ):
        read_robot_log(path, command_topic="/commands")


def test_several_logs_join_with_a_gap_and_a_file_given_twice_is_refused(tmp_path, arm7):
    from idkit.data.commands import read_robot_logs
    from idkit.sim.segments import split

    first = save_robot_log(arm7.head(200), tmp_path / "a.csv")
    second = save_robot_log(arm7.head(300), tmp_path / "b.csv")
    joined = read_robot_logs([first, second])
    assert joined.n_samples == 500 and joined.source == f"{first}, {second}"
    np.testing.assert_array_equal(joined.q[200:], arm7.q[:300])
    assert split(joined.t, None) == [(0, 200), (200, 500)]  # the rollout restarts after the join
    assert read_robot_logs(str(first)).n_samples == 200
    with pytest.raises(ValueError, match="gives .*b.csv twice"):
        read_robot_logs([second, first, second])
    with pytest.raises(ValueError, match="no log given"):
        read_robot_logs([])
