"""Config nodes derived from a plugin's constructor signature ("plugins are configs").

A plugin's hyperparameters are the keyword arguments of its constructor (the plugin contract), so
its config node is ``{_name_: <registry name>, <argument>: <default>, ...}``; overriding
``estimator.particles=40`` then maps one-to-one onto ``ParticleSwarm(particles=40)``. Third-party
plugins get the same treatment without writing YAML.
"""

from __future__ import annotations

import enum
import inspect
from collections.abc import Mapping
from typing import Any

from idkit import registry

NAME_KEY = "_name_"
MISSING = "???"  # OmegaConf's mandatory-value marker: a constructor argument without a default


def _config_value(value: Any) -> tuple[bool, Any]:
    """``(True, value)`` if a default can live in a YAML/OmegaConf node, else ``(False, None)``."""
    if value is None or isinstance(value, (bool, int, float, str, enum.Enum)):
        return True, value
    if isinstance(value, (list, tuple)):
        items = [_config_value(v) for v in value]
        return all(ok for ok, _ in items), [v for _, v in items]
    if isinstance(value, Mapping):
        items = {k: _config_value(v) for k, v in value.items()}
        ok = all(isinstance(k, str) and good for k, (good, _) in items.items())
        return ok, {k: v for k, (_, v) in items.items()}
    return False, None


def constructor_options(factory: Any) -> dict[str, Any]:
    """Keyword arguments of ``factory`` with their defaults (``"???"`` where there is none).

    Arguments whose default cannot be written in a config (a tensor, a callable) are left out: the
    plugin keeps its default and the option is simply not overridable from the command line.
    """
    try:
        signature = inspect.signature(factory)
    except (TypeError, ValueError):  # builtins without a signature
        return {}
    options: dict[str, Any] = {}
    for name, param in signature.parameters.items():
        if param.kind in (param.VAR_POSITIONAL, param.VAR_KEYWORD, param.POSITIONAL_ONLY):
            continue
        if name.startswith("_"):
            continue
        if param.default is inspect.Parameter.empty:
            options[name] = MISSING
            continue
        ok, value = _config_value(param.default)
        if ok:
            options[name] = value
    return options


def plugin_node(kind: registry.Kind, name: str, *, names_only: bool = False) -> dict[str, Any]:
    """The config node of one registered plugin.

    Args:
        kind: ``"robot"``, ``"estimator"`` or ``"cost"``.
        name: the plugin's registry name.
        names_only: skip the signature (no plugin import). Used for ``--help`` so that listing
            the groups never imports torch.
    """
    node: dict[str, Any] = {NAME_KEY: name}
    if not names_only:
        node.update(constructor_options(registry.load(kind, name)))
    return node
