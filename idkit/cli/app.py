"""The Hydra application behind ``idkit``.

``setup()`` must run before Hydra composes anything (``main`` calls it; tests using Hydra's compose
API call it too): it registers the ``idkit://`` config source that turns the plugin registry into
config groups and the ``${idkit.uid:}`` resolver that keeps run directories unique.
"""

from __future__ import annotations

import importlib
import sys
import uuid
from pathlib import Path
from typing import Any

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.core.plugins import Plugins
from hydra.errors import CompactHydraException
from omegaconf import DictConfig, OmegaConf

from idkit import registry
from idkit.cli.source import RegistryConfigSource, RegistrySearchPath

#: ``task`` key of the composed config → function ``(cfg, run_dir) -> result`` (imported on use).
TASKS = {
    "single": "idkit.experiments.single:run_config",
    "paper": "idkit.experiments.paper:run_config",
    "robustness": "idkit.experiments.robustness:run_config",
    "kuka": "idkit.experiments.kuka_task:run_config",
}

HELP_FLAGS = ("--help", "-h", "--hydra-help")

#: Errors caused by what the user asked for: reported as one clear message and exit status 1,
#: not as a traceback (HYDRA_FULL_ERROR=1 still shows the traceback).
USER_ERRORS = (registry.PluginError, ValueError, TypeError, FileNotFoundError)


def _uid() -> str:
    """Six hex digits, drawn once per config (the resolver is cached) — see ``hydra.run.dir``."""
    return uuid.uuid4().hex[:6]


OmegaConf.register_new_resolver("idkit.uid", _uid, use_cache=True, replace=True)


def setup(names_only: bool = False) -> None:
    """Register idkit's config source with Hydra (idempotent).

    Args:
        names_only: serve plugin nodes without reading constructor signatures, so composing the
            config imports no plugin (and no torch). ``main`` sets it for ``--help``.
    """
    RegistryConfigSource.names_only = names_only
    Plugins.instance().register(RegistryConfigSource)
    Plugins.instance().register(RegistrySearchPath)


def _resolve_task(name: str) -> Any:
    if name not in TASKS:
        raise ValueError(f"unknown task {name!r}; the tasks are {', '.join(TASKS)}")
    module, _, attr = TASKS[name].partition(":")
    return getattr(importlib.import_module(module), attr)


def task(cfg: DictConfig) -> Any:
    """Run the experiment named by ``cfg.task`` in Hydra's output directory."""
    run_dir = Path(HydraConfig.get().runtime.output_dir)
    try:
        return _resolve_task(cfg.task)(cfg, run_dir)
    except USER_ERRORS as exc:
        raise CompactHydraException(f"idkit: {exc}") from exc


def main() -> None:
    setup(names_only=any(arg in HELP_FLAGS for arg in sys.argv[1:]))
    hydra.main(version_base="1.3", config_path="pkg://idkit.conf", config_name="config")(task)()
