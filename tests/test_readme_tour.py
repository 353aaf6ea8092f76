"""The README's tour runs as written: every ``bash`` block of "A short tour", in order, in one fresh
shell started in the clone — the first block activates ``.venv`` and moves to ``mktemp -d``, here
made inside the test's folder — and nothing lands outside that scratch folder."""

from __future__ import annotations

import ast
import inspect
import json
import os
import re
import subprocess
import warnings
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"


def tour_blocks() -> list[str]:
    text = README.read_text()
    tour = text[text.index("## A short tour") : text.index("\n## ", text.index("## A short tour"))]
    return re.findall(r"```bash\n(.*?)```", tour, re.S)


def tour_truths() -> tuple[dict[str, float], dict[str, float]]:
    """The values the tour's log-writing script sets: the arm's (``truth = {...}``) and the drive's
    (``log("current.csv", drive, {...}``), read from the README so that the test follows it."""
    script = next(block for block in tour_blocks() if "def log(" in block)
    arm = re.search(r"^truth = (\{.*?\})$", script, re.S | re.M)
    drive = re.search(r'log\("current\.csv", drive, (\{.*?\})', script, re.S)
    assert arm and drive, "the tour's script no longer sets the truths this test reads"
    return ast.literal_eval(arm.group(1)), ast.literal_eval(drive.group(1))


def true_values(scratch: Path, result: dict, truth: dict[str, float]) -> dict[str, float]:
    """Every standard and base parameter's true value for a run: its robot's model built on the tour's
    URDF with the run's options, the URDF's values changed where ``truth`` says (a base parameter that
    regroups several is the same combination of the true ones)."""
    from idkit.robots.urdf import URDFRobot

    accepted = inspect.signature(URDFRobot).parameters
    options = {k: v for k, v in result["config"]["robot"].items() if k in accepted and k != "urdf"}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # a merged armature, said by the run already
        robot = URDFRobot(str(scratch / "arm.urdf"), **options)
    params = robot.nominal_params().clone()
    for name, value in truth.items():
        params[robot.param_names.index(name)] = value
    base = robot.base_params(params).tolist()
    return dict(zip(robot.param_names, params.tolist(), strict=True)) | dict(
        zip(robot.base_param_names, base, strict=True)
    )


def beyond_three_sigma(result: dict, true: dict[str, float]) -> list[str]:
    """The parameters with a std (every base parameter, varpro's shapes) farther than 3 std from the
    truth; a parameter without a truth is one too (the comparison must not skip it)."""
    estimate = result["payload"]["estimate"]
    values = {**estimate["params"], **(estimate["base_params"] or {})}
    std = {k: float(s) for k, s in estimate["details"]["uncertainty"]["std"].items()}  # "Infinity" too
    return [
        f"{name}: {values[name]:.5g} ± {sigma:.3g} against {true.get(name)}"
        for name, sigma in std.items()
        if name not in true or not abs(values[name] - true[name]) <= 3 * sigma
    ]


def test_the_tour_sets_truths_for_the_arm_and_the_drive():
    arm, drive = tour_truths()
    assert arm["d2.fv"] == 1.0 and drive["d2.phi2"] == 30.0


def test_the_tour_starts_in_a_scratch_folder_with_the_venv_activated():
    first = tour_blocks()[0]
    assert ". .venv/bin/activate" in first and 'cd "$(mktemp -d)"' in first


@pytest.mark.integration
@pytest.mark.slow
def test_the_readme_tour_runs_as_written_in_a_scratch_folder(tmp_path):
    if not (REPO / ".venv" / "bin" / "activate").is_file():
        pytest.skip("the tour activates the venv `make` creates in .venv")
    scratch_root = tmp_path / "tmp"
    scratch_root.mkdir()
    repo_before = sorted(p.name for p in REPO.iterdir())
    script = "set -euo pipefail\n" + "\n".join(tour_blocks())
    env = {**os.environ, "TMPDIR": str(scratch_root)}
    done = subprocess.run(
        ["bash", "-c", script], cwd=REPO, env=env, capture_output=True, text=True, timeout=1800
    )
    assert done.returncode == 0, f"{done.stderr[-3000:]}\n{done.stdout[-3000:]}"
    assert "Traceback" not in done.stderr
    assert sorted(p.name for p in REPO.iterdir()) == repo_before  # nothing written into the clone
    (scratch,) = scratch_root.iterdir()
    for written in (
        "motion/excitation.csv",
        "arm/identified.urdf",
        "arm/identified.xml",
        "mj/identified.xml",
        "drive/result.json",
        "arm/report.html",
        "compare.html",
    ):
        assert (scratch / written).is_file(), written
    # the tour's claims about its simulated arm: the tool is 2 kg, d2's rotor inertia 2 kg (a slide)
    payload = json.loads((scratch / "tool/result.json").read_text())["payload"]["estimate"]["details"]
    assert (
        payload["payload"]["mass"] == pytest.approx(2.0, rel=0.01) and payload["payload"]["verdict"]["mass"]
    )
    # the excitation improves on its start or says it did not, every margin at least the configured one
    motion = json.loads((scratch / "motion/result.json").read_text())["payload"]
    assert motion["improved"] is (motion["after"] < motion["start"]) and motion["check"]["violations"] == []
    shares = [m["share"] for joint in motion["check"]["margins"].values() for m in joint.values()]
    assert min(shares) >= 0.05 - 1e-9
    assert motion["improved"] or "no improvement found" in done.stdout
    drive = json.loads((scratch / "drive/result.json").read_text())["payload"]["estimate"]["params"]
    assert drive["d2.armature"] == pytest.approx(2.0, rel=0.02)
    validation = json.loads((scratch / "arm/result.json").read_text())["payload"]["validation"]
    assert list(validation) == ["test.csv"]
    # every parameter the tour sets a truth for (each base parameter, varpro's shapes) lies within 3
    # standard deviations of its estimate
    arm, drive = tour_truths()
    for run, truth in (("arm", arm), ("mj", arm), ("drive", drive)):
        result = json.loads((scratch / run / "result.json").read_text())
        far = beyond_three_sigma(result, true_values(scratch, result, truth))
        assert not far, (run, far)
