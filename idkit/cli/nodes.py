"""Config nodes derived from a plugin's constructor signature ("plugins are configs").

A plugin's hyperparameters are the keyword arguments of its constructor (the plugin contract), so
its config node is ``{_name_: <registry name>, <argument>: <default>, ...}``; overriding
``estimator.particles=40`` then maps one-to-one onto ``ParticleSwarm(particles=40)``. Third-party
plugins get the same treatment without writing YAML.
"""

from __future__ import annotations

from typing import Any

from idkit import registry
from idkit.registry import NAME_KEY
from idkit.studies.build import constructor_options


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
