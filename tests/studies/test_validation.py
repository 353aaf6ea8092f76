"""Held-out validation metrics: by hand, standard vs base parameters, effort limits from the URDF."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from idkit import registry
from idkit.data.scenarios import simulate
from idkit.problem import Samples
from idkit.robots.urdf import URDFRobot
from idkit.studies.validation import effort_limits, validate


class Constant:
    """A stand-in robot whose prediction is a fixed array (to check the metrics by hand)."""

    joint_names = ("a", "b")
    param_names = ("unused",)
    n_joints = 2

    def __init__(self, predicted: torch.Tensor) -> None:
        self.predicted = predicted

    def inverse_dynamics(self, params, q, qd, qdd):
        return self.predicted


def test_metrics_by_hand():
    measured = torch.tensor([[1.0, -2.0], [3.0, 2.0]], dtype=torch.float64)
    predicted = torch.tensor([[0.0, -2.0], [3.0, 0.0]], dtype=torch.float64)
    samples = Samples(torch.zeros(2, 2), torch.zeros(2, 2), torch.zeros(2, 2), measured)
    v = validate(Constant(predicted), samples, torch.zeros(1), effort=np.array([10.0, 4.0]))
    np.testing.assert_allclose(v.rms, [np.sqrt(0.5), np.sqrt(2.0)])
    np.testing.assert_allclose(v.relative, [np.sqrt(0.5) / np.sqrt(5.0), np.sqrt(2.0) / np.sqrt(4.0)])
    assert v.rel_all == pytest.approx(np.sqrt(5.0) / np.sqrt(18.0))
    assert v.nrms_limit == pytest.approx(np.sqrt((0.1**2 + 0.5**2) / 4))
    np.testing.assert_array_equal(v.predicted, predicted.numpy())
    assert validate(Constant(predicted), samples, torch.zeros(1)).nrms_limit is None


def test_base_and_standard_parameters_score_the_same():
    robot = URDFRobot("cylindrical", friction=True)
    truth = robot.nominal_params().clone()
    truth[-6:] = 0.3
    samples = simulate(robot, "torque_noise", seed=0, n_samples=50, params=truth)
    by_standard = validate(robot, samples, truth)
    by_base = validate(robot, samples, base_params=robot.base_params(truth))
    np.testing.assert_allclose(by_base.predicted, by_standard.predicted, atol=1e-10)
    assert 0 < by_standard.rel_all < 0.2
    np.testing.assert_array_equal(effort_limits(robot), [1000.0, 1000.0, 1000.0])
    assert by_standard.nrms_limit == pytest.approx(
        np.sqrt((((by_standard.measured - by_standard.predicted) / 1000.0) ** 2).mean())
    )


def test_mismatched_inputs_are_named():
    robot = registry.create("robot", "cylindrical")
    samples = Samples(*(torch.zeros(4, 2) for _ in range(4)))
    with pytest.raises(ValueError, match="samples have 2 joints but robot CylindricalRobot has 3"):
        validate(robot, samples, torch.ones(4))
    with pytest.raises(ValueError, match="exactly one of params"):
        validate(robot, samples)


def test_torques_are_compared_in_the_fixed_band_on_their_timestamps():
    """Above the 6 Hz band (sensor noise, vibration) nothing counts; inside it everything does."""
    t = np.arange(4000) / 200.0
    measured = np.stack([10 * np.sin(2 * np.pi * 0.3 * t), 5 * np.cos(2 * np.pi * 0.5 * t)], 1)
    samples = Samples(*(torch.zeros(4000, 2, dtype=torch.float64),) * 3, torch.from_numpy(measured))
    quiet_ends = np.hanning(t.size)[:, None]  # the padding at the ends would pass a kink of the error
    above = measured + 0.5 * quiet_ends * np.sin(2 * np.pi * 30.0 * t)[:, None]
    inside = measured + 0.5 * np.sin(2 * np.pi * 1.0 * t)[:, None]
    high = validate(Constant(torch.from_numpy(above)), samples, torch.zeros(1), times=t)
    low = validate(Constant(torch.from_numpy(inside)), samples, torch.zeros(1), times=t)
    raw = 0.5 / np.sqrt(2) / np.sqrt((measured**2).mean())  # the unfiltered figure of a 0.5 sine error
    assert high.band == low.band == 6.0
    assert high.rel_all < 1e-6 and high.rel_all_raw == pytest.approx(np.sqrt(3 / 8) * raw, rel=1e-2)
    assert low.rel_all == pytest.approx(raw, rel=1e-3) and low.rel_all_raw == pytest.approx(raw, rel=1e-3)
    assert "both low-passed at 6 Hz" in high.to_dict()["metric"] and high.to_dict()["band_hz"] == 6.0
    slow = validate(Constant(torch.from_numpy(inside)), samples, torch.zeros(1), times=t * 20)  # 10 Hz
    assert slow.band == pytest.approx(4.0)  # 0.4 x the sampling rate below 15 Hz


def test_without_timestamps_the_score_is_unfiltered_and_says_so():
    measured = torch.tensor([[1.0, -2.0], [3.0, 2.0]], dtype=torch.float64)
    samples = Samples(torch.zeros(2, 2), torch.zeros(2, 2), torch.zeros(2, 2), measured)
    v = validate(Constant(measured * 0.5), samples, torch.zeros(1))
    assert v.band is None and v.rel_all == v.rel_all_raw == pytest.approx(0.5)
    assert "unfiltered (the file has no timestamps" in v.metric
