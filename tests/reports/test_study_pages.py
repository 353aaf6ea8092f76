"""The paper and robustness tasks' report.html: verdicts first, the numbers of result.json, and
plots whose axes one wild estimate does not stretch."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from idkit.reports import paper as paper_report
from idkit.reports import plots
from idkit.reports import robustness as robustness_report
from idkit.studies import paper, robustness
from tests.reports.test_report_html import Page, offline, value

TINY_PSO = {"_name_": "pso", "runs": 2, "particles": 6, "iterations": 15}


@pytest.fixture(scope="module")
def robustness_run(tmp_path_factory):
    study = robustness.run(
        trials=8,
        estimator=TINY_PSO,
        scenarios=["torque_noise"],
        estimators=[{"_name_": "ls", "relative": True}, {"_name_": "rls", "relative": True}],
        pso_costs=["f13", "f14"],
        progress=False,
    )
    folder = tmp_path_factory.mktemp("robustness")
    robustness_report.write(study, folder, plots=True)
    return study, folder


def test_the_robustness_page_gives_the_verdicts_first_and_the_study_s_numbers(robustness_run):
    study, folder = robustness_run
    document = json.loads((folder / "result.json").read_text())
    page = Page((folder / "report.html").read_text())
    assert page.sections[0] == "verdicts" and page.sections[1] == "summary"
    offline(page)
    assert sum(url.startswith("data:image/png") for url in page.urls) == 1  # the box plot
    verdicts = page.rows("verdicts")
    for scenario, cmp in study.focus_comparisons().items():
        cells = verdicts[scenario]
        assert value(cells[0]) == cmp.win_rate and cells[-1][0] == cmp.verdict
        assert json.loads(cells[1][1]) == [cmp.ci_low, cmp.ci_high]
    assert document["payload"]["conclusion"] in (folder / "report.html").read_text()
    summary = page.tables["summary"]
    assert len(summary) == 1 + len(study.rows())  # the header, then one row per estimator


def test_the_paper_page_gives_the_verdicts_first_and_the_tables(tmp_path):
    tables = paper.run(estimator=TINY_PSO, scenarios=["outliers"], progress=False)
    paper_report.write(tables, tmp_path, plots=True)
    page = Page((tmp_path / "report.html").read_text())
    assert page.sections[:2] == ["verdicts", "tables"]
    offline(page)
    (comparison,) = tables.comparisons()
    (row,) = page.rows("verdicts").values()
    assert value(row[0]) == comparison["error"] and value(row[1]) == comparison["baseline_error"]
    assert row[2][0] == ("beats" if comparison["error"] < comparison["baseline_error"] else "loses")
    shown = page.rows("outliers")
    for est in tables.tables[0].estimates:
        assert value(shown[est.estimator][0]) == est.params["m2"]


def test_one_wild_estimate_does_not_stretch_the_axis():
    ratios = list(np.random.default_rng(0).normal(1.0, 0.05, 80)) + [-70.0, 45.0]
    low, high = plots.robust_limits(ratios, 1.0)
    assert 0.5 < low < 1.0 < high < 1.5  # the bulk fills the axis
    inside = [r for r in ratios if low <= r <= high]
    assert len(inside) >= 78
    assert plots.robust_limits([1.0, 1.0, 1.0], 1.0)[0] < 1.0  # no spread: a small window around 1


def test_values_beyond_the_axis_are_marked_with_their_values(tmp_path, monkeypatch):
    drawn = []
    monkeypatch.setattr(plots, "save_figure", lambda fig, path: drawn.append(fig) or path)
    estimates = {f"M{k}": {"a": 1.0 + 0.01 * k, "b": 2.0 - 0.02 * k} for k in range(10)}
    estimates["TLS"] = {"a": -70.0, "b": 2.0}
    plots.estimates_vs_truth(estimates, {"a": 1.0, "b": 2.0}, "t", tmp_path / "p.png")
    (fig,) = drawn
    (ax,) = fig.axes
    low, high = ax.get_ylim()
    assert low > -1 and high < 2 and "1 beyond the axis" in ax.get_title()
    assert any(text.get_text() == "-70" for text in ax.texts)
    assert not math.isnan(low)
