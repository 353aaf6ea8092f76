"""``idkit.excitation.check``: margins and violations of a trajectory, and the command line."""

from __future__ import annotations

import math
import re
import subprocess
import sys

import numpy as np
import pytest
import torch

from idkit.excitation.check import check_trajectory, main
from idkit.excitation.collision import NotChecked, self_collision
from idkit.excitation.effort import nominal_torques
from idkit.excitation.export import Trajectory, columns, controller_times
from idkit.excitation.fourier import FourierExcitation
from idkit.excitation.margins import Margins
from idkit.limits import MotionLimits
from idkit.reports import files
from idkit.robots.urdf import URDFRobot
from tests.excitation.arm_cases import ARM_URDF, TOUCH

JOINTS = ("a", "b")
LIMITS = MotionLimits.from_ranges(JOINTS, [(-1, 1), (1, 2)], [(-3, 3), (-3, 3)], [(-15, 15), (-15, 15)])
NO_MARGIN = Margins.of(0.0)


def sine_trajectory(amplitude: float = 0.5, rate: float = 100.0) -> Trajectory:
    """``q_a = A sin(2π t / 2)²``-like motion at rest at both ends: ``q = A (1 - cos(π t))`` over 2 s."""
    t = controller_times(2.0, rate).numpy()
    w = math.pi
    q = np.stack((amplitude * (1 - np.cos(w * t)) ** 2, 1 + amplitude * (1 - np.cos(w * t)) ** 2), 1)
    qd = np.stack([2 * amplitude * (1 - np.cos(w * t)) * w * np.sin(w * t)] * 2, 1)
    qdd = np.stack([2 * amplitude * w**2 * (np.sin(w * t) ** 2 + (1 - np.cos(w * t)) * np.cos(w * t))] * 2, 1)
    return Trajectory(JOINTS, t, q, qd, qdd)


def test_margins_are_the_worst_sample_distance_from_each_limit():
    trajectory = sine_trajectory(0.2)
    found = check_trajectory(trajectory, LIMITS, None, None, NotChecked("test"), margins=NO_MARGIN)
    assert found.ok and found.samples == 201 and found.rate == pytest.approx(100.0) and found.duration == 2.0
    position = found.margins["a"]["position"]
    # q_a peaks at 0.2 · 2² = 0.8 at t = 1 s: 0.2 from the upper limit, a fifth of the half-range.
    assert position["worst"] == pytest.approx(0.8) and position["margin"] == pytest.approx(0.2)
    assert position["share"] == pytest.approx(0.2) and position["at"] == pytest.approx(1.0)
    assert found.margins["b"]["position"]["margin"] == pytest.approx(0.0)  # q_b starts on its lower limit
    assert "effort" not in found.margins["a"] and found.effort.startswith("not checked")
    assert found.rest["start"] == {"velocity": 0.0, "acceleration": 0.0}
    assert "| a | 0.2 (20.0 %) |" in found.table()


def test_a_sample_inside_a_limit_but_within_its_margin_is_a_violation():
    trajectory = sine_trajectory(0.2)  # q_b starts on its lower limit 1; q_a peaks 0.2 below its upper
    found = check_trajectory(trajectory, LIMITS, None, None, NotChecked("test"))  # the default: 5 %
    (violation,) = found.violations
    close = int((trajectory.q[:, 1] - 1 < 0.05 * 0.5).sum())  # within 5 % of the half-range 0.5
    assert (
        violation.line()
        == f"b: position 1 at t = 0 s within the 5 % safety margin of the limit 1 ({close} samples)"
    )
    assert not found.ok and found.summary().splitlines()[-1].startswith(
        "1 violation(s) (required margins: 5 %"
    )
    # a margin per quantity: none on positions passes; 25 % on them also catches q_a (20 % from its limit)
    assert check_trajectory(
        trajectory, LIMITS, None, None, NotChecked("x"), margins=Margins.of({"position": 0})
    ).ok
    wide = check_trajectory(trajectory, LIMITS, None, None, NotChecked("x"), margins=Margins.of(0.25))
    assert [(v.subject, v.quantity) for v in wide.violations] == [("a", "position"), ("b", "position")]
    assert found.as_dict()["required_margins"]["effort"] == 0.05


def test_margins_are_shares_in_zero_to_one():
    assert Margins.of({"effort": 0.1}).as_dict() == {
        "position": 0.05,
        "velocity": 0.05,
        "acceleration": 0.05,
        "effort": 0.1,
    }
    for bad in (1.0, -0.1, float("nan"), True, "x"):
        with pytest.raises(ValueError, match=r"excitation.margin must be a share .* in \[0, 1\)"):
            Margins.of(bad, "excitation.margin")
    with pytest.raises(
        ValueError, match="excitation.margin.torque is not a limit with a margin; they are position"
    ):
        Margins.of({"torque": 0.1}, "excitation.margin")


def test_narrowed_limits_keep_the_margin_inside_every_finite_box():
    limits = MotionLimits.from_ranges(["a"], [(1.0, 3.0)], [(-2.0, 2.0)], [(-math.inf, math.inf)])
    inner = Margins.of(0.1).narrowed(limits, extra=0.0)
    assert inner.lower[:, 0].tolist() == pytest.approx([1.1, -1.8, -math.inf])
    assert inner.upper[:, 0].tolist() == pytest.approx([2.9, 1.8, math.inf])
    assert Margins.of(0.1).narrowed_effort(torch.tensor([10.0]), extra=0.0).tolist() == pytest.approx([9.0])


def test_every_violation_names_joint_time_value_and_limit():
    trajectory = sine_trajectory(0.3)  # q_a up to 1.2 > 1; q_b up to 2.2 > 2
    torques = np.stack((np.linspace(0, 5, 201), np.zeros(201)), 1)
    found = check_trajectory(trajectory, LIMITS, torques, np.array([4.0, 1.0]), NotChecked("test"))
    lines = [v.line() for v in found.violations]
    beyond = int((trajectory.q[:, 0] > 1).sum())  # 39: cos(πt) < -0.8257, t in (0.81, 1.19)
    assert lines[0] == f"a: position 1.2 at t = 1 s beyond the limit 1 ({beyond} samples)"
    assert lines[1] == f"b: position 2.2 at t = 1 s beyond the limit 2 ({beyond} samples)"
    assert f"a: effort 5 at t = 2 s beyond the limit 4 ({int((torques[:, 0] > 4).sum())} samples)" in lines
    assert found.margins["a"]["effort"]["margin"] == pytest.approx(-1.0)
    assert not found.ok and found.as_dict()["violations"] == lines


def test_not_at_rest_and_irregular_rate_are_violations():
    trajectory = sine_trajectory(0.2)
    moving = Trajectory(JOINTS, trajectory.t, trajectory.q, trajectory.qd + 1e-5, trajectory.qdd)
    checked = check_trajectory(moving, LIMITS, None, None, NotChecked("x"), margins=NO_MARGIN)
    lines = [v.line() for v in checked.violations]
    assert lines == [
        "a: not at rest at t = 0 s: |qd| = 1e-05 > 1e-06",
        "b: not at rest at t = 0 s: |qd| = 1e-05 > 1e-06",
        "a: not at rest at t = 2 s: |qd| = 1e-05 > 1e-06",
        "b: not at rest at t = 2 s: |qd| = 1e-05 > 1e-06",
    ]
    t = trajectory.t.copy()
    t[50:] += 0.004  # a 14 ms step where 10 ms are due
    jumpy = Trajectory(JOINTS, t, trajectory.q, trajectory.qd, trajectory.qdd)
    (violation,) = check_trajectory(jumpy, LIMITS, None, None, NotChecked("x"), margins=NO_MARGIN).violations
    assert violation.line() == "t: step 0.014 s after t = 0.49 s, expected 0.01 s (±1e-06 relative)"


def test_time_going_backwards_is_named_by_its_sample_not_as_a_step_size():
    trajectory = sine_trajectory(0.2)
    t = trajectory.t.copy()
    t[[60, 61]] = t[[61, 60]]  # two rows swapped: 0.61 s then 0.60 s
    swapped = Trajectory(JOINTS, t, trajectory.q, trajectory.qd, trajectory.qdd)
    found = check_trajectory(swapped, LIMITS, None, None, NotChecked("x")).violations
    lines = [v.line() for v in found if v.subject == "t"]
    assert lines[0] == "t: time goes backwards at sample 61: t = 0.6 s after t = 0.61 s"
    assert lines[1].startswith("t: step 0.02 s after t = 0.59 s")  # the forward step around the swap
    t = trajectory.t.copy()
    t[30] = t[29]
    repeated = Trajectory(JOINTS, t, trajectory.q, trajectory.qd, trajectory.qdd)
    found = check_trajectory(repeated, LIMITS, None, None, NotChecked("x")).violations
    lines = [v.line() for v in found if v.subject == "t"]
    assert lines[0] == "t: time repeats at sample 30: t = 0.29 s after t = 0.29 s"


@pytest.mark.parametrize("rate", [100.0, 1000.0])
def test_derivative_columns_that_are_not_the_derivatives_are_violations(rate):
    """A robot follows the positions: ``qd`` in another unit, or ``t`` in milliseconds with ``qd`` per
    second, made the check pass a motion ten times faster than its limits ("all checks passed")."""
    trajectory = sine_trajectory(0.2, rate)
    assert check_trajectory(trajectory, LIMITS, None, None, NotChecked("x"), margins=NO_MARGIN).ok
    t, q, qd, qdd = trajectory.t, trajectory.q, trajectory.qd, trajectory.qdd
    for wrong, flagged in (
        (Trajectory(JOINTS, t / 10, q, qd, qdd), {"qd", "qdd"}),  # the same samples, ten times as fast
        (Trajectory(JOINTS, t, q, np.degrees(qd), qdd), {"qd", "qdd"}),
        (Trajectory(JOINTS, t, q, qd, qdd / 2), {"qdd"}),
    ):
        found = check_trajectory(wrong, LIMITS, None, None, NotChecked("x"), margins=NO_MARGIN).violations
        derivatives = [v for v in found if v.quantity.endswith("derivative")]
        assert {v.quantity.split()[0] for v in derivatives} == flagged
        assert {v.subject for v in derivatives} == set(JOINTS)
    (first, *_) = check_trajectory(
        Trajectory(JOINTS, t / 10, q, qd, qdd), LIMITS, None, None, NotChecked("x"), margins=NO_MARGIN
    ).violations
    assert re.fullmatch(
        r"a: qd \S+ at t = \S+ s where q changes at \S+/s \(\d+ samples\): not q's derivative \(qd in "
        r"another unit, or t not in seconds\?\)",
        first.line(),
    )
    assert first.limit == pytest.approx(10 * first.value, rel=0.02)


def test_contacts_are_violations_with_their_first_time():
    pytest.importorskip("pinocchio")
    robot = URDFRobot(ARM_URDF)
    t = controller_times(1.0, 100.0)
    q = torch.zeros(101, 4, dtype=torch.float64)
    q[:, 1] = 1.2 * t  # q2 crosses the touching angle at t = TOUCH / 1.2
    trajectory = Trajectory.of(robot.joint_names, t, q, torch.zeros_like(q), torch.zeros_like(q))
    limits = robot.motion_limits().replace("acceleration", -1.0, 1.0)
    found = check_trajectory(trajectory, limits, None, None, self_collision(robot))
    contact = [v for v in found.violations if v.quantity == "self-collision"]
    first = math.ceil(TOUCH / 1.2 * 100 + 1e-9) / 100
    assert (
        contact[0].line()
        == f"arm–table: in contact at t = {first:.6g} s ({101 - round(first * 100)} samples)"
    )
    assert found.collision.startswith("checked with pinocchio + coal")


@pytest.fixture
def arm_file(tmp_path):
    """An arm motion at rest at both ends, inside its limits, with q2 reaching ``reach``."""

    def write(reach: float, suffix: str = ".csv"):
        robot = URDFRobot(ARM_URDF)
        family = FourierExcitation(
            4, 3, 6.0, offset=[0, 0, 0, 0], a=[[0.3, -0.1, -0.2]] * 4, b=[[0.1, 0.2, -0.1]] * 4, rest=True
        )
        t = controller_times(6.0, 500.0)
        q, qd, qdd = family(t)
        scale = reach / float(q[:, 1].max())
        trajectory = Trajectory.of(robot.joint_names, t, q * scale, qd * scale, qdd * scale)
        path = tmp_path / f"arm{suffix}"
        if suffix == ".csv":
            return files.write_csv(path, columns(trajectory.joint_names), trajectory.rows().tolist())
        return files.write_npz(path, trajectory.arrays())

    urdf = tmp_path / "arm.urdf"
    urdf.write_text(ARM_URDF)
    return write, str(urdf)


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_command_line_exit_status_and_lines(arm_file, capsys, suffix):
    write, urdf = arm_file
    assert main([str(write(0.5, suffix)), "--robot", urdf]) == 0
    out = capsys.readouterr().out
    assert (
        "acceleration limits ±[" in out and "the effort-derived default" in out and "all checks passed" in out
    )
    assert (
        "| j2 |" in out
        and "effort: checked" in out
        and "self-collision: checked with pinocchio + coal" in out
    )
    assert main([str(write(1.0, suffix)), "--robot", urdf, "--acceleration-limit", "0.5"]) == 1
    lines = capsys.readouterr().out.splitlines()
    assert lines[-7] == "6 violation(s) (required margins: 5 % of each limit's half-range)"
    assert [line.split(": ")[0] for line in lines[-6:]] == ["j1", "j2", "j3", "j4", "arm–table", "hand–table"]
    assert all(" acceleration " in line and "beyond the limit -0.5" in line for line in lines[-6:-2])
    assert lines[-2].startswith("arm–table: in contact at t = ")


def test_command_line_margin_option(arm_file, capsys):
    write, urdf = arm_file
    path = str(write(0.5))
    assert main([path, "--robot", urdf, "--no-collision", "--margin", "0.9"]) == 1
    out = capsys.readouterr().out
    assert "within the 90 % safety margin" in out and "required margins: 90 %" in out
    assert main([path, "--robot", urdf, "--no-collision", "--margin", "position=0", "effort=0.2"]) == 0
    assert "position 0 %, velocity 5 %, acceleration 5 %, effort 20 %" in capsys.readouterr().out
    for bad in (["2"], ["torque=0.1"], ["x"]):
        assert main([path, "--robot", urdf, "--margin", *bad]) == 2
        (line,) = capsys.readouterr().err.splitlines()
        assert line.startswith("idkit: --margin")


def test_command_line_refuses_unusable_input_in_one_line(arm_file, tmp_path, capsys):
    _, urdf = arm_file
    assert main([str(tmp_path / "none.csv"), "--robot", urdf]) == 2
    assert capsys.readouterr().err == f"idkit: data file not found: {tmp_path / 'none.csv'}\n"
    assert main([str(tmp_path / "none.csv"), "--robot", urdf, "--acceleration-limit", "1", "2"]) == 2
    assert "one positive number or one per joint (4: j1, j2, j3, j4)" in capsys.readouterr().err


def test_runs_as_a_module(arm_file):
    write, urdf = arm_file
    done = subprocess.run(
        [sys.executable, "-m", "idkit.excitation.check", str(write(0.5)), "--robot", urdf, "--no-collision"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    assert "self-collision: not checked (switched off (--no-collision))" in done.stdout


def test_torques_of_the_check_are_the_nominal_model():
    robot = URDFRobot(ARM_URDF)
    q = torch.tensor([[0.1, 0.2, 0.3, 0.4]], dtype=torch.float64)
    tau = nominal_torques(robot, q, torch.zeros_like(q), torch.zeros_like(q))
    # Holding the arm against gravity about j2 (+y tilts the arm's +x down): arm 1.5 kg at x = 0.3,
    # wrist 0.3 kg at x = 0.6, hand 0.4 kg at x = 0.6 and 0.05 along z turned by q3 about x.
    moment = (1.5 * 0.3 + 0.3 * 0.6 + 0.4 * 0.6) * math.cos(0.2) + 0.4 * 0.05 * math.cos(0.3) * math.sin(0.2)
    assert float(tau[0, 1]) == pytest.approx(-9.81 * moment, rel=1e-12)
