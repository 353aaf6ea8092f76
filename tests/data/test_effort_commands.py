"""A torque or current log read as motor commands (idkit.data.effort_commands)."""

from __future__ import annotations

import numpy as np
import pytest

from idkit.data.effort_commands import read_effort_log

JOINTS = ("a", "b")


def _csv(path, velocities=True):
    t = np.arange(20) * 0.01
    q = np.column_stack([np.sin(t), np.cos(t)])
    tau = np.column_stack([1.0 + t, -2.0 + 0 * t])
    columns = {"t": t, "a.q": q[:, 0], "b.q": q[:, 1], "b.tau": tau[:, 1], "a.tau": tau[:, 0]}
    if velocities:
        columns |= {"a.qd": np.cos(t), "b.qd": -np.sin(t)}
    np.savetxt(
        path, np.column_stack(list(columns.values())), delimiter=",", header=",".join(columns), comments=""
    )
    return t, q, tau


def test_efforts_become_scaled_torques_minus_offsets_by_joint_name(tmp_path):
    t, q, tau = _csv(tmp_path / "log.csv")
    log = read_effort_log(tmp_path / "log.csv", JOINTS, np.array([2.0, 0.5]), np.array([0.1, -0.3]))
    assert log.command_names == ("a.ctrl", "b.ctrl")
    np.testing.assert_allclose(log.commands, tau * [2.0, 0.5] - [0.1, -0.3])
    np.testing.assert_allclose(log.q, q)
    np.testing.assert_array_equal(log.command_t, log.t)


def test_flobaroid_npz_is_read_by_position(tmp_path):
    t = np.arange(30) * 0.005
    rng = np.random.default_rng(0)
    arrays = {k: rng.normal(size=(30, 2)) for k in ("positions", "velocities", "torques")}
    np.savez(tmp_path / "arm.npz", times=t + 100.0, **arrays)
    log = read_effort_log(tmp_path / "arm.npz", JOINTS, np.ones(2), np.array([1.0, 0.0]))
    np.testing.assert_allclose(log.t, t, atol=1e-12)
    np.testing.assert_allclose(log.commands, arrays["torques"] - [1.0, 0.0])
    np.testing.assert_allclose(log.qd, arrays["velocities"])


def test_a_log_without_velocities_is_refused_in_one_line(tmp_path):
    _csv(tmp_path / "log.csv", velocities=False)
    with pytest.raises(ValueError, match="no joint velocities") as error:
        read_effort_log(tmp_path / "log.csv", JOINTS, np.ones(2), np.zeros(2))
    assert "\n" not in str(error.value)


def test_scales_of_another_length_are_refused(tmp_path):
    _csv(tmp_path / "log.csv")
    with pytest.raises(ValueError, match="2 joints but 3 effort scale"):
        read_effort_log(tmp_path / "log.csv", JOINTS, np.ones(3), np.zeros(2))
