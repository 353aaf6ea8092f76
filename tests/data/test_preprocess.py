"""Preprocessing of raw recordings: error bounds on signals with known derivatives, and the KUKA files."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from idkit.data.preprocess import GapWarning, PreprocessOptions, preprocess, preprocess_recording
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
    done = preprocess_recording(recording, options)
    samples, times = done.samples, done.times
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
    done = preprocess_recording(with_qd, PreprocessOptions(velocities="measured"))
    samples, times = done.samples, done.times
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
        (PreprocessOptions(trim=30.0), r"leaves no samples after trimming 30 s \(preprocess\.trim\) at"),
        (PreprocessOptions(min_speed=100.0), "drops every sample"),
    ],
)
def test_bad_options_are_explained(options, message):
    with pytest.raises(ValueError, match=message):
        preprocess(jittered(seed=3, noise=0.0, seconds=5.0), options)


def test_a_rate_whose_grid_does_not_fit_in_memory_is_refused_before_resampling(monkeypatch):
    """``rate=1e9`` used to reach numpy ("Unable to allocate 89.4 GiB") without naming the option."""
    import idkit.memory

    monkeypatch.setattr(idkit.memory, "available_memory", lambda: 1_000_000)  # a machine with 1 MB free
    recording = jittered(seed=3, noise=0.0, seconds=5.0)  # 3 joints, 200 Hz: ~1000 points at its own rate
    assert preprocess(recording, PreprocessOptions()).n_samples > 0  # ~16 kB of grids: fits
    # 5 s at 1e5 Hz: 5e5 points × (5 arrays × 3 joints + the grid) × 8 B = 64 MB
    with pytest.raises(
        ValueError,
        match=r"preprocess\.rate=100000 Hz resamples 4.98 s of 3 joints to 4.98e\+05 points.*63.7 MB",
    ):
        preprocess(recording, PreprocessOptions(rate=1e5))


@pytest.mark.kuka
def test_kuka_accelerations_recomputed_from_positions(kuka_dir):
    """The files' accelerations were low-passed near 2 Hz; recomputed from positions with a 2 Hz
    cut-off they agree to 2.6 % RMS on joints 1, 3, 4, 6, 7 and 13–15 % on joints 2 and 5 (whose
    file accelerations keep 4–8 Hz content our filter removes); velocities agree to 0.3 %."""
    path = kuka_dir / "measurements_1.npz"
    done = preprocess_recording(load_recording(path, FLOBAROID_RECORDING_KEYS), PreprocessOptions(cutoff=2.0))
    samples, times = done.samples, done.times
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


def cut(recording: Recording, rows: slice) -> Recording:
    return Recording(recording.t[rows], recording.q[rows], recording.tau[rows], source=recording.source)


def with_gap(seconds: float, at: int = 1500, rate: float = 200.0) -> Recording:
    """A clean 3-joint recording at ``rate`` whose timestamps jump by ``seconds`` after sample ``at``."""
    t = np.arange(3000) / rate
    t[at:] += seconds
    q = np.stack([exact(t, j)[0] for j in range(3)], 1)
    return Recording(t, q, np.stack([exact(t, j)[2] for j in range(3)], 1), source="gap.csv")


@pytest.mark.parametrize("seconds", [2.0, 5.0, 0.03])
def test_a_gap_splits_the_recording_and_is_never_interpolated_across(seconds):
    recording = with_gap(seconds)
    options = PreprocessOptions(rate=200.0)  # the median step of one stretch may differ in its last bit
    with pytest.warns(GapWarning) as said:
        done = preprocess_recording(recording, options)
    # Independent reference: the two stretches preprocessed as recordings of their own, stacked.
    first = preprocess_recording(cut(recording, slice(0, 1500)), options)
    second = preprocess_recording(cut(recording, slice(1500, None)), options)
    for name in ("q", "qd", "qdd", "tau"):
        expected = np.concatenate(
            [getattr(first.samples, name).numpy(), getattr(second.samples, name).numpy()]
        )
        np.testing.assert_array_equal(getattr(done.samples, name).numpy(), expected)
    gap_start, gap_end = recording.t[1499] - recording.t[0], recording.t[1500] - recording.t[0]
    assert not ((done.times > gap_start) & (done.times < gap_end)).any()
    assert [(s.raw, s.too_short) for s in done.segments] == [(1500, False), (1500, False)]
    assert len(said) == 1 and str(said[0].message) == done.note
    assert done.note == (
        f"gap.csv: 1 gap(s) in the timestamps longer than 5 median steps (25 ms) at t = "
        f"{gap_start:.6g}–{gap_end:.6g} s; not interpolated across: 2 segments preprocessed separately and "
        "stacked"
    )


def test_a_step_within_max_gap_is_resampled_across_as_jitter():
    """4 lost samples (a 5-step hole) are not a gap at the default max_gap=5; a smaller max_gap splits."""
    recording = with_gap(4 / 200.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", GapWarning)
        assert preprocess_recording(recording).note is None
    with pytest.warns(GapWarning, match="longer than 3 median steps"):
        assert len(preprocess_recording(recording, PreprocessOptions(max_gap=3)).segments) == 2


def test_segments_too_short_to_filter_are_dropped_and_counted():
    recording = with_gap(2.0, at=40)  # 40 samples = 0.2 s, less than the 2 x 0.3 s trims
    with pytest.warns(
        GapWarning, match=r"dropped 1 segment\(s\) shorter than the 123 samples filtering needs "
    ):
        done = preprocess_recording(recording)
    assert [(s.raw, s.kept, s.too_short) for s in done.segments] == [(40, 0, True), (2960, 2840, False)]
    assert "(40 raw samples: 0–0.195 s)" in done.note
    short = Recording(recording.t[:80], recording.q[:80], recording.tau[:80], source="short.csv")
    short = Recording(np.r_[short.t[:40], short.t[40:] + 5.0], short.q, short.tau, source="short.csv")
    with pytest.raises(ValueError, match=r"short\.csv\): .* any of the 2 segments between gaps"):
        preprocess_recording(short)


def test_unordered_or_repeated_timestamps_are_refused_naming_the_sample():
    t = np.arange(6) / 100.0
    for bad, message in (
        (np.r_[t[:3], t[2], t[4:]], r"t\[3\] = 0.02 follows t\[2\] = 0.02"),
        (np.r_[t[:3], t[1], t[4:]], r"t\[3\] = 0.01 follows t\[2\] = 0.02"),
    ):
        with pytest.raises(ValueError, match=r"^x\.csv: timestamps must increase strictly; " + message):
            Recording(bad, np.zeros((6, 1)), np.zeros((6, 1)), source="x.csv")
    with pytest.raises(
        ValueError, match=r"^preprocess\.max_gap must be a number of median steps > 1, got 1\.0$"
    ):
        PreprocessOptions(max_gap=1.0)
