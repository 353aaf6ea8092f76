"""``history_table``: the documented ``details["history"]`` formats, and errors naming what breaks them."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from idkit.estimate import HistoryError, history_table

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
    assert header == ["iteration", "run_0", "run_1"] and rows == [[0, 1.0, 2.0], [1, None, 0.5]]
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
