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


def test_a_ready_object_is_labelled_as_the_spec_that_builds_it():
    from idkit import registry

    ls = registry.create("estimator", "ls", relative=True)
    assert estimator_label(ls) == estimator_label({"_name_": "ls", "relative": True}) == "LS-rel"
    pso = registry.create("estimator", "pso", runs=4)
    huber = registry.create("cost", "huber", relative=True)
    assert cost_label(huber) == "huber(relative)"
    assert estimator_label(pso, huber, with_cost=True, all_options=True) == "PSO(runs=4)-huber(relative)"
    with pytest.raises(ValueError, match="would both be labelled 'LS-rel'"):
        unique_labels([(ls, None, False), ({"_name_": "ls", "relative": True}, None, False)], where="test")


def test_an_unregistered_class_is_named_by_its_class_and_options_not_its_own_label():
    from idkit.estimators.linear.least_squares import LeastSquares

    class Tweaked(LeastSquares):
        label = "LS"  # what the estimator calls itself; the study's label does not read it

    assert estimator_label(Tweaked()) == "Tweaked"
    assert estimator_label(Tweaked(relative=True, floor=0.1), all_options=True) == "Tweaked(floor=0.1)-rel"


#: One spec per row, in the three forms a study accepts: name (or mapping) and ready object.
FORMS = [
    ("pso", "f13", True),
    ({"_name_": "pso", "runs": 3}, "f13", True),
    ({"_name_": "ls", "relative": True}, None, False),
    ({"_name_": "rls", "solver": "cvxpy"}, None, False),
    ("pso", {"_name_": "huber", "relative": True}, True),
]


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, len(FORMS) - 1), st.booleans()), min_size=1, max_size=5))
def test_labels_are_unique_or_the_specs_are_the_same_whatever_their_form(picks):
    """A spec given as an object and as a config is one spec: two of them are refused, like two
    equal configs; distinct specs always get distinct labels."""
    from idkit.studies.build import build

    def form(index: int, ready: bool) -> tuple:
        estimator, cost, with_cost = FORMS[index]
        if not ready:
            return estimator, cost, with_cost
        return build("estimator", estimator), cost if cost is None else build("cost", cost), with_cost

    specs = [form(index, ready) for index, ready in picks]
    if len({index for index, _ in picks}) < len(picks):
        with pytest.raises(ValueError, match="would both be labelled"):
            unique_labels(specs, where="test")
    else:
        labels = unique_labels(specs, where="test")
        assert len(set(labels)) == len(labels)
