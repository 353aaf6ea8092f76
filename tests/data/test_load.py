"""One data file → samples: samples files as they are, raw recordings preprocessed, the apply modes."""

from __future__ import annotations

import numpy as np
import pytest

from idkit.data.load import file_kind, load_data_file
from idkit.data.preprocess import PreprocessOptions
from idkit.data.table import read_table


def sines(n: int = 400, rate: float = 100.0):
    t = np.arange(n) / rate
    w = 2 * np.pi * np.array([0.5, 0.8])
    q = np.sin(np.outer(t, w))
    return t, q, np.cos(np.outer(t, w)) * w, -np.sin(np.outer(t, w)) * w**2


def test_kinds_of_files(tmp_path):
    t, q, qd, qdd = sines()
    np.savez(tmp_path / "s.npz", q=q, qd=qd, qdd=qdd, tau=q)
    np.savez(tmp_path / "r.npz", t=t, q=q, tau=q)
    np.savez(tmp_path / "f.npz", times=t, positions=q, velocities=qd, accelerations=qdd, torques=q)
    (tmp_path / "r.csv").write_text("t,q1,tau1\n0,1,2\n1,2,3\n")
    kind = file_kind(read_table(tmp_path / "s.npz"))
    assert (kind.samples, kind.timestamps, kind.flobaroid) == (True, False, False)
    kind = file_kind(read_table(tmp_path / "r.npz"))
    assert (kind.samples, kind.timestamps, kind.flobaroid) == (False, True, False)
    kind = file_kind(read_table(tmp_path / "f.npz"))
    assert (kind.samples, kind.timestamps, kind.flobaroid) == (True, True, True)
    kind = file_kind(read_table(tmp_path / "r.csv"))
    assert (kind.samples, kind.timestamps) == (False, True)
    with pytest.raises(ValueError, match=r"unsupported file type '\.txt'"):
        (tmp_path / "x.txt").write_text("")
        file_kind(read_table(tmp_path / "x.txt"))


def test_apply_modes(tmp_path):
    t, q, qd, qdd = sines()
    np.savez(tmp_path / "f.npz", times=t + 50.0, positions=q, velocities=qd, accelerations=qdd, torques=q)
    np.savez(tmp_path / "s.npz", q=q, qd=qd, qdd=qdd, tau=q)
    np.savez(tmp_path / "r.npz", t=t, q=q, tau=q)
    loaded = load_data_file(tmp_path / "f.npz")  # auto: the file's own derivatives
    samples, times, done = loaded.samples, loaded.times, loaded.preprocessed
    assert not done and np.array_equal(samples.qdd.numpy(), qdd) and times[0] == 0.0
    options = PreprocessOptions(cutoff=5.0)
    loaded = load_data_file(tmp_path / "f.npz", options, "on")
    samples, times, done = loaded.samples, loaded.times, loaded.preprocessed
    trim = int(np.ceil(3.0 / 5.0 * 100.0))
    assert done and samples.n_samples == 400 - 2 * trim and times[0] == pytest.approx(trim / 100.0)
    # idkit's filter recomputes the (exact, slow) accelerations to within the stated (ωh)²/12 order
    middle = slice(20, -20)
    np.testing.assert_allclose(
        samples.qdd.numpy()[middle], qdd[trim:-trim][middle], atol=2e-2 * np.abs(qdd).max()
    )
    with pytest.raises(ValueError, match=r"s\.npz: preprocess=on needs timestamps"):
        load_data_file(tmp_path / "s.npz", options, "on")
    with pytest.raises(ValueError, match=r"r\.npz: a raw recording \(no accelerations qdd\)"):
        load_data_file(tmp_path / "r.npz", options, "off")
    with pytest.raises(ValueError, match=r"preprocess\.apply must be one of auto, on, off, got 'yes'"):
        load_data_file(tmp_path / "r.npz", options, "yes")
    with pytest.raises(FileNotFoundError, match="data file not found"):
        load_data_file(tmp_path / "none.npz")


@pytest.mark.parametrize(
    ("name", "arrays"),
    [("samples.npz", ("q", "qd", "qdd", "tau")), ("raw.npz", ("t", "q", "tau"))],
)
def test_torques_that_are_all_zero_are_refused_naming_the_file(tmp_path, name, arrays):
    """An empty effort column: LS would answer it with zero parameters and exit status 0."""
    t, q, qd, qdd = sines()
    values = {"t": t, "q": q, "qd": qd, "qdd": qdd, "tau": np.zeros_like(q)}
    np.savez(tmp_path / name, **{k: values[k] for k in arrays})
    with pytest.raises(ValueError) as caught:
        load_data_file(tmp_path / name, PreprocessOptions(cutoff=5.0))
    assert str(caught.value) == (
        f"{tmp_path / name}: every torque in the file is exactly zero (400 samples × 2 joints): an empty "
        "effort column or topic? Nothing can be identified or scored from it"
    )
    values["tau"][7, 1] = 1e-9  # one non-zero torque is a measurement, however small
    np.savez(tmp_path / name, **{k: values[k] for k in arrays})
    assert load_data_file(tmp_path / name, PreprocessOptions(cutoff=5.0)).samples.n_samples > 0


def test_a_topic_option_given_for_a_table_is_said_to_do_nothing(tmp_path):
    """``recording.effort_topic=/efforts`` with a CSV was ignored without a word."""
    from idkit.data.logs import LogWarning
    from idkit.data.options import RecordingOptions

    t, q, _, _ = sines()
    np.savez(tmp_path / "r.npz", t=t, q=q, tau=q)
    with pytest.warns(LogWarning) as said:
        load_data_file(
            tmp_path / "r.npz", PreprocessOptions(cutoff=5.0), log=RecordingOptions(effort_topic="/e")
        )
    assert [str(w.message) for w in said] == [
        f"{tmp_path / 'r.npz'}: recording.effort_topic names a ROS log's topics; this file is a table, read "
        "from its own columns"
    ]
