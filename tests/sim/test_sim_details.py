"""The rollout estimator's typed record: read by attribute, written to JSON as its ``to_dict``."""

from __future__ import annotations

import json

import numpy as np

from idkit.estimate import Estimate
from idkit.sim.details import PolishSolve, RolloutDetails, SearchSummary, States
from idkit.sim.uncertainty import Uncertainty


def _details() -> RolloutDetails:
    unc = Uncertainty(
        {"j1.damping": 0.1, "command_delay": np.inf},
        {"j1.damping": (0.8, 1.2), "command_delay": (-np.inf, np.inf)},
        misfit=1.3,
        autocorrelation=0.2,
        disagreement=1.1,
    )
    solves = (
        PolishSolve(4, False, 3, [5.0, 2.0], "ftol", [0.1, 0.2]),
        PolishSolve(8, True, 2, [2.0, 1.5], "xtol", [0.1, 0.2]),
    )
    states = States(np.zeros((2, 1)), np.ones((2, 1)))
    return RolloutDetails(
        "huber", "problem cost", SearchSummary(3.0, 40, np.array([1.0, 0.0])), [4.0, 3.0], solves, unc,
        False, ((0, 5), (5, 10)), states, states, rollouts=12, simulated_seconds=0.02,
        outliers={"stalled": 3},
    )  # fmt: skip


def test_attributes_and_mapping_agree_and_the_polish_cost_is_the_last_solves():
    details = _details()
    assert details.polish_cost == 1.5 and details["polish_cost"] == 1.5
    assert details["uncertainty"]["std"]["j1.damping"] == details.uncertainty.std["j1.damping"]
    assert set(details) == set(details.to_dict()) and len(details) == len(details.to_dict())
    assert details["initial_states"]["qd"] == [[1.0], [1.0]]


def test_an_estimate_with_typed_details_survives_strict_json():
    estimate = Estimate("rollout", {"j1.damping": 1.0, "command_delay": 0.0}, 2.0, 0.5, details=_details())
    text = estimate.to_json()
    assert json.loads(text)["details"]["outliers"] == {"stalled": 3}
    again = Estimate.from_json(text)
    assert again.to_dict() == estimate.to_dict()
    assert again.details["uncertainty"]["interval95"]["command_delay"] == [-np.inf, np.inf]
