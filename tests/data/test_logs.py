"""ROS logs as raw recordings: ROS 2 (MCAP, sqlite3; folder or file) and ROS 1 bags written here,
joints by name in any order, one clock, and every bad log refused in one line naming it."""

from __future__ import annotations

import re
import sys
import warnings

import numpy as np
import pytest
from bag_cases import Stream, storage_file, with_chunk_checksums, write_ros1, write_ros2

from idkit.data.load import load_data_file
from idkit.data.logs import LogWarning, read_log
from idkit.data.options import RecordingOptions
from idkit.data.recording import load_recording, main

pytest.importorskip("rosbags")

JOINTS = ["shoulder", "elbow", "wrist"]
DRIVER = ["wrist", "shoulder", "elbow"]  # the order the driver publishes
START = 1_700_000_000_000_000_000  # ns: an epoch-sized stamp


def signals(n: int = 400, rate: float = 200.0) -> dict[str, np.ndarray]:
    """``t`` (s from the start), stamps (ns) and robot-ordered ``q, qd, tau`` ``[n, 3]``."""
    t = np.arange(n) / rate
    w = 2 * np.pi * np.array([0.3, 0.5, 0.7])
    return {
        "t": t,
        "stamps": START + np.round(t * 1e9).astype(np.int64),
        "q": np.sin(np.outer(t, w)),
        "qd": np.cos(np.outer(t, w)) * w,
        "tau": 10 * np.cos(np.outer(t, w) + 0.3),
    }


def driver(values: np.ndarray) -> np.ndarray:
    return values[:, [JOINTS.index(j) for j in DRIVER]]


def states(s: dict[str, np.ndarray], **changes) -> Stream:
    fields = {
        "topic": "/joint_states",
        "stamps": s["stamps"],
        "names": DRIVER,
        "position": driver(s["q"]),
        "velocity": driver(s["qd"]),
        "effort": driver(s["tau"]),
    }
    return Stream(**(fields | changes))


def write(kind: str, folder, streams):
    if kind == "ros1":
        return write_ros1(folder / "run.bag", streams)
    bag = write_ros2(folder / "run", streams, storage="mcap" if kind.startswith("mcap") else "sqlite3")
    return storage_file(bag) if kind.endswith("file") else bag


@pytest.mark.parametrize("kind", ["mcap", "mcap-file", "sqlite3", "sqlite3-file", "ros1"])
def test_every_log_kind_gives_the_robots_joints_by_name(tmp_path, kind):
    s = signals()
    path = write(kind, tmp_path, [states(s)])
    recording, read = read_log(path, JOINTS)
    assert recording.joint_names == tuple(JOINTS)
    np.testing.assert_allclose(recording.t, s["t"], rtol=0, atol=1e-12)
    for name in ("q", "qd", "tau"):
        np.testing.assert_array_equal(getattr(recording, name), s[name])
    assert read["topic"] == "/joint_states" and read["clock"] == "header stamps"
    assert read["ignored_joints"] == ["gripper"] and read["ignored_topics"] == ["/status"]


def test_without_a_robot_the_first_messages_joints_are_taken(tmp_path):
    s = signals()
    recording, _ = read_log(write("mcap", tmp_path, [states(s, shuffle=False, extra={})]))
    assert recording.joint_names == tuple(DRIVER)
    np.testing.assert_array_equal(recording.q, driver(s["q"]))


def test_a_joint_the_robot_needs_and_the_log_lacks_is_named(tmp_path):
    s = signals()
    path = write("mcap", tmp_path, [states(s)])
    with pytest.raises(ValueError) as caught:
        read_log(path, [*JOINTS, "hand"])
    assert str(caught.value) == (
        f"{path}: /joint_states: the log has no joint 'hand' (the robot needs it); the log's joints: "
        "wrist, shoulder, elbow, gripper"
    )


@pytest.mark.parametrize("joints", [JOINTS, None])
def test_a_joint_named_twice_in_one_message_is_refused(tmp_path, joints):
    """Which of the two values is the elbow's cannot be known (the last one used to be taken)."""
    s = signals()
    path = write("mcap", tmp_path, [states(s, extra={"elbow": 0.5})])
    with pytest.raises(ValueError) as caught:
        read_log(path, joints)
    assert str(caught.value) == (
        f"{path}: /joint_states message 0 names joint 'elbow' twice; the log's joints: "
        "wrist, shoulder, elbow, elbow"
    )


def test_efforts_on_their_own_topic_and_clock_are_interpolated_onto_the_states(tmp_path):
    s = signals()
    tau_t = s["t"][::2] + 0.0025  # 100 Hz, half a state step late
    tau = 10 * np.outer(tau_t, [1.0, 2.0, 3.0])  # linear in time: interpolation is exact
    stamps = START + np.round(tau_t * 1e9).astype(np.int64)
    effort = Stream("/efforts", stamps, DRIVER, effort=driver(tau), extra={})
    path = write("mcap", tmp_path, [states(s, effort=None), effort])
    with pytest.raises(
        ValueError, match=r"topic /joint_states carries no effort .* recording\.effort_topic=…$"
    ):
        read_log(path, JOINTS, RecordingOptions("/joint_states"))
    with pytest.raises(
        ValueError,
        match=r"several JointState topics: /efforts, /joint_states; choose the one of the positions",
    ):
        read_log(path, JOINTS)
    with pytest.warns(LogWarning, match=r"2 of 400 state samples \(0\.5 %\) have no effort and are dropped"):
        recording, read = read_log(path, JOINTS, RecordingOptions("/joint_states", "/efforts"))
    keep = (s["t"] >= tau_t[0]) & (s["t"] <= tau_t[-1])
    np.testing.assert_array_equal(recording.q, s["q"][keep])
    np.testing.assert_allclose(recording.tau, 10 * np.outer(s["t"][keep], [1.0, 2.0, 3.0]), rtol=1e-9)
    assert read["effort_topic"] == {"topic": "/efforts", "clock": "header stamps", "dropped_samples": 2}
    with pytest.warns(LogWarning):  # the effort topic alone: the positions are on the other one
        alone, _ = read_log(path, JOINTS, RecordingOptions(effort_topic="/efforts"))
    np.testing.assert_array_equal(alone.tau, recording.tau)


def test_an_effort_topic_over_half_the_log_says_what_it_drops(tmp_path):
    """Efforts recorded over the second half only: half the state samples have none. They are dropped
    (no effort is invented), and the console says how many and where instead of halving the data
    silently."""
    s = signals(n=2000)
    late = s["t"] >= s["t"][1000]
    effort = Stream("/efforts", s["stamps"][late], DRIVER, effort=driver(s["tau"][late]), extra={})
    path = write("mcap", tmp_path, [states(s, effort=None), effort])
    with pytest.warns(LogWarning) as said:
        recording, read = read_log(path, JOINTS, RecordingOptions(effort_topic="/efforts"))
    (line,) = [str(w.message) for w in said]
    assert line == (
        f"{path}: the effort topic /efforts covers 5–9.995 s of the state topic's 0–9.995 s: 1000 of 2000 "
        "state samples (50 %) have no effort and are dropped (1000 before its first message)"
    )
    assert recording.t.size == 1000 and read["effort_topic"]["dropped_samples"] == 1000


def test_an_empty_topic_option_is_refused_naming_it():
    with pytest.raises(ValueError, match=r"^recording\.effort_topic is empty; name a JointState topic"):
        RecordingOptions(effort_topic="")
    with pytest.raises(ValueError, match=r"^recording\.topic is empty"):
        RecordingOptions(topic=" ")


def test_zero_header_stamps_use_the_receive_time_and_say_so(tmp_path):
    s = signals()
    path = write("mcap", tmp_path, [states(s, stamps=np.zeros_like(s["stamps"]), received=s["stamps"])])
    with pytest.warns(
        LogWarning, match=r"/joint_states has header stamps all zero; its receive times are used"
    ):
        recording, read = read_log(path, JOINTS)
    assert read["clock"] == "receive time (every header stamp is zero)"
    np.testing.assert_allclose(recording.t, s["t"], rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("change", "options", "message"),
    [
        (
            {"stamps": "zero", "received": "zero"},
            None,
            r"every stamp of /joint_states is zero and so is every",
        ),
        ({"stamps": "some zero"}, None, r"header stamps of /joint_states are zero in 1 of 400 messages"),
        (
            {"stamps": "back"},
            None,
            r"stamps of /joint_states must increase: message 5 \(t = 0.015 s\) follows ",
        ),
        ({"stamps": "repeat"}, None, r"message 5 \(t = 0.02 s\) follows message 4 \(t = 0.02 s\)"),
        (
            {},
            RecordingOptions("/nope"),
            r"no topic '/nope' \(recording\.topic\); the log's topics: /joint_st",
        ),
        ({}, RecordingOptions("/status"), r"topic /status \(recording\.topic\) holds std_msgs/msg/String"),
        ({"topic": "/status_only"}, None, None),
    ],
)
def test_bad_logs_are_one_line_naming_the_log(tmp_path, change, options, message):
    s = signals()
    stamps = s["stamps"].copy()
    if change.get("stamps") == "zero":
        stamps[:] = 0
    if change.get("stamps") == "some zero":
        stamps[7] = 0
    if change.get("stamps") == "back":
        stamps[5] = stamps[3]
    if change.get("stamps") == "repeat":
        stamps[5] = stamps[4]
    received = np.zeros_like(stamps) if change.get("received") == "zero" else s["stamps"]
    if change.get("topic"):  # no JointState at all: only the String topic
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore

        store = get_typestore(Stores.ROS2_HUMBLE)
        path = tmp_path / "empty"
        with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            status = writer.add_connection("/status", "std_msgs/msg/String", typestore=store)
            text = store.types["std_msgs/msg/String"](data="idle")
            writer.write(status, 1, store.serialize_cdr(text, "std_msgs/msg/String"))
        message = r"no sensor_msgs/JointState topic; the log's topics: /status \(std_msgs/msg/String\)$"
    else:
        path = write("mcap", tmp_path, [states(s, stamps=stamps, received=received)])
    with pytest.raises(ValueError) as caught:
        read_log(path, JOINTS, options)
    text = str(caught.value)
    assert text.startswith(f"{path}: ") and "\n" not in text
    assert re.search(message, text), text


def test_a_file_that_is_not_a_log_and_a_missing_rosbags_are_one_line(tmp_path, monkeypatch):
    fake = tmp_path / "fake.mcap"
    fake.write_bytes(b"not an mcap file at all")
    with pytest.raises(ValueError, match=r"fake\.mcap: not a readable ROS log \("):
        read_log(fake)
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)
    with pytest.raises(
        ValueError,
        match=r"reading ROS logs needs the optional package rosbags: pip install robot-idkit\[logs\]$",
    ):
        read_log(fake)


def test_load_data_file_preprocesses_a_log_like_the_same_samples_in_a_csv(tmp_path):
    s = signals(n=2000)
    path = write("mcap", tmp_path, [states(s)])
    csv = tmp_path / "same.csv"
    header = ["t", *(f"{j}.q" for j in JOINTS), *(f"{j}.tau" for j in JOINTS)]
    np.savetxt(
        csv,
        np.column_stack([s["t"], s["q"], s["tau"]]),
        fmt="%.17g",
        delimiter=",",
        header=",".join(header),
        comments="",
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        from_log = load_data_file(path, joints=JOINTS[::-1])
        from_csv = load_data_file(csv, joints=JOINTS[::-1])
    for name in ("q", "qd", "qdd", "tau"):
        np.testing.assert_allclose(
            getattr(from_log.samples, name), getattr(from_csv.samples, name), rtol=1e-9, atol=1e-9
        )
    assert from_log.log["joints"] == JOINTS[::-1] and from_csv.log is None
    with pytest.raises(
        ValueError, match=r"run: a ROS log is a raw recording \(no accelerations\); preprocess it"
    ):
        load_data_file(path, apply="off", joints=JOINTS)


def test_the_converter_writes_a_per_joint_csv_that_reads_back(tmp_path, capsys):
    s = signals()
    path = write("ros1", tmp_path, [states(s)])
    main([str(path), str(tmp_path / "out.csv"), "--velocities"])
    assert (
        capsys.readouterr().out
        == f"{tmp_path / 'out.csv'}: 400 samples, 4 joints from /joint_states (header stamps)\n"
    )
    back = load_recording(tmp_path / "out.csv", joints=JOINTS)
    direct, _ = read_log(path, JOINTS)
    for name in ("t", "q", "qd", "tau"):
        np.testing.assert_array_equal(getattr(back, name), getattr(direct, name))
    assert (
        (tmp_path / "out.csv")
        .read_text()
        .splitlines()[0]
        .startswith("t,wrist.q,shoulder.q,elbow.q,gripper.q,")
    )
    with pytest.raises(SystemExit) as stop:
        main([str(path), str(tmp_path / "x.csv"), "--topic", "/nope"])
    assert stop.value.code == 1
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"python -m idkit.data.recording: {path}: no topic '/nope'")


@pytest.mark.parametrize("checksums", [True, False])
def test_a_log_damaged_in_the_middle_is_one_line_or_read_intact(tmp_path, checksums):
    """Bytes overwritten inside an MCAP (a bad disk, a cut copy): every read either refuses the log in
    one line naming it or returns exactly what was recorded — never a traceback (an ``OverflowError``
    from the reader before) nor, where the chunks carry their checksums as ROS 2's recorder writes them,
    other numbers. (Without checksums a changed value inside a message cannot be told: then only the
    structure is checked — messages lost against the index, impossible stamps.)"""
    s = signals(n=1000)
    original = storage_file(write_ros2(tmp_path / "bag", [states(s)]))
    if checksums:
        with_chunk_checksums(original)
    intact, _ = read_log(original, JOINTS)
    data = original.read_bytes()
    rng = np.random.default_rng(11)
    refused = 0
    for k in range(40):
        damaged = bytearray(data)
        start = int(rng.integers(len(data) // 4, 3 * len(data) // 4))
        width = int(rng.choice([1, 8, 64, 512]))
        damaged[start : start + width] = rng.integers(0, 256, width, dtype=np.uint8).tobytes()
        path = tmp_path / f"damaged_{k}.mcap"
        path.write_bytes(bytes(damaged))
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                recording, _ = read_log(path, JOINTS)
        except ValueError as exc:
            assert str(exc).startswith(f"{path}: ") and "\n" not in str(exc)
            refused += 1
            continue
        if checksums:
            for name in ("t", "q", "tau", "qd"):
                np.testing.assert_array_equal(getattr(recording, name), getattr(intact, name))
    assert refused >= 20  # most damage lands in the messages' chunk
