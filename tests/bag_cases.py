"""ROS logs written by the tests themselves with rosbags (no ROS install): JointState streams with the
joints in another order than the robot's, an extra joint, and an unrelated topic beside them."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

JOINT_STATE = "sensor_msgs/msg/JointState"


@dataclass
class Stream:
    """Messages of one JointState topic: stamps and receive times (ns) and per-joint values in the
    message order ``names`` (``[M, k]``); ``shuffle`` reverses the order in every other message."""

    topic: str
    stamps: np.ndarray
    names: Sequence[str]
    position: np.ndarray | None = None
    velocity: np.ndarray | None = None
    effort: np.ndarray | None = None
    received: np.ndarray | None = None
    shuffle: bool = True
    extra: dict[str, float] = field(default_factory=lambda: {"gripper": 0.01})


def _messages(stream: Stream, module):
    """``(receive ns, JointState)`` per message."""
    header_type, time_type = module.types["std_msgs/msg/Header"], module.types["builtin_interfaces/msg/Time"]
    received = stream.stamps if stream.received is None else stream.received
    for k, stamp in enumerate(stream.stamps):
        order = list(range(len(stream.names)))
        if stream.shuffle and k % 2:
            order = order[::-1]
        names = [stream.names[i] for i in order] + list(stream.extra)

        def values(array, order=order, k=k):
            if array is None:
                return np.zeros(0)
            return np.r_[array[k, order], list(stream.extra.values())]

        stamp = int(stamp)
        fields = {
            "stamp": time_type(sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000),
            "frame_id": "",
        }
        if "seq" in header_type.__dataclass_fields__:
            fields["seq"] = k
        yield (
            int(received[k]),
            module.types[JOINT_STATE](
                header=header_type(**fields),
                name=names,
                position=values(stream.position),
                velocity=values(stream.velocity),
                effort=values(stream.effort),
            ),
        )


def write_ros2(path: Path, streams: Sequence[Stream], storage: str = "mcap") -> Path:
    """A ROS 2 bag folder (``metadata.yaml`` + ``.mcap``/``.db3``) with ``streams`` and a ``/status``
    String topic; returns the folder."""
    rosbag2 = pytest.importorskip("rosbags.rosbag2")
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    plugin = rosbag2.StoragePlugin.MCAP if storage == "mcap" else rosbag2.StoragePlugin.SQLITE3
    with rosbag2.Writer(path, version=9, storage_plugin=plugin) as writer:
        _write(writer, store, streams, store.serialize_cdr)
    return path


def write_ros1(path: Path, streams: Sequence[Stream]) -> Path:
    """A ROS 1 ``.bag`` with ``streams`` and a ``/status`` String topic."""
    rosbag1 = pytest.importorskip("rosbags.rosbag1")
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    with rosbag1.Writer(path) as writer:
        _write(writer, store, streams, store.serialize_ros1)
    return path


def _write(writer, store, streams, serialize) -> None:
    status = writer.add_connection("/status", "std_msgs/msg/String", typestore=store)
    text = store.types["std_msgs/msg/String"]
    for stream in streams:
        connection = writer.add_connection(stream.topic, JOINT_STATE, typestore=store)
        for received, message in _messages(stream, store):
            writer.write(connection, received, serialize(message, JOINT_STATE))
    writer.write(status, int(streams[0].stamps[0]), serialize(text(data="recording"), "std_msgs/msg/String"))


def storage_file(folder: Path) -> Path:
    """The ``.mcap`` or ``.db3`` file inside a ROS 2 bag folder."""
    (found,) = [p for p in folder.iterdir() if p.suffix in (".mcap", ".db3")]
    return found


def with_chunk_checksums(mcap: Path) -> Path:
    """``mcap`` with the CRC-32 of every uncompressed chunk filled in, as ROS 2's own recorder writes
    them (rosbags' writer leaves them 0, "not computed"), so that a damaged chunk can be told."""
    import struct
    from binascii import crc32

    data = bytearray(mcap.read_bytes())
    offset = 8  # the magic
    while offset < len(data) - 8:
        opcode = data[offset]
        (length,) = struct.unpack_from("<Q", data, offset + 1)
        content = offset + 9
        if opcode == 0x06:  # chunk: start, end, uncompressed size, crc, compression, records
            (size,) = struct.unpack_from("<Q", data, content + 16)
            (name_length,) = struct.unpack_from("<I", data, content + 28)
            assert not name_length, "an uncompressed chunk"
            records = content + 32 + name_length + 8
            struct.pack_into("<I", data, content + 24, crc32(data[records : records + size]))
        if opcode == 0x02:  # the footer
            break
        offset = content + length
    mcap.write_bytes(data)
    return mcap
