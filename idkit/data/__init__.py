"""Samples for identification: simulated noise scenarios and user data files.

Attributes are imported lazily, so that ``idkit.data.presets`` (the scenario presets, torch-free)
serves the command line's ``--help`` without importing torch.
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "FLOBAROID_KEYS": "idkit.data.io",
    "load_samples": "idkit.data.io",
    "save_samples": "idkit.data.io",
    "PAPER_SCENARIOS": "idkit.data.presets",
    "SCENARIOS": "idkit.data.presets",
    "Scenario": "idkit.data.presets",
    "UnknownScenarioError": "idkit.data.presets",
    "SampleBatch": "idkit.data.scenarios",
    "clean_samples": "idkit.data.scenarios",
    "get_scenario": "idkit.data.scenarios",
    "simulate": "idkit.data.scenarios",
    "simulate_batch": "idkit.data.scenarios",
    "sample_times": "idkit.data.trajectory",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module 'idkit.data' has no attribute {name!r}")
    return getattr(importlib.import_module(_LAZY[name]), name)
