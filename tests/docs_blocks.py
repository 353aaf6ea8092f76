"""Run a docs page's code as written: its ``bash`` and ``python`` blocks, in order, in one folder.

Each ``bash`` block runs in ``bash -eo pipefail`` and each ``python`` block in this interpreter, both
started in ``folder`` with this interpreter's ``bin`` first on ``PATH`` (so ``idkit`` and ``python`` are
the ones under test). Other blocks (``text``, ``yaml``: shown output, configs) are not run, nor a block
whose previous line is ``<!-- docs-test: skip: <why> -->`` (the docs pages' runner's mark). A failing
block fails with its language, its first line and its output.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

#: The languages run, and how.
RUNNERS = {"bash": ["bash", "-eo", "pipefail", "-c"], "python": [sys.executable, "-c"]}


#: The line before a block that is not run.
SKIP = re.compile(r"<!--\s*docs-test:\s*skip\b.*?-->\s*\n$")


def code_blocks(page: str | Path) -> list[tuple[str, str]]:
    """``(language, code)`` of every fenced ``bash`` or ``python`` block of ``page`` to run, in order."""
    text = Path(page).read_text(encoding="utf-8")

    def line_before(index: int) -> str:
        return ("\n" + text[:index]).rsplit("\n", 2)[-2] + "\n"

    return [
        (found.group(1), found.group(2))
        for found in re.finditer(r"^```(\w+)\n(.*?)^```", text, re.S | re.M)
        if found.group(1) in RUNNERS and not SKIP.search(line_before(found.start()))
    ]


def run_blocks(blocks: list[tuple[str, str]], folder: str | Path, timeout: float = 600) -> list[str]:
    """Run ``blocks`` in ``folder`` (module docstring); returns each block's stdout.

    Raises:
        AssertionError: a block failed (its exit status, first line and output).
    """
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    outputs = []
    for k, (language, code) in enumerate(blocks, start=1):
        done = subprocess.run(
            [*RUNNERS[language], code], cwd=folder, env=env, capture_output=True, text=True, timeout=timeout
        )
        assert done.returncode == 0, (
            f"block {k} ({language}: {code.splitlines()[0]}) exited {done.returncode}\n"
            f"{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
        )
        outputs.append(done.stdout)
    return outputs
