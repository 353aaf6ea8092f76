"""A refused command-line input becomes one line naming its cause (in process, fast)."""

from __future__ import annotations

import os

import pytest

from idkit.cli import app, errors


def refusal(compose, *overrides: str) -> str:
    """The one line for the error Hydra raises composing ``overrides``."""
    with pytest.raises(Exception) as err:
        compose(*overrides)
    line = errors.one_line(err.value)
    assert line is not None and "\n" not in line, line
    return line


def test_unknown_names_list_the_closest_first(hydra_compose):
    line = refusal(hydra_compose, "cost=f133")
    assert line.startswith("unknown cost 'f133'; available costs (closest first): f13, ")
    assert "search path" not in line
    assert refusal(hydra_compose, "robot=cylindricl").startswith(
        "unknown robot 'cylindricl'; available robots (closest first): cylindrical, "
    )
    assert refusal(hydra_compose, "+experiment=kukaa") == (
        "unknown experiment 'kukaa'; available experiments (closest first): "
        "kuka, paper, rollout, robustness, excitation"
    )


def test_a_key_typo_lists_the_valid_keys_closest_first(hydra_compose):
    line = refusal(hydra_compose, "estimator.particls=40")
    assert line.startswith(
        "estimator 'pso' has no option 'particls'; its options (closest first): particles, "
    )
    assert "_name_" not in line
    line = refusal(hydra_compose, "seeed=1")
    assert line.startswith("there is no setting 'seeed'; the settings (closest first): seed, ")
    assert "hydra" not in line
    line = refusal(hydra_compose, "+experiment=paper", "paper.costz=[f1]")
    assert line.startswith("paper has no key 'costz'; its keys (closest first): costs, ")


def test_other_hydra_refusals_are_flattened_to_one_line(hydra_compose):
    assert "particles" in refusal(hydra_compose, "estimator.particles=[")


def test_user_errors_pass_and_bugs_keep_their_traceback():
    assert errors.one_line(ValueError("stride must be >= 1")) == "stride must be >= 1"
    assert errors.one_line(FileNotFoundError("x.npz")) == "x.npz"
    assert errors.one_line(ZeroDivisionError("division by zero")) is None
    assert errors.one_line(RuntimeError("bug")) is None


def test_running_out_of_memory_is_one_line_naming_the_sizes():
    import torch

    try:
        torch.empty(10**15)  # 8 PB: refused by the allocator before anything is touched
    except RuntimeError as exc:
        line = errors.one_line(exc)
    assert line is not None
    assert line.startswith("out of memory: can't allocate memory: you tried to allocate ")
    assert line.endswith(f"; smaller sizes need less ({errors.SIZES})")
    assert errors.one_line(MemoryError("kernel buffers")) == (
        f"out of memory: kernel buffers; smaller sizes need less ({errors.SIZES})"
    )
    assert errors.one_line(RuntimeError("shape mismatch")) is None  # a bug keeps its traceback


def test_main_prints_one_line_and_exits_1(run_idkit):
    status, said = run_idkit("estimator=psoo")
    assert status == errors.USAGE
    assert len(said) == 1 and said[0].startswith("idkit: unknown estimator 'psoo'; available estimators")
    assert app.FULL_ERROR not in os.environ  # set for Hydra during the run only


@pytest.mark.skipif(not os.path.isdir("/proc/self/fd"), reason="finds the file being written through /proc")
def test_a_full_disk_is_one_line_and_leaves_what_was_written_intact(run_idkit, tmp_path, monkeypatch):
    """The disk fills while the results are written (``OSError: No space left on device``): one line
    naming the file, exit status 1, no half-written file, and an earlier result kept as it was."""
    import errno
    import json

    from idkit.reports import files

    earlier = tmp_path / "earlier"
    assert run_idkit("estimator=ls", "~cost", "plots=false", f"hydra.run.dir={earlier}")[0] == 0
    before = (earlier / "result.json").read_text()
    real = os.fdopen

    def full_disk(fd, *args, **kwargs):
        handle = real(fd, *args, **kwargs)
        if "result.json" in os.readlink(f"/proc/self/fd/{fd}"):

            def write(data):
                raise OSError(errno.ENOSPC, "No space left on device")

            handle.write = write
        return handle

    monkeypatch.setattr(files.os, "fdopen", full_disk)
    run = tmp_path / "run"
    status, said = run_idkit("estimator=ls", "~cost", "plots=false", f"hydra.run.dir={run}")
    assert status == 1 and said == [
        f"idkit: cannot write {run / 'result.json'}: No space left on device; nothing of it was written "
        "(files written before it are intact)"
    ]
    assert not (run / "result.json").exists() and not list(run.glob(".*.tmp"))
    assert (run / ".hydra" / "config.yaml").is_file()  # written before: intact
    with pytest.raises(files.WriteError):  # over an earlier result: the earlier one stays
        files.write_json(earlier / "result.json", {"new": 1})
    assert (earlier / "result.json").read_text() == before and json.loads(before)["task"] == "single"


def test_ctrl_c_while_composing_the_config_is_one_line_and_exit_130(monkeypatch, capsys):
    """Ctrl-C in the first seconds (importing torch, Hydra composing the config: before any task, which
    says what it wrote) printed a hundred lines of Hydra's and torch's frames."""
    import idkit.cli

    def interrupted() -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(app, "main", interrupted)
    with pytest.raises(SystemExit) as stop:
        idkit.cli.main()
    assert stop.value.code == idkit.cli.INTERRUPTED == 130
    assert capsys.readouterr().err.splitlines() == ["idkit: interrupted"]
