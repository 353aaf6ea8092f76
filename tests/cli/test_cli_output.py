"""What the command prints besides results: warnings, the progress bar, --version, its words."""

from __future__ import annotations

import importlib.metadata
import io
import sys
import warnings

import pytest

from idkit.cli import app, command_line, errors, output


def test_a_warning_is_one_line_and_shown_once(capsys, monkeypatch):
    """What Python's printer gets from the installed formatter (pytest records warnings itself)."""
    monkeypatch.delenv(output.DEBUG_VARIABLE, raising=False)
    message = "irls: huber stage did not converge\n    in 200 iterations"
    with output.one_line_warnings():
        for text in (message, message, "another one"):
            assert warnings.formatwarning(RuntimeWarning(text), RuntimeWarning, "x.py", 1, "code") == ""
    assert capsys.readouterr().err.splitlines() == [
        "warning: irls: huber stage did not converge in 200 iterations",
        "warning: another one",
    ]
    assert not isinstance(warnings.formatwarning, output.OneLineWarnings)  # restored after the block


def test_recorded_warnings_stay_recorded(monkeypatch):
    """``pytest.warns`` around the command (tests run ``main`` in process) still sees each warning."""
    monkeypatch.delenv(output.DEBUG_VARIABLE, raising=False)
    with pytest.warns(UserWarning, match="kept") as said, output.one_line_warnings():
        warnings.warn("kept", UserWarning, stacklevel=1)
        warnings.warn("kept", UserWarning, stacklevel=1)
    assert len(said) >= 1


def test_debug_leaves_pythons_own_warning_format(monkeypatch):
    monkeypatch.setenv(output.DEBUG_VARIABLE, "1")
    before = warnings.formatwarning
    with output.one_line_warnings():
        assert warnings.formatwarning is before  # path, line and code of every warning, as Python prints


def _screen(stream: str) -> list[str]:
    """The lines a terminal shows for ``stream``: each carriage return rewrites its line."""
    shown = []
    for line in stream.split("\n"):
        row = ""
        for part in line.split("\r"):
            row = part + row[len(part) :]
        if row.strip():
            shown.append(row.rstrip())
    return shown


@pytest.mark.parametrize("through_idkit", [True, False])
def test_a_warning_during_a_progress_bar_leaves_one_bar(through_idkit):
    from tqdm import tqdm

    stream = io.StringIO()
    with tqdm(total=2, desc="robustness", file=stream, mininterval=0, ncols=60) as bar:
        bar.update(1)
        if through_idkit:
            output.write_line("warning: something", file=stream)
        else:  # what Python's own warning printer does
            stream.write("warning: something\n")
        bar.update(1)
    screen = _screen(stream.getvalue())
    if through_idkit:
        assert len(screen) == 2 and screen[0] == "warning: something"
        assert screen[1].startswith("robustness: 100%")
    else:  # what the command printed before: the bar torn in two, the warning glued to the first
        assert len([row for row in screen if "robustness" in row]) == 2


def test_version_is_the_distributions_not_hydras(monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["idkit", "estimator=ls", "--version"])
    app.main()
    assert capsys.readouterr().out == f"idkit {importlib.metadata.version('robot-idkit')}\n"
    import idkit

    assert idkit.__version__ == importlib.metadata.version("robot-idkit")


@pytest.mark.parametrize(
    ("word", "meant"),
    [
        ("paper", "+experiment=paper"),
        ("robustnes", "+experiment=robustness"),
        ("outliers", "+scenario=outliers"),
        ("pso", "estimator=pso"),
        ("f13", "cost=f13"),
        ("urdf", "robot=urdf"),
        ("help", "--help"),
    ],
)
def test_a_bare_word_suggests_the_override_it_names(word, meant):
    assert command_line.bare_word_message(word) == (
        f"{word!r} is not an override (key=value); did you mean {meant}?"
    )


def test_a_bare_word_naming_nothing_says_what_an_override_is():
    assert command_line.bare_word_message("xyzzy").startswith("'xyzzy' is not an override: write key=value")


def test_flags_may_come_anywhere_and_their_mistakes_are_one_line():
    assert command_line.arrange(["estimator=ls", "-m", "seed=1,2", "--cfg", "job", "~cost"]) == [
        "estimator=ls",
        "seed=1,2",
        "~cost",
        "-m",
        "--cfg",
        "job",
    ]
    with pytest.raises(command_line.UsageError, match=r"^argument --cfg/-c: invalid choice: 'jobb'"):
        command_line.arrange(["--cfg", "jobb"])
    with pytest.raises(command_line.UsageError, match=r"unrecognized arguments: --particles"):
        command_line.arrange(["--particles", "3"])


def test_main_refuses_a_bare_word_in_one_line(run_idkit):
    assert run_idkit("paper") == (
        errors.USAGE,
        ["idkit: 'paper' is not an override (key=value); did you mean +experiment=paper?"],
    )


def test_a_note_is_one_line_marked_as_a_note(capsys, monkeypatch):
    """A choice idkit made (``idkit.notes.Note``) is not a problem: ``note:``, not ``warning:``."""
    from idkit.notes import Note

    monkeypatch.delenv(output.DEBUG_VARIABLE, raising=False)
    with output.one_line_warnings():
        warnings.formatwarning(Note("cut-off 6 Hz\n (auto: …)"), Note, "x.py", 1)
        warnings.formatwarning(UserWarning("torques floored"), UserWarning, "x.py", 1)
    printed = capsys.readouterr().err.splitlines()
    assert printed == ["note: cut-off 6 Hz (auto: …)", "warning: torques floored"]
