"""The real ``idkit`` command in a subprocess: the issue's command, plugins, errors, sweeps.

Each subprocess pays the torch import, so there are few of them and each checks several things; all
but the issue's command and ``--help`` are ``integration`` tests (``make test-all``, CI).
"""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
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
        print("torch imported:", "torch" in sys.modules, "pydantic imported:", "pydantic" in sys.modules)
        """
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, check=True
    )
    assert "torch imported: False pydantic imported: False" in out.stdout
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


#: Issue 12's bad inputs: (arguments, what the one line ``idkit`` prints instead must say).
#: Files named here are made by ``bad_files``; every command starts with ``plots=false``.
BAD_INPUTS = [
    (["estimator.particles=abc"], "estimator 'pso' option 'particles' must be an int or None, got 'abc'"),
    (["estimator.particles=1.5"], "estimator 'pso' option 'particles' must be an int or None, got 1.5"),
    (["estimator.particles=0"], "particles"),  # the range check: estimators (speed branch)
    (["robot.g=abc"], "robot 'cylindrical' option 'g' must be a float, got 'abc'"),
    (["seed=abc"], "setting 'seed' must be an int, got 'abc'"),
    (["estimator=ls", "plots=maybe"], "setting 'plots' must be a bool"),
    (["estimator=ls", "estimator.relative=maybe"], "estimator 'ls' option 'relative' must be a bool"),
    (["estimator=ls", "device=cuda"], "device 'cuda' requested but CUDA is not available"),
    (["estimator=ls", "data=empty.npz"], "empty.npz: not a NumPy .npz archive"),
    (["estimator=ls", "data=no-arrays.npz"], "no-arrays.npz: the .npz archive contains no arrays"),
    (["estimator=ls", "data=text.npz"], "text.npz: not a NumPy .npz archive"),
    (["estimator=ls", "data=strings.npz"], "strings.npz: array 'q' has dtype <U1 (text)"),
    (["estimator=ls", "data=folder"], "folder is a directory, not a data file (.npz, .csv) nor a ROS 2 bag"),
    (["estimator=ls", "data=no-such-file.npz"], "data file not found: no-such-file.npz"),
    (
        ["estimator=pso", "cost=f13", "n_samples=1"],
        "robot CylindricalRobot: 1 sample × 3 joints = 3 equations",
    ),
    (
        ["estimator=adam", "cost=f13", "n_samples=1"],
        "robot CylindricalRobot: 1 sample × 3 joints = 3 equations",
    ),
    (["estimator=pso_f13_f14", "~cost", "n_samples=1"], "robot CylindricalRobot: 1 sample × 3 joints"),
    (["cost=f133"], "unknown cost 'f133'; available costs (closest first): f13, "),
    (["estimator=psoo"], "unknown estimator 'psoo'; available estimators (closest first): pso, "),
    (["robot=cylindricl"], "unknown robot 'cylindricl'; available robots (closest first): cylindrical, "),
    (["+experiment=kukaa"], "unknown experiment 'kukaa'; available experiments (closest first): kuka, "),
    (["+scenario=outlier"], "unknown scenario 'outlier'; available scenarios (closest first): outliers, "),
    (
        ["estimator.particls=40"],
        "estimator 'pso' has no option 'particls'; its options (closest first): particles, ",
    ),
    (["seeed=1"], "there is no setting 'seeed'; the settings (closest first): seed, "),
    (["+experiment=kuka", "cost=f13"], "the kuka task takes no cost (got cost=f13)"),
    (["+scenario=outliers", "data=recording.npz", "estimator=ls"], "give either data= (measured samples) or"),
    (["estimator=ls", "hydra.run.dir=other-run"], "other-run already holds another run (result.json);"),
    (["hydra.output_subdir=.hydra"], "hydra.output_subdir=.hydra is not supported"),
    (["paper"], "'paper' is not an override (key=value); did you mean +experiment=paper?"),
    (["--cfg", "jobb"], "argument --cfg/-c: invalid choice: 'jobb'"),
    (["preprocess=xyz"], "unknown preprocess option 'xyz'; the options (closest first): "),
]


def bad_files(folder: Path) -> None:
    """The bad data files of :data:`BAD_INPUTS`, and a folder holding another run's result."""
    import numpy as np

    (folder / "empty.npz").write_bytes(b"")
    np.savez(folder / "no-arrays.npz")
    (folder / "text.npz").write_text("q,qd,qdd,tau\n")
    text = np.array([["a", "b", "c"]])
    np.savez(folder / "strings.npz", q=text, qd=text, qdd=text, tau=text)
    (folder / "folder").mkdir()
    (folder / "other-run").mkdir()
    (folder / "other-run" / "result.json").write_text(json.dumps({"run_id": "another run"}))


@pytest.mark.integration
def test_each_bad_input_ends_in_one_line_naming_its_cause(tmp_path):
    """Issue 12's edges from the real ``idkit`` command: exit status 1, no traceback, one line."""
    import concurrent.futures

    import torch

    bad_files(tmp_path)
    command = shutil.which("idkit", path=Path(sys.executable).parent)
    assert command, "the idkit console script is not installed next to this Python"
    cases = [
        (args, line)
        for args, line in BAD_INPUTS
        if "device=cuda" not in args or not torch.cuda.is_available()
    ]

    def run(args: list[str]) -> subprocess.CompletedProcess:
        env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
        return subprocess.run(
            [command, "plots=false", *args],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
        )

    with concurrent.futures.ThreadPoolExecutor(max_workers=3) as pool:  # each pays the torch import
        outcomes = list(pool.map(run, [args for args, _ in cases]))
    wrong = []
    for (args, line), out in zip(cases, outcomes, strict=True):
        said = [text for text in out.stderr.splitlines() if text.strip()]
        if (
            out.returncode != 1
            or "Traceback" in out.stderr + out.stdout
            or said != said[:1]
            or not (said and said[0].startswith("idkit: ") and line in said[0])
        ):
            wrong.append(f"idkit {' '.join(args)}: exit {out.returncode}, stderr {out.stderr[-600:]!r}")
    assert not wrong, "\n".join(wrong)
    other = json.loads((tmp_path / "other-run" / "result.json").read_text())
    assert other == {"run_id": "another run"}  # the refused run left the other run's result alone


@pytest.mark.integration
def test_warnings_are_one_line_each_and_debug_shows_their_source(tmp_path):
    """The urdf fit warns (a floored torque, twice; a non-physical export): one line per message."""
    env = {k: v for k, v in os.environ.items() if k not in ("HYDRA_FULL_ERROR", "IDKIT_DEBUG")}
    out = idkit("robot=urdf", "plots=false", cwd=tmp_path, env=env)
    assert out.returncode == 0, out.stderr
    said = out.stderr.splitlines()
    assert said and all(line.startswith("warning: ") for line in said), said
    assert len(said) == len(set(said)) and ".py:" not in out.stderr
    debug = idkit("robot=urdf", "plots=false", cwd=tmp_path, env={**env, "IDKIT_DEBUG": "1"})
    assert debug.returncode == 0, debug.stderr
    assert "idkit/costs/paper.py:" in debug.stderr and "RelativeFloorWarning: " in debug.stderr


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
    """SIGINT during a robustness study: exit 130, one line naming the folder, files marked partial.

    stderr is a terminal (a pty), as for a person pressing Ctrl-C: the progress bar shows there,
    and its rate says when a chunk of trials is done.
    """
    import fcntl
    import pty
    import signal
    import struct
    import termios
    import threading
    import time

    terminal, child_end = pty.openpty()
    fcntl.ioctl(child_end, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # 0 columns: no bar
    process = subprocess.Popen(
        [*IDKIT, "+experiment=robustness", "trials=100000", "robustness.scenarios=[outliers]",
         "estimator.runs=2", "estimator.iterations=10", "plots=false"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=child_end,
        # A runner started in the background of a non-interactive shell ignores SIGINT, and Python
        # keeps an inherited SIG_IGN: give the child the default disposition, as a terminal would.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )  # fmt: skip
    os.close(child_end)
    stderr: list[str] = []

    def read() -> None:
        while True:
            try:
                chunk = os.read(terminal, 1024)
            except OSError:  # EIO: the child closed its end
                return
            if not chunk:
                return
            stderr.append(chunk.decode("utf-8", "replace"))

    reader = threading.Thread(target=read)
    reader.start()
    deadline = time.monotonic() + 240
    measured_rate = re.compile(r"\d trial/s|\dtrial/s")  # tqdm's rate once a chunk of trials is done
    while not measured_rate.search("".join(stderr)) and time.monotonic() < deadline:
        time.sleep(0.2)
    process.send_signal(signal.SIGINT)
    try:
        process.wait(timeout=300)
    except subprocess.TimeoutExpired:
        process.kill()
        reader.join(timeout=10)
        pytest.fail("no exit 300 s after SIGINT; stderr ends with: " + "".join(stderr)[-2000:])
    reader.join(timeout=10)
    os.close(terminal)
    text = "".join(stderr)
    assert process.returncode == 130, text[-2000:]
    run_dir = only(list((tmp_path / "outputs").glob("*/*")))
    lines = [line for line in text.replace("\r", "\n").splitlines() if line.startswith("idkit:")]
    assert len(lines) == 1 and f"in {run_dir}" in lines[0] and "partial results" in lines[0]
    assert "Traceback" not in text
    document = json.loads((run_dir / "result.json").read_text())
    assert document["status"] == "partial" and document["progress"]["requested"] == 100000
    assert 0 <= document["progress"]["done"] < 100000


def test_help_into_a_closed_pipe_is_quiet(tmp_path):
    """``idkit --help | head -1``: the reader has left before the help is written; no traceback."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        process = subprocess.run(
            [*IDKIT, "--help"], cwd=tmp_path, stdout=write_end, stderr=subprocess.PIPE, text=True, timeout=120
        )
    finally:
        os.close(write_end)
    assert "Traceback" not in process.stderr and "BrokenPipeError" not in process.stderr, process.stderr
