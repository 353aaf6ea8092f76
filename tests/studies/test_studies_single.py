"""One fit as a library call: the result.json contract, measured data, conflicting inputs."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

import idkit
from idkit.studies import single
from idkit.studies.metrics import parameter_error, relative_errors

TINY_PSO = {"_name_": "pso", "runs": 2, "particles": 6, "iterations": 15}
ENVELOPE = (
    "task",
    "label",
    "status",
    "progress",
    "seed",
    "data",
    "plugins",
    "config",
    "run_id",
    "idkit_version",
    "created",
    "files",
    "payload",
)


def test_run_writes_the_common_envelope_and_the_single_payload(tmp_path):
    result = idkit.run(
        estimator="ls", cost="f1", scenario="torque_noise", seed=3, out_dir=tmp_path, plots=True
    )
    data = json.loads((tmp_path / "result.json").read_text())
    assert tuple(data) == ENVELOPE
    assert (data["task"], data["label"], data["status"], data["seed"]) == ("single", "LS", "complete", 3)
    assert data["progress"] == {"done": 1, "requested": 1, "unit": "fit"}
    payload = data["payload"]
    assert payload["truth"] == {"m2": 5.0, "m3": 3.0, "s3z": -0.5, "I": 3.0}
    params = payload["estimate"]["params"]
    for name, value in params.items():
        true = payload["truth"][name]
        assert payload["relative_error"][name] == pytest.approx((value - true) / abs(true), rel=1e-12)
    assert payload["cost"] == {
        "name": "f1",
        "value": pytest.approx(result.estimate.cost),
        "used_by_fit": False,
    }
    assert data["plugins"]["estimator"]["distribution"] == "robot-idkit"
    assert data["plugins"]["cost"]["name"] == "f1"
    assert (tmp_path / "estimate.png").stat().st_size > 0
    assert "cost (f1)" in result.table()


def test_reported_cost_names_the_estimators_criterion_without_a_cost():
    result = idkit.run(estimator="ls", cost=None, scenario="torque_noise")
    assert result.cost_name == "LS criterion"
    assert "cost (LS criterion)" in result.table()


def test_history_csv_has_one_column_per_run(tmp_path):
    idkit.run(estimator=TINY_PSO, cost="f13", out_dir=tmp_path, plots=False)
    with open(tmp_path / "history.csv") as handle:
        rows = list(csv.reader(handle))
    assert rows[0] == ["iteration", "run_0", "run_1"]
    assert len(rows) == 1 + TINY_PSO["iterations"]
    best = [float(r[1]) for r in rows[1:]]
    assert best == sorted(best, reverse=True)  # a global best never gets worse


def test_a_malformed_history_still_writes_result_json(tmp_path):
    """Runs of unequal length used to crash the writer after the fit: no result.json at all."""
    from idkit.estimators.linear.least_squares import LeastSquares

    class RaggedHistory(LeastSquares):
        def fit(self, problem):
            estimate = super().fit(problem)
            estimate.details["history"] = [[3.0, 2.0, 1.0], [3.0, 2.0]]
            return estimate

    with pytest.warns(UserWarning, match="history.csv not written: .*run 1 has 2 iterations"):
        idkit.run(estimator=RaggedHistory(), cost=None, out_dir=tmp_path, plots=False)
    assert json.loads((tmp_path / "result.json").read_text())["status"] == "complete"
    assert not (tmp_path / "history.csv").exists()


def test_objects_work_as_well_as_names():
    from idkit.estimators.linear.least_squares import LeastSquares
    from idkit.robots.cylindrical import CylindricalRobot

    result = idkit.run(robot=CylindricalRobot(), estimator=LeastSquares(relative=True), cost=None)
    assert result.estimate.estimator == "LS-rel"
    assert result.plugins["estimator"]["entry_point"] == "idkit.estimators.linear.least_squares:LeastSquares"
    assert result.parameter_error < 1e-9  # clean data


def test_parameter_error_is_the_mean_absolute_relative_error():
    truth = np.array([5.0, 3.0, -0.5, 3.0])
    est = np.array([[5.5, 3.0, -0.25, 3.3], [np.nan, 3, -0.5, 3]])
    expected = (0.1 + 0.0 + 0.5 + 0.1) / 4
    np.testing.assert_allclose(parameter_error(est, truth), [expected, np.inf])
    rel = relative_errors({"a": 1.5, "b": 0.0}, {"a": 1.0, "b": 0.0})
    assert rel == {"a": 0.5, "b": None}


def _recording(tmp_path, cylindrical):
    from idkit.data import simulate

    samples = simulate(cylindrical, "torque_noise", seed=1)
    path = tmp_path / "recording.npz"
    np.savez(path, **{k: getattr(samples, k).numpy() for k in ("q", "qd", "qdd", "tau")})
    return path


def test_measured_data_have_no_truth(tmp_path, cylindrical):
    path = _recording(tmp_path, cylindrical)
    result = idkit.run(estimator="ls", cost=None, data=path, out_dir=tmp_path / "run")
    data = json.loads((tmp_path / "run" / "result.json").read_text())
    assert data["payload"]["truth"] is None and data["payload"]["relative_error"] is None
    joint_torque = "joint torque (N·m; N on a prismatic joint)"
    assert data["data"] == {"file": str(path), "torques": {"recorded": joint_torque, "fitted": joint_torque}}
    same = idkit.run(estimator="ls", cost=None, scenario="torque_noise", seed=1)
    assert result.estimate.params == pytest.approx(same.estimate.params, rel=1e-12)


def test_scenario_and_data_together_is_an_error(tmp_path, cylindrical):
    path = _recording(tmp_path, cylindrical)
    with pytest.raises(ValueError, match="either data= .* or scenario="):
        single.run(estimator="ls", cost=None, scenario="outliers", data=path)
    with pytest.raises(ValueError, match="n_samples=5 applies to a simulated scenario"):
        single.run(estimator="ls", cost=None, data=path, n_samples=5)


def test_n_samples_is_the_one_knob_for_the_number_of_samples():
    result = single.run(estimator="ls", cost=None, scenario="outliers", n_samples=25)
    assert result.data["scenario"]["n_samples"] == 25 and result.data["scenario"]["n_outliers"] == 10


def test_too_few_equations_are_refused_before_any_estimator_fits():
    """The study checks identifiability itself, so an estimator that does not is covered too."""
    from idkit.estimate import Estimate
    from idkit.interfaces import Estimator
    from idkit.problem import IdentificationError

    class Unchecked(Estimator):
        fitted = False

        def fit(self, problem):
            Unchecked.fitted = True
            return Estimate("unchecked", dict.fromkeys(problem.robot.param_names, 0.0), 0.0, 0.0)

    with pytest.raises(IdentificationError, match=r"1 sample × 3 joints = 3 equations < 4"):
        idkit.run(estimator=Unchecked(), cost="f13", n_samples=1)
    assert not Unchecked.fitted
    assert idkit.run(estimator=Unchecked(), cost="f13", n_samples=2).estimate.params["m2"] == 0.0


@pytest.mark.parametrize(
    ("params", "message"),
    [
        (
            {"m2": math.nan, "m3": 1.0, "s3z": 0.1, "I": math.inf},
            "estimator NaNs returned 2 non-finite parameter(s) of 4 (m2 = nan, I = inf); nothing is reported",
        ),
        (
            {"m2": 1.0},
            "estimator NaNs returned no value for 3 of the robot's 4 parameters (m3, s3z, I); nothing is "
            "reported",
        ),
    ],
)
def test_an_estimator_returning_no_answer_is_refused_not_reported(params, message):
    """A third-party estimator that fails quietly (NaN parameters) was reported with exit status 0."""
    from idkit.estimate import Estimate
    from idkit.interfaces import Estimator
    from idkit.problem import IdentificationError

    class NaNs(Estimator):
        def fit(self, problem):
            return Estimate(estimator="nan", params=dict(params), cost=math.nan, wall_time_s=0.0)

    with pytest.raises(IdentificationError) as info:
        single.run(estimator=NaNs(), cost=None, scenario="outliers")
    assert str(info.value) == message
