"""The paper study: every method of Tables II–V, labels, the f13/f14 average, the published rows."""

from __future__ import annotations

import csv

import pytest

from idkit.data.presets import PAPER_SCENARIOS
from idkit.estimators.aggregate import average_label
from idkit.reports import paper as report
from idkit.studies import paper

TINY_PSO = {"_name_": "pso", "runs": 2, "particles": 6, "iterations": 15}


def test_reference_tables_are_read_with_physical_signs():
    ref = paper.load_reference()
    assert set(ref) == set(PAPER_SCENARIOS)
    ls = ref["state_noise"]["LS"]
    assert ls["params"] == {"m2": 5.44, "m3": 2.56, "s3z": -0.52, "I": 2.78}
    assert ls["time_s"] == pytest.approx(2e-6)
    avg = ref["outliers"][average_label(("f13", "f14"))]["params"]
    assert avg["m2"] == pytest.approx((4.49 + 5.43) / 2)


def test_paper_tables_have_every_method_and_the_published_values(tmp_path):
    tables = paper.run(estimator=TINY_PSO, scenarios=["outliers"], progress=False)
    labels = [e.estimator for e in tables.tables[0].estimates]
    assert labels[:6] == ["LS", "TLS", "RLS", "LS-rel", "TLS-rel", "RLS-rel"]
    assert labels[6:22] == [f"PSO-f{i}" for i in range(1, 17)]
    assert labels[22] == "PSO-f13/f14"
    est = {e.estimator: e.params for e in tables.tables[0].estimates}
    assert est["PSO-f13/f14"]["m2"] == pytest.approx((est["PSO-f13"]["m2"] + est["PSO-f14"]["m2"]) / 2)
    text = report.text(tables)
    assert "| TLS | " in text and "(8.52)" in text  # the paper's TLS m2 in Table V, beside idkit's
    written = report.write(tables, tmp_path, plots=False)
    with open(written["csv"]) as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 23 and rows[0]["paper_m2"] == "5.42"
    # a header starting with '-' is written as text ("'-s3z"), as every CSV cell idkit writes that a
    # spreadsheet could read as a formula
    assert float(rows[0]["'-s3z"]) == pytest.approx(-est["LS"]["s3z"])


def test_average_of_a_cost_not_in_the_run_is_an_error():
    with pytest.raises(ValueError, match=r"average_of names \['f15'\]"):
        paper.run(estimator=TINY_PSO, scenarios=["outliers"], costs=["f13", "f14"], average_of=["f15"])
