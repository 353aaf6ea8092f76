"""Raw recordings: CSV/npz loading with located errors, validation, stacking of samples."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit.data.recording import Recording, load_recording, stack_samples
from idkit.problem import Samples


def write_csv(path, header, rows):
    path.write_text(",".join(header) + "\n" + "\n".join(",".join(map(str, r)) for r in rows) + "\n")
    return path


def test_csv_with_and_without_velocities(tmp_path):
    rows = [[0.0, 0.1, 0.2, 1.0, 2.0], [0.01, 0.11, 0.21, 1.1, 2.1], [0.02, 0.12, 0.22, 1.2, 2.2]]
    recording = load_recording(write_csv(tmp_path / "a.csv", ["t", "q1", "q2", "tau1", "tau2"], rows))
    np.testing.assert_array_equal(recording.q, [[0.1, 0.2], [0.11, 0.21], [0.12, 0.22]])
    assert recording.qd is None and recording.n_joints == 2
    header = ["tau1", "qd1", "t", "q1", "note"]
    recording = load_recording(write_csv(tmp_path / "b.csv", header, [[1, 5, 0, 2, 9], [1, 6, 1, 3, 9]]))
    np.testing.assert_array_equal(recording.qd, [[5], [6]])
    np.testing.assert_array_equal(recording.t, [0, 1])


@settings(max_examples=20, deadline=None)
@given(n=st.integers(1, 4), N=st.integers(2, 30), velocities=st.booleans(), seed=st.integers(0, 2**16))
def test_npz_round_trip(tmp_path_factory, n, N, velocities, seed):
    rng = np.random.default_rng(seed)
    arrays = {
        "t": np.cumsum(rng.uniform(0.001, 0.01, N)),
        "q": rng.normal(size=(N, n)),
        "tau": rng.normal(size=(N, n)),
    }
    if velocities:
        arrays["qd"] = rng.normal(size=(N, n))
    path = tmp_path_factory.mktemp("rec") / "r.npz"
    np.savez(path, **arrays)
    recording = load_recording(path)
    arrays["t"] = arrays["t"] - arrays["t"][0]  # read as seconds from the first stamp
    for k, v in arrays.items():
        np.testing.assert_array_equal(getattr(recording, k), v)


@pytest.mark.parametrize(
    ("header", "rows", "message"),
    [
        (["q1", "tau1"], [[0, 1], [1, 2]], r"header must have columns t; found \['q1', 'tau1'\]"),
        (
            ["t", "q1", "q2", "tau1"],
            [[0, 1, 2, 3], [1, 1, 2, 3]],
            r"joints \(q 2, tau 1\)",
        ),
        (
            ["t", "q1", "tau1"],
            [[0, 1, 2], [1, "x", 2]],
            r"line 3 \(sample 1\), column 'q1': not a number",
        ),
        (["t", "q1", "tau1"], [[0, 1, 2], [0, 1, 2]], r"t\[1\] = 0.0 follows t\[0\] = 0.0"),
        (
            ["t", "q2", "tau2"],
            [[0, 1, 2], [1, 1, 2]],
            "numbered from 1 without gaps; found q2",
        ),
    ],
)
def test_bad_csv_is_located(tmp_path, header, rows, message):
    with pytest.raises(ValueError, match=message):
        load_recording(write_csv(tmp_path / "bad.csv", header, rows))


def test_missing_file_and_arrays(tmp_path):
    with pytest.raises(FileNotFoundError, match="data file not found"):
        load_recording(tmp_path / "none.npz")
    np.savez(tmp_path / "x.npz", times=np.arange(3.0))
    with pytest.raises(ValueError, match=r"missing array\(s\) \['t', 'q', 'tau'\]"):
        load_recording(tmp_path / "x.npz")
    with pytest.raises(ValueError, match="non-finite value at sample 1"):
        Recording(np.arange(2.0), np.array([[0.0], [np.nan]]), np.zeros((2, 1)))


def test_stacking_concatenates_and_checks_joints():
    a = Samples(*(torch.full((3, 2), float(k)) for k in range(4)))
    b = Samples(*(torch.full((2, 2), float(k + 10)) for k in range(4)))
    stacked = stack_samples([a, b])
    assert stacked.n_samples == 5
    np.testing.assert_array_equal(stacked.tau[:, 0].numpy(), [3, 3, 3, 13, 13])
    c = Samples(*(torch.zeros(2, 3) for _ in range(4)))
    with pytest.raises(ValueError, match="test.npz has 3 joints but train.npz has 2"):
        stack_samples([a, c], ["train.npz", "test.npz"])
    with pytest.raises(ValueError, match="no recordings"):
        stack_samples([])


@settings(max_examples=20, deadline=None)
@given(
    n_samples=st.integers(2, 8),
    n_joints=st.integers(1, 4),
    with_qd=st.booleans(),
    seed=st.integers(0, 2**16),
)
def test_save_recording_round_trips_exactly(tmp_path_factory, n_samples, n_joints, with_qd, seed):
    from idkit.data.recording import save_recording

    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(1e-3, 1.0, n_samples)) + rng.uniform(0, 1e9)
    q, tau, qd = (rng.normal(size=(n_samples, n_joints)) * 10.0 ** rng.integers(-6, 6) for _ in range(3))
    original = Recording(t, q, tau, qd if with_qd else None)
    path = save_recording(original, tmp_path_factory.mktemp("rec") / "raw.csv", velocities=with_qd)
    back = load_recording(path)
    # from the first stamp: the written decimals' difference, within a unit of the last place of t
    np.testing.assert_allclose(back.t, original.t - original.t[0], rtol=0, atol=np.spacing(original.t[-1]))
    for name in ("q", "tau"):
        np.testing.assert_array_equal(getattr(back, name), getattr(original, name))
    assert (back.qd is None) == (not with_qd)
    if with_qd:
        np.testing.assert_array_equal(back.qd, qd)


def test_export_command_writes_a_raw_csv_from_flobaroid_names(tmp_path, capsys):
    from idkit.data.recording import FLOBAROID_RECORDING_KEYS, main

    t, q, tau = np.arange(5.0) + 100.0, np.ones((5, 2)), np.zeros((5, 2))
    source = tmp_path / "m.npz"
    names = FLOBAROID_RECORDING_KEYS
    np.savez(source, **{names["t"]: t, names["q"]: q, names["tau"]: tau, "accelerations": q})
    main([str(source), str(tmp_path / "raw.csv")])
    assert "5 samples, 2 joints" in capsys.readouterr().out
    assert (tmp_path / "raw.csv").read_text().splitlines()[0] == "t,q1,q2,tau1,tau2"
    np.testing.assert_array_equal(load_recording(tmp_path / "raw.csv").t, t - t[0])
