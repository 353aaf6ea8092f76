"""User data files: .npz/.csv round trips and errors that name file, array and sample."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from idkit.data.io import FLOBAROID_KEYS, load_samples, save_samples
from idkit.problem import SAMPLE_ARRAYS, Samples

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@st.composite
def samples(draw) -> Samples:
    n_samples, n_joints = draw(st.integers(1, 6)), draw(st.integers(1, 4))
    return Samples(
        *(
            torch.from_numpy(draw(arrays(np.float64, (n_samples, n_joints), elements=finite)))
            for _ in range(4)
        )
    )


@settings(max_examples=40, deadline=None)
@given(
    samples(), st.sampled_from([".npz", ".csv"]), st.sampled_from([None, FLOBAROID_KEYS, {"tau": "effort"}])
)
def test_round_trip_is_exact(original, suffix, keys):
    with tempfile.TemporaryDirectory() as tmp:
        path = save_samples(original, Path(tmp) / f"data{suffix}", keys=keys)
        loaded = load_samples(path, keys=keys)
    for k in SAMPLE_ARRAYS:
        assert getattr(loaded, k).dtype == torch.float64
        assert torch.equal(getattr(loaded, k), getattr(original, k)), k


def write_npz(path: Path, n_samples: int = 5, n_joints: int = 2, **changes) -> Path:
    rng = np.random.default_rng(0)
    data = {k: rng.normal(size=(n_samples, n_joints)) for k in SAMPLE_ARRAYS}
    data.update(changes)
    np.savez(path, **data)
    return path


def test_npz_nan_names_file_array_and_sample(tmp_path):
    qd = np.ones((5, 2))
    qd[3, 1] = np.nan
    path = write_npz(tmp_path / "bad.npz", qd=qd)
    with pytest.raises(ValueError, match=r"bad\.npz.*'qd'.*sample 3, joint 1"):
        load_samples(path)


def test_npz_renamed_key_is_reported(tmp_path):
    rng = np.random.default_rng(1)
    data = {v: rng.normal(size=(4, 3)) for v in FLOBAROID_KEYS.values()}
    data["torques"][2, 0] = np.inf
    np.savez(tmp_path / "kuka.npz", **data)
    with pytest.raises(
        ValueError,
        match=r"kuka\.npz: array 'torques' \(for tau\) has a non-finite value \(inf\) "
        r"at sample 2, joint 0$",
    ):
        load_samples(tmp_path / "kuka.npz", keys=FLOBAROID_KEYS)


def test_npz_mismatched_shapes(tmp_path):
    path = write_npz(tmp_path / "shapes.npz", tau=np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"shapes\.npz.*'tau' has shape \(4, 2\) but 'q' has \(5, 2\)"):
        load_samples(path)
    path = write_npz(tmp_path / "flat.npz", q=np.zeros(5))
    with pytest.raises(ValueError, match=r"flat\.npz.*'q' must be 2-D"):
        load_samples(path)


def test_npz_missing_key_lists_available(tmp_path):
    np.savez(tmp_path / "m.npz", positions=np.zeros((2, 2)), torques=np.zeros((2, 2)))
    with pytest.raises(
        ValueError, match=r"m\.npz: missing array\(s\) \['q', 'qd', 'qdd', 'tau'\].*'positions', 'torques'"
    ):
        load_samples(tmp_path / "m.npz")


def write_csv(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


HEADER = "t,q1,q2,qd1,qd2,qdd1,qdd2,tau1,tau2\n"


def test_csv_layout_any_column_order_and_extra_columns(tmp_path):
    path = write_csv(tmp_path / "ok.csv", "tau2,q2,qd2,qdd2,t,q1,qd1,qdd1,tau1\n8,2,4,6,0.5,1,3,5,7\n")
    s = load_samples(path)
    assert s.q.tolist() == [[1.0, 2.0]] and s.qd.tolist() == [[3.0, 4.0]]
    assert s.qdd.tolist() == [[5.0, 6.0]] and s.tau.tolist() == [[7.0, 8.0]]


def test_csv_nan_names_line_column_array_and_sample(tmp_path):
    path = write_csv(tmp_path / "nan.csv", HEADER + "0,1,2,3,4,5,6,7,8\n1,1,2,3,nan,5,6,7,8\n")
    with pytest.raises(ValueError, match=r"nan\.csv.*'qd' \(column qd2\).*sample 1 \(line 3\), joint 1"):
        load_samples(path)


def test_csv_errors(tmp_path):
    with pytest.raises(ValueError, match=r"line 2 \(sample 0\), column 'q2': not a number: 'x'"):
        load_samples(write_csv(tmp_path / "a.csv", HEADER + "0,1,x,3,4,5,6,7,8\n"))
    with pytest.raises(ValueError, match=r"different numbers of joints \(q 2, qd 2, qdd 2, tau 1\)"):
        load_samples(write_csv(tmp_path / "b.csv", "q1,q2,qd1,qd2,qdd1,qdd2,tau1\n1,2,3,4,5,6,7\n"))
    with pytest.raises(ValueError, match="line 3 .* has 8 values"):
        load_samples(write_csv(tmp_path / "c.csv", HEADER + "0,1,2,3,4,5,6,7,8\n0,1,2,3,4,5,6,7\n"))
    with pytest.raises(ValueError, match="no samples"):
        load_samples(write_csv(tmp_path / "d.csv", HEADER))
    with pytest.raises(ValueError, match="empty file"):
        load_samples(write_csv(tmp_path / "e.csv", ""))


def test_other_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.npz"):
        load_samples(tmp_path / "nope.npz")
    with pytest.raises(ValueError, match="unsupported file type '.txt'"):
        load_samples(write_csv(tmp_path / "x.txt", "1"))
    with pytest.raises(ValueError, match="unknown array name"):
        load_samples(write_npz(tmp_path / "k.npz"), keys={"torque": "tau"})


def test_kuka_recording_loads(kuka_dir):
    s = load_samples(kuka_dir / "measurements_1.npz", keys=FLOBAROID_KEYS)
    assert (s.n_samples, s.n_joints) == (5027, 7)
    with np.load(kuka_dir / "measurements_1.npz") as raw:
        np.testing.assert_array_equal(s.tau.numpy(), raw["torques"])


# --- files that are not what their name says ---------------------------------------------------


def test_directory_is_refused_and_its_data_files_listed(tmp_path):
    write_npz(tmp_path / "run1.npz")
    (tmp_path / "run2.mcap").write_bytes(b"")  # a bag's file without its metadata.yaml: readable alone
    with pytest.raises(ValueError) as err:
        load_samples(tmp_path)
    assert (
        str(err.value) == f"{tmp_path} is a directory, not a data file (.npz, .csv) nor a ROS 2 bag folder "
        "(no metadata.yaml); data files in it: run1.npz, run2.mcap"
    )


def test_npz_that_is_not_an_archive_is_refused_without_pickle_advice(tmp_path):
    (tmp_path / "empty.npz").write_bytes(b"")
    (tmp_path / "text.npz").write_text(HEADER + "0,1,2,3,4,5,6,7,8\n")
    (tmp_path / "broken.npz").write_bytes(b"PK\x03\x04 truncated")
    not_zip = "not a NumPy .npz archive (a zip of arrays, as numpy.savez writes) but"
    cases = {
        "empty.npz": f"{not_zip} an empty file",
        "text.npz": f"{not_zip} a file starting with b't,q1'",
        "broken.npz": "a damaged .npz archive (BadZipFile",
    }
    for name, message in cases.items():
        with pytest.raises(ValueError) as err:
            load_samples(tmp_path / name)
        assert str(err.value).startswith(f"{tmp_path / name}: {message}")
        assert "allow_pickle=True" not in str(err.value)


def test_npz_without_arrays(tmp_path):
    np.savez(tmp_path / "none.npz")
    with pytest.raises(
        ValueError,
        match=r"none\.npz: the \.npz archive contains no arrays; "
        r"expected samples \(q, qd, qdd, tau\)",
    ):
        load_samples(tmp_path / "none.npz")


def test_text_bool_and_object_arrays_name_the_array(tmp_path):
    with pytest.raises(ValueError, match=r"s\.npz: array 'qdd' has dtype <U1 \(text\); expected numbers"):
        load_samples(write_npz(tmp_path / "s.npz", qdd=np.full((5, 2), "a")))
    with pytest.raises(
        ValueError, match=r"b\.npz: array 'velocities' \(for qd\) has dtype bool \(booleans\)"
    ):
        data = {v: np.ones((5, 2)) for v in FLOBAROID_KEYS.values()} | {"velocities": np.ones((5, 2), bool)}
        np.savez(tmp_path / "b.npz", **data)
        load_samples(tmp_path / "b.npz", keys=FLOBAROID_KEYS)
    objects = np.empty((5, 2), dtype=object)
    with pytest.raises(
        ValueError,
        match=r"o\.npz: array 'tau' holds Python objects \(dtype object\), which idkit never loads",
    ):
        load_samples(write_npz(tmp_path / "o.npz", tau=objects))


def test_integer_arrays_are_read_as_float64(tmp_path):
    loaded = load_samples(write_npz(tmp_path / "i.npz", q=np.arange(10).reshape(5, 2)))
    assert loaded.q.dtype == torch.float64 and loaded.q[4, 1].item() == 9.0


def test_csv_that_is_not_text(tmp_path):
    (tmp_path / "bin.csv").write_bytes(b"\x89PNG\r\n\x1a\n")
    with pytest.raises(ValueError, match=r"bin\.csv: a binary file, not CSV text \(byte 0x1a at offset 6\)"):
        load_samples(tmp_path / "bin.csv")


def test_csv_with_byte_order_mark_loads(tmp_path):
    path = tmp_path / "bom.csv"
    path.write_bytes(("\ufeff" + HEADER + "0,1,2,3,4,5,6,7,8\n").encode("utf-8"))
    assert load_samples(path).q.tolist() == [[1.0, 2.0]]  # 't' is column 0
