"""Turn a plugin *spec* — a registry name, a config mapping or a ready object — into an object.

The same spec works on the command line (a Hydra node ``{_name_: pso, particles: 40}``) and in
Python (``"pso"``, ``{"_name_": "pso", "particles": 40}`` or ``ParticleSwarm(particles=40)``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from idkit import registry
from idkit.cli.nodes import MISSING, NAME_KEY

Spec = str | Mapping[str, Any] | Any


def plain(spec: Any) -> Any:
    """OmegaConf containers → plain dicts/lists (resolved); anything else unchanged."""
    from omegaconf import DictConfig, ListConfig, OmegaConf

    if isinstance(spec, (DictConfig, ListConfig)):
        return OmegaConf.to_container(spec, resolve=True)
    return spec


def split(kind: registry.Kind, spec: Mapping[str, Any]) -> tuple[str, dict[str, Any]]:
    """``(name, options)`` of a mapping spec; a missing ``_name_`` or ``???`` value is an error."""
    options = dict(plain(spec))
    if NAME_KEY not in options:
        raise ValueError(f"{kind} config {options} has no {NAME_KEY!r} key naming the plugin")
    name = options.pop(NAME_KEY)
    missing = [key for key, value in options.items() if value == MISSING]
    if missing:
        raise ValueError(
            f"{kind} {name!r} needs a value for {', '.join(missing)} (e.g. {kind}.{missing[0]}=...)"
        )
    return name, options


def build(kind: registry.Kind, spec: Spec | None) -> Any:
    """Build a plugin from a spec; ``None`` stays ``None`` (e.g. no cost for least squares)."""
    if spec is None:
        return None
    if isinstance(spec, str):
        return registry.create(kind, spec)
    if isinstance(spec, Mapping):
        name, options = split(kind, spec)
        return registry.create(kind, name, **options)
    return spec


def describe(kind: registry.Kind, spec: Spec | None) -> dict[str, Any] | None:
    """Where a plugin comes from: its name, entry point, distribution and version."""
    if spec is None:
        return None
    if isinstance(spec, (str, Mapping)):
        name = spec if isinstance(spec, str) else split(kind, spec)[0]
        meta = registry.info(kind, name)
        return {
            "name": name,
            "entry_point": meta.value,
            "distribution": meta.distribution,
            "version": meta.version,
        }
    cls = type(spec)
    return {
        "name": None,
        "entry_point": f"{cls.__module__}:{cls.__qualname__}",
        "distribution": None,
        "version": None,
    }
