"""Turn a plugin *spec* — a registry name, a config mapping or a ready object — into an object.

The same spec works on the command line (a Hydra node ``{_name_: pso, particles: 40}``) and in
Python (``"pso"``, ``{"_name_": "pso", "particles": 40}`` or ``ParticleSwarm(particles=40)``). A
plugin's options are its constructor's keyword arguments (:func:`constructor_options`), so a config
node maps one-to-one onto a constructor call. Import-light (no torch): the command line's config
source uses it to list options.
"""

from __future__ import annotations

import enum
import inspect
from collections.abc import Mapping
from typing import Any

from idkit import registry
from idkit.registry import MISSING, NAME_KEY

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


def name_and_options(kind: registry.Kind, spec: Spec) -> tuple[str | None, dict[str, Any]]:
    """``(registry name, options)`` of a name or mapping spec; ``(None, {})`` for a ready object."""
    spec = plain(spec)
    if isinstance(spec, str):
        return spec, {}
    if isinstance(spec, Mapping):
        return split(kind, spec)
    return None, {}


def build(kind: registry.Kind, spec: Spec | None) -> Any:
    """Build a plugin from a spec; ``None`` stays ``None`` (e.g. no cost for least squares).

    A ready object is held to the plugin contract as a registered plugin is
    (:func:`idkit.registry.conform_instance`): one that does not subclass the interface gets its
    defaults (a cost without ``structure()``), one lacking a required member is refused naming it.
    """
    if spec is None:
        return None
    name, options = name_and_options(kind, spec)
    if name is None:
        cls = type(spec)
        return registry.conform_instance(kind, spec, f"{kind} object {cls.__qualname__} ({cls.__module__})")
    return registry.create(kind, name, **options)


def describe(kind: registry.Kind, spec: Spec | None) -> dict[str, Any] | None:
    """Where a plugin comes from: its name, options, entry point, distribution and version."""
    if spec is None:
        return None
    name, options = name_and_options(kind, spec)
    if name is not None:
        meta = registry.info(kind, name)
        return {
            "name": name,
            "options": options,
            "entry_point": meta.value,
            "distribution": meta.distribution,
            "version": meta.version,
        }
    cls = type(spec)
    return {
        "name": None,
        "options": None,
        "entry_point": f"{cls.__module__}:{cls.__qualname__}",
        "distribution": None,
        "version": None,
    }


def _config_value(value: Any) -> tuple[bool, Any]:
    """``(True, value)`` if a default can live in a YAML/OmegaConf node, else ``(False, None)``."""
    if value is None or isinstance(value, (bool, int, float, str, enum.Enum)):
        return True, value
    if isinstance(value, (list, tuple)):
        items = [_config_value(v) for v in value]
        return all(ok for ok, _ in items), [v for _, v in items]
    if isinstance(value, Mapping):
        entries = {k: _config_value(v) for k, v in value.items()}
        ok = all(isinstance(k, str) and good for k, (good, _) in entries.items())
        return ok, {k: v for k, (_, v) in entries.items()}
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
