"""The scoring band's filter (band_limit) and the cut-off chosen by cross-validation (choose_cutoff)."""

from __future__ import annotations

import functools
import re
from dataclasses import replace

import numpy as np
import pytest
import torch
from scipy import signal

from idkit.data.cutoff import CANDIDATES_HZ, candidates, choose_cutoff
from idkit.data.preprocess import PreprocessOptions, band_limit, preprocess
from idkit.data.recording import Recording
from idkit.robots.urdf import URDFRobot


def test_band_limit_is_sosfiltfilt_on_uniform_samples():
    rng = np.random.default_rng(0)
    t = np.arange(2000) / 200.0
    x = rng.normal(size=(2000, 3))
    sos = signal.butter(4, 6.0, fs=200.0, output="sos")
    expected = signal.sosfiltfilt(sos, x, axis=0, padlen=100)  # 3 / 6 Hz of odd extension at 200 Hz
    np.testing.assert_allclose(band_limit(t, x, 6.0), expected, atol=1e-12)


def test_band_limit_keeps_the_motion_and_removes_what_lies_above_on_jittered_stamps():
    rng = np.random.default_rng(1)
    t = np.cumsum((1 + 0.3 * rng.uniform(-1, 1, 4000)) / 200.0)
    motion = np.sin(2 * np.pi * 0.7 * t)
    vibration = 0.1 * np.sin(2 * np.pi * 25.0 * t)
    inner = slice(200, -200)  # away from the ends, where the padding guesses
    # the motion passes (gain 1 - 1e-7 at 0.7 Hz; the linear resampling costs 1.2e-4 measured)
    assert np.abs(band_limit(t, motion[:, None], 6.0)[:, 0] - motion)[inner].max() < 2e-4
    # 25 Hz is cut by 1e-10, but resampling it linearly at stamps jittered by ±30 % folds ~2 % of its
    # amplitude into the band (1.6e-3 measured)
    filtered = band_limit(t, (motion + vibration)[:, None], 6.0)[:, 0]
    assert np.abs(filtered - motion)[inner].max() < 2.5e-3


def test_band_limit_never_filters_across_a_gap():
    t = np.concatenate([np.arange(400), 1000 + np.arange(400)]) / 200.0
    x = np.concatenate([np.zeros(400), np.ones(400)])[:, None]
    np.testing.assert_allclose(band_limit(t, x, 6.0), x, atol=1e-12)


def test_band_limit_refuses_a_band_at_or_above_nyquist():
    with pytest.raises(ValueError, match=r"cutoff 60 Hz is not between 0 and the Nyquist frequency 50 Hz"):
        band_limit(np.arange(100) / 100.0, np.zeros((100, 1)), 60.0)


def test_preprocess_needs_a_number_for_the_cutoff():
    recording = Recording(np.arange(400) / 200.0, np.zeros((400, 1)), np.zeros((400, 1)), source="r.csv")
    with pytest.raises(ValueError, match=r"^preprocess \(r\.csv\): cutoff='auto' is chosen with the robot's"):
        preprocess(recording, PreprocessOptions(cutoff="auto"))


@functools.cache
def arm() -> URDFRobot:
    return URDFRobot("cylindrical", friction=True)


def recording(position_noise: float, seed: int = 0, rate: float = 200.0, seconds: float = 30.0) -> Recording:
    """A raw recording of the friction cylindrical arm: 0.1-0.6 Hz motion, torques with 0.5 % noise,
    positions with ``position_noise`` rad of white noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / rate)
    w = 2 * np.pi * np.array([0.1, 0.23, 0.6])
    phase = rng.uniform(0, 2 * np.pi, (3, 3))
    amplitude = np.array([0.6, 0.1, 0.3])[:, None] / np.arange(1, 4)
    arg = w[None, None, :] * t[:, None, None] + phase[None]
    q = np.array([0.0, 0.4, 0.5]) + (amplitude[None] * np.sin(arg)).sum(-1)
    qd = (amplitude[None] * w * np.cos(arg)).sum(-1)
    qdd = -(amplitude[None] * w**2 * np.sin(arg)).sum(-1)
    robot = arm()
    params = robot.nominal_params().clone()
    params[-6:] = 0.3
    tau = robot.inverse_dynamics(params, *(torch.from_numpy(a) for a in (q, qd, qdd))).numpy()
    tau += 0.005 * np.sqrt((tau**2).mean(0)) * rng.standard_normal(tau.shape)
    return Recording(t, q + position_noise * rng.standard_normal(q.shape), tau, source="arm.csv")


def regressor(samples):
    return arm().regressor(samples.q, samples.qd, samples.qdd)


def test_noisier_positions_choose_a_lower_cutoff():
    """Position noise, twice differentiated, is what a high cut-off lets in: without it every cut-off
    above the motion's band scores the same (the torques are not filtered, so the cut-off only shapes
    the states), with it the score rises with the cut-off and the choice is low; every candidate is
    scored in the same band."""
    clean = choose_cutoff([recording(0.0)], regressor, PreprocessOptions(), band=6.0)
    noisy = choose_cutoff([recording(3e-4)], regressor, PreprocessOptions(), band=6.0)
    assert set(clean.scores) == set(noisy.scores) == set(CANDIDATES_HZ)
    flat = [clean.scores[c] for c in CANDIDATES_HZ]
    assert max(flat) < 1.01 * min(flat), clean.scores
    rising = [noisy.scores[c] for c in CANDIDATES_HZ]
    assert rising == sorted(rising) and rising[-1] > 3 * rising[0], noisy.scores
    assert noisy.cutoff <= 4.0, noisy.scores
    assert noisy.scores[noisy.cutoff] == min(noisy.scores.values())
    assert noisy.line().startswith(f"cut-off {noisy.cutoff:g} Hz (auto: lowest 5-fold cross-validated")
    assert noisy.to_dict()["scores"][f"{noisy.cutoff:g}"] == noisy.scores[noisy.cutoff]


def test_candidates_stay_below_a_quarter_of_the_sampling_rate():
    slow = recording(0.0, rate=40.0)
    assert candidates([slow], PreprocessOptions()) == [2.0, 3.0, 4.0, 6.0, 8.0]
    assert candidates([slow], PreprocessOptions(decimate=2)) == [2.0, 3.0, 4.0]
    # the slowest recording and a decimation are named (stamps in ms, decimate=1e9 were not)
    fast, slow = (
        replace(recording(0.0), source="fast.csv"),
        replace(recording(0.0, rate=6.0), source="slow.csv"),
    )
    with pytest.raises(ValueError, match=r"is below a quarter of the 6 Hz sampling rate of slow\.csv; give"):
        choose_cutoff([fast, slow], regressor, PreprocessOptions(), band=2.0)
    with pytest.raises(
        ValueError,
        match=r"the 2e-07 Hz sampling rate of fast\.csv keeping every preprocess\.decimate=1000000000-th",
    ):
        choose_cutoff([fast], regressor, PreprocessOptions(decimate=10**9), band=2.0)


def test_a_candidate_the_recording_is_too_short_for_is_left_out_and_said():
    """3 s at 200 Hz: 2 Hz trims 1.5 s at each end, too much to filter; the others are scored."""
    choice = choose_cutoff([recording(0.0, seconds=3.0)], regressor, PreprocessOptions(), band=6.0)
    assert set(choice.scores) == set(CANDIDATES_HZ) - {2.0}
    assert re.search(r"; 2 Hz left out \(2 Hz: preprocess \(arm\.csv\): .* leaves no samples", choice.reason)
