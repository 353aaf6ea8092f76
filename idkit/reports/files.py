"""Atomic file writes: a run that fails half-way never leaves a truncated result behind.

Each writer renders the whole content first, writes it to a temporary file in the same directory
and renames it over the target (``os.replace`` is atomic on POSIX and Windows), so a reader — or a
sweep summary gathered while other jobs still run — sees either the old file or the new one. A file
replaced keeps its mode; a new one gets what ``open()`` would give. :func:`stage_text` splits the two
steps, so that a model file appears only once its ``result.json`` is written
(:func:`idkit.reports.result_file.write_result`). Every CSV cell passes :func:`idkit.untrusted.csv_cell`.
"""

from __future__ import annotations

import io
import json
import os
import stat
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from idkit.estimate import json_safe
from idkit.untrusted import csv_lines

_UMASK = os.umask(0)
os.umask(_UMASK)
_MODE = 0o666 & ~_UMASK  # what open() would have given; mkstemp's 0600 is for secrets


class FolderError(ValueError):
    """A folder results cannot be written into (a file, a read-only place, no permission)."""


class WriteError(OSError):
    """A result file could not be written (the disk full, a quota, the folder gone read-only): the
    message names the file; the file as it was before, and every file written earlier, are intact."""

    def __init__(self, path: Path, error: OSError) -> None:
        super().__init__(error.errno, error.strerror or str(error), str(path))
        self.message = (
            f"cannot write {path}: {error.strerror or error}; nothing of it was written (files written "
            "before it are intact)"
        )

    def __str__(self) -> str:
        return self.message


def writable_folder(folder: str | Path, setting: str) -> Path:
    """``folder``, created if missing, once a file could be written in it; else one line naming it.

    Checked before a run so that a folder it cannot use ends the run at its start, with the option
    that named the folder, not with a traceback from the first file it writes after the fit.

    Args:
        folder: where the results go.
        setting: the option that named it (``hydra.run.dir``, ``out_dir``), for the message.

    Raises:
        FolderError: ``folder`` or a folder above it is a file, or it cannot be created or written.
    """
    folder = Path(folder)
    for part in (folder, *folder.parents):
        if part.exists():
            if not part.is_dir():
                inside = "" if part == folder else f", so {folder} cannot be created"
                raise FolderError(f"{setting}: {part} is a file, not a folder{inside}")
            break
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        raise FolderError(f"{setting}: cannot write into {folder}: {error.strerror or error}") from None
    return folder


def _mode(path: Path) -> int:
    """The mode a write to ``path`` leaves: the existing file's, else ``open()``'s default."""
    try:
        return stat.S_IMODE(path.stat().st_mode)
    except OSError:
        return _MODE


@dataclass(frozen=True)
class Staged:
    """A file's whole content written to a temporary file beside ``path``, not yet in its place."""

    path: Path
    temporary: Path

    def commit(self) -> Path:
        """Put the file in place (one rename, with the mode :func:`_mode` gives); returns its path."""
        try:
            os.chmod(self.temporary, _mode(self.path))
            os.replace(self.temporary, self.path)
        except BaseException as error:
            self.discard()
            if isinstance(error, OSError):
                raise WriteError(self.path, error) from None
            raise
        return self.path

    def discard(self) -> None:
        """Remove the temporary file (the target is left as it was)."""
        self.temporary.unlink(missing_ok=True)


def stage_text(path: str | Path, text: str) -> Staged:
    """Write ``text`` (UTF-8) next to ``path`` for a later :meth:`Staged.commit`.

    Raises:
        WriteError: the temporary file cannot be written (none is left behind).
    """
    return _stage(Path(path), text.encode("utf-8"))


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8, newlines as given) to ``path`` atomically; returns the path."""
    return _write_bytes(path, text.encode("utf-8"))


def write_json(path: str | Path, data: Any) -> Path:
    """Strict JSON (a non-finite float becomes ``"Infinity"``, ``"-Infinity"`` or ``"NaN"``), indented,
    written atomically."""
    return write_text(path, json.dumps(json_safe(data), indent=2, allow_nan=False) + "\n")


def write_csv(path: str | Path, header: Sequence[str], rows: Iterable[Sequence[Any]]) -> Path:
    """A CSV with one header line, written atomically; a text cell that a spreadsheet would take for a
    formula is escaped (:func:`idkit.untrusted.csv_lines`)."""
    return write_text(path, csv_lines([header, *rows]))


def write_npz(path: str | Path, arrays: dict[str, Any]) -> Path:
    """Named arrays as an uncompressed ``.npz``, written atomically."""
    import numpy as np

    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return _write_bytes(path, buffer.getvalue())


def _write_bytes(path: str | Path, data: bytes) -> Path:
    return _stage(Path(path), data).commit()


def _stage(path: Path, data: bytes) -> Staged:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as error:
        raise WriteError(path, error) from None
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
    except BaseException as error:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(error, OSError):
            raise WriteError(path, error) from None
        raise
    return Staged(path, Path(tmp))


def save_figure(fig: Any, path: str | Path) -> Path:
    """Save a matplotlib figure as PNG atomically (a bare ``Figure``: nothing to close)."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=120, bbox_inches="tight")
    return _write_bytes(path, buffer.getvalue())
