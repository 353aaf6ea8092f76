"""A run into a folder another run used is refused before anything is written, in every mode.

The command runs in process (the ``run_idkit`` fixture), so these stay in the fast suite.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from idkit.cli import errors
from idkit.cli.callbacks import claim_sweep
from idkit.cli.provenance import RunDirectoryTaken, claim

FIT = ["estimator=ls", "plots=false"]


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (hidden ones too) and its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_claim_refuses_a_folder_with_another_runs_files(tmp_path):
    claim(tmp_path / "new")  # absent: fine
    claim(tmp_path)  # empty: fine
    (tmp_path / "notes.txt").write_text("mine")
    claim(tmp_path)  # a user's own files are not a run
    for name in ("result.json", ".hydra", "error.json"):
        folder = tmp_path / name.strip(".")
        folder.mkdir()
        (folder / name).mkdir() if name == ".hydra" else (folder / name).write_text("{}")
        with pytest.raises(RunDirectoryTaken, match=rf"already holds another run \({name}\); nothing was"):
            claim(folder)


def test_claim_sweep_refuses_a_folder_with_another_sweep(tmp_path):
    claim_sweep(tmp_path / "new")
    (tmp_path / "3").mkdir()
    claim_sweep(tmp_path)  # an empty job folder holds no run
    (tmp_path / "3" / "result.json").write_text("{}")
    with pytest.raises(RunDirectoryTaken, match=r"another sweep \(3/result.json\).*hydra.sweep.dir"):
        claim_sweep(tmp_path)
    (tmp_path / "3" / "result.json").unlink()
    (tmp_path / "multirun.yaml").write_text("{}")
    with pytest.raises(RunDirectoryTaken, match=r"another sweep \(multirun.yaml\)"):
        claim_sweep(tmp_path)


def test_a_run_into_an_earlier_runs_folder_changes_none_of_its_files(tmp_path, monkeypatch, run_idkit):
    monkeypatch.chdir(tmp_path)
    run = tmp_path / "run"
    assert run_idkit(*FIT, f"hydra.run.dir={run}") == (0, [])
    assert {"result.json", ".hydra/config.yaml", ".hydra/hydra.yaml", ".hydra/overrides.yaml"} <= set(
        snapshot(run)
    )
    overrides = (run / ".hydra" / "overrides.yaml").read_text()
    assert "- estimator=ls" in overrides and f"- hydra.run.dir={run}" not in overrides  # as Hydra writes it
    before = snapshot(run)
    status, said = run_idkit("estimator=rls", "plots=false", f"hydra.run.dir={run}")
    assert status == errors.USAGE
    assert said == [
        f"idkit: {run} already holds another run (result.json, .hydra); nothing was written: "
        "choose another hydra.run.dir (a new folder) or leave it unset"
    ]
    assert snapshot(run) == before


def test_a_folder_holding_only_a_saved_result_gets_nothing(tmp_path, run_idkit):
    """A folder ``Result.save`` wrote (no .hydra, no log): not even Hydra's log file appears."""
    folder = tmp_path / "saved"
    folder.mkdir()
    (folder / "result.json").write_text(json.dumps({"run_id": "library"}))
    status, said = run_idkit(*FIT, f"hydra.run.dir={folder}")
    assert status == errors.USAGE and "already holds another run (result.json)" in said[0]
    assert snapshot(folder) == {"result.json": b'{"run_id": "library"}'}


def test_a_sweep_into_an_earlier_sweeps_folder_changes_none_of_its_files(tmp_path, monkeypatch, run_idkit):
    monkeypatch.chdir(tmp_path)
    sweep = tmp_path / "sweep"
    assert run_idkit("-m", *FIT, "seed=0,1", f"hydra.sweep.dir={sweep}")[0] == 0
    before = snapshot(sweep)
    assert {"multirun.yaml", "summary.csv", "0/result.json", "1/.hydra/config.yaml"} <= set(before)
    status, said = run_idkit("-m", *FIT, "seed=2,3", f"hydra.sweep.dir={sweep}")
    assert status == errors.USAGE
    assert said == [
        f"idkit: {sweep} already holds another sweep (multirun.yaml, summary.csv, summary.md, 0/result.json, "
        "…); nothing was written: choose another hydra.sweep.dir (a new folder) or leave it unset"
    ]
    assert snapshot(sweep) == before


def test_two_jobs_sent_to_one_folder_keep_the_first(tmp_path, monkeypatch, run_idkit):
    """``hydra.sweep.subdir`` that names one folder for two jobs: the second is refused and its
    error is not written into the first job's folder."""
    monkeypatch.chdir(tmp_path)
    sweep = tmp_path / "sweep"
    words = ["-m", *FIT, "seed=0,1", f"hydra.sweep.dir={sweep}", "hydra.sweep.subdir=same"]
    status, said = run_idkit(*words)
    assert status == errors.USAGE
    assert said[-1].startswith(f"idkit: {sweep / 'same'} already holds another run")
    job = json.loads((sweep / "same" / "result.json").read_text())
    assert job["seed"] == 0 and not (sweep / "same" / "error.json").exists()
    assert "seed=0" in (sweep / "same" / ".hydra" / "overrides.yaml").read_text()


# --- a folder the run cannot write into: one line at the start, never Hydra's mkdir traceback ---


def test_a_run_folder_that_is_a_file_or_lies_under_one_is_one_line(tmp_path, monkeypatch, run_idkit):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "afile").write_text("mine")
    assert run_idkit(*FIT, "hydra.run.dir=afile") == (
        1,
        ["idkit: hydra.run.dir: afile is a file, not a folder"],
    )
    assert run_idkit(*FIT, "hydra.run.dir=afile/run") == (
        1,
        ["idkit: hydra.run.dir: afile is a file, not a folder, so afile/run cannot be created"],
    )
    assert run_idkit("-m", *FIT, "hydra.sweep.dir=afile/sweep")[1] == [
        "idkit: hydra.sweep.dir: afile is a file, not a folder, so afile/sweep cannot be created"
    ]
    assert (tmp_path / "afile").read_text() == "mine"


def test_a_run_folder_without_write_permission_is_one_line(tmp_path, monkeypatch, run_idkit):
    """As a read-only mount or a folder of another user does (simulated: the test may run as root)."""
    import tempfile

    def refused(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(tempfile, "TemporaryFile", refused)
    status, lines = run_idkit(*FIT, "hydra.run.dir=locked/run")
    assert (status, lines) == (1, ["idkit: hydra.run.dir: cannot write into locked/run: Permission denied"])


def test_the_api_refuses_an_out_dir_it_cannot_use_before_fitting(tmp_path, monkeypatch):
    import idkit
    from idkit.reports.files import FolderError
    from idkit.studies import single

    (tmp_path / "afile").write_text("mine")
    monkeypatch.setattr(single, "run", lambda *a, **k: pytest.fail("fitted before checking out_dir"))
    with pytest.raises(FolderError, match=r"^out_dir: .*afile is a file, not a folder$"):
        idkit.run(estimator="ls", cost=None, out_dir=tmp_path / "afile")
