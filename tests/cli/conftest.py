"""The command run in process, for tests that need its exit status and what it printed."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import NamedTuple

import pytest
from hydra.core.global_hydra import GlobalHydra

from idkit.cli import app


class Outcome(NamedTuple):
    status: int
    out: str
    err: str


@pytest.fixture
def run_idkit(monkeypatch, capsys) -> Callable[..., Outcome]:
    """``run_idkit(*words)``: ``idkit.cli.app.main`` with ``sys.argv = ["idkit", *words]``.

    Once torch is imported a least-squares fit takes milliseconds, so whole runs stay fast.
    """

    def run(*words: str) -> Outcome:
        monkeypatch.setattr(sys, "argv", ["idkit", *words])
        monkeypatch.delenv(app.FULL_ERROR, raising=False)
        GlobalHydra.instance().clear()
        try:
            app.main()
            status = 0
        except SystemExit as exit_:
            status = exit_.code
        finally:
            GlobalHydra.instance().clear()
        said = capsys.readouterr()
        return Outcome(status, said.out, said.err)

    return run
