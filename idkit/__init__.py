"""idkit: identify robot dynamic parameters from measured joint states and torques.

Attributes are imported lazily so that ``import idkit`` (and ``idkit --help``) does not pay for
torch until something needs it.
"""

from __future__ import annotations

import importlib
from typing import Any

#: The distribution that installs the package (``idkit`` on PyPI is an unrelated project).
DISTRIBUTION = "robot-idkit"

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


def _version() -> str:
    """The installed distribution's version: ``pyproject.toml`` is its one source."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(DISTRIBUTION)
    except PackageNotFoundError:  # a source tree on sys.path that was never installed
        return "0+unknown"


def __getattr__(name: str) -> Any:
    if name == "__version__":
        return _version()
    if name not in _LAZY:
        raise AttributeError(f"module 'idkit' has no attribute {name!r}")
    module = importlib.import_module(_LAZY[name])
    return module if module.__name__ == f"idkit.{name}" else getattr(module, name)
