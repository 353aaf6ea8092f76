"""The robustness study's per-trial CSV: written and read back exactly, columns found by name, a file
that does not hold the study's trials refused."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from idkit.reports.files import write_csv
from idkit.studies import robustness_trials
from idkit.studies.result import Provenance
from idkit.studies.robustness import RobustnessStudy

NAMES = ["m1", "m2", "I1", "I2"]


def study(params: dict[str, dict[str, np.ndarray]], first: int = 0) -> RobustnessStudy:
    done = len(next(iter(next(iter(params.values())).values())))
    return RobustnessStudy(
        provenance=Provenance("robustness", "test", 0, None, {}, requested=done, done=done, unit="trial"),
        param_names=NAMES,
        truth=np.array([1.0, 2.0, 0.5, 0.25]),
        params=params,
        baseline="LS",
        focus=None,
        sharding={"first_trial": first},
    )


def written(tmp_path, made: RobustnessStudy):  # noqa: ANN201
    return write_csv(tmp_path / robustness_trials.FILE, *robustness_trials.table(made))


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=30, deadline=None)
@given(
    values=hnp.arrays(np.float64, st.tuples(st.integers(1, 4), st.just(len(NAMES))), elements=finite),
    first=st.integers(0, 50),
)
def test_written_then_read_gives_the_same_numbers(tmp_path_factory, values, first):
    """Every float, however small or large, comes back bit for bit, in the trials' order."""
    made = study({"torque_noise": {"LS": values, "PSO-f13": values[::-1].copy()}}, first)
    path = written(tmp_path_factory.mktemp("csv"), made)
    back = robustness_trials.read(path, NAMES, range(first, first + len(values)))
    assert list(back) == ["torque_noise"] and list(back["torque_noise"]) == ["LS", "PSO-f13"]
    for label, array in made.params["torque_noise"].items():
        assert back["torque_noise"][label].tobytes() == array.tobytes()


def test_the_rows_are_one_per_scenario_estimate_and_trial_with_the_error(tmp_path):
    values = np.array([[1.0, 2.0, 0.5, 0.5], [2.0, 2.0, 0.5, 0.25]])
    header, rows = robustness_trials.table(study({"outliers": {"LS": values}}, first=7))
    assert header == ["scenario", "trial", "estimator", *NAMES, "error"]
    assert [row[:3] for row in rows] == [["outliers", 7, "LS"], ["outliers", 8, "LS"]]
    # the parameter error, mean |p - truth| / |truth|: one of the four parameters is off by 100 %
    assert [row[-1] for row in rows] == [0.25, 0.25]


def test_columns_are_found_by_name_not_position(tmp_path):
    values = np.arange(8.0).reshape(2, 4)
    path = written(tmp_path, study({"outliers": {"LS": values}}))
    with open(path, newline="") as handle:
        rows = list(csv.reader(handle))
    order = [0, 2, 1, 6, 5, 4, 3, 7]  # trial before scenario, the parameters reversed
    reordered = tmp_path / "reordered.csv"
    write_csv(reordered, [rows[0][i] for i in order], ([row[i] for i in order] for row in rows[1:]))
    back = robustness_trials.read(reordered, NAMES, range(2))
    np.testing.assert_array_equal(back["outliers"]["LS"], values)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda rows: [[c for i, c in enumerate(r) if i != 4] for r in rows], "no column 'm2'"),
        (lambda rows: rows[:2], "LS has trials 0..0; its result.json says 0..1 were done"),
        (lambda rows: [rows[0], rows[2], rows[1]], "trials 1, 0 (not consecutive)"),
        (lambda rows: [rows[0], rows[1], [*rows[2][:3], "x", *rows[2][4:]]], "line 3"),
        (lambda rows: [rows[0], rows[1], rows[2][:-1]], "line 3: 7 values for 8 columns"),
    ],
)
def test_a_file_that_is_not_the_study_is_refused_saying_why(tmp_path, edit, message):
    path = written(tmp_path, study({"outliers": {"LS": np.ones((2, 4))}}))
    with open(path, newline="") as handle:
        rows = edit(list(csv.reader(handle)))
    write_csv(path, rows[0], rows[1:])
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")) as error:
        robustness_trials.read(path, NAMES, range(2))
    assert str(path) in str(error.value)
