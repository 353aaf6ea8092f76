"""What the command prints besides results: one line per warning, and the debug switch.

Python prints a warning as ``path:line: Category: message`` plus the source line that raised it —
two lines of idkit internals per warning, and the same warning again after every
``warnings.catch_warnings`` block resets the once-per-location registry (a 1000-trial study printed
its IRLS warning once per chunk). The command installs :class:`OneLineWarnings` instead:
``warning: <message>`` on one line, each distinct message once (``note: <message>`` for an
:class:`idkit.notes.Note`, a choice made automatically). A line printed while a progress
bar runs goes through tqdm, which clears the bar and draws it again below: the bar stays one bar.

``IDKIT_DEBUG=1`` shows each warning as Python would (source path and line, every occurrence) and
every error with its traceback (as Hydra's ``HYDRA_FULL_ERROR=1``).
"""

from __future__ import annotations

import contextlib
import os
import sys
import warnings
from collections.abc import Iterator
from typing import TextIO

from idkit.notes import Note

#: The environment switch for source paths in warnings and tracebacks in errors.
DEBUG_VARIABLE = "IDKIT_DEBUG"

PREFIX = "warning: "
NOTE_PREFIX = "note: "  #: a choice idkit made (:class:`idkit.notes.Note`), not a problem


def debugging() -> bool:
    """``IDKIT_DEBUG`` is set to a true value (``1``, ``true``, ``yes``, ``on``)."""
    return os.environ.get(DEBUG_VARIABLE, "").strip().lower() in ("1", "true", "yes", "on")


def single_line(text: str) -> str:
    """The message on one line: wrapped and indented lines joined by single spaces."""
    return " ".join(part.strip() for part in str(text).strip().splitlines() if part.strip())


def say(text: str) -> None:
    """Print ``text`` on stdout; a reader that went away (``idkit ... | head``) is not an error."""
    try:
        print(text, flush=True)
    except BrokenPipeError:  # the results are written; only the echo is lost. Quiet from here on:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())


def write_line(line: str, file: TextIO | None = None) -> None:
    """Print ``line`` on ``file`` (stderr); around a running tqdm bar, through tqdm (no torn bar)."""
    file = sys.stderr if file is None else file
    tqdm = sys.modules.get("tqdm")  # imported by a study with a bar; the command itself stays light
    if tqdm is not None:
        tqdm.tqdm.write(line, file=file)
    else:
        print(line, file=file, flush=True)


class OneLineWarnings:
    """The ``warnings.formatwarning`` replacement: each distinct message once, on one line.

    It writes the line itself (through tqdm while a bar runs, which a returned string could not)
    and gives Python nothing more to write. Replacing the formatter, not ``warnings.showwarning``,
    leaves recorders alone: ``warnings.catch_warnings(record=True)`` and ``pytest.warns`` collect
    warnings without formatting them, so they still see every one.
    """

    def __init__(self) -> None:
        self.seen: set[str] = set()

    def __call__(
        self,
        message: Warning | str,
        category: type[Warning],
        filename: str,
        lineno: int,
        line: str | None = None,
    ) -> str:
        text = single_line(str(message))
        if text not in self.seen:
            self.seen.add(text)
            write_line((NOTE_PREFIX if issubclass(category, Note) else PREFIX) + text)
        return ""


@contextlib.contextmanager
def one_line_warnings() -> Iterator[None]:
    """Show warnings on one line each while the block runs (nothing changes under ``IDKIT_DEBUG``).

    Re-entrant: an inner block (a job inside the command) leaves the outer one in charge, so a
    message already shown by an earlier job of a sweep is not shown again.
    """
    if debugging() or isinstance(warnings.formatwarning, OneLineWarnings):
        yield
        return
    previous = warnings.formatwarning
    warnings.formatwarning = OneLineWarnings()
    try:
        yield
    finally:
        warnings.formatwarning = previous
