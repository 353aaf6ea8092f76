"""The robustness study: statistics against scipy, verdicts, end to end, load/merge, interruption."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import binomtest

from idkit.reports import robustness as report
from idkit.studies import robustness
from idkit.studies.metrics import parameter_error
from idkit.studies.result import StudyInterrupted

TINY_PSO = {"_name_": "pso", "runs": 2, "particles": 6, "iterations": 15}
SMALL = {
    "estimator": TINY_PSO,
    "scenarios": ["torque_noise"],
    "estimators": [{"_name_": "ls", "relative": True}, {"_name_": "rls", "relative": True}],
    "pso_costs": ["f13", "f14"],
    "optional": ["huber"],
    "progress": False,
}


def test_comparison_matches_scipy_and_counts_ties():
    errors = np.array([1.0, 2.0, 3.0, 0.5, 2.0, 0.1])
    base = np.array([2.0, 1.0, 4.0, 1.0, 2.0, 0.2])
    cmp = robustness.Comparison.of(errors, base)
    assert (cmp.wins, cmp.losses, cmp.ties) == (4, 1, 1)
    test = binomtest(4, 5, 0.5)
    ci = test.proportion_ci(0.95, method="exact")
    assert (cmp.p_value, cmp.ci_low, cmp.ci_high) == (test.pvalue, ci.low, ci.high)
    assert cmp.verdict == "undecided"


@settings(max_examples=200, deadline=None)
@given(wins=st.integers(0, 600), losses=st.integers(0, 600))
def test_the_verdict_the_interval_and_the_p_value_agree(wins, losses):
    """One rule: the verdict is read off the interval, and the p-value printed beside it is below
    5 % exactly when that interval excludes 1/2 (no "undecided" under an interval of 36.3–49.9 %)."""
    cmp = robustness.Comparison.of(np.r_[np.zeros(wins), np.ones(losses)], np.full(wins + losses, 0.5))
    if wins + losses == 0:
        assert cmp.verdict == "undecided"
        return
    excludes = cmp.ci_high < 0.5 or cmp.ci_low > 0.5
    assert excludes == (binomtest(wins, wins + losses, 0.5).pvalue < 0.05)
    expected = "better" if cmp.ci_low > 0.5 else "worse" if cmp.ci_high < 0.5 else "undecided"
    assert cmp.verdict == expected


def test_conclusion_agrees_with_the_verdicts():
    assert robustness.conclusion(["better", "better"]) == "holds"
    assert robustness.conclusion(["better", "undecided"]) == "undecided"
    assert robustness.conclusion(["undecided", "worse"]) == "does not hold"
    assert robustness.conclusion([]) == "undecided"


def test_robustness_study_end_to_end(tmp_path):
    study = robustness.run(trials=6, **SMALL)
    by = study.params["torque_noise"]
    assert set(by) == {"LS-rel", "RLS-rel", "PSO-f13", "PSO-f14", "PSO-f13/f14"}
    np.testing.assert_allclose(by["PSO-f13/f14"], (by["PSO-f13"] + by["PSO-f14"]) / 2)
    row = next(r for r in study.rows() if r["estimator"] == "LS-rel")
    err = parameter_error(by["LS-rel"], study.truth)
    assert row["median"] == pytest.approx(np.median(err))
    assert row["wins"] + row["losses"] + row["ties"] == 6
    written = report.write(study, tmp_path, plots=True)
    assert (tmp_path / "robustness_boxplot.png").stat().st_size > 0
    assert "PSO-f13/f14" in Path(written["markdown"]).read_text()
    document = json.loads((tmp_path / "result.json").read_text())
    assert document["status"] == "complete" and document["progress"]["done"] == 6
    assert not math.isnan(document["payload"]["wall_time_s"])
    again = robustness.load(tmp_path)
    assert again.rows() == study.rows()
    other = robustness.RobustnessStudy(
        **{**vars(again), "params": {"outliers": again.params["torque_noise"]}}
    )
    assert list(robustness.merge([again, other]).params) == ["torque_noise", "outliers"]


def test_interrupted_study_keeps_whole_trials_and_says_partial(tmp_path, monkeypatch):
    """Ctrl-C in trial 3 of 5: the partial result has 2 trials everywhere and is marked partial."""
    from idkit.estimators.linear.least_squares import LeastSquares

    calls = {"n": 0}
    fit_trials = LeastSquares.fit_trials

    def interrupting_fit_trials(self, problems, costs=None, chunk=None):
        calls["n"] += 1
        if calls["n"] == 5:  # chunks of 1 trial, 2 estimators per trial: the 5th call is in trial 3
            raise KeyboardInterrupt
        return fit_trials(self, problems, costs, chunk)

    monkeypatch.setattr(LeastSquares, "fit_trials", interrupting_fit_trials)
    with pytest.raises(StudyInterrupted) as stop:
        robustness.run(
            trials=5,
            chunk=1,
            baseline="LS",
            **{**SMALL, "estimators": [{"_name_": "ls", "relative": True}, "ls"]},
        )
    partial = stop.value.partial
    assert (partial.provenance.done, partial.provenance.requested) == (2, 5)
    assert {len(v) for v in partial.params["torque_noise"].values()} == {2}
    report.write(partial, tmp_path, plots=False)
    document = json.loads((tmp_path / "result.json").read_text())
    assert document["status"] == "partial" and document["progress"] == {
        "done": 2,
        "requested": 5,
        "unit": "trial",
    }
    assert "PARTIAL: 2 of 5 trials" in (tmp_path / "robustness.md").read_text()


#: Every path of the study: the LS family, a third-party estimator (IRLS), native and eager costs.
MIXED = {
    **SMALL,
    "scenarios": ["torque_noise", "outliers"],
    "estimators": [{"_name_": "ls", "relative": True}, {"_name_": "rls", "relative": True}, "irls"],
    "pso_costs": ["f13", "f14", "huber"],
    "optional": [],
}


def _same_numbers(a: robustness.RobustnessStudy, b: robustness.RobustnessStudy) -> None:
    assert list(a.params) == list(b.params)
    for scenario, by in a.params.items():
        assert list(by) == list(b.params[scenario])
        for label, values in by.items():
            np.testing.assert_array_equal(values, b.params[scenario][label], err_msg=f"{scenario} {label}")


def test_study_numbers_do_not_depend_on_the_chunk_size():
    """Chunks of 1, 7 and all trials: bit-identical parameters for every estimator and scenario."""
    studies = [robustness.run(trials=9, chunk=chunk, **MIXED) for chunk in (1, 7, 9)]
    for other in studies[1:]:
        _same_numbers(studies[0], other)


def test_batched_trials_equal_fitting_each_trial_alone():
    """Trial t of the batched study is what the estimators give on (seed + t) fitted one by one."""
    from idkit.data.scenarios import simulate_batch
    from idkit.problem import Problem
    from idkit.studies.build import build

    study = robustness.run(trials=4, seed=3, **MIXED)
    robot = build("robot", "cylindrical")
    search = build("estimator", TINY_PSO)
    costs = [build("cost", c) for c in MIXED["pso_costs"]]
    singles = [build("estimator", s) for s in MIXED["estimators"]]
    for scenario in MIXED["scenarios"]:
        draws = simulate_batch(robot, scenario, trials=4, seed=3)
        by = study.params[scenario]
        for t in range(4):
            problem = Problem(robot, draws[t], None, seed=3 + t)
            for label, est in zip(["LS-rel", "RLS-rel", "IRLS"], singles, strict=True):
                np.testing.assert_allclose(by[label][t], list(est.fit(problem).params.values()), rtol=1e-12)
            searched = search.fit_costs(problem, costs)
            for label, e in zip(["PSO-f13", "PSO-f14", "PSO-huber"], searched, strict=True):
                np.testing.assert_array_equal(by[label][t], list(e.params.values()))


def test_the_search_runs_without_its_convergence_record(monkeypatch):
    """The study reports parameters only: a search estimator built from a spec fits with
    ``history=False`` (set or not; provenance says so), a ready object as it was given."""
    from idkit.estimators.pso import ParticleSwarm

    seen = []
    fit_trials = ParticleSwarm.fit_trials

    def spy(self, problems, costs=None, chunk=None):
        seen.append(self.history)
        return fit_trials(self, problems, costs, chunk)

    monkeypatch.setattr(ParticleSwarm, "fit_trials", spy)
    study = robustness.run(trials=2, **{**SMALL, "estimator": {**TINY_PSO, "history": True}})
    assert seen and not any(seen)
    assert study.provenance.plugins["estimator"]["options"]["history"] is False
    seen.clear()
    robustness.run(trials=2, **{**SMALL, "estimator": ParticleSwarm(runs=2, particles=6, iterations=15)})
    assert seen and all(seen)


def test_shards_merge_into_the_one_process_study(tmp_path):
    """Two shards written and read back, merged: the same numbers as one process over all trials."""
    whole = robustness.run(trials=5, **MIXED)
    parts = []
    for shard in (1, 0):
        study = robustness.run(trials=5, shard=shard, shards=2, **MIXED)
        assert study.trials == len(robustness.shard_trials(5, shard, 2))
        report.write(study, tmp_path / str(shard), plots=False)
        parts.append(robustness.load(tmp_path / str(shard)))
    merged = robustness.merge(parts)
    _same_numbers(whole, merged)
    assert (merged.trials, merged.provenance.status) == (5, "complete")
    assert [r["win_rate"] for r in merged.rows()] == [r["win_rate"] for r in whole.rows()]


def test_shard_options_are_checked():
    assert list(robustness.shard_trials(10, 2, 3)) == list(range(6, 10))
    with pytest.raises(ValueError, match="robustness.shard must be below"):
        robustness.shard_trials(10, 3, 3)
    with pytest.raises(ValueError, match="exceeds trials"):
        robustness.shard_trials(2, 0, 3)
    with pytest.raises(ValueError, match="chunk"):
        robustness.run(trials=2, chunk=0, **SMALL)


def test_a_baseline_that_is_none_of_the_estimates_is_refused_before_fitting(monkeypatch):
    """Before, ``robustness.baseline=XYZ`` (or estimators overridden without RLS-rel) ran and left
    every win-rate column empty, exit status 0."""
    import idkit.data.scenarios

    monkeypatch.setattr(idkit.data.scenarios, "simulate_batch", lambda *a, **k: pytest.fail("drew noise"))
    with pytest.raises(ValueError) as refused:
        robustness.run(
            trials=2,
            baseline="XYZ",
            **{**SMALL, "pso_costs": ["f13", "f14", "absent"], "optional": ["absent"]},
        )
    assert str(refused.value) == (
        "robustness: baseline 'XYZ' is none of the study's estimates: LS-rel, RLS-rel, PSO-f13, PSO-f14, "
        "PSO-f13/f14 (skipped, not installed: cost absent); the win rates are against the baseline, "
        "name one of them"
    )


def test_trials_are_checked_before_anything_is_drawn(monkeypatch):
    import idkit.data.scenarios
    from idkit import memory

    def must_not_draw(*args, **kwargs):
        raise AssertionError("drew noise before checking trials")

    monkeypatch.setattr(idkit.data.scenarios, "simulate_batch", must_not_draw)
    for trials in (0, -3, 2.5, True):
        with pytest.raises(ValueError, match=rf"^trials must be an integer >= 1, got {trials!r}$"):
            robustness.run(trials=trials, **SMALL)
    with pytest.raises(ValueError, match=r"^robustness.shards=3 exceeds trials=2: .*use at most 2 shards$"):
        robustness.run(trials=2, shards=3, **SMALL)
    with pytest.raises(memory.SizeError) as refused:
        robustness.run(trials=10**9, **SMALL)
    assert "\n" not in str(refused.value)
    assert str(refused.value).startswith(
        "robustness: trials=1000000000 (1 scenario(s) x 5 estimates per trial) needs about "
    )
    assert "TB of memory; this machine has " in str(refused.value) and str(refused.value).endswith(
        "; lower trials"
    )
    monkeypatch.setattr(memory, "available_memory", lambda: 500_000)
    with pytest.raises(
        memory.SizeError,
        match="trials=100 .* needs about 684 kB of memory; this machine has 500 kB available; lower trials$",
    ):
        robustness.run(trials=100, **SMALL)


def test_the_memory_model_counts_every_scenario_and_estimate():
    from idkit.robots.cylindrical import CylindricalRobot

    robot, r = CylindricalRobot(), robustness  # 3 joints, 4 parameters; 10 samples: 120 components
    row = r.ESTIMATE_BYTES + 4 * r.PARAMETER_BYTES
    one = r.memory_needed(robot, ["torque_noise"], {}, drawn=10, fitted=10, labels=1)
    assert one == 10 * 120 * (r.DRAW_BYTES_KEPT + r.DRAW_BYTES_PEAK)  # drawing outweighs one estimate
    longer = r.memory_needed(robot, ["torque_noise"], {"n_samples": 20}, drawn=10, fitted=10, labels=1)
    assert longer == 2 * one
    four = r.memory_needed(robot, ["torque_noise"] * 4, {}, drawn=10, fitted=10, labels=1)
    assert four == 10 * 120 * (4 * r.DRAW_BYTES_KEPT + r.DRAW_BYTES_PEAK)
    many = r.memory_needed(robot, ["torque_noise"] * 4, {}, drawn=10, fitted=10, labels=100)
    assert many == 10 * (4 * 120 * r.DRAW_BYTES_KEPT + 4 * 100 * row)  # the estimates outweigh drawing


@pytest.mark.skipif(not __import__("torch").cuda.is_available(), reason="no CUDA device")
def test_study_runs_on_cuda():
    study = robustness.run(trials=3, device="cuda", **MIXED)
    assert {len(v) for by in study.params.values() for v in by.values()} == {3}
