"""docs/rollout.md runs as written: every ``bash`` and ``python`` block, in order, in a scratch folder,
on the servo arm that ships with idkit; what the page says of the result holds."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from docs_blocks import code_blocks, run_blocks

from idkit.examples.make_servo_arm import TRUTH

PAGE = Path(__file__).resolve().parents[1] / "docs" / "rollout.md"


def test_the_page_starts_from_the_shipped_example():
    blocks = code_blocks(PAGE)
    assert blocks[0][0] == "bash" and "python -m idkit.examples servo_arm" in blocks[0][1]
    assert {language for language, _ in blocks} == {"bash", "python"}


def test_a_block_marked_skip_is_not_run(tmp_path):
    page = tmp_path / "page.md"
    page.write_text(
        "```bash\necho one\n```\n\n<!-- docs-test: skip: needs a robot -->\n```bash\necho two\n```\n"
        "```text\nshown\n```\n```python\nprint(3)\n```\n"
    )
    assert code_blocks(page) == [("bash", "echo one\n"), ("python", "print(3)\n")]
    assert run_blocks(code_blocks(page), tmp_path) == ["one\n", "3\n"]


@pytest.mark.slow
def test_the_page_runs_as_written(tmp_path):
    outputs = run_blocks(code_blocks(PAGE), tmp_path)
    assert len(outputs) == len(code_blocks(PAGE))
    document = json.loads((tmp_path / "servo" / "result.json").read_text())
    intervals = document["payload"]["estimate"]["details"]["uncertainty"]["interval95"]
    outside = [n for n, v in TRUTH.items() if not intervals[n][0] <= v <= intervals[n][1]]
    assert not outside, f"the page says every interval holds the truth; these do not: {outside}"
    for name in ("report.html", "identified.xml", "fit.png", "validation_1.png"):
        assert (tmp_path / "servo" / name).is_file(), name
    held = document["payload"]["validation"]["held_out.csv"]
    fitted = [r for r in held if r["values"] == "fitted"]
    assert {r["mode"] for r in fitted} == {"whole", "segments"}  # "scored in both modes"
    assert all(v == "within noise" for r in fitted for v in r["verdicts"].values())
    assert (tmp_path / "compare.html").is_file() and (tmp_path / "identified.xml").is_file()
    damping = np.array(outputs[1].splitlines()[-1].strip("[]").split(), dtype=float)  # model.dof_damping
    np.testing.assert_allclose(damping, [TRUTH[f"j{j}.damping"] for j in (1, 2, 3)], rtol=0.05)
