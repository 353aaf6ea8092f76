"""The real-robot defaults (:mod:`idkit.studies.defaults`) applied to a composed config.

Only the command line knows which options the user typed (Hydra's task overrides): the defaults
replace the others in the config itself, before it is recorded, so ``.hydra/config.yaml`` and
``result.json`` say what ran. One choice must come earlier: options of the default estimator typed
without naming it (``estimator.prior_weight=300``) are checked by Hydra against the config's own
estimator while it composes, so :func:`preselect_estimator` names it among the overrides first.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.errors import OverrideParseException
from omegaconf import DictConfig, OmegaConf, open_dict

from idkit.cli.nodes import plugin_node
from idkit.studies.defaults import (
    MODEL_ROBOTS,
    REAL_ROBOT,
    RealRobotNote,
    applies,
    chosen,
    describe,
    searches_cost,
)

#: Overrides :func:`preselect_estimator` added: the user did not type them, and the note says so.
_PRESELECTED: set[str] = set()


def preselect_estimator(words: list[str]) -> list[str]:
    """The command line's ``words`` with the real-robot estimator named (``estimator=pcls``) when they
    set options of an estimator without naming one, for a fit of a model robot to measured data: those
    options are the real-robot estimator's (``prior_weight``), and Hydra would check them against the
    paper's."""
    overrides = [word for word in words if "=" in word and not word.startswith("-")]
    try:
        parsed = OverridesParser.create().parse_overrides(overrides)
    except OverrideParseException:
        return words  # Hydra refuses it in its own words, in one line (idkit.cli.errors)
    keys = {override.key_or_group: override for override in parsed}
    robot = keys.get("robot")
    task = keys.get("task")
    if (
        robot is None
        or robot.value() not in MODEL_ROBOTS
        or "data" not in keys
        or "estimator" in keys
        or "experiment" in keys
        or (task is not None and task.value() != "single")
        or not any(key.startswith("estimator.") for key in keys)
    ):
        return words
    added = f"estimator={REAL_ROBOT['estimator']}"
    _PRESELECTED.add(added)
    return [added, *words]


def apply_real_robot_defaults(cfg: DictConfig, overrides: Sequence[str]) -> None:
    """Set the real-robot options the user left open in ``cfg`` (in place) and say so in a note."""
    if not applies(str(cfg.get("task")), cfg.get("robot"), cfg.get("data"), cfg.get("estimator")):
        return
    typed = [override for override in overrides if override not in _PRESELECTED]
    given = {override.key_or_group for override in OverridesParser.create().parse_overrides(typed)}
    options = chosen(given, searches_cost(cfg.get("estimator")))
    if not options:
        return
    with open_dict(cfg):
        for key, value in options.items():
            if key == "estimator":
                if cfg.estimator.get("_name_") != value:  # preselected: keep the options typed for it
                    cfg.estimator = plugin_node("estimator", value)
            elif key == "cost":
                cfg.cost = None
            else:
                OmegaConf.update(cfg, key, value, force_add=False)
    warnings.warn(describe(options), RealRobotNote, stacklevel=2)
