"""Samples for identification: the paper's trajectory, simulated noise scenarios, user data files."""

from idkit.data.io import FLOBAROID_KEYS, load_samples, save_samples
from idkit.data.scenarios import (
    SCENARIOS,
    SampleBatch,
    Scenario,
    UnknownScenarioError,
    clean_samples,
    get_scenario,
    simulate,
    simulate_batch,
)
from idkit.data.trajectory import check_bounds, paper_trajectory, sample_times

__all__ = [
    "FLOBAROID_KEYS",
    "SCENARIOS",
    "SampleBatch",
    "Scenario",
    "UnknownScenarioError",
    "check_bounds",
    "clean_samples",
    "get_scenario",
    "load_samples",
    "paper_trajectory",
    "sample_times",
    "save_samples",
    "simulate",
    "simulate_batch",
]
