"""The command line writes nowhere it was not asked to, and answers unusable input in one line:
``idkit compare`` on results sent by someone else, a required setting left out, a failed or
interrupted run (its empty folder goes, a re-run may reuse it), Ctrl-C in a sweep."""

from __future__ import annotations

import json

import pytest

from idkit.cli import INTERRUPTED
from idkit.cli.compare import main as compare_main


def _result(folder, run_id="r1", task="paper", payload=None):
    folder.mkdir(parents=True, exist_ok=True)
    document = {"task": task, "run_id": run_id, "label": run_id, "payload": payload or {}}
    (folder / "result.json").write_text(json.dumps(document))
    return folder


def test_compare_never_writes_outside_the_current_folder(tmp_path, monkeypatch, capsys):
    """A ``run_id`` is text from a file people send each other: ``../../../X`` once put the page three
    folders up (creating them), with exit status 0."""
    here = tmp_path / "a" / "b" / "c" / "here"
    here.mkdir(parents=True)
    monkeypatch.chdir(here)
    a = _result(tmp_path / "runs" / "one", run_id="../../../X")
    b = _result(tmp_path / "runs" / "two", run_id="/etc/passwd")
    assert compare_main([str(a), str(b)]) == 0
    assert capsys.readouterr().out == "compare page: compare-X-etc_passwd.html\n"
    assert [p.name for p in here.iterdir()] == ["compare-X-etc_passwd.html"]
    written = {p.relative_to(tmp_path) for p in tmp_path.rglob("*.html")}
    assert written == {here.relative_to(tmp_path) / "compare-X-etc_passwd.html"}
    c = _result(tmp_path / "runs" / "three", run_id="..")  # nothing usable left: the side's letter
    assert compare_main([str(c), str(c)]) == 0
    assert (here / "compare-A-B.html").is_file()


def test_compare_writes_where_out_says(tmp_path, capsys):
    a = _result(tmp_path / "one", run_id="../../../X")
    out = tmp_path / "pages" / "mine.html"
    assert compare_main([str(a), str(a), "--out", str(out)]) == 0
    assert out.is_file() and not (tmp_path.parent / "X").exists()


@pytest.mark.parametrize(
    ("payload", "said"),
    [
        (None, "payload is null, expected an object"),
        ({"estimate": [1, 2]}, "payload.estimate is a list, expected an object"),
        ({"estimate": {"params": [1.0]}}, "payload.estimate.params is a list, expected an object or null"),
        ({"estimate": {}, "validation": 3}, "payload.validation is a number, expected an object or null"),
    ],
)
def test_compare_refuses_a_damaged_result_in_one_line(tmp_path, capsys, payload, said):
    good = _result(tmp_path / "good", task="single", payload={"estimate": {"params": {"a": 1.0}}})
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "result.json").write_text(json.dumps({"task": "single", "run_id": "x", "payload": payload}))
    assert compare_main([str(good), str(bad)]) == 2
    captured = capsys.readouterr()
    assert captured.err == f"idkit: compare: {bad / 'result.json'}: {said}: not a result idkit wrote\n"
    assert captured.out == "" and not list(tmp_path.glob("*.html"))


def test_a_required_setting_left_out_says_what_it_is(run_idkit, tmp_path):
    run = tmp_path / "run"
    status, said = run_idkit("+experiment=rollout", "data=log.csv", f"hydra.run.dir={run}")
    assert status == 1
    assert said == [
        "idkit: rollout.model is required: the MJCF (.xml) or URDF (.urdf) file; give rollout.model=…"
    ]
    assert not run.exists()  # nothing was left behind


def test_a_failed_run_leaves_no_empty_folder_and_a_rerun_may_use_it(run_idkit, tmp_path):
    """Six of eight folders in a newcomer's ``outputs/`` held only ``.hydra`` and an empty log, and a
    re-run into the same folder was refused as another run's."""
    run = tmp_path / "run"
    for _ in range(2):
        status, said = run_idkit("data=nothing.csv", f"hydra.run.dir={run}")
        assert status == 1 and len(said) == 1 and "nothing.csv" in said[0]
        assert "already holds" not in said[0]
        assert not run.exists()
    status, _ = run_idkit("estimator=ls", "~cost", "plots=false", f"hydra.run.dir={run}")
    assert status == 0 and (run / "result.json").is_file()


def test_a_failed_run_keeps_a_log_with_content_and_says_where(tmp_path):
    from idkit.cli.provenance import RECORD_DIR, abandon

    run = tmp_path / "run"
    (run / RECORD_DIR).mkdir(parents=True)
    (run / RECORD_DIR / "config.yaml").write_text("a: 1\n")
    (run / "idkit.log").write_text("something worth reading\n")
    assert abandon(run) == f" (its log: {run / 'idkit.log'})"
    assert [p.name for p in run.iterdir()] == ["idkit.log"]
    mine = tmp_path / "mine"  # a folder that holds anything else is left as it is
    (mine / RECORD_DIR).mkdir(parents=True)
    (mine / "notes.txt").write_text("mine")
    assert abandon(mine) == "" and {p.name for p in mine.iterdir()} == {RECORD_DIR, "notes.txt"}


def test_ctrl_c_early_in_a_sweep_job_stops_the_sweep_with_130(run_idkit, tmp_path, monkeypatch):
    """Ctrl-C in a robustness job before its first chunk ended made the partial report fail
    (``IndexError: boolean index did not match``), and the sweep ran the next job to its end."""
    import idkit.estimators.trials as trials

    real, calls = trials.fit_trials, []

    def interrupted(*args, **kwargs):
        calls.append(1)
        if len(calls) == 4:  # the first chunk, once its first scenario is fitted
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(trials, "fit_trials", interrupted)
    sweep = tmp_path / "sweep"
    status, said = run_idkit(
        "-m",
        "+experiment=robustness",
        "trials=4",
        "robustness.chunk=2",
        "robustness.scenarios=[state_noise,outliers]",
        "robustness.estimators=[{_name_: ls},{_name_: rls}]",
        "robustness.pso_costs=[f1]",
        "robustness.average_of=[]",
        "robustness.optional=[]",
        "robustness.baseline=LS",
        "estimator.runs=1",
        "estimator.particles=4",
        "estimator.iterations=2",
        "plots=false",
        "seed=0,1",
        f"hydra.sweep.dir={sweep}",
    )
    assert status == INTERRUPTED, said
    assert said[-1] == f"idkit: interrupted; partial results (0 of 4 trials) in {sweep / '0'}"
    assert len(calls) == 4 and not (sweep / "1").exists()  # no further job
    partial = json.loads((sweep / "0" / "result.json").read_text())
    assert partial["status"] == "partial" and partial["progress"]["done"] == 0


def test_an_interrupted_run_leaves_no_empty_folder(run_idkit, tmp_path, monkeypatch):
    import functools

    import idkit.studies.single as single

    @functools.wraps(single.run)  # the task reads the study's signature
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(single, "run", interrupted)
    run = tmp_path / "run"
    status, said = run_idkit("estimator=ls", "~cost", f"hydra.run.dir={run}")
    assert status == INTERRUPTED, said
    assert said == [f"idkit: interrupted; no results were written to {run}"]
    assert not run.exists()


def test_compare_refuses_a_value_of_another_type_in_one_line(tmp_path, capsys):
    payload = {"estimate": {"params": {"a": 1.0}}}
    good = _result(tmp_path / "good", task="single", payload=payload)
    odd = _result(tmp_path / "odd", task="single", payload={"estimate": {"params": {"a": "one"}}})
    assert compare_main([str(good), str(odd)]) == 2
    said = capsys.readouterr().err
    assert said.startswith(f"idkit: compare: {good}, {odd}: a result.json idkit cannot read (TypeError: ")
    assert said.count("\n") == 1 and not list(tmp_path.glob("*.html"))


def test_ctrl_c_turned_into_another_error_still_ends_the_sweep_with_130(run_idkit, tmp_path, monkeypatch):
    """Whatever a job's code makes of the KeyboardInterrupt (here an IndexError, as a half-built result
    gave), the command ends with 130 and the sweep runs no further job."""
    import functools
    import os
    import signal
    import time

    import idkit.studies.single as single

    # a process started in the background inherits SIGINT ignored: give it Python's own handler
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    jobs = []

    @functools.wraps(single.run)
    def interrupted(*args, **kwargs):
        jobs.append(1)
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5)  # the handler raises at once: never reached
        except KeyboardInterrupt:
            raise IndexError("boolean index did not match") from None

    monkeypatch.setattr(single, "run", interrupted)
    try:
        status, said = run_idkit(
            "-m", "estimator=ls", "~cost", "seed=0,1", f"hydra.sweep.dir={tmp_path / 's'}"
        )
    finally:
        signal.signal(signal.SIGINT, previous)
    assert status == INTERRUPTED, said
    assert said[-1] == "idkit: interrupted (IndexError on the way out)"
    assert jobs == [1]
