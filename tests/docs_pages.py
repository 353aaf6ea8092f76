"""The documentation's code blocks, read and run as a reader would: every ``bash`` and ``python``
block of a page, in order, in one scratch folder.

A page marks what the runner should know in HTML comments (invisible on the site):

* ``<!-- docs-test: skip: <why> -->`` on the line before a block: not run, and the reason is
  required (for what cannot run here: a real robot, a cluster, the network, the test suite itself);
* ``<!-- docs-test: slow -->`` anywhere on a page: its run is a slow, integration test.

A ``python``, ``yaml`` or ``toml`` block whose first line is a comment naming a file of its kind
(``# pkg/module.py``, ``# myconf/estimator/mine.yaml``) is that file: it is written there, for later
blocks to import, read or run. The other ``python`` blocks share one
namespace, as in one interpreter session; each ``bash`` block runs in a new ``bash -euo pipefail``
started in the folder the previous one ended in. Any page's runner (``docs/rollout.md``'s too) is
``run_page(page, scratch)``.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"
RUN = ("bash", "python")
#: blocks of these languages opening with a comment that names a file are that file, written
FILES = ("python", "yaml", "toml")
FENCE = re.compile(
    r"^(?P<indent>[ \t]*)```(?P<info>[^\n`]*)\n(?P<body>.*?)^(?P=indent)```[ \t]*$", re.S | re.M
)
MARK = re.compile(r"<!--\s*docs-test:\s*(?P<what>.*?)\s*-->", re.S)
FILE_HEADER = re.compile(r"#\s*(?P<path>[\w./-]+\.(?:py|yaml|yml|toml))\s*$")


@dataclass(frozen=True)
class Block:
    page: Path
    line: int
    language: str
    code: str
    skip: str | None  # the reason given, where the page says not to run it

    @property
    def where(self) -> str:
        page = self.page.relative_to(REPO) if self.page.is_relative_to(REPO) else self.page.name
        return f"{page}:{self.line}"

    @property
    def file(self) -> str | None:
        """The file a python block is, where its first line names one."""
        first = self.code.lstrip("\n").split("\n", 1)[0]
        found = FILE_HEADER.fullmatch(first.strip()) if self.language in FILES else None
        return found["path"] if found else None


def blocks(page: Path) -> list[Block]:
    """Every fenced block of ``page``, with the language of its info string (``""`` where none)."""
    text = page.read_text()
    found = []
    for fence in FENCE.finditer(text):
        before = text[: fence.start()].rstrip().rsplit("\n", 1)[-1]
        mark = MARK.fullmatch(before.strip())
        skip = None
        if mark and mark["what"].startswith("skip"):
            skip = mark["what"].removeprefix("skip").lstrip(":").strip()
        indent = fence["indent"]
        code = "\n".join(line.removeprefix(indent) for line in fence["body"].split("\n"))
        language = fence["info"].strip().split(" ")[0]
        found.append(Block(page, text.count("\n", 0, fence.start()) + 1, language, code, skip))
    return found


def page_marks(page: Path) -> set[str]:
    return {m["what"] for m in MARK.finditer(page.read_text())}


def is_slow(page: Path) -> bool:
    return "slow" in page_marks(page)


def runnable(page: Path) -> list[Block]:
    return [b for b in blocks(page) if (b.language in RUN or b.file) and b.skip is None]


#: Runs in the scratch folder: one process, the blocks as the page gives them (a JSON list on stdin).
DRIVER = r"""
import json, os, subprocess, sys
namespace = {"__name__": "__main__"}
sys.path.insert(0, os.getcwd())
for block in json.load(sys.stdin):
    print(f"--- {block['where']} ({block['language']})", flush=True)
    if block["file"]:
        os.makedirs(os.path.dirname(block["file"]) or ".", exist_ok=True)
        with open(block["file"], "w") as out:
            out.write(block["code"])
    elif block["language"] == "python":
        exec(compile(block["code"], block["where"], "exec"), namespace)
    else:
        script = block["code"] + '\npwd > "$DOCS_TEST_CWD"\n'
        done = subprocess.run(["bash", "-euo", "pipefail", "-c", script], env=os.environ)
        if done.returncode:
            sys.exit(f"{block['where']}: the bash block exited with status {done.returncode}")
        with open(os.environ["DOCS_TEST_CWD"]) as cwd:
            os.chdir(cwd.read().strip())
"""


def run_page(page: Path, scratch: Path, timeout: float = 1800) -> subprocess.CompletedProcess[str]:
    """Run ``page``'s blocks in order in ``scratch``; the finished process (its output says which
    block failed). The clone's ``idkit`` is imported and its command is on ``PATH``."""
    todo = [
        {"where": b.where, "language": b.language, "code": b.code, "file": b.file} for b in runnable(page)
    ]
    env = {
        **os.environ,
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
        "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])),
        "MPLBACKEND": "Agg",
        "TMPDIR": str(scratch),
        "DOCS_TEST_CWD": str(scratch / ".docs-test-cwd"),
    }
    return subprocess.run(
        [sys.executable, "-c", DRIVER],
        input=json.dumps(todo),
        cwd=scratch,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
