"""Progress lines for a step that runs longer than a few seconds.

A user who starts a fit and sees nothing for a minute cannot tell a slow step from a hung one. A
step that counts its work (iterations, fits) reports it here: nothing for the first
:data:`QUIET_S` seconds — a quick step stays silent — then one line on stderr every
:data:`EVERY_S` seconds with what is done, the time so far and an estimate of the time left, and
one closing line. Lines, not a redrawn bar: they read the same in a terminal, a log file and a CI
log. While a tqdm bar runs (the robustness study's), a line goes through ``tqdm.write``, which
keeps the bar whole.

    with Progress("excitation search", total=iterations, unit="iterations") as progress:
        for _ in range(iterations):
            ...
            progress.advance()
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from types import TracebackType
from typing import Any, TextIO

#: Seconds a step runs before its first line.
QUIET_S = 3.0
#: Seconds between lines.
EVERY_S = 10.0
#: Set to ``0`` to silence every progress line (e.g. in a batch job whose log is read by a program).
ENVIRONMENT = "IDKIT_PROGRESS"


class Progress:
    """Counts a step's work and prints a line now and then (module doc).

    Args:
        what: the step, as the line starts (``"pcls prior_weight=auto"``).
        total: the work to do, in ``unit`` (``None``: unknown, no estimate of the time left).
        unit: what is counted (``"iterations"``, ``"fits"``).
        enabled: ``False`` prints nothing (and so does ``IDKIT_PROGRESS=0``).
        stream: where lines go (default: ``sys.stderr`` at the time of each line).
        clock: seconds, for tests (default ``time.monotonic``).
    """

    def __init__(
        self,
        what: str,
        total: int | None = None,
        unit: str = "steps",
        *,
        enabled: bool = True,
        stream: TextIO | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.what, self.total, self.unit = what, total, unit
        self.enabled = enabled and os.environ.get(ENVIRONMENT, "1") != "0"
        self.stream, self.clock = stream, clock
        self.done = 0
        self.started = clock()
        self.next_line = self.started + QUIET_S
        self.lines = 0

    def __enter__(self) -> Progress:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        if kind is None:
            self.finish()

    def advance(self, amount: int = 1) -> None:
        """``amount`` more units done; a line if one is due."""
        self.done += amount
        now = self.clock()
        if self.enabled and now >= self.next_line:
            self.next_line = now + EVERY_S
            self._say(self._status(now))

    def finish(self) -> None:
        """The closing line, where the step printed any (a quick step stays silent)."""
        if self.enabled and self.lines:
            self._say(f"{self.what}: done, {self._count()} in {self.clock() - self.started:.0f} s")

    def _count(self) -> str:
        return f"{self.done} {self.unit}" if self.total is None else f"{self.done}/{self.total} {self.unit}"

    def _status(self, now: float) -> str:
        elapsed = now - self.started
        line = f"{self.what}: {self._count()}, {elapsed:.0f} s"
        if self.total and 0 < self.done < self.total:
            line += f", about {elapsed * (self.total - self.done) / self.done:.0f} s left"
        return line

    def _say(self, line: str) -> None:
        self.lines += 1
        stream = self.stream or sys.stderr
        bar: Any = sys.modules.get("tqdm")
        if bar is not None and stream is sys.stderr:
            bar.tqdm.write(line, file=stream)
        else:
            print(line, file=stream, flush=True)

    def counting(self, function: Callable[..., Any]) -> Callable[..., Any]:
        """``function``, advancing this count by one on every call (an objective the search calls
        once per iteration)."""

        def counted(*args: Any, **kwargs: Any) -> Any:
            result = function(*args, **kwargs)
            self.advance()
            return result

        return counted
