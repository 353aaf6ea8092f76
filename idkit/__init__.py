"""idkit: identify robot dynamic parameters from measured joint states and torques.

Attributes are imported lazily so that ``import idkit`` (and ``idkit --help``) does not pay for
torch until something needs it.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

_LAZY = {
    "Robot": "idkit.interfaces",
    "Cost": "idkit.interfaces",
    "Estimator": "idkit.interfaces",
    "Problem": "idkit.problem",
    "Samples": "idkit.problem",
    "Estimate": "idkit.estimate",
    "registry": "idkit.registry",
    "run": "idkit.api",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module 'idkit' has no attribute {name!r}")
    module = importlib.import_module(_LAZY[name])
    return module if module.__name__ == f"idkit.{name}" else getattr(module, name)
