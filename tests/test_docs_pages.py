"""Every page of docs/ runs as written: its ``bash`` and ``python`` blocks, in order, in a scratch
folder, with the inputs a block before them on the same page creates (tests/docs_pages.py says how a
page marks a block it cannot run, and a slow page). Nothing lands in the clone."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest
import yaml
from docs_pages import DOCS, REPO, RUN, blocks, is_slow, run_page, runnable

#: docs/rollout.md has its own runner (the rollout flow's files and checks): tests/test_docs_rollout.py
OWN_RUNNER = {"rollout.md"}
PAGES = sorted(p for p in DOCS.rglob("*.md") if p.name not in OWN_RUNNER)


def page_id(page):
    return str(page.relative_to(DOCS))


def page_param(page):
    marks = [pytest.mark.slow, pytest.mark.integration] if is_slow(page) else []
    return pytest.param(page, id=page_id(page), marks=marks)


@pytest.mark.parametrize("page", [page_param(p) for p in PAGES if runnable(p)])
def test_the_page_runs_as_written(page, tmp_path):
    before = git_status()
    done = run_page(page, tmp_path)
    assert done.returncode == 0, f"{done.stderr[-4000:]}\n{done.stdout[-3000:]}"
    assert "Traceback" not in done.stderr, done.stderr[-4000:]
    assert git_status() == before, "a page's code wrote into the clone"


def git_status() -> set[str]:
    """The clone's new files and folders, untracked or ignored (edits of tracked files are not a
    page's doing; caches are written by the suite itself)."""
    lines = subprocess.run(
        ["git", "status", "--porcelain", "--ignored"], cwd=REPO, capture_output=True, text=True
    ).stdout.splitlines()
    caches = (".hypothesis", ".pytest_cache", ".ruff_cache", ".mypy_cache", "site/")  # site/: make docs
    return {line[3:] for line in lines if line[:2] in ("??", "!!") and not line[3:].startswith(caches)}


# ---- what the runner reads: checked on every page, fast ----


@pytest.mark.parametrize("page", PAGES + [DOCS / "rollout.md"], ids=page_id)
def test_every_block_says_its_language(page):
    """A block without one would be neither run nor shown as code to copy: commands are ``bash``."""
    assert not [b.where for b in blocks(page) if not b.language]


@pytest.mark.parametrize("page", PAGES + [DOCS / "rollout.md"], ids=page_id)
def test_every_block_not_run_says_why(page):
    unexplained = [b.where for b in blocks(page) if b.skip is not None and len(b.skip) < 10]
    assert not unexplained, "<!-- docs-test: skip: <why> --> needs its reason"


def test_blocks_not_run_are_few():
    """Skipping is for what cannot run here (a robot's own logs, a cluster, the network, the suite
    itself): most blocks run, and a new skip has to fit under this cap."""
    code = [b for p in PAGES for b in blocks(p) if b.language in RUN]
    skipped = [b for b in code if b.skip is not None]
    assert len(skipped) <= len(code) // 3, [f"{b.where}: {b.skip}" for b in skipped]


def test_the_runner_reads_marks_files_and_indented_blocks(tmp_path):
    page = tmp_path / "page.md"
    page.write_text(
        "<!-- docs-test: slow -->\n# A page\n\n"
        "```python\n# pkg/mod.py\nVALUE = 3\n```\n\n"
        "```python\nfrom pkg.mod import VALUE\nseen = VALUE\n```\n\n"
        "* a list item:\n\n  ```bash\n  mkdir sub && cd sub\n  ```\n\n"
        '```bash\ntest "$(basename "$PWD")" = sub\n```\n\n'
        "<!-- docs-test: skip: a real robot is needed -->\n```bash\nexit 3\n```\n\n"
        "```python\nassert seen == 3\n```\n\n```text\nnot code\n```\n"
    )
    found = blocks(page)
    assert [b.language for b in found] == ["python", "python", "bash", "bash", "bash", "python", "text"]
    assert found[0].file == "pkg/mod.py" and found[1].file is None
    assert found[2].code == "mkdir sub && cd sub\n" and found[4].skip == "a real robot is needed"
    assert is_slow(page)
    (tmp_path / "scratch").mkdir()
    done = run_page(page, tmp_path / "scratch", timeout=60)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "scratch/pkg/mod.py").is_file()


def test_a_failing_block_fails_the_page_and_is_named(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("```bash\ntrue\n```\n\n```bash\nfalse\necho not reached\n```\n")
    done = run_page(page, tmp_path)
    assert done.returncode != 0 and "page.md:5" in done.stderr and "not reached" not in done.stdout


# ---- commands a reader pastes: zsh globs unquoted brackets ("no matches found") ----


def unquoted_brackets(line: str) -> list[str]:
    """The arguments of an ``idkit`` command line holding ``[`` or ``]`` outside quotes."""
    line = re.sub(r"\s#.*$", "", line)
    words = re.findall(r"""(?:[^\s'"]+|'[^']*'|"[^"]*")+""", line)
    return [w for w in words if re.search(r"[\[\]]", re.sub(r"""'[^']*'|"[^"]*\"""", "", w))]


def idkit_command_lines() -> list[tuple[str, str]]:
    found = []
    for page in PAGES + [DOCS / "rollout.md", REPO / "README.md"]:
        for block in blocks(page):
            if block.language == "bash":
                found += [(block.where, line) for line in command_lines(block.code)]
    footer = yaml.safe_load((REPO / "conf" / "config.yaml").read_text())["hydra"]["help"]["footer"]
    found += [("idkit --help", line) for line in footer.splitlines() if line.strip().startswith("idkit ")]
    return found


def command_lines(code: str) -> list[str]:
    """``idkit`` command lines of a shell block, continuation lines joined, heredocs left out."""
    joined = re.sub(r"\\\n", " ", re.sub(r"<<'?(\w+)'?\n.*?\n\1\n", "\n", code, flags=re.S))
    return [line for line in joined.splitlines() if re.match(r"\s*(\S*/)?idkit\s", line)]


def test_commands_are_quoted_for_zsh():
    lines = idkit_command_lines()
    assert len(lines) > 20  # the README's, the pages' and --help's
    assert not [(where, unquoted_brackets(line)) for where, line in lines if unquoted_brackets(line)]


def test_the_bracket_check_catches_an_unquoted_list():
    assert unquoted_brackets("idkit data=a.csv validate=[b.csv]  # [x]") == ["validate=[b.csv]"]
    assert unquoted_brackets("idkit 'validate=[b.csv]' \"x=[1]\" a=b") == []


HELP = "import sys; from idkit.cli import main; sys.argv[0] = 'idkit'; main()"


def test_help_examples_are_the_ones_checked():
    out = subprocess.run(
        [sys.executable, "-c", HELP, "--help"],
        capture_output=True,
        text=True,
        cwd=REPO,
        check=False,
    ).stdout
    assert "'validate=[test.csv]'" in out
