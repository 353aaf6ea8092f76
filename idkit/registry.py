"""Plugin registry on ``importlib.metadata`` entry points.

Every robot, estimator, cost and excitation — the built-ins included — is found through one
entry-point group per interface, so a third-party distribution adds plugins by being installed and
nothing else.
Listing names reads installed metadata only (no plugin module is imported); loading is lazy and
cached, and a plugin that fails to import is reported without breaking the others.
"""

from __future__ import annotations

import difflib
import functools
import re
from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points
from typing import Any, Literal

from idkit.options import OptionError as OptionError  # re-exported: registry.create raises it
from idkit.options import check_options

Kind = Literal["robot", "estimator", "cost", "excitation"]

#: Key naming the plugin in a config mapping: ``{"_name_": "pso", "particles": 40}``. Shared by the
#: command line's config nodes and the library's builders, so it lives below both.
NAME_KEY = "_name_"
#: OmegaConf's mandatory-value marker: a constructor argument without a default, to be given.
MISSING = "???"

GROUPS: dict[str, str] = {
    "robot": "idkit.robots",
    "estimator": "idkit.estimators",
    "cost": "idkit.costs",
    "excitation": "idkit.excitations",
}


class PluginError(Exception):
    """Base class of the registry's errors."""


class UnknownPluginError(PluginError, LookupError):
    """No installed distribution provides the requested name."""


class DuplicatePluginError(PluginError):
    """Two installed distributions register the same name in one group."""


class PluginLoadError(PluginError, ImportError):
    """The entry point exists but importing the object behind it failed."""


@dataclass(frozen=True)
class PluginInfo:
    """What the metadata says about one plugin, without importing it."""

    kind: str
    name: str
    value: str
    distribution: str
    version: str


def _group(kind: str) -> str:
    try:
        return GROUPS[kind]
    except KeyError:
        raise UnknownPluginError(
            f"unknown plugin kind {kind!r}; the kinds are {', '.join(GROUPS)}"
        ) from None


def _distribution(ep: EntryPoint) -> tuple[str, str]:
    dist = ep.dist
    if dist is None:
        return "<unknown>", "<unknown>"
    return dist.metadata["Name"], dist.version


@functools.cache
def _entry_points(kind: str) -> dict[str, tuple[EntryPoint, PluginInfo]]:
    """Name → entry point for one group; the same name from two distributions is an error."""
    found: dict[str, tuple[EntryPoint, PluginInfo]] = {}
    for ep in entry_points(group=_group(kind)):
        dist, version = _distribution(ep)
        info = PluginInfo(kind, ep.name, ep.value, dist, version)
        if ep.name in found:
            other = found[ep.name][1]
            if (other.distribution, other.value) == (dist, ep.value):
                continue  # one distribution seen twice on sys.path (e.g. editable + site)
            raise DuplicatePluginError(
                f"{kind} {ep.name!r} is registered twice in entry-point group {_group(kind)!r}: "
                f"by {other.distribution} {other.version} ({other.value}) and by "
                f"{dist} {version} ({ep.value}); uninstall one of them"
            )
        found[ep.name] = (ep, info)
    return found


def _natural(name: str) -> list[object]:
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", name)]


def available(kind: Kind) -> list[str]:
    """Names of the installed plugins of one kind, naturally sorted (f2 before f10); imports nothing."""
    return sorted(_entry_points(kind), key=_natural)


def info(kind: Kind, name: str) -> PluginInfo:
    """Metadata of one plugin: entry point value, distribution and its version."""
    return _lookup(kind, name)[1]


def _lookup(kind: str, name: str) -> tuple[EntryPoint, PluginInfo]:
    eps = _entry_points(kind)
    if name not in eps:
        raise UnknownPluginError(unknown_name_message(kind, name, list(eps)))
    return eps[name]


def unknown_name_message(kind: str, name: object, names: list[str]) -> str:
    """One line: the unknown name and the available ones, closest first (for the registry and CLI)."""
    close = difflib.get_close_matches(str(name), sorted(names, key=_natural), n=len(names), cutoff=0.0)
    listed = ", ".join(close) if close else "none installed"
    return f"unknown {kind} {name!r}; available {kind}s (closest first): {listed}"


@functools.cache
def load(kind: Kind, name: str) -> Any:
    """Import and return the object (class or factory) behind a plugin name; cached."""
    ep, meta = _lookup(kind, name)
    try:
        return ep.load()
    except Exception as exc:  # any import-time failure of third-party code
        raise PluginLoadError(
            f"{kind} plugin {name!r} (entry point {meta.value!r} in group {_group(kind)!r}, "
            f"distribution {meta.distribution} {meta.version}) failed to load: "
            f"{type(exc).__name__}: {exc}"
        ) from exc


def create(kind: Kind, name: str, /, **options: Any) -> Any:
    """Build a plugin instance; ``options`` are its constructor's keyword arguments.

    The options are checked against the constructor's signature and annotations first
    (``idkit.options``: unknown keys and wrong types raise ``OptionError``; strings that spell a
    value of the annotated type, as a command line passes them, are converted).
    """
    factory = load(kind, name)
    checked = check_options(kind, name, factory, options)
    try:
        return factory(**checked)
    except TypeError as exc:
        raise TypeError(f"{kind} {name!r} rejected options {checked}: {exc}") from exc


def refresh() -> None:
    """Forget cached metadata and imports, e.g. after installing a distribution at run time."""
    _entry_points.cache_clear()
    load.cache_clear()
