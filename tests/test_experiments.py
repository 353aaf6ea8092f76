"""Experiments as a library: single runs, the paper tables, the robustness statistics, files."""

from __future__ import annotations

import csv
import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import binomtest

import idkit
from idkit.experiments import files, paper, robustness
from idkit.experiments.metrics import parameter_error, relative_errors

TINY_PSO = {"_name_": "pso", "runs": 2, "particles": 6, "iterations": 15}


def test_run_returns_the_result_json_contract(tmp_path):
    result = idkit.run(
        estimator="ls", cost="f1", scenario="torque_noise", seed=3, out_dir=tmp_path, plots=True
    )
    data = json.loads((tmp_path / "result.json").read_text())
    for key in ("estimate", "truth", "relative_error", "cost", "wall_time_s", "seed", "plugins", "config"):
        assert key in data
    assert data["seed"] == 3 and data["estimator"] == "LS"
    assert data["truth"] == {"m2": 5.0, "m3": 3.0, "s3z": -0.5, "I": 3.0}
    for name, value in data["estimate"].items():
        true = data["truth"][name]
        assert data["relative_error"][name] == pytest.approx((value - true) / abs(true), rel=1e-12)
    assert data["plugins"]["estimator"]["distribution"] == "robot-idkit"
    assert data["plugins"]["cost"]["name"] == "f1"
    assert (tmp_path / "estimate.png").stat().st_size > 0
    assert "m2" in result.table()


def test_history_csv_has_one_column_per_run(tmp_path):
    idkit.run(estimator=TINY_PSO, cost="f13", out_dir=tmp_path, plots=False)
    with open(tmp_path / "history.csv") as handle:
        rows = list(csv.reader(handle))
    assert rows[0] == ["iteration", "run_0", "run_1"]
    assert len(rows) == 1 + TINY_PSO["iterations"]
    best = [float(r[1]) for r in rows[1:]]
    assert best == sorted(best, reverse=True)  # a global best never gets worse


def test_objects_work_as_well_as_names():
    from idkit.estimators.least_squares import LeastSquares
    from idkit.robots.cylindrical import CylindricalRobot

    result = idkit.run(robot=CylindricalRobot(), estimator=LeastSquares(relative=True), cost=None)
    assert result.estimate.estimator == "LS-rel"
    assert result.plugins["estimator"]["entry_point"] == "idkit.estimators.least_squares:LeastSquares"
    assert result.parameter_error < 1e-9  # clean data


def test_parameter_error_is_the_mean_absolute_relative_error():
    truth = np.array([5.0, 3.0, -0.5, 3.0])
    est = np.array([[5.5, 3.0, -0.25, 3.3], [np.nan, 3, -0.5, 3]])
    expected = (0.1 + 0.0 + 0.5 + 0.1) / 4
    np.testing.assert_allclose(parameter_error(est, truth), [expected, np.inf])
    rel = relative_errors({"a": 1.5, "b": 0.0}, {"a": 1.0, "b": 0.0})
    assert rel == {"a": 0.5, "b": None}


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


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_reference_tables_are_read_with_physical_signs():
    ref = paper.load_reference()
    assert set(ref) == set(paper.SCENARIOS)
    ls = ref["state_noise"]["LS"]
    assert ls["params"] == {"m2": 5.44, "m3": 2.56, "s3z": -0.52, "I": 2.78}
    assert ls["time_s"] == pytest.approx(2e-6)
    avg = ref["outliers"][paper.AVERAGE_LABEL]["params"]
    assert avg["m2"] == pytest.approx((4.49 + 5.43) / 2)


def test_paper_tables_have_every_method_and_the_published_values(tmp_path):
    tables = paper.run(pso=TINY_PSO, scenarios=["outliers"], progress=False)
    labels = [e.estimator for e in tables.tables[0].estimates]
    assert labels[:6] == ["LS", "TLS", "RLS", "LS-rel", "TLS-rel", "RLS-rel"]
    assert labels[6:22] == [f"PSO-f{i}" for i in range(1, 17)]
    assert labels[22] == "PSO-f13/f14"
    est = {e.estimator: e.params for e in tables.tables[0].estimates}
    assert est["PSO-f13/f14"]["m2"] == pytest.approx((est["PSO-f13"]["m2"] + est["PSO-f14"]["m2"]) / 2)
    text = tables.markdown()
    assert "| TLS | " in text and "(8.52)" in text  # the paper's TLS m2 in Table V, beside idkit's
    written = tables.save(tmp_path, make_plots=False)
    with open(written["csv"]) as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 23 and rows[0]["paper_m2"] == "5.42"
    assert float(rows[0]["-s3z"]) == pytest.approx(-est["LS"]["s3z"])


def test_comparison_matches_scipy_and_counts_ties():
    errors = np.array([1.0, 2.0, 3.0, 0.5, 2.0, 0.1])
    base = np.array([2.0, 1.0, 4.0, 1.0, 2.0, 0.2])
    cmp = robustness.Comparison.of(errors, base)
    assert (cmp.wins, cmp.losses, cmp.ties) == (4, 1, 1)
    test = binomtest(4, 5, 0.5)
    ci = test.proportion_ci(0.95, method="wilson")
    assert (cmp.p_value, cmp.ci_low, cmp.ci_high) == (test.pvalue, ci.low, ci.high)
    assert cmp.verdict == "undecided"


def test_robustness_study_end_to_end(tmp_path):
    study = robustness.run(
        pso=TINY_PSO,
        trials=6,
        scenarios=["torque_noise"],
        estimators=[{"_name_": "ls", "relative": True}, {"_name_": "rls", "relative": True}],
        pso_costs=["f13", "f14"],
        optional=["huber"],
        progress=False,
    )
    by = study.params["torque_noise"]
    assert set(by) == {"LS-rel", "RLS-rel", "PSO-f13", "PSO-f14", "PSO-f13/f14"}
    np.testing.assert_allclose(by["PSO-f13/f14"], (by["PSO-f13"] + by["PSO-f14"]) / 2)
    row = next(r for r in study.rows() if r["estimator"] == "LS-rel")
    err = parameter_error(by["LS-rel"], study.truth)
    assert row["median"] == pytest.approx(np.median(err))
    assert row["wins"] + row["losses"] + row["ties"] == 6
    written = study.save(tmp_path, make_plots=True)
    assert (tmp_path / "robustness_boxplot.png").stat().st_size > 0
    assert "PSO-f13/f14" in Path(written["markdown"]).read_text()
    assert not math.isnan(json.loads((tmp_path / "result.json").read_text())["wall_time_s"])
    again = robustness.load(tmp_path)
    assert again.rows() == study.rows()
    other = robustness.RobustnessStudy(
        **{**vars(again), "params": {"outliers": again.params["torque_noise"]}}
    )
    assert list(robustness.merge([again, other]).params) == ["torque_noise", "outliers"]


def test_measured_data_have_no_truth(tmp_path, cylindrical):
    from idkit.data import simulate

    samples = simulate(cylindrical, "torque_noise", seed=1)
    path = tmp_path / "recording.npz"
    np.savez(path, **{k: getattr(samples, k).numpy() for k in ("q", "qd", "qdd", "tau")})
    result = idkit.run(estimator="ls", cost=None, data=path, out_dir=tmp_path / "run")
    data = json.loads((tmp_path / "run" / "result.json").read_text())
    assert data["truth"] is None and data["relative_error"] is None and data["data"] == {"file": str(path)}
    same = idkit.run(estimator="ls", cost=None, scenario="torque_noise", seed=1)
    assert result.estimate.params == pytest.approx(same.estimate.params, rel=1e-12)
