"""Identify a robot's dynamic parameters (masses, inertias, friction) from its logs.

    m = idkit.identify({"_name_": "urdf", "urdf": "arm.urdf"}, "train.csv", validate=["test.csv"])
    m.params["link2.m"], m.params.std["link2.m"]   # a value and its σ; m.predict(q, qd, qdd) torques
    m.save("identified.urdf")      # shell: idkit robot=urdf robot.urdf=arm.urdf data=train.csv

To try it without a robot, ``python -m idkit.data.demo`` writes a simulated arm's ``arm.urdf``,
``train.csv`` and ``test.csv``; the documentation (``docs/library.md``) reads q, qd, qdd from a log.

The public names below are imported lazily, so that ``import idkit`` (and ``idkit --help``) does not
pay for torch until something needs one. The entries: :func:`identify` (a robot's recordings → an
:class:`IdentifiedModel`), :func:`identify_simulator` (a MuJoCo model and a robot's logs → a
:class:`SimulatorModel`) and :func:`run` (one fit of any kind → its result); the plugin interfaces
``Robot``, ``Cost``, ``Estimator``; ``Problem``, ``Samples`` and ``Estimate``; the plugin ``registry``.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # what the lazy names are, for type checkers, help() and the API docs
    from idkit import registry
    from idkit.api import identify, identify_simulator, run
    from idkit.estimate import Estimate
    from idkit.interfaces import Cost, Estimator, Robot
    from idkit.model import IdentifiedModel, Parameters
    from idkit.problem import Problem, Samples
    from idkit.sim.simulator_model import SimulatorModel

#: The distribution that installs the package (``idkit`` on PyPI is an unrelated project).
DISTRIBUTION = "robot-idkit"

_LAZY = {
    "identify": "idkit.api",
    "identify_simulator": "idkit.api",
    "run": "idkit.api",
    "IdentifiedModel": "idkit.model",
    "Parameters": "idkit.model",
    "Robot": "idkit.interfaces",
    "Cost": "idkit.interfaces",
    "Estimator": "idkit.interfaces",
    "Problem": "idkit.problem",
    "Samples": "idkit.problem",
    "Estimate": "idkit.estimate",
    "SimulatorModel": "idkit.sim.simulator_model",
    "registry": "idkit.registry",
}

__all__ = [
    "DISTRIBUTION",
    "Cost",
    "Estimate",
    "Estimator",
    "IdentifiedModel",
    "Parameters",
    "Problem",
    "Robot",
    "Samples",
    "SimulatorModel",
    "identify",
    "identify_simulator",
    "registry",
    "run",
]


def _version() -> str:
    """The installed distribution's version: ``pyproject.toml`` is its one source."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(DISTRIBUTION)
    except PackageNotFoundError:  # a source tree on sys.path that was never installed
        return "0+unknown"


def __getattr__(name: str) -> Any:
    """A public name (``__all__``), imported on first use."""
    if name == "__version__":
        return _version()
    if name not in _LAZY:
        raise AttributeError(f"module 'idkit' has no attribute {name!r}")
    module = importlib.import_module(_LAZY[name])
    value = module if module.__name__ == f"idkit.{name}" else getattr(module, name)
    globals()[name] = value  # once imported, an ordinary attribute
    return value


def __dir__() -> list[str]:
    """The public names too (``help(idkit)``, tab completion), imported or not."""
    return sorted({*globals(), *__all__})
