"""Atomic writes, the one result.json writer (never a mix of two runs), the one table writer."""

from __future__ import annotations

import json
import os

import pytest

import idkit
from idkit.reports import files
from idkit.reports.tables import markdown_table


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_atomic_write_keeps_the_old_file_on_failure(tmp_path):
    target = files.write_json(tmp_path / "result.json", {"ok": 1})

    class Boom:
        def tolist(self):
            raise RuntimeError("fails mid-way")

    with pytest.raises(RuntimeError):
        files.write_json(target, {"ok": Boom()})
    assert json.loads(target.read_text()) == {"ok": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["result.json"]  # no temporary left behind
    assert oct(target.stat().st_mode & 0o777) == oct(0o666 & ~_umask())


def test_save_into_another_runs_folder_is_refused_before_any_file_changes(tmp_path):
    first = idkit.run(estimator={"_name_": "pso", "runs": 2, "particles": 6, "iterations": 10}, cost="f13")
    first.save(tmp_path, make_plots=False)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    second = idkit.run(estimator="ls", cost=None)
    with pytest.raises(FileExistsError, match="already holds the result of another run"):
        second.save(tmp_path, make_plots=False)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    first.save(tmp_path, make_plots=False)  # the same run may save again (replaces its own files)


def test_markdown_table_aligns_formats_and_escapes():
    text = markdown_table(["a", "b"], [["x|y", 1.23456789], [None, 2]], align="lr")
    assert text.splitlines() == ["| a | b |", "|---|---:|", "| x\\|y | 1.23457 |", "|  | 2 |"]
    with pytest.raises(ValueError, match="1 alignments for 2 columns"):
        markdown_table(["a", "b"], [], align="l")
