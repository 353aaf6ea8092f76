"""An estimator with its own criterion (LS, TLS, RLS, pcls) ignores ``cost=``: a run says so in one
note, result.json records it, and a sweep's summary names the jobs that repeat an earlier fit."""

from __future__ import annotations

import warnings

import pytest

import idkit
from idkit.cli.callbacks import mark_repeats
from idkit.studies.single import CostIgnoredNote


def test_a_cost_given_to_least_squares_is_said_to_change_nothing():
    with pytest.warns(CostIgnoredNote, match="LS minimises its own criterion and ignores cost="):
        f13 = idkit.run(estimator="ls", cost="f13", scenario="outliers", seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", CostIgnoredNote)
        alone = idkit.run(estimator="ls", cost=None, scenario="outliers", seed=0)
    assert f13.estimate.params == alone.estimate.params  # the claim the note makes
    assert f13.payload()["cost"]["used_by_fit"] is False and alone.payload()["cost"]["used_by_fit"]


def test_the_summary_names_the_job_a_cost_ignoring_fit_repeats():
    rows = [
        {"job": "0", "overrides": "estimator=ls cost=f1 +scenario=outliers", "cost_ignored": True},
        {"job": "1", "overrides": "estimator=ls cost=f13 +scenario=outliers", "cost_ignored": True},
        {"job": "2", "overrides": "estimator=pso cost=f1 +scenario=outliers", "cost_ignored": False},
        {"job": "3", "overrides": "estimator=pso cost=f13 +scenario=outliers", "cost_ignored": False},
        {"job": "4", "overrides": "estimator=ls cost=f13 +scenario=all_noise", "cost_ignored": True},
    ]
    mark_repeats(rows)
    assert [row.get("repeats") for row in rows] == [
        None, "job 0 (the estimator ignores cost=)", None, None, None
    ]  # fmt: skip
    assert all("cost_ignored" not in row for row in rows)
