"""The real-robot defaults (:mod:`idkit.studies.defaults`) applied to a composed config.

Only the command line knows which options the user typed (Hydra's task overrides): the defaults
replace the others in the config itself, before it is recorded, so ``.hydra/config.yaml`` and
``result.json`` say what ran.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import DictConfig, OmegaConf, open_dict

from idkit.cli.nodes import plugin_node
from idkit.studies.defaults import RealRobotNote, applies, chosen, describe, searches_cost


def apply_real_robot_defaults(cfg: DictConfig, overrides: Sequence[str]) -> None:
    """Set the real-robot options the user left open in ``cfg`` (in place) and say so in a note."""
    if not applies(str(cfg.get("task")), cfg.get("robot"), cfg.get("data"), cfg.get("estimator")):
        return
    given = {override.key_or_group for override in OverridesParser.create().parse_overrides(list(overrides))}
    options = chosen(given, searches_cost(cfg.get("estimator")))
    if not options:
        return
    with open_dict(cfg):
        for key, value in options.items():
            if key == "estimator":
                cfg.estimator = plugin_node("estimator", value)
            elif key == "cost":
                cfg.cost = None
            else:
                OmegaConf.update(cfg, key, value, force_add=False)
    warnings.warn(describe(options), RealRobotNote, stacklevel=2)
