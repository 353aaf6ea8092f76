"""``history_table``: the documented ``details["history"]`` formats, and errors naming what breaks them."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from idkit.estimate import Estimate, HistoryError, history_table, to_python

number = st.floats(allow_nan=False, allow_infinity=False) | st.integers(-1000, 1000)


def test_three_formats():
    assert history_table([3.0, 2.0]) == (["iteration", "best_cost"], [[0, 3.0], [1, 2.0]])
    assert history_table([[3, 2], [5, 1]]) == (["iteration", "run_0", "run_1"], [[0, 3, 5], [1, 2, 1]])
    assert history_table({"cost": [2.0, None], "lr": [0.1, 0.05]}) == (
        ["iteration", "cost", "lr"],
        [[0, 2.0, 0.1], [1, None, 0.05]],
    )


def test_tensors_and_arrays_read_as_lists():
    header, rows = history_table(torch.tensor([[1.0, float("inf")], [2.0, 0.5]]))
    assert header == ["iteration", "run_0", "run_1"] and rows == [[0, 1.0, 2.0], [1, float("inf"), 0.5]]
    assert history_table(np.arange(3.0)) == (["iteration", "best_cost"], [[0, 0.0], [1, 1.0], [2, 2.0]])


@pytest.mark.parametrize("empty", [None, [], {}, [[], []]])
def test_no_history(empty):
    assert history_table(empty) is None


@pytest.mark.parametrize(
    ("history", "message"),
    [
        ([[3.0, 2.0, 1.0], [3.0, 2.0]], "run 1 has 2 iterations but run 0 has 3"),
        ({"a": [1.0], "b": [1.0, 2.0]}, "column 'b' has 2 iterations but column 'a' has 1"),
        ([1.0, [2.0]], "the history has [2.0] (list) at iteration 1; expected a number"),
        ([[[1.0]]], "run 0 has [1.0] (list) at iteration 0"),
        ({"a": "abc"}, "column 'a' must be a list of numbers, got str"),
        ([1.0, "x"], "has 'x' (str) at iteration 1"),
        ([True], "has True (bool) at iteration 0"),
        (3.0, 'details["history"] must be a list, a list of lists [runs][iterations] or a mapping'),
    ],
)
def test_bad_history_names_run_and_iteration(history, message):
    with pytest.raises(HistoryError) as err:
        history_table(history)
    assert message in str(err.value)


@given(st.lists(st.lists(number, min_size=4, max_size=4), min_size=1, max_size=5))
def test_runs_round_trip_through_the_table(runs):
    header, rows = history_table(runs)
    assert header[1:] == [f"run_{r}" for r in range(len(runs))]
    assert [row[0] for row in rows] == list(range(4))
    assert [list(column) for column in zip(*(row[1:] for row in rows), strict=True)] == runs


any_float = st.floats(allow_nan=True, allow_infinity=True)


def _same(a, b):
    """Equality where NaN equals NaN (a round trip must keep it, not drop it)."""
    if isinstance(a, float) and isinstance(b, float):
        return (np.isnan(a) and np.isnan(b)) or a == b
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return a == b


@given(
    params=st.dictionaries(st.text(min_size=1, max_size=5), any_float, max_size=4),
    cost=any_float,
    divergence=st.lists(any_float, max_size=4),
)
def test_estimate_round_trips_through_strict_json_with_non_finite_numbers(params, cost, divergence):
    """Infinities and NaN are strings in the file and typed floats again after reading it."""
    divergence = torch.tensor(divergence, dtype=torch.float64)
    est = Estimate("x", params, cost, 0.1, details={"divergence": divergence})
    assert isinstance(est.to_dict()["details"]["divergence"], list)
    text = est.to_json()  # allow_nan=False: raises if a bare NaN/Infinity token would be written
    back = Estimate.from_json(text)
    assert _same(back.to_dict(), est.to_dict())
    if not torch.isfinite(divergence).all():
        assert '"Infinity"' in text or '"-Infinity"' in text or '"NaN"' in text


def test_details_keep_infinity_in_memory():
    est = Estimate("x", {"a": 1.0}, None, 0.0, details=to_python({"divergence": np.array([1.0, np.inf])}))
    assert sum(est.details["divergence"]) == float("inf")
