"""Preprocessing of raw recordings: error bounds on signals with known derivatives, and the KUKA files."""

from __future__ import annotations

import numpy as np
import pytest

from idkit.data.preprocess import PreprocessOptions, preprocess, preprocess_with_times
from idkit.data.recording import FLOBAROID_RECORDING_KEYS, Recording, load_recording

FREQS = np.array([0.2, 0.5, 1.3])  # Hz: the band of an identification trajectory
AMPS = np.array([0.5, 0.3, 0.1])  # rad


def exact(t: np.ndarray, joint: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A sum of sines and its exact first and second derivatives at ``t``."""
    w = 2 * np.pi * FREQS
    arg = np.outer(t, w) + 0.7 * (joint + 1) * np.arange(1, 4)
    return np.sin(arg) @ AMPS, (w * np.cos(arg)) @ AMPS, (-(w**2) * np.sin(arg)) @ AMPS


def jittered(seed: int, noise: float, rate: float = 200.0, seconds: float = 20.0, n: int = 3) -> Recording:
    """Timestamps with ±30 % jitter around ``1/rate``; positions with Gaussian noise (rad)."""
    rng = np.random.default_rng(seed)
    t = 1.0 + np.cumsum((1 + 0.3 * rng.uniform(-1, 1, int(seconds * rate))) / rate)
    q = np.stack([exact(t, j)[0] for j in range(n)], 1) + noise * rng.normal(size=(t.size, n))
    tau = np.stack([exact(t, j)[2] for j in range(n)], 1)
    return Recording(t, q, tau)


def relative_errors(recording: Recording, options: PreprocessOptions) -> dict[str, np.ndarray]:
    samples, times = preprocess_with_times(recording, options)
    t = times + recording.t[0]
    out = {}
    for k, name in enumerate(("q", "qd", "qdd")):
        reference = np.stack([exact(t, j)[k] for j in range(samples.n_joints)], 1)
        error = getattr(samples, name).numpy() - reference
        out[name] = np.sqrt((error**2).mean(0) / (reference**2).mean(0))
    return out


@pytest.mark.parametrize(
    ("noise", "bounds"),
    [
        # Noise-free: linear interpolation of the jittered samples dominates (measured 3e-5 / 3e-4 / 9e-4).
        (0.0, {"q": 1e-4, "qd": 1e-3, "qdd": 3e-3}),
        # 1e-4 rad of encoder-like noise, amplified by (2 pi f)^2 up to the 10 Hz cut-off
        # (measured 8e-5 / 1.1e-3 / 9.7e-3).
        (1e-4, {"q": 3e-4, "qd": 3e-3, "qdd": 2e-2}),
    ],
)
def test_derivatives_of_jittered_noisy_sines_are_within_stated_bounds(noise, bounds):
    errors = relative_errors(jittered(seed=0, noise=noise), PreprocessOptions())
    for name, bound in bounds.items():
        assert errors[name].max() < bound, (name, errors[name])


def test_trim_decimate_and_min_speed():
    recording = jittered(seed=1, noise=0.0)
    full = preprocess(recording, PreprocessOptions(trim=0.5))
    rate = 1 / np.median(np.diff(recording.t))
    expected = np.arange(0, recording.t[-1] - recording.t[0] + 0.5 / rate, 1 / rate)
    expected = expected[expected <= recording.t[-1] - recording.t[0]]
    assert full.n_samples == expected.size - 2 * int(np.ceil(0.5 * rate))
    halved = preprocess(recording, PreprocessOptions(trim=0.5, decimate=2))
    assert halved.n_samples == (full.n_samples + 1) // 2
    np.testing.assert_array_equal(halved.q.numpy(), full.q.numpy()[::2])
    moving = preprocess(recording, PreprocessOptions(trim=0.5, min_speed=0.3))
    assert 0 < moving.n_samples < full.n_samples
    assert (moving.qd.abs() >= 0.3).all()


def test_measured_velocities_are_filtered_not_differentiated():
    recording = jittered(seed=2, noise=0.0)
    t = recording.t
    qd = np.stack([exact(t, j)[1] for j in range(3)], 1)
    with_qd = Recording(t, recording.q, recording.tau, qd)
    samples, times = preprocess_with_times(with_qd, PreprocessOptions(velocities="measured"))
    reference = np.stack([exact(times + t[0], j)[1] for j in range(3)], 1)
    assert np.abs(samples.qd.numpy() - reference).max() < 1e-3 * np.abs(reference).max()


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (
            PreprocessOptions(rate=200.0, cutoff=120.0),
            r"cutoff 120 Hz is not below the Nyquist frequency 100 Hz",
        ),
        (PreprocessOptions(rate=50.0, cutoff=30.0), r"cutoff 30 Hz is not below the Nyquist frequency 25 Hz"),
        (PreprocessOptions(rate=200.0, cutoff=30.0, decimate=4), r"decimated Nyquist frequency 25 Hz"),
        (PreprocessOptions(velocities="measured"), "has no qd columns"),
        (PreprocessOptions(trim=30.0), "leaves no samples after trimming"),
        (PreprocessOptions(min_speed=100.0), "drops every sample"),
    ],
)
def test_bad_options_are_explained(options, message):
    with pytest.raises(ValueError, match=message):
        preprocess(jittered(seed=3, noise=0.0, seconds=5.0), options)


@pytest.mark.kuka
def test_kuka_accelerations_recomputed_from_positions(kuka_dir):
    """The files' accelerations were low-passed near 2 Hz; recomputed from positions with a 2 Hz
    cut-off they agree to 2.6 % RMS on joints 1, 3, 4, 6, 7 and 13–15 % on joints 2 and 5 (whose
    file accelerations keep 4–8 Hz content our filter removes); velocities agree to 0.3 %."""
    path = kuka_dir / "measurements_1.npz"
    samples, times = preprocess_with_times(
        load_recording(path, FLOBAROID_RECORDING_KEYS), PreprocessOptions(cutoff=2.0)
    )
    with np.load(path) as data:
        t = data["times"] - data["times"][0]
        files = {
            k: np.stack([np.interp(times, t, c) for c in data[v].T], 1)
            for k, v in (("qd", "velocities"), ("qdd", "accelerations"))
        }
    rel = {
        k: np.sqrt(((getattr(samples, k).numpy() - v) ** 2).mean(0) / (v**2).mean(0))
        for k, v in files.items()
    }
    assert rel["qd"].max() < 0.005
    assert rel["qdd"][[0, 2, 3, 5, 6]].max() < 0.03
    assert rel["qdd"][[1, 4]].max() < 0.16
