"""The README's tour runs as written: every ``bash`` block of "A short tour", in order, in one fresh
shell started in the clone — the first block activates ``.venv`` and moves to ``mktemp -d``, here
made inside the test's folder — and nothing lands outside that scratch folder."""

from __future__ import annotations

import json
import os
import re
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"


def tour_blocks() -> list[str]:
    text = README.read_text()
    tour = text[text.index("## A short tour") : text.index("\n## ", text.index("## A short tour"))]
    return re.findall(r"```bash\n(.*?)```", tour, re.S)


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
