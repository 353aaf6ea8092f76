"""Labels from registry names and options, unique within a study."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit.studies.labels import cost_label, estimator_label, unique_labels


def test_labels_come_from_names_and_changed_options():
    assert estimator_label("pso", "f13", with_cost=True) == "PSO-f13"
    assert estimator_label({"_name_": "ls", "relative": True}) == "LS-rel"
    assert estimator_label({"_name_": "ls", "relative": False}) == "LS"
    assert estimator_label("pso_f13_f14") == "PSO-f13-f14"
    assert estimator_label("rls", "f13", with_cost=False) == "RLS"
    assert cost_label({"_name_": "huber", "relative": True}) == "huber(relative)"
    assert cost_label({"_name_": "huber", "delta": 2.0, "relative": False}) == "huber(delta=2.0)"
    assert (
        estimator_label("pso", {"_name_": "huber", "relative": True}, with_cost=True) == "PSO-huber(relative)"
    )


def test_two_options_variants_of_one_cost_get_distinct_labels():
    labels = unique_labels(
        [("pso", "huber", True), ("pso", {"_name_": "huber", "relative": True}, True)], where="test"
    )
    assert labels == ["PSO-huber", "PSO-huber(relative)"]


def test_collisions_are_told_apart_by_the_estimators_options_or_refused():
    specs = [({"_name_": "pso", "runs": 4}, "f1", True), ("pso", "f1", True)]
    assert unique_labels(specs, where="test") == ["PSO(runs=4)-f1", "PSO-f1"]
    with pytest.raises(ValueError, match="test: two estimators would both be labelled 'PSO-f1'"):
        unique_labels([("pso", "f1", True), ("pso", "f1", True)], where="test")


SPECS = st.sampled_from(
    [
        ("pso", "f13", True),
        ("pso", "huber", True),
        ("pso", {"_name_": "huber", "relative": True}, True),
        ("pso", {"_name_": "huber", "delta": 2.0}, True),
        ({"_name_": "pso", "runs": 3}, "f13", True),
        ("ls", None, False),
        ({"_name_": "ls", "relative": True}, None, False),
        ({"_name_": "rls", "solver": "cvxpy"}, None, False),
    ]
)


@settings(max_examples=60, deadline=None)
@given(st.lists(SPECS, min_size=1, max_size=6))
def test_labels_are_unique_or_the_specs_are_identical(specs):
    """Distinct specs always get distinct labels; only a repeated spec is refused."""
    repeated = len({repr(s) for s in specs}) < len(specs)
    if repeated:
        with pytest.raises(ValueError, match="would both be labelled"):
            unique_labels(specs, where="test")
    else:
        labels = unique_labels(specs, where="test")
        assert len(set(labels)) == len(labels)
