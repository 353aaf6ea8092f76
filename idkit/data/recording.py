"""Raw recordings (timestamps, positions, torques, maybe velocities) and stacking of samples.

A raw recording is what a robot controller logs: ``t[N]`` (s, increasing, possibly irregular),
``q[N, n]`` and ``tau[N, n]``, and sometimes ``qd[N, n]``; no accelerations.
:func:`idkit.data.preprocess.preprocess` turns it into ``Samples``.

Files (read by :mod:`idkit.data.table`, which says what is refused and how):
    ``.csv``: one header line naming the columns ``t, q1..qn, tau1..taun`` and optionally
    ``qd1..qdn`` (joint numbers from 1), or per joint ``t, <joint>.q, <joint>.tau[, <joint>.qd]``;
    any column order, any case, other columns ignored; then one line per sample.
    ``.npz``: arrays ``t`` ``[N]``, ``q`` and ``tau`` ``[N, n]``, optionally ``qd``. Other names map
    through ``keys``, e.g. :data:`FLOBAROID_RECORDING_KEYS` for the KUKA/FloBaRoID files.

Timestamps must increase strictly: a repeated or earlier timestamp is refused naming the sample
(which of two samples at one time is right cannot be known). Gaps are the preprocessing's business
(:mod:`idkit.data.preprocess` never interpolates across one).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import torch

from idkit.data.logs import is_log, read_log
from idkit.data.options import RecordingOptions
from idkit.data.raw import Recording
from idkit.data.table import Table, names_hint, read_quantities, read_table
from idkit.problem import SAMPLE_ARRAYS, Samples
from idkit.untrusted import csv_header

RECORDING_ARRAYS = ("t", "q", "tau", "qd")
#: File names of the arrays in the FloBaRoID recordings (``shared/data/kuka-lwr4``).
FLOBAROID_RECORDING_KEYS: Mapping[str, str] = {
    "t": "times",
    "q": "positions",
    "tau": "torques",
    "qd": "velocities",
}


def load_recording(
    path: str | Path, keys: Mapping[str, str] | None = None, joints: Sequence[str] | None = None
) -> Recording:
    """Read a raw recording from ``.csv`` or ``.npz`` (module doc; the file is read by
    :func:`idkit.data.table.read_table`).

    Args:
        path: the file.
        keys: file name of each array (npz key or CSV column prefix) where it differs from
            ``t``, ``q``, ``tau``, ``qd``.
        joints: the joints wanted, in this order, from per-joint CSV columns (``<joint>.q``);
            ``None``: every joint the file names.

    Raises:
        FileNotFoundError: no such file.
        ValueError: unknown suffix, missing arrays/columns, non-numeric values (naming file, column
            and line), or what :class:`Recording` rejects.
    """
    unknown = sorted(set(keys or {}) - set(RECORDING_ARRAYS))
    if unknown:
        raise ValueError(f"keys: unknown array name(s) {unknown}; map some of {', '.join(RECORDING_ARRAYS)}")
    return recording_from_table(read_table(path), keys, joints)


def recording_from_table(
    table: Table, keys: Mapping[str, str] | None = None, joints: Sequence[str] | None = None
) -> Recording:
    """A :class:`Recording` from an open table (arguments as :func:`load_recording`)."""
    names = {k: k for k in RECORDING_ARRAYS} | dict(keys or {})
    table.require(matrices=[names["q"], names["tau"]], vectors=[names["t"]], hint=names_hint(table, names))
    arrays, found = read_quantities(
        table, {k: names[k] for k in ("q", "tau", "qd")}, joints, optional=("qd",)
    )
    return Recording(
        table.times(names["t"]), arrays["q"], arrays["tau"], arrays.get("qd"), str(table.path), found
    )


def stack_samples(parts: Sequence[Samples], labels: Sequence[str] | None = None) -> Samples:
    """Concatenate the samples of several recordings (``data=[a, b]``) along the sample axis.

    Preprocess each recording on its own first (a filter must not run across the seam).

    Raises:
        ValueError: no parts, or parts with different numbers of joints (naming both).
    """
    if not parts:
        raise ValueError("stack_samples: no recordings to stack")
    labels = list(labels) if labels is not None else [f"recording {i}" for i in range(len(parts))]
    first = parts[0]
    for label, part in zip(labels, parts, strict=True):
        if part.n_joints != first.n_joints:
            raise ValueError(
                f"stack_samples: {label} has {part.n_joints} joints but {labels[0]} has {first.n_joints}"
            )
    device, dtype = first.q.device, first.q.dtype
    return Samples(
        *(torch.cat([getattr(p, k).to(device=device, dtype=dtype) for p in parts]) for k in SAMPLE_ARRAYS)
    )


def save_recording(recording: Recording, path: str | Path, velocities: bool = False) -> Path:
    """Write ``recording`` as a raw CSV that :func:`load_recording` reads back: ``t``, then positions,
    torques and (with ``velocities``) measured velocities, as per-joint columns ``<joint>.q`` when
    the recording names its joints, else numbered ``q1..qn``; 17 significant digits round-trip
    float64."""
    n = recording.n_joints
    names = recording.joint_names

    def labels(quantity: str) -> list[str]:
        return [f"{j}.{quantity}" for j in names] if names else [f"{quantity}{j}" for j in range(1, n + 1)]

    columns = [recording.t[:, None], recording.q, recording.tau]
    header = ["t", *labels("q"), *labels("tau")]
    if velocities:
        if recording.qd is None:
            raise ValueError(f"{recording.source}: no velocities to write")
        columns.append(recording.qd)
        header += labels("qd")
    path = Path(path)
    np.savetxt(path, np.hstack(columns), fmt="%.17g", delimiter=",", header=csv_header(header), comments="")
    return path


def main(argv: Sequence[str] | None = None) -> None:
    """``python -m idkit.data.recording IN OUT.csv``: a recording — a ROS log of JointState (bag folder,
    ``.mcap``, ``.db3``, ``.bag``), a FloBaRoID/KUKA ``.npz`` or a CSV — as a raw CSV of timestamps,
    positions and torques (per-joint columns ``<joint>.q`` for a log). Bad input: one line, exit 1."""
    import argparse
    import sys

    parser = argparse.ArgumentParser(prog="python -m idkit.data.recording", description=main.__doc__)
    parser.add_argument(
        "source", help="ROS log, .npz or .csv recording (FloBaRoID array names are recognised)"
    )
    parser.add_argument("target", help="the raw .csv to write (t, q.., tau..)")
    parser.add_argument("--velocities", action="store_true", help="also write the measured velocities")
    parser.add_argument("--topic", help="a log's JointState topic (default: its only one)")
    parser.add_argument("--effort-topic", help="a log's JointState topic carrying the efforts")
    args = parser.parse_args(argv)
    try:
        if is_log(args.source):
            recording, read = read_log(args.source, None, RecordingOptions(args.topic, args.effort_topic))
            said = f" from {read['topic']} ({read['clock']})"
        else:
            table = read_table(args.source)
            flobaroid = table.has(FLOBAROID_RECORDING_KEYS["t"])
            recording, said = recording_from_table(table, FLOBAROID_RECORDING_KEYS if flobaroid else None), ""
        path = save_recording(recording, args.target, velocities=args.velocities)
    except (ValueError, FileNotFoundError) as exc:
        print(f"{parser.prog}: {exc}", file=sys.stderr)
        sys.exit(1)
    print(f"{path}: {recording.t.size} samples, {recording.n_joints} joints{said}")


if __name__ == "__main__":
    main()
