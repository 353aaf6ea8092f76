"""Progress lines: silent for a quick step, a line every few seconds for a long one, a closing line;
the excitation search and pcls' prior-weight choice count their work through it."""

from __future__ import annotations

import io

import pytest

from idkit import progress as progress_module
from idkit.progress import EVERY_S, QUIET_S, Progress


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_a_quick_step_prints_nothing():
    out, clock = io.StringIO(), Clock()
    with Progress("step", 10, "fits", stream=out, clock=clock) as progress:
        for _ in range(10):
            clock.now += (QUIET_S - 0.5) / 10
            progress.advance()
    assert out.getvalue() == ""


def test_a_long_step_says_what_is_done_and_what_is_left():
    out, clock = io.StringIO(), Clock()
    with Progress("excitation search", 100, "iterations", stream=out, clock=clock) as progress:
        for _ in range(100):
            clock.now += 0.5  # 50 s in all
            progress.advance()
    lines = out.getvalue().splitlines()
    assert lines[0] == "excitation search: 6/100 iterations, 3 s, about 47 s left"
    assert len(lines) == 2 + int((50 - QUIET_S) // EVERY_S)  # one every EVERY_S, and the closing one
    assert lines[-1] == "excitation search: done, 100/100 iterations in 50 s"


def test_no_lines_when_disabled_or_silenced(monkeypatch):
    for enabled, variable in ((False, "1"), (True, "0")):
        monkeypatch.setenv(progress_module.ENVIRONMENT, variable)
        out, clock = io.StringIO(), Clock()
        with Progress("step", 5, stream=out, clock=clock, enabled=enabled) as progress:
            clock.now += 60
            progress.advance()
        assert out.getvalue() == ""


def test_counting_advances_once_per_call():
    progress = Progress("objective", 3, stream=io.StringIO())
    double = progress.counting(lambda x: 2 * x)
    assert [double(1), double(2)] == [2, 4] and progress.done == 2


def test_the_excitation_search_reports_its_work(monkeypatch, capsys):
    """With the quiet time at 0, every stage prints: its count reaches its stated total."""
    monkeypatch.setattr(progress_module, "QUIET_S", 0.0)
    from idkit import registry
    from idkit.excitation.optimize import optimize_excitation

    robot = registry.create("robot", "cylindrical")
    optimize_excitation(
        robot, swarms=2, particles=4, iterations=3, adam_steps=2, grid_points=20, check_points=50
    )
    said = capsys.readouterr().err
    assert "excitation search (particle swarm): done, 3/3 iterations" in said
    assert "excitation polish (Adam): done, 3/3 steps" in said


@pytest.mark.slow
def test_the_prior_weight_choice_reports_its_fits(monkeypatch, capsys, tmp_path):
    monkeypatch.setattr(progress_module, "QUIET_S", 0.0)
    import idkit
    from idkit.data.demo import write
    from idkit.estimators.physical import PRIOR_CANDIDATES, PRIOR_FOLDS

    write(tmp_path)
    idkit.identify({"_name_": "urdf", "urdf": str(tmp_path / "arm.urdf")}, str(tmp_path / "train.csv"))
    total = len(PRIOR_CANDIDATES) * PRIOR_FOLDS
    assert f"pcls prior_weight=auto (cross-validation): done, {total}/{total} fits" in capsys.readouterr().err
