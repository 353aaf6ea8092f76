"""The one reader of table files (``.csv``, ``.npz``) behind samples files and raw recordings.

:mod:`idkit.data.io` (samples ``q, qd, qdd, tau``) and :mod:`idkit.data.recording` (raw recordings
``t, q, tau[, qd]``) both read through :func:`read_table`, so a file is refused for the same reasons,
with the same message naming the file (and the column, line or array), whichever of the two reads it.

CSV:
    UTF-8 text (a leading byte-order mark, as Excel's "CSV UTF-8" writes, is skipped; UTF-16,
    Latin-1/Windows-1252 text and binary files are refused naming the encoding problem), separated by
    commas, the first line naming the columns, then one line per sample (blank lines are skipped).
    Column names are matched case-insensitively (``Q1`` is ``q1``, ``TAU1`` is ``tau1``); a name that
    appears twice, in any case, is refused — which one would be meant? — and so are two numbers of one
    joint (``q1`` and ``q01``). A quantity's columns are either
    numbered from 1 (``q1..qn``) or named per joint (``<joint>.q``, the joint name as the robot spells
    it, the quantity in any case), not both. A first line that looks ``;``-, tab- or space-separated, or
    holds numbers, is refused saying what was found. Only the columns asked for are parsed as numbers;
    others (``note``) are ignored.

NPZ:
    a zip of named numeric arrays (``numpy.savez``); object arrays are never loaded (that would need
    ``allow_pickle=True``, which lets a data file run code).

Every value read must be finite: a NaN or infinity is refused naming the array (and column), the
sample and the joint, for CSV also the line.
"""

from __future__ import annotations

import codecs
import csv
import io
import os
import re
import zipfile
from abc import ABC, abstractmethod
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from decimal import Decimal, localcontext
from pathlib import Path

import numpy as np

from idkit.untrusted import csv_text

#: What idkit reads from a CSV file, for messages about files that are not that.
EXPECTED_CSV = (
    "idkit reads comma-separated CSV whose first line names the columns t, q1.., qd1.., qdd1.., tau1.. "
    "(or <joint>.q, <joint>.qd, <joint>.qdd, <joint>.tau)"
)
#: First bytes of a zip archive (an ``.npz``); ``PK\x05\x06`` starts an empty one.
ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")
#: Array kinds (``numpy.dtype.kind``) read as numbers: signed, unsigned integers and floats.
NUMERIC_KINDS = "iuf"
_KIND_NAMES = {
    "U": "text",
    "S": "bytes",
    "b": "booleans",
    "c": "complex numbers",
    "M": "dates",
    "m": "time spans",
}
_NUMBERED = re.compile(r"(?P<prefix>[A-Za-z_]+?)(?P<index>\d+)")
_NAMED = re.compile(r"(?P<joint>.+)\.(?P<quantity>[A-Za-z_]+)")
#: Bytes that do not occur in text (C0 controls other than tab, newlines, form feed, escape).
_CONTROL = bytes(set(range(32)) - {9, 10, 12, 13, 27})
_SEPARATORS = {";": "';'", "\t": "tab", "|": "'|'"}


def check_table_path(path: str | os.PathLike[str]) -> Path:
    """``path`` as a ``Path`` if it is an existing ``.npz`` or ``.csv`` file.

    Raises:
        FileNotFoundError: no such file.
        ValueError: a directory (listing the data files in it) or another suffix.
    """
    path = Path(path)
    if path.is_dir():
        # and idkit.data.logs.LOG_SUFFIXES (not imported: it brings torch): read without metadata.yaml
        readable = (".npz", ".csv", ".mcap", ".db3", ".bag")
        found = sorted(p.name for p in path.iterdir() if p.suffix.lower() in readable)
        inside = f"; data files in it: {', '.join(found[:5])}{' …' * (len(found) > 5)}" if found else ""
        raise ValueError(
            f"{path} is a directory, not a data file (.npz, .csv) nor a ROS 2 bag folder (no metadata.yaml)"
            f"{inside}"
        )
    if not path.is_file():
        raise FileNotFoundError(f"data file not found: {path}")
    if path.suffix.lower() not in (".npz", ".csv"):
        raise ValueError(
            f"{path}: unsupported file type {path.suffix!r}; use .npz, .csv or a ROS log (a bag folder, "
            ".mcap, .db3, .bag)"
        )
    return path


@dataclass(frozen=True)
class Column:
    """One quantity's values ``[N, n]`` and, for per-joint CSV columns, the joints they belong to."""

    values: np.ndarray
    joints: tuple[str, ...] | None


class Table(ABC):
    """A table file's named columns (CSV) or arrays (NPZ), read once; values parsed on request."""

    path: Path

    @abstractmethod
    def has(self, name: str) -> bool:
        """Whether the file has the column/array ``name`` or the columns of quantity ``name``."""

    @abstractmethod
    def names(self) -> list[str]:
        """The column or array names as the file spells them (for messages)."""

    @abstractmethod
    def vector(self, name: str) -> np.ndarray:
        """The finite ``[N]`` values of column/array ``name``."""

    @abstractmethod
    def times(self, name: str) -> np.ndarray:
        """Column/array ``name`` as seconds from its first value ``[N]``, the subtraction done exactly.

        Stamps since the epoch written as decimal text (``1700000000.123456789``) hold more digits
        than a float64: converted first and subtracted after, they keep ~0.2 µs, enough to move an
        estimate through differentiation. So a CSV's first stamp is subtracted in exact decimal
        arithmetic and only the difference becomes a float (an ``.npz`` holds float64 already).
        """

    @abstractmethod
    def matrix(self, name: str, joints: Sequence[str] | None = None, label: str | None = None) -> Column:
        """Quantity ``name``'s finite ``[N, n]`` values.

        Args:
            name: the array (NPZ) or column prefix (CSV: ``q`` for ``q1..qn`` or ``<joint>.q``).
            joints: the joints wanted, in this order, from per-joint CSV columns (``None``: every joint
                the file names, in its column order). Positional data ignore it.
            label: what the caller calls the quantity, when ``name`` is the file's own name for it.
        """

    @abstractmethod
    def missing_message(self, matrices: Sequence[str], vectors: Sequence[str]) -> str:
        """What is missing and what the file has, in one line."""

    def require(self, matrices: Iterable[str] = (), vectors: Iterable[str] = (), hint: str = "") -> None:
        """Refuse the file in one line if a quantity (``matrices``) or column (``vectors``) is missing."""
        lacking = [n for n in matrices if not self.has(n)], [n for n in vectors if not self.has(n)]
        if any(lacking):
            raise ValueError(self.missing_message(*lacking) + hint)


def read_table(path: str | os.PathLike[str]) -> Table:
    """Open ``path`` (``.csv`` or ``.npz``, module doc), refusing what is not such a file.

    Raises:
        FileNotFoundError: no such file.
        ValueError: a directory, another suffix, a CSV that is not UTF-8 comma-separated text with a
            header of distinct names, an ``.npz`` that is not an archive of arrays.
    """
    path = check_table_path(path)
    if path.suffix.lower() == ".npz":
        return NpzTable(path)
    return CsvTable.read(path)


# --- CSV -----------------------------------------------------------------------------------------


def decode_text(path: Path) -> str:
    """The file's text: UTF-8, without a leading byte-order mark; else one line naming the problem."""
    data = path.read_bytes()
    if data.startswith(codecs.BOM_UTF8):
        data = data[len(codecs.BOM_UTF8) :]
    elif data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        raise ValueError(
            f"{path}: UTF-16 text (it starts with a UTF-16 byte-order mark); idkit reads UTF-8 — save it "
            "as UTF-8 (Excel: 'CSV UTF-8')"
        )
    control = next((i for i, byte in enumerate(data[:4096]) if byte in _CONTROL), None)
    if control is not None:
        raise ValueError(
            f"{path}: a binary file, not CSV text (byte 0x{data[control]:02x} at offset {control}); "
            + EXPECTED_CSV
        )
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise ValueError(
            f"{path}: not UTF-8 text: byte 0x{data[exc.start]:02x} on line {line} cannot be decoded "
            "(Latin-1 or Windows-1252 text?); save the file as UTF-8"
        ) from None


def _key(label: str) -> str:
    """A column name as matched: the quantity part lower-case, a per-joint name as written."""
    named = _NAMED.fullmatch(label)
    if named:
        return f"{named['joint']}.{named['quantity'].casefold()}"
    return label.casefold()


@dataclass
class CsvTable(Table):
    """A CSV file's header and rows of text cells; columns become numbers when asked for."""

    path: Path
    header: list[str]
    rows: list[list[str]]
    lines: list[int]  # the file line of each row (blank lines skipped)
    _parsed: dict[int, np.ndarray] = field(default_factory=dict)

    @classmethod
    def read(cls, path: Path) -> CsvTable:
        reader = csv.reader(io.StringIO(decode_text(path), newline=""))
        header: list[str] | None = None
        rows: list[list[str]] = []
        lines: list[int] = []
        for row in reader:
            if not any(cell.strip() for cell in row):
                continue
            if header is None:
                header = [csv_text(cell.strip()) for cell in row]  # idkit's own escapes undone
                _check_header(path, header)
                continue
            if len(row) != len(header):
                raise ValueError(
                    f"{path}: line {reader.line_num} (sample {len(rows)}) has {len(row)} values but the "
                    f"header has {len(header)}"
                )
            rows.append(row)
            lines.append(reader.line_num)
        if header is None:
            raise ValueError(f"{path}: empty file; " + EXPECTED_CSV)
        if not rows:
            raise ValueError(f"{path}: no samples after the header line")
        return cls(path, header, rows, lines)

    def names(self) -> list[str]:
        return list(self.header)

    def _columns(self, prefix: str) -> tuple[dict[int, int], dict[str, int]]:
        """Quantity ``prefix``'s numbered columns ``{index: column}`` and per-joint ``{joint: column}``."""
        prefix = prefix.casefold()
        numbered: dict[int, int] = {}
        named: dict[str, int] = {}
        for col, label in enumerate(self.header):
            joint = _NAMED.fullmatch(label)
            if joint and joint["quantity"].casefold() == prefix:
                named[joint["joint"]] = col
                continue
            number = _NUMBERED.fullmatch(label)
            if number and number["prefix"].casefold() == prefix:
                index = int(number["index"])
                if index in numbered:  # q1 and q01: two columns for one joint
                    raise ValueError(
                        f"{self.path}: columns {self.header[numbered[index]]!r} and {label!r} both number "
                        f"joint {index} (columns {numbered[index] + 1} and {col + 1}); which one is meant? "
                        "Name each column once"
                    )
                numbered[index] = col
        return numbered, named

    def has(self, name: str) -> bool:
        return name.casefold() in map(_key, self.header) or any(self._columns(name))

    def missing_message(self, matrices: Sequence[str], vectors: Sequence[str]) -> str:
        wanted = [*vectors, *(f"{m}1..{m}n or <joint>.{m}" for m in matrices)]
        return f"{self.path}: header must have columns {'; '.join(wanted)}; found {self.header}"

    def vector(self, name: str) -> np.ndarray:
        return self._parse(self._column(name), name, None)

    def times(self, name: str) -> np.ndarray:
        col = self._column(name)
        self._parse(col, name, None)  # refuses what is not a finite number, naming the line
        cells = [row[col].strip() for row in self.rows]
        with localcontext(prec=60):  # wider than any stamp's digits: the difference is exact
            first = Decimal(cells[0])
            return np.array([float(Decimal(cell) - first) for cell in cells], dtype=np.float64)

    def _column(self, name: str) -> int:
        return [_key(label) for label in self.header].index(name.casefold())

    def matrix(self, name: str, joints: Sequence[str] | None = None, label: str | None = None) -> Column:
        numbered, named = self._columns(name)
        if not numbered and not named:
            raise ValueError(self.missing_message([name], []))
        if numbered and named:
            raise ValueError(
                f"{self.path}: both numbered ({name}1..) and per-joint (<joint>.{name}) columns for "
                f"{label or name}; keep one kind"
            )
        if named:
            order = list(named) if joints is None else list(joints)
            missing = [j for j in order if j not in named]
            if missing:
                raise ValueError(
                    f"{self.path}: no column '{missing[0]}.{name}' for joint {missing[0]!r}; the file's "
                    f"{name} columns name the joints {', '.join(named)}"
                )
            columns = [(named[j], joint) for joint, j in enumerate(order)]
            names: tuple[str, ...] | None = tuple(order)
        else:
            n = len(numbered)
            if sorted(numbered) != list(range(1, n + 1)):
                found = ", ".join(self.header[c] for _, c in sorted(numbered.items()))
                raise ValueError(
                    f"{self.path}: columns {name}1..{name}n must be numbered from 1 without gaps; "
                    f"found {found}"
                )
            columns = [(numbered[j + 1], j) for j in range(n)]
            names = None
        values = np.stack([self._parse(col, label or name, joint) for col, joint in columns], axis=1)
        return Column(values, names)

    def _parse(self, col: int, quantity: str, joint: int | None) -> np.ndarray:
        if col not in self._parsed:
            cells = [row[col] for row in self.rows]
            try:
                values = np.array(cells, dtype=np.float64)
            except ValueError:
                i = next(i for i, cell in enumerate(cells) if not _is_number(cell))
                raise ValueError(
                    f"{self.path}: line {self.lines[i]} (sample {i}), column {self.header[col]!r}: not a "
                    f"number: {cells[i]!r}"
                ) from None
            bad = np.flatnonzero(~np.isfinite(values))
            if bad.size:
                i = int(bad[0])
                where = f", joint {joint}" if joint is not None else ""
                raise ValueError(
                    f"{self.path}: array {quantity!r} (column {self.header[col]}) has a non-finite value "
                    f"({values[i]}) at sample {i} (line {self.lines[i]}){where}"
                )
            self._parsed[col] = values
        return self._parsed[col]


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _check_header(path: Path, header: list[str]) -> None:
    """Refuse a first line that is not comma-separated column names, or that names a column twice."""
    if len(header) == 1:
        for separator, name in _SEPARATORS.items():
            if separator in header[0]:
                parts = header[0].split(separator)
                shown = separator.join(parts[:3]) + (separator + "…" if len(parts) > 3 else "")
                raise ValueError(f"{path}: found {name}-separated columns {shown!r}; " + EXPECTED_CSV)
        if len(header[0].split()) > 1:
            parts = header[0].split()
            shown = " ".join(parts[:3]) + (" …" if len(parts) > 3 else "")
            raise ValueError(f"{path}: found space-separated columns {shown!r}; " + EXPECTED_CSV)
    if all(_is_number(cell) for cell in header):
        shown = ",".join(header[:3]) + (",…" if len(header) > 3 else "")
        raise ValueError(f"{path}: the first line holds numbers ({shown}), not column names; " + EXPECTED_CSV)
    seen: dict[str, int] = {}
    for col, label in enumerate(header):
        if not label:
            continue
        key = _key(label)
        if key in seen:
            first = header[seen[key]]
            same = f"column {label!r} appears twice" if first == label else f"columns {first!r} and {label!r}"
            case = "" if first == label else " name the same column (names are read case-insensitively)"
            raise ValueError(
                f"{path}: {same}{case} (columns {seen[key] + 1} and {col + 1}); which one is meant? "
                "Name each column once"
            )
        seen[key] = col


# --- NPZ -----------------------------------------------------------------------------------------


def open_npz(path: Path, expected: str) -> np.lib.npyio.NpzFile:
    """Open an ``.npz`` archive of arrays without pickles (close it, e.g. ``with open_npz(...)``).

    Args:
        path: the file.
        expected: the arrays it should hold, for the message when it holds none.

    Raises:
        ValueError: not a zip (an empty or text file), a damaged archive, or no arrays in it.
    """
    with path.open("rb") as handle:
        head = handle.read(4)
    if head not in ZIP_MAGIC:
        what = "an empty file" if not head else f"a file starting with {head!r}"
        raise ValueError(
            f"{path}: not a NumPy .npz archive (a zip of arrays, as numpy.savez writes) but {what}; "
            "text data go in a .csv file (see idkit.data.io)"
        )
    try:
        archive = np.load(path, allow_pickle=False)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise ValueError(f"{path}: a damaged .npz archive ({type(exc).__name__}: {exc})") from None
    if not archive.files:
        archive.close()
        raise ValueError(f"{path}: the .npz archive contains no arrays; expected {expected}")
    return archive


class NpzTable(Table):
    """An ``.npz`` archive's arrays (read when asked for; positional joints, no names)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        with open_npz(path, "samples (q, qd, qdd, tau) or a recording (t, q, tau)") as data:
            self.files = list(data.files)

    def has(self, name: str) -> bool:
        return name in self.files

    def names(self) -> list[str]:
        return sorted(self.files)

    def missing_message(self, matrices: Sequence[str], vectors: Sequence[str]) -> str:
        return f"{self.path}: missing array(s) {[*vectors, *matrices]}; the file has {sorted(self.files)}"

    def _array(self, key: str, label: str | None) -> np.ndarray:
        """Array ``key`` if it holds finite numbers; else a ValueError naming file and array."""
        name = f"array {key!r}" + (f" (for {label})" if label and label != key else "")
        try:
            with np.load(self.path, allow_pickle=False) as data:
                array = np.asarray(data[key])
        except ValueError:  # numpy refuses object arrays without allow_pickle
            raise ValueError(
                f"{self.path}: {name} holds Python objects (dtype object), which idkit never loads (that "
                "would need allow_pickle=True, which lets the file run code); save numeric arrays"
            ) from None
        except (zipfile.BadZipFile, OSError, EOFError) as exc:
            raise ValueError(f"{self.path}: {name} cannot be read ({type(exc).__name__}: {exc})") from None
        if array.dtype.kind not in NUMERIC_KINDS:
            raise ValueError(
                f"{self.path}: {name} has dtype {array.dtype} "
                f"({_KIND_NAMES.get(array.dtype.kind, 'not numbers')}); expected numbers (int or float)"
            )
        array = array.astype(np.float64)
        bad = np.argwhere(~np.isfinite(array))
        if len(bad):
            index = tuple(int(i) for i in bad[0])
            joint = f", joint {index[1]}" if len(index) > 1 else ""
            raise ValueError(
                f"{self.path}: {name} has a non-finite value ({array[index]}) at sample {index[0]}{joint}"
            )
        return array

    def vector(self, name: str) -> np.ndarray:
        array = self._array(name, None)
        if array.ndim != 1:
            raise ValueError(f"{self.path}: array {name!r} must be 1-D [N], got shape {array.shape}")
        return array

    def times(self, name: str) -> np.ndarray:
        values = self.vector(name)  # float64 in the file: what it holds is what it has
        return values - values[0]

    def matrix(self, name: str, joints: Sequence[str] | None = None, label: str | None = None) -> Column:
        return Column(self._array(name, label), None)


def names_hint(table: Table, names: Mapping[str, str]) -> str:
    """What a missing-column message adds: the file names asked for, or (``.npz``) how to map them."""
    renamed = {k: v for k, v in names.items() if k != v}
    if renamed:
        return f" (file names: {', '.join(f'{k}={v!r}' for k, v in renamed.items())})"
    if isinstance(table, NpzTable):
        return " (map other names with keys={'q': ..., ...}, e.g. FLOBAROID_KEYS for FloBaRoID/KUKA files)"
    return ""


def read_quantities(
    table: Table,
    names: Mapping[str, str],
    joints: Sequence[str] | None = None,
    optional: Sequence[str] = (),
) -> tuple[dict[str, np.ndarray], tuple[str, ...] | None]:
    """The quantities ``names`` (``{"q": file name, ...}``, positions first) of one table, each ``[N, n]``.

    Per-joint CSV columns are put in ``joints``' order (default: the order of the position columns),
    so every quantity has the same joints in the same order. ``optional`` quantities are left out
    when the file has none of their columns.

    Returns:
        ``({quantity: values}, joint names or None for numbered columns and arrays)``.

    Raises:
        ValueError: a required quantity missing (listing what the file has; an ``.npz`` also says how
            to map other names), a joint without a column, numbered and per-joint columns mixed.
    """
    table.require(matrices=[v for k, v in names.items() if k not in optional], hint=names_hint(table, names))
    present = [k for k in names if table.has(names[k])]
    first = table.matrix(names[present[0]], joints, label=present[0])
    order = first.joints if joints is None else joints
    columns = {present[0]: first, **{k: table.matrix(names[k], order, label=k) for k in present[1:]}}
    kinds = {k: c.joints is None for k, c in columns.items()}
    if len(set(kinds.values())) > 1:
        numbered = [k for k, positional in kinds.items() if positional]
        raise ValueError(
            f"{table.path}: {', '.join(numbered)} in numbered columns (q1..) but "
            f"{', '.join(k for k in kinds if k not in numbered)} per joint (<joint>.q); use one kind"
        )
    if any(c.values.ndim and not len(c.values) for c in columns.values()):
        shown = ", ".join(f"{k} {c.values.shape}" for k, c in columns.items())
        raise ValueError(f"{table.path}: no samples (the arrays have 0 rows: {shown})")
    widths = {k: c.values.shape[1] for k, c in columns.items() if c.values.ndim == 2}
    if len(set(widths.values())) > 1:
        shown = ", ".join(f"{k} {w}" for k, w in widths.items())
        raise ValueError(f"{table.path}: the quantities have different numbers of joints ({shown})")
    return {k: c.values for k, c in columns.items()}, first.joints
