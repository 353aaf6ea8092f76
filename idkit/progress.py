"""Progress lines of a long fit: what it is doing, at most one line every few seconds.

A study that takes ``progress`` (the command sets it when stderr is a terminal, as for the robustness
study's bar) opens :func:`reporting`; the estimator, wherever it is, calls :func:`report` with its stage,
iteration and best cost — a call that costs a clock read and prints nothing when no study listens, so
an estimator used from Python stays quiet. A line looks like::

    rollout: search · iteration 12/30 · best cost 3.21 · 1,234 rollouts · 8.1 s

A new stage prints at once; within a stage at most one line per :data:`INTERVAL` seconds.
"""

from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Callable, Iterator
from contextvars import ContextVar
from dataclasses import dataclass, field

#: Seconds between two lines of the same stage, at least.
INTERVAL = 3.0


def _stderr(line: str) -> None:
    """Print on stderr; around a running tqdm bar, through tqdm (no torn bar)."""
    tqdm = sys.modules.get("tqdm")
    if tqdm is not None:
        tqdm.tqdm.write(line, file=sys.stderr)
    else:
        print(line, file=sys.stderr, flush=True)


@dataclass
class Reporter:
    """Where progress goes (:func:`reporting` makes one): ``write`` each line, ``label`` leading it."""

    label: str
    write: Callable[[str], None] = _stderr
    interval: float = INTERVAL
    clock: Callable[[], float] = time.monotonic
    rollouts: Callable[[], int] | None = None
    started: float = field(init=False)
    _last: float = field(init=False, default=-float("inf"))
    _stage: str | None = field(init=False, default=None)
    _calls: dict[str, int] = field(init=False, default_factory=dict)

    def __post_init__(self) -> None:
        self.started = self.clock()

    def update(
        self,
        stage: str,
        iteration: int | None,
        of: int | None = None,
        best: float | None = None,
        what: str = "best cost",
    ) -> None:
        self._calls[stage] = self._calls.get(stage, 0) + 1
        iteration = self._calls[stage] if iteration is None else iteration
        now = self.clock()
        if stage == self._stage and now - self._last < self.interval:
            return
        self._stage, self._last = stage, now
        parts = [f"{self.label}: {stage}", f"iteration {iteration}" + (f"/{of}" if of else "")]
        if best is not None:
            parts.append(f"{what} {best:.4g}")
        if self.rollouts is not None:
            parts.append(f"{self.rollouts():,} rollouts")
        parts.append(f"{now - self.started:.1f} s")
        self.write(" · ".join(parts))


_current: ContextVar[Reporter | None] = ContextVar("idkit_progress", default=None)


@contextlib.contextmanager
def reporting(
    label: str, enabled: bool = True, write: Callable[[str], None] = _stderr, interval: float = INTERVAL
) -> Iterator[Reporter | None]:
    """Within the block, :func:`report` calls print lines through ``write`` (``enabled=False``: nothing)."""
    if not enabled:
        yield None
        return
    reporter = Reporter(label, write, interval)
    token = _current.set(reporter)
    try:
        yield reporter
    finally:
        _current.reset(token)


def listening() -> bool:
    """Whether a study is :func:`reporting` (a caller skips computing what only a line would show)."""
    return _current.get() is not None


def count_rollouts(counter: Callable[[], int]) -> None:
    """Lines from here on show ``counter()`` rollouts run (the estimator that runs them says how many)."""
    reporter = _current.get()
    if reporter is not None:
        reporter.rollouts = counter


def report(
    stage: str,
    iteration: int | None = None,
    of: int | None = None,
    best: float | None = None,
    what: str = "best cost",
) -> None:
    """Say where a fit is: ``stage`` (``search``, ``polish``), ``iteration`` (of ``of``; ``None``: the
    count of this stage's reports so far), the ``best`` value so far (named ``what``). Nothing happens
    unless a study is :func:`reporting`."""
    reporter = _current.get()
    if reporter is not None:
        reporter.update(stage, iteration, of, best, what)
