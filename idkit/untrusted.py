"""Names from users' files (run ids, robot, joint and link names) made safe where idkit writes them.

A result folder is something people send each other, and a URDF is anyone's text: a ``run_id`` of
``../../../X`` must not become a path outside the folder asked for, nor a joint named ``=1+1`` a
formula that a spreadsheet evaluates when it opens a CSV idkit wrote. Every file name made from such
a name goes through :func:`safe_basename`, every CSV cell through :func:`csv_cell` (and a CSV idkit
reads back through :func:`csv_text`, so its own files still round-trip). Core: no idkit imports.
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Iterable
from typing import Any

#: What a spreadsheet takes as the start of a formula (OWASP's list: ``= + - @``, tab, carriage return).
FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")
#: Prefixed to such a cell: spreadsheets show the text after it, and evaluate nothing.
ESCAPE = "'"

_NOT_IN_NAME = re.compile(r"[^A-Za-z0-9._-]+")
_DOTS = re.compile(r"\.{2,}")
#: Names Windows reserves for devices, whatever the suffix.
_DEVICES = {"con", "prn", "aux", "nul", *(f"com{i}" for i in range(10)), *(f"lpt{i}" for i in range(10))}
#: Longest name returned (file systems allow 255 bytes; a prefix and suffix are added around it).
MAX_NAME = 80


def safe_basename(text: object, fallback: str = "unnamed") -> str:
    """``text`` as one harmless file-name part: ASCII letters, digits, ``_``, ``-`` and single dots
    (everything else becomes ``_``), no leading dot or dash, at most :data:`MAX_NAME` characters,
    never a device name; ``fallback`` when nothing is left.

    ``"../../../X"`` → ``"X"``, ``"a/b c"`` → ``"a_b_c"``, ``None`` or ``".."`` → ``fallback``.
    """
    name = _DOTS.sub(".", _NOT_IN_NAME.sub("_", "" if text is None else str(text)))
    name = name.lstrip("._-")[:MAX_NAME].rstrip(".")
    if not name:
        return fallback
    if name.split(".")[0].casefold() in _DEVICES:
        name = f"_{name}"
    return name


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def csv_cell(value: Any) -> Any:
    """A CSV cell a spreadsheet shows as written: text starting with ``=``, ``+``, ``-``, ``@``, tab or
    carriage return gets a leading ``'`` (a number such as ``-0.5`` or ``+1e3`` stays as it is);
    anything but text is returned unchanged."""
    if isinstance(value, str) and value.startswith(FORMULA_STARTS) and not _is_number(value):
        return ESCAPE + value
    return value


def csv_text(cell: str) -> str:
    """The text :func:`csv_cell` escaped (its inverse, for the CSV files idkit reads back)."""
    if cell.startswith(ESCAPE) and cell[1:].startswith(FORMULA_STARTS) and not _is_number(cell[1:]):
        return cell[1:]
    return cell


def csv_lines(rows: Iterable[Iterable[Any]]) -> str:
    """CSV text of ``rows`` (each cell through :func:`csv_cell`), lines ending in ``\\n``.

    A cell holding a line break (``\\r`` included) is quoted, so it cannot start a row of its own:
    Python's writer quotes only the characters of its line terminator, hence the ``\\r\\n`` one
    cut off each row.
    """
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\r\n")
    lines = []
    for row in rows:
        buffer.seek(0)
        buffer.truncate()
        writer.writerow([csv_cell(cell) for cell in row])
        lines.append(buffer.getvalue()[:-2])
    return "".join(line + "\n" for line in lines)


def csv_header(names: Iterable[str]) -> str:
    """One CSV line of column names (:func:`csv_lines`, without its line end), for writers that take
    the header as text, such as ``np.savetxt``."""
    return csv_lines([names])[:-1]
