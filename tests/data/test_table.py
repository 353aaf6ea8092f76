"""The one table reader: duplicated or case-folded names, encodings, separators, per-joint columns.

Every refusal is checked through both readers that use it (samples and raw recordings) and is one
line naming the file.
"""

from __future__ import annotations

import codecs
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit.data.io import load_samples
from idkit.data.load import load_data_file
from idkit.data.recording import load_recording
from idkit.data.table import read_quantities, read_table

RAW = "t,q1,q2,tau1,tau2\n0,0.1,0.2,1,2\n0.01,0.11,0.21,1.1,2.1\n0.02,0.12,0.22,1.2,2.2\n"
SAMPLES = "q1,qd1,qdd1,tau1\n1,2,3,4\n5,6,7,8\n"


def write(path: Path, text: str | bytes) -> Path:
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")
    return path


def refusal(reader, path: Path) -> str:
    with pytest.raises(ValueError) as caught:
        reader(path)
    message = str(caught.value)
    assert "\n" not in message and message.startswith(str(path)), message
    return message


READERS = [load_samples, load_recording, load_data_file]


@pytest.mark.parametrize("reader", READERS)
def test_a_duplicated_column_is_refused_naming_it(tmp_path, reader):
    path = write(tmp_path / "dup.csv", "t,q1,tau1,qd1,qdd1,tau1\n0,1,2,3,4,5\n1,1,2,3,4,6\n")
    message = refusal(reader, path)
    assert "column 'tau1' appears twice (columns 3 and 6)" in message


@pytest.mark.parametrize("reader", READERS)
def test_names_differing_only_in_case_are_one_name(tmp_path, reader):
    path = write(tmp_path / "case.csv", "t,q1,TAU1,qd1,qdd1,tau1\n0,1,2,3,4,5\n1,1,2,3,4,6\n")
    message = refusal(reader, path)
    assert "columns 'TAU1' and 'tau1' name the same column (names are read case-insensitively)" in message


@pytest.mark.parametrize("reader", READERS)
def test_two_numbers_of_one_joint_are_refused_naming_both(tmp_path, reader):
    """``tau1`` and ``tau01`` both read as joint 1: the later one used to win without a word."""
    path = write(tmp_path / "zero.csv", "t,q1,tau1,qd1,qdd1,tau01\n0,1,2,3,4,5\n1,1,2,3,4,6\n")
    message = refusal(reader, path)
    assert "columns 'tau1' and 'tau01' both number joint 1 (columns 3 and 6)" in message


def test_upper_case_headers_read_like_lower_case(tmp_path):
    lower = load_recording(write(tmp_path / "lower.csv", RAW))
    upper = load_recording(write(tmp_path / "upper.csv", RAW.upper()))
    for name in ("t", "q", "tau"):
        np.testing.assert_array_equal(getattr(upper, name), getattr(lower, name))
    samples = load_samples(write(tmp_path / "s.csv", SAMPLES.replace("qdd1", "QDD1").replace("tau1", "Tau1")))
    assert samples.qdd.tolist() == [[3.0], [7.0]] and samples.tau.tolist() == [[4.0], [8.0]]


@pytest.mark.parametrize(
    ("name", "data", "message"),
    [
        ("bom.csv", codecs.BOM_UTF8 + RAW.encode(), None),
        (
            "latin1.csv",
            ("t,q1,tau1\n0,1,2\n# café\n").encode("latin-1"),
            "not UTF-8 text: byte 0xe9 on line 3",
        ),
        ("utf16.csv", RAW.encode("utf-16"), "UTF-16 text (it starts with a UTF-16 byte-order mark)"),
        ("image.csv", b"\x89PNG\r\n\x1a\n\x00\x00", "a binary file, not CSV text (byte 0x1a at offset 6)"),
    ],
)
@pytest.mark.parametrize("reader", READERS)
def test_encodings_are_read_or_refused_naming_the_problem(tmp_path, reader, name, data, message):
    path = write(tmp_path / name, data)
    if message is None:  # Excel's "CSV UTF-8": the byte-order mark is skipped
        np.testing.assert_array_equal(load_recording(path).t, [0.0, 0.01, 0.02])
        return
    assert message in refusal(reader, path)


@pytest.mark.parametrize(
    ("text", "found"),
    [
        ("T;Q1;Q2;TAU1;TAU2\n0;0,1;0,2;1;2\n", "found ';'-separated columns 'T;Q1;Q2;…'"),
        ("t\tq1\ttau1\n0\t1\t2\n", "found tab-separated columns 't\\tq1\\ttau1'"),
        ("t q1 tau1\n0 1 2\n", "found space-separated columns 't q1 tau1'"),
        ("0,1,2\n1,2,3\n", "the first line holds numbers (0,1,2), not column names"),
    ],
)
@pytest.mark.parametrize("reader", READERS)
def test_separator_and_header_problems_say_what_was_found(tmp_path, reader, text, found):
    message = refusal(reader, write(tmp_path / "odd.csv", text))
    assert found in message
    assert "idkit reads comma-separated CSV whose first line names the columns t, q1.." in message
    assert "no timestamps" not in message and "preprocess=off" not in message


def test_what_is_not_a_problem_is_not_refused(tmp_path):
    """Blank lines, a trailing comma (an unnamed empty column) and text columns nobody asks for."""
    text = "note,t,q1,tau1,\n\nstart,0,1,2,\n\n middle ,1,2,3,\n"
    recording = load_recording(write(tmp_path / "loose.csv", text))
    np.testing.assert_array_equal(recording.q, [[1.0], [2.0]])
    with pytest.raises(ValueError, match=r"line 5 \(sample 1\), column 'q1': not a number: 'x'"):
        load_recording(write(tmp_path / "x.csv", "t,q1,tau1\n\n0,1,2\n\n1,x,3\n"))
    with pytest.raises(
        ValueError, match=r"'q' \(column q1\) has a non-finite value \(nan\) at sample 1 \(line 4\)"
    ):
        load_recording(write(tmp_path / "nan.csv", "t,q1,tau1\n0,1,2\n\n1,nan,3\n"))


NAMED = "t,elbow.tau,shoulder.q,elbow.q,shoulder.TAU,gripper.q\n0,1,2,3,4,9\n1,5,6,7,8,9\n"


def test_per_joint_columns_follow_the_robots_order_and_ignore_other_joints(tmp_path):
    path = write(tmp_path / "named.csv", NAMED)
    recording = load_recording(path, joints=["shoulder", "elbow"])
    assert recording.joint_names == ("shoulder", "elbow")
    np.testing.assert_array_equal(recording.q, [[2, 3], [6, 7]])
    np.testing.assert_array_equal(recording.tau, [[4, 1], [8, 5]])
    with pytest.raises(
        ValueError, match=r"no column 'wrist\.q' for joint 'wrist'; the file's q columns name "
    ):
        load_recording(path, joints=["shoulder", "wrist"])
    with pytest.raises(ValueError, match=r"no column 'gripper\.tau' for joint 'gripper'"):
        load_recording(path)  # without a robot: every joint with a position needs a torque


def test_numbered_and_per_joint_columns_are_not_mixed(tmp_path):
    both = write(tmp_path / "both.csv", "t,q1,a.q,tau1\n0,1,2,3\n1,1,2,3\n")
    assert "both numbered (q1..) and per-joint (<joint>.q) columns" in refusal(load_recording, both)
    across = write(tmp_path / "across.csv", "t,a.q,tau1\n0,1,3\n1,1,3\n")
    assert "tau in numbered columns (q1..) but q per joint" in refusal(load_recording, across)


def test_npz_arrays_keep_their_messages(tmp_path):
    np.savez(tmp_path / "r.npz", t=np.arange(3.0), q=np.ones((3, 2)), tau=np.ones((3, 2)))
    table = read_table(tmp_path / "r.npz")
    arrays, joints = read_quantities(table, {"q": "q", "tau": "tau", "qd": "qd"}, optional=("qd",))
    assert joints is None and set(arrays) == {"q", "tau"}
    with pytest.raises(ValueError, match=r"missing array\(s\) \['qd'\]; the file has \['q', 't', 'tau'\]"):
        read_quantities(table, {"q": "q", "qd": "qd"})


@settings(max_examples=25, deadline=None)
@given(
    order=st.permutations(range(5)),
    upper=st.lists(st.booleans(), min_size=5, max_size=5),
    blank=st.booleans(),
)
def test_column_order_case_and_blank_lines_do_not_change_the_values(tmp_path_factory, order, upper, blank):
    rows = [line.split(",") for line in RAW.strip().splitlines()]
    columns = [[row[k] for row in rows] for k in order]
    columns = [[c[0].upper() if up else c[0], *c[1:]] for c, up in zip(columns, upper, strict=True)]
    lines = [",".join(cells) for cells in zip(*columns, strict=True)]
    if blank:
        lines.insert(2, "")
    path = write(tmp_path_factory.mktemp("perm") / "p.csv", "\n".join(lines) + "\n")
    reference = load_recording(write(path.with_name("ref.csv"), RAW))
    shuffled = load_recording(path)
    for name in ("t", "q", "tau"):
        np.testing.assert_array_equal(getattr(shuffled, name), getattr(reference, name))


@pytest.mark.parametrize("reader", [load_samples, load_data_file])
def test_arrays_without_rows_are_refused_naming_the_file(tmp_path, reader):
    """Before, an .npz of [0, n] arrays reached the fit: "0 samples × 3 joints = 0 equations", no file."""
    path = tmp_path / "empty.npz"
    np.savez(path, **{k: np.zeros((0, 2)) for k in ("q", "qd", "qdd", "tau")})
    assert refusal(reader, path) == (
        f"{path}: no samples (the arrays have 0 rows: q (0, 2), qd (0, 2), qdd (0, 2), tau (0, 2))"
    )


@pytest.mark.parametrize(
    ("arrays", "ours", "theirs"),
    [
        ({"q": 1, "qd": 1, "qdd": 1, "tau": 1, "torques": 2}, "tau", "torques"),
        ({"t": 0, "times": 0, "q": 1, "tau": 1}, "t", "times"),
        ({"positions": 1, "q": 1, "velocities": 1, "accelerations": 1, "torques": 1}, "q", "positions"),
    ],
)
def test_one_quantity_under_both_names_is_refused(tmp_path, arrays, ours, theirs):
    """``tau`` and FloBaRoID's ``torques`` in one file: which is meant? Before, one was silently used."""
    path = tmp_path / "both.npz"
    t = np.arange(5.0)
    np.savez(path, **{k: t if v == 0 else np.outer(t, [v, v]) for k, v in arrays.items()})
    assert refusal(load_data_file, path) == (
        f"{path}: both {ours!r} and {theirs!r} (FloBaRoID's name for {ours}); which one is meant? "
        "Keep one of them"
    )


@settings(max_examples=50, deadline=None)
@given(
    start=st.integers(1_000_000_000 * 10**9, 4_000_000_000 * 10**9),
    steps=st.lists(st.integers(1, 10**8), min_size=1, max_size=20),
)
def test_epoch_stamps_lose_no_digit_before_the_first_is_subtracted(tmp_path_factory, start, steps):
    """Stamps since the epoch to the nanosecond, as decimal text in a CSV, give the seconds from the
    first stamp as the exact difference rounded once (float64 seconds since the epoch would keep only
    ~0.2 µs)."""
    folder = tmp_path_factory.mktemp("stamps")
    stamps = np.cumsum([start, *steps]).astype(np.int64)
    exact = np.array([(s - stamps[0]) / 1e9 for s in stamps.tolist()])
    csv = folder / "t.csv"
    csv.write_text("t,q1,tau1\n" + "".join(f"{s // 10**9}.{s % 10**9:09d},0,1\n" for s in stamps.tolist()))
    np.testing.assert_array_equal(read_table(csv).times("t"), exact)
