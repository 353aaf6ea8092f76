"""The real ``idkit`` command in a subprocess: the issue's command, plugins, errors, sweeps.

Each subprocess pays the torch import, so there are few of them and each checks several things; all
but the issue's command and ``--help`` are ``integration`` tests (``make test-all``, CI).
"""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

IDKIT = [sys.executable, "-c", "from idkit.cli import main; main()"]


def idkit(*args: str, cwd: Path, env: dict[str, str] | None = None, timeout: float = 300):
    return subprocess.run([*IDKIT, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def only(paths: list[Path]) -> Path:
    assert len(paths) == 1, paths
    return paths[0]


def test_help_lists_the_registry_without_importing_torch(tmp_path):
    code = textwrap.dedent(
        """
        import sys
        sys.argv = ["idkit", "--help"]
        from idkit.cli import main
        try:
            main()
        except SystemExit:
            pass
        print("torch imported:", "torch" in sys.modules)
        """
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, check=True
    )
    assert "torch imported: False" in out.stdout
    assert "estimator: " in out.stdout and "pso" in out.stdout and "f13" in out.stdout
    assert "scenario: all_noise, clean, outliers, state_noise, torque_noise" in out.stdout  # from the presets
    assert not (tmp_path / "outputs").exists()


def test_the_issue_command_writes_the_documented_results(tmp_path):
    out = idkit("+scenario=outliers", "estimator=pso", "cost=f13", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    run_dir = only(list((tmp_path / "outputs").glob("*/*")))
    data = json.loads((run_dir / "result.json").read_text())
    payload = data["payload"]
    assert data["label"] == "PSO-f13" and data["task"] == "single" and data["status"] == "complete"
    assert data["data"]["scenario"]["name"] == "outliers"
    names = {"m2", "m3", "s3z", "I"}
    assert (
        set(payload["estimate"]["params"]) == set(payload["truth"]) == set(payload["relative_error"]) == names
    )
    assert data["config"]["estimator"]["_name_"] == "pso" and data["config"]["cost"]["_name_"] == "f13"
    assert data["plugins"]["estimator"]["distribution"] == "robot-idkit"
    assert payload["cost"]["name"] == "f13" and isinstance(payload["cost"]["value"], float)
    assert payload["estimate"]["wall_time_s"] > 0 and data["seed"] == 0
    with open(run_dir / "history.csv") as handle:
        assert next(csv.reader(handle))[:2] == ["iteration", "run_0"]
    assert (run_dir / "convergence.png").exists() and (run_dir / "estimate.png").exists()
    assert "PSO-f13" in out.stdout and "rel. error" in out.stdout and "wall time" in out.stdout
    assert Path.cwd() != run_dir  # hydra.job.chdir=False: the process stayed where it started


@pytest.mark.integration
def test_bad_input_fails_with_a_clear_message(tmp_path):
    unknown = idkit("estimator=psoo", cwd=tmp_path)
    assert unknown.returncode != 0
    assert "Could not find 'estimator/psoo'" in unknown.stderr and "pso_f13_f14" in unknown.stderr
    assert "Traceback" not in unknown.stderr
    missing = idkit("estimator=ls", "data=no-such-file.npz", cwd=tmp_path)
    assert missing.returncode != 0
    assert "idkit:" in missing.stderr and "no-such-file.npz" in missing.stderr
    assert "Traceback" not in missing.stderr
    unused = idkit("+experiment=kuka", "cost=f13", cwd=tmp_path)
    assert unused.returncode != 0 and "Traceback" not in unused.stderr
    assert "idkit: the kuka task takes no cost (got cost=f13)" in unused.stderr
    both = idkit("+scenario=outliers", "data=recording.npz", "estimator=ls", cwd=tmp_path)
    assert both.returncode != 0 and "Traceback" not in both.stderr
    assert "give either data= (measured samples) or scenario= (a simulation), not both" in both.stderr


@pytest.mark.integration
def test_a_third_party_distribution_is_selectable_by_name(tmp_path):
    site = tmp_path / "site"
    info = site / "toy_dist-1.2.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: toy-dist\nVersion: 1.2\n")
    (info / "entry_points.txt").write_text("[idkit.estimators]\nmidpoint = toy_midpoint:Midpoint\n")
    (site / "toy_midpoint.py").write_text(
        textwrap.dedent(
            """
            from idkit.estimate import Estimate
            from idkit.interfaces import Estimator


            class Midpoint(Estimator):
                '''Returns lower + share * (upper - lower) of the search box.'''

                def __init__(self, share: float = 0.5):
                    self.share = share

                def fit(self, problem):
                    lower, upper = problem.robot.bounds()
                    params = lower + self.share * (upper - lower)
                    names = problem.robot.param_names
                    return Estimate("Midpoint", dict(zip(names, params.tolist())), None, 0.0)
            """
        )
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])}
    out = idkit("estimator=midpoint", "estimator.share=0.25", "plots=false", cwd=tmp_path, env=env)
    assert out.returncode == 0, out.stderr
    data = json.loads(only(list((tmp_path / "outputs").glob("*/*/result.json"))).read_text())
    assert data["plugins"]["estimator"] == {
        "name": "midpoint",
        "options": {"share": 0.25},
        "entry_point": "toy_midpoint:Midpoint",
        "distribution": "toy-dist",
        "version": "1.2",
    }
    assert data["payload"]["estimate"]["params"] == {"m2": 2.5, "m3": 2.5, "s3z": -0.5, "I": 2.5}


@pytest.mark.integration
@pytest.mark.filterwarnings("ignore")
def test_joblib_sweep_keeps_finished_jobs_when_one_fails(tmp_path):
    out = idkit(
        "-m", "estimator=ls,tls", "n_samples=10,0", "plots=false",
        "hydra/launcher=joblib", "hydra.launcher.n_jobs=2",
        cwd=tmp_path,
    )  # fmt: skip
    assert out.returncode != 0  # the sweep reports its failed jobs
    sweep = only(list((tmp_path / "outputs" / "multirun").glob("*/*")))
    with open(sweep / "summary.csv") as handle:
        rows = {row["overrides"].replace(" plots=False", ""): row for row in csv.DictReader(handle)}
    assert {k: r["status"] for k, r in rows.items()} == {
        "estimator=ls n_samples=10": "complete",
        "estimator=ls n_samples=0": "failed",
        "estimator=tls n_samples=10": "complete",
        "estimator=tls n_samples=0": "failed",
    }
    assert "n_samples must be an integer >= 1" in rows["estimator=ls n_samples=0"]["error"]
    assert rows["estimator=tls n_samples=10"]["label"] == "TLS"
    assert rows["estimator=tls n_samples=10"]["cost_name"] == "f13"
    assert len(list(sweep.glob("*/result.json"))) == 2 and len(list(sweep.glob("*/error.json"))) == 2


@pytest.mark.integration
def test_ctrl_c_leaves_a_partial_study_and_one_line(tmp_path):
    """SIGINT during a robustness study: exit 130, one line naming the folder, files marked partial."""
    import signal
    import threading
    import time

    process = subprocess.Popen(
        [*IDKIT, "+experiment=robustness", "trials=100000", "robustness.scenarios=[outliers]",
         "estimator.runs=2", "estimator.iterations=10", "plots=false"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    stderr: list[str] = []
    reader = threading.Thread(target=lambda: stderr.extend(iter(lambda: process.stderr.read(64), "")))
    reader.start()
    deadline = time.monotonic() + 240
    while "trial/s" not in "".join(stderr) and time.monotonic() < deadline:  # tqdm: trials are running
        time.sleep(0.2)
    process.send_signal(signal.SIGINT)
    process.wait(timeout=120)
    reader.join(timeout=10)
    text = "".join(stderr)
    assert process.returncode == 130, text[-2000:]
    run_dir = only(list((tmp_path / "outputs").glob("*/*")))
    lines = [line for line in text.replace("\r", "\n").splitlines() if line.startswith("idkit:")]
    assert len(lines) == 1 and f"in {run_dir}" in lines[0] and "partial results" in lines[0]
    assert "Traceback" not in text
    document = json.loads((run_dir / "result.json").read_text())
    assert document["status"] == "partial" and document["progress"]["requested"] == 100000
    assert 0 <= document["progress"]["done"] < 100000
