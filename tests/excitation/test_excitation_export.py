"""Trajectory files at a controller rate: the grid, exact round trips, joints by name, refusals."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from idkit.excitation.export import Trajectory, columns, controller_times, read_trajectory
from idkit.reports import files

JOINTS = ("theta1", "d2", "d3")


def trajectory(n: int = 11, seed: int = 0) -> Trajectory:
    g = torch.Generator().manual_seed(seed)
    t = controller_times(n / 1000 - 0.001, 1000.0)
    q, qd, qdd = (torch.randn(n, 3, generator=g, dtype=torch.float64) / 3 for _ in range(3))
    return Trajectory.of(JOINTS, t, q, qd, qdd)


def write(path, found: Trajectory):
    if path.suffix == ".csv":
        return files.write_csv(path, columns(found.joint_names), found.rows().tolist())
    return files.write_npz(path, found.arrays())


def test_controller_times_are_the_rate_including_both_ends():
    t = controller_times(20.0, 1000.0)
    assert t.numel() == 20001 and t[0] == 0.0 and t[-1] == 20.0
    torch.testing.assert_close(t.diff(), torch.full((20000,), 1e-3, dtype=torch.float64), rtol=1e-9, atol=0)
    assert controller_times(0.5, 500).numel() == 251


@pytest.mark.parametrize(
    ("t_end", "rate", "match"),
    [
        (25.1294, 1000.0, r"t_end=25.1294 s is not a whole number of 0.001 s steps .* 25.129 or 25.13 s"),
        (1.0, 0.0, "rate must be a positive number"),
        (1.0, True, "rate must be a positive number"),
        (0.0, 1000.0, r"^excitation\.t_end must be a finite number of seconds > 0, got 0\.0$"),
        (-5.0, 1000.0, r"^excitation\.t_end must be a finite number of seconds > 0, got -5\.0$"),
    ],
)
def test_controller_times_refuse_a_grid_that_would_not_end_at_t_end(t_end, rate, match):
    with pytest.raises(ValueError, match=match):
        controller_times(t_end, rate)


def test_controller_times_that_do_not_fit_in_memory_are_refused_before_allocating(monkeypatch):
    """``excitation.t_end=1e9`` at 1 kHz used to end in torch's allocation error, whose hint named the
    estimator's sizes."""
    import idkit.memory

    monkeypatch.setattr(idkit.memory, "available_memory", lambda: 1_000_000)  # a machine with 1 MB free
    assert controller_times(2.0, 1000.0, joints=3).numel() == 2001  # 2001 × (6 × 3 + 1) × 8 B = 304 kB
    with pytest.raises(
        ValueError,
        match=r"^excitation\.t_end × excitation\.rate = 20 s × 1000 Hz = 2e\+04 samples of 3 joint\(s\), "
        r"which needs about 3\.04 MB of memory; this machine has 1 MB available; lower excitation\.t_end",
    ):
        controller_times(20.0, 1000.0, joints=3)


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_round_trip_is_exact(tmp_path, suffix):
    found = trajectory()
    path = write(tmp_path / f"motion{suffix}", found)
    back = read_trajectory(path, JOINTS)
    for name in ("t", "q", "qd", "qdd"):
        np.testing.assert_array_equal(getattr(back, name), getattr(found, name))
    assert back.joint_names == JOINTS


def test_csv_columns_follow_the_named_joint_convention(tmp_path):
    path = write(tmp_path / "m.csv", trajectory(3))
    header = path.read_text().splitlines()[0]
    assert header == "t,theta1.q,theta1.qd,theta1.qdd,d2.q,d2.qd,d2.qdd,d3.q,d3.qd,d3.qdd"


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_columns_are_matched_by_joint_name(tmp_path, suffix):
    found = trajectory()
    shuffled = Trajectory(
        ("d3", "theta1", "d2"), found.t, *(x[:, [2, 0, 1]] for x in (found.q, found.qd, found.qdd))
    )
    back = read_trajectory(write(tmp_path / f"m{suffix}", shuffled), JOINTS)
    np.testing.assert_array_equal(back.q, found.q)
    np.testing.assert_array_equal(back.qdd, found.qdd)


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_other_joints_are_refused_naming_them(tmp_path, suffix):
    path = write(tmp_path / f"m{suffix}", trajectory())
    with pytest.raises(
        ValueError, match=r"no columns for joint\(s\) j1; joint\(s\) theta1 that the robot does not have"
    ):
        read_trajectory(path, ("j1", "d2", "d3"))


def test_csv_refusals_name_file_line_and_column(tmp_path):
    path = write(tmp_path / "m.csv", trajectory(3))
    lines = path.read_text().splitlines()
    bad = tmp_path / "bad.csv"
    bad.write_text(
        "\n".join([lines[0], lines[1], lines[2].replace(lines[2].split(",")[4], "abc", 1), lines[3]])
    )
    with pytest.raises(ValueError, match=r"bad.csv: line 3 \(sample 1\), column 'd2.q': not a number: 'abc'"):
        read_trajectory(bad, JOINTS)
    bad.write_text("\n".join([lines[0], lines[1].replace(lines[1].split(",")[3], "nan", 1), lines[2]]))
    with pytest.raises(ValueError, match=r"\(column theta1.qdd\) has a non-finite value \(nan\) at sample 0"):
        read_trajectory(bad, JOINTS)
    bad.write_text(
        "\n".join([lines[0].replace(",d3.qdd", ""), *(line.rpartition(",")[0] for line in lines[1:])])
    )
    with pytest.raises(ValueError, match=r"no column 'd3.qdd' for joint 'd3'"):
        read_trajectory(bad, JOINTS)


def test_npz_without_joint_names_is_refused(tmp_path):
    arrays = trajectory().arrays()
    del arrays["joint_names"]
    path = files.write_npz(tmp_path / "m.npz", arrays)
    with pytest.raises(ValueError, match="no joint_names array"):
        read_trajectory(path, JOINTS)


@pytest.mark.parametrize(
    ("name", "match"), [("x.txt", "unsupported file type '.txt'"), ("none.csv", "not found")]
)
def test_other_files_are_refused(tmp_path, name, match):
    path = tmp_path / name
    if name.endswith(".txt"):
        path.write_text("t\n0\n")
    with pytest.raises((ValueError, FileNotFoundError), match=match):
        read_trajectory(path, JOINTS)


def test_one_sample_is_not_a_trajectory(tmp_path):
    path = write(tmp_path / "m.csv", trajectory(3))
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:2]))
    with pytest.raises(ValueError, match="at least two samples, got 1"):
        read_trajectory(path, JOINTS)


def test_numbered_columns_do_not_name_their_joints(tmp_path):
    found = trajectory(3)
    path = tmp_path / "numbered.csv"
    header = ["t", *(f"{q}{j}" for q in ("q", "qd", "qdd") for j in (1, 2, 3))]
    rows = np.concatenate((found.t[:, None], found.q, found.qd, found.qdd), axis=1)
    files.write_csv(path, header, rows.tolist())
    with pytest.raises(ValueError, match=r"columns q1..qn do not name their joints; name them <joint>.q"):
        read_trajectory(path, JOINTS)
