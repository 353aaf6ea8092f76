"""A file checked against its robot before a fit (``idkit.data.plausible``): units, wraps, limits."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from idkit.data.options import DataOptions
from idkit.data.pipeline import read_training
from idkit.data.plausible import LimitWarning
from idkit.robots.urdf import URDFRobot

ASSET = Path(__file__).resolve().parents[2] / "idkit" / "robots" / "assets" / "cylindrical.urdf"
RATE = 200.0
JOINTS = ("theta1", "d2", "d3")  # limits ±π, [0, 1], [0, 1]; velocities 4, 2, 1.5; effort 1000


@pytest.fixture(scope="module")
def robot() -> URDFRobot:
    return URDFRobot(str(ASSET), friction=True, offset=True)


def recording(robot: URDFRobot, seconds: float = 6.0) -> dict[str, np.ndarray]:
    """A motion inside every limit of the cylindrical arm, with its torques: ``t, q, qd, tau``."""
    t = np.arange(0.0, seconds, 1.0 / RATE)
    w = 2 * np.pi * 0.25
    q = np.stack([1.2 * np.sin(w * t), 0.5 + 0.2 * np.sin(1.3 * w * t), 0.5 + 0.3 * np.cos(0.7 * w * t)], 1)
    qd = np.stack(
        [1.2 * w * np.cos(w * t), 0.26 * w * np.cos(1.3 * w * t), -0.21 * w * np.sin(0.7 * w * t)], 1
    )
    qdd = np.gradient(qd, t, axis=0)
    tau = robot.inverse_dynamics(robot.nominal_params(), *(torch.from_numpy(x) for x in (q, qd, qdd))).numpy()
    return {"t": t, "q": q, "qd": qd, "tau": tau}


def write(path: Path, arrays: dict[str, np.ndarray], t: np.ndarray | None = None) -> Path:
    header = ["t", *(f"{j}.q" for j in JOINTS), *(f"{j}.qd" for j in JOINTS), *(f"{j}.tau" for j in JOINTS)]
    columns = [arrays["t"] if t is None else t, arrays["q"], arrays["qd"], arrays["tau"]]
    np.savetxt(
        path, np.column_stack(columns), delimiter=",", header=",".join(header), comments="", fmt="%.17g"
    )
    return path


def read(robot: URDFRobot, path: Path, **preprocess):
    return read_training(robot, path, DataOptions.of({"cutoff": 5.0, **preprocess}))


def test_a_recording_inside_the_limits_is_read_without_a_word(robot, tmp_path):
    path = write(tmp_path / "fine.csv", recording(robot))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read(robot, path, velocities="measured")


def test_positions_in_degrees_are_refused_naming_joint_value_and_unit(robot, tmp_path):
    arrays = recording(robot)
    arrays["q"][:, 0] = np.degrees(arrays["q"][:, 0])
    path = write(tmp_path / "degrees.csv", arrays)
    with pytest.raises(ValueError) as caught:
        read(robot, path)
    assert str(caught.value) == (
        f"data file {path}: joint theta1's position reaches -68.75, beyond the robot's limits "
        "[-3.142, 3.142]: logged in degrees where radians are due? (divided by the factor it lies within "
        "them); convert the file, or correct the robot's limits if they are wrong"
    )


def test_prismatic_positions_in_millimetres_are_refused(robot, tmp_path):
    arrays = recording(robot)
    arrays["q"][:, 1] *= 1000.0
    with pytest.raises(
        ValueError, match=r"joint d2's position reaches 700, .* logged in millimetres where metres"
    ):
        read(robot, write(tmp_path / "mm.csv", arrays))


def test_a_little_beyond_a_limit_is_said_and_the_fit_goes_on(robot, tmp_path):
    arrays = recording(robot)
    arrays["q"][:, 2] += 0.25  # d3 up to 1.05: another zero?
    with pytest.warns(
        LimitWarning, match=r"joint d3's position reaches 1.05, beyond .* by 0.05: another zero"
    ):
        training = read(robot, write(tmp_path / "offset.csv", arrays))
    assert training.files[0].samples.n_samples > 0


def test_timestamps_in_milliseconds_are_refused_naming_the_unit(robot, tmp_path):
    arrays = recording(robot)
    path = write(tmp_path / "ms.csv", arrays, t=arrays["t"] * 1e3)
    with pytest.raises(ValueError) as caught:
        read(robot, path)
    assert str(caught.value) == (
        f"data file {path}: the timestamps step by a median 5 (0.2 Hz in seconds): milliseconds where "
        "seconds are due? idkit reads t in seconds; convert the time column"
    )
    stamps = np.round(arrays["t"] * 1e9) + 1.7e18
    with pytest.raises(ValueError, match=r"step by a median 5e\+06 .*: nanoseconds where seconds are due"):
        read(robot, write(tmp_path / "ns.csv", arrays, t=stamps))


def test_an_angle_wrapped_at_pi_is_refused_where_it_jumps(robot, tmp_path):
    arrays = recording(robot, seconds=8.0)
    arrays["q"][:, 0] *= 2.0  # up to 2.4 rad: inside ±π
    arrays["q"][:, 0] = np.angle(np.exp(1j * (arrays["q"][:, 0] + 1.5)))  # an encoder wrapping at ±π
    path = write(tmp_path / "wrapped.csv", arrays)
    with pytest.raises(
        ValueError, match=r"joint theta1's position jumps by -6\.2\d* between samples \d+ and"
    ):
        read(robot, path)
    arrays["q"][:, 0] = np.unwrap(arrays["q"][:, 0]) - 1.5
    read(robot, write(tmp_path / "unwrapped.csv", arrays))


def test_a_jump_across_a_gap_is_not_a_wrap(robot, tmp_path):
    """Two recordings in one file: the positions jump where the time does, and preprocessing splits."""
    arrays = recording(robot)
    half = arrays["t"].size // 2
    arrays["t"] = arrays["t"] + np.where(np.arange(arrays["t"].size) >= half, 60.0, 0.0)
    arrays["q"][half:, 0] -= 1.5
    with pytest.warns(UserWarning, match=r"gap"):
        read(robot, write(tmp_path / "two.csv", arrays))


def test_velocities_beyond_their_limits_are_said_with_the_unit(robot, tmp_path):
    arrays = recording(robot)
    arrays["qd"][:, 0] = np.degrees(arrays["qd"][:, 0])
    path = write(tmp_path / "deg_per_s.csv", arrays)
    with pytest.warns(
        LimitWarning, match=r"joint theta1's velocity reaches .* degrees where radians are due\?"
    ):
        read(robot, path, velocities="measured")
    with warnings.catch_warnings():  # differentiated: the file's velocities are not used
        warnings.simplefilter("error")
        read(robot, path)


def test_degrees_on_a_joint_without_position_limits_are_said_by_their_speed(tmp_path):
    """A continuous joint has no position limits to catch degrees (fitted without a word before); its
    velocity limit does, on the positions' rate of change where the file's velocities are not used."""
    urdf = tmp_path / "continuous.urdf"
    urdf.write_text(
        ASSET.read_text().replace('name="theta1" type="revolute"', 'name="theta1" type="continuous"')
    )
    robot = URDFRobot(str(urdf), friction=True, offset=True)
    arrays = recording(robot)
    arrays["q"][:, 0] = np.degrees(arrays["q"][:, 0])
    path = write(tmp_path / "degrees.csv", arrays)
    with pytest.warns(LimitWarning) as said:
        read(robot, path)
    (line,) = [str(w.message) for w in said if issubclass(w.category, LimitWarning)]
    assert line.startswith(f"data file {path}: joint theta1's velocity (the positions' rate of change) ")
    assert "beyond the robot's limits [-4, 4] by" in line and line.endswith(
        ": degrees where radians are due?"
    )
    with warnings.catch_warnings():  # in radians: nothing to say, encoder noise and all
        warnings.simplefilter("error")
        noisy = recording(robot)
        noisy["q"] += 1e-3 * np.random.default_rng(0).standard_normal(noisy["q"].shape)
        read(robot, write(tmp_path / "radians.csv", noisy))


def test_torques_beyond_the_effort_limits_or_all_zero_are_said(robot, tmp_path):
    arrays = recording(robot)
    arrays["tau"][:, 2] = 0.0
    scaled = URDFRobot(str(ASSET), friction=True, offset=True, effort_scale=[1e4, 1.0, 1.0])
    with pytest.warns(LimitWarning) as said:
        read(scaled, write(tmp_path / "torques.csv", arrays))
    lines = [str(w.message) for w in said if issubclass(w.category, LimitWarning)]
    assert any(
        "joint theta1's torque reaches" in line and "is robot.effort_scale right" in line for line in lines
    )
    assert any(
        "joint d3's torques are all exactly zero: an effort column or topic left empty?" in line
        for line in lines
    )


def test_a_delay_in_milliseconds_given_as_seconds_is_refused():
    from idkit.data.options import RecordingOptions

    with pytest.raises(ValueError) as caught:
        RecordingOptions(torque_lag=20)
    assert str(caught.value) == (
        "recording.torque_lag=20 s: a torque lag is a filter's or a bus's, milliseconds (at most ±1 s here); "
        "milliseconds given as seconds? (20 ms is 0.02)"
    )
    assert RecordingOptions(torque_lag=-0.02).torque_lag == -0.02


def test_the_old_name_recording_delay_still_works_and_says_it_is_deprecated():
    from idkit.data.options import RecordingOptions

    with pytest.warns(FutureWarning, match="recording.delay is now recording.torque_lag"):
        options = RecordingOptions(delay=0.01)
    assert options.torque_lag == 0.01 and options.delay is None
    with pytest.warns(FutureWarning), pytest.raises(ValueError, match=r"^recording.delay=20 s: a torque lag"):
        RecordingOptions(delay=20)
    with pytest.raises(ValueError, match="are both set; give recording.torque_lag only"):
        RecordingOptions(torque_lag=0.02, delay=0.01)
