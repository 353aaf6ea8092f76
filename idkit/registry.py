"""Plugin registry on ``importlib.metadata`` entry points.

Every robot, estimator, cost and excitation — the built-ins included — is found through one
entry-point group per interface, so a third-party distribution adds plugins by being installed and
nothing else.
Listing names reads installed metadata only (no plugin module is imported); loading is lazy and
cached, and a plugin that fails to import is reported without breaking the others.

A plugin is held to its interface's contract (``idkit.interfaces``) by what it has, not by its
base class: the *required* members are the interface's abstract methods (checked when the class
is loaded) and its annotated attributes without a default (``Robot.joint_names``, checked on the
instance ``create`` builds); a plugin missing one is refused in one line naming them. Every other
member is *optional*: a class that does not subclass the interface gets the interface's default
(``Cost.structure()`` → ``None``, ``Robot.nominal_params()`` → ``None``, …) by being loaded as a
subclass of both, so estimators never meet a plugin without them.
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


class PluginContractError(PluginError, TypeError):
    """The plugin lacks a member its interface requires (or cannot take the interface's defaults)."""


#: The interface (a class of ``idkit.interfaces``) each kind of plugin implements.
INTERFACES: dict[str, str] = {
    "robot": "Robot",
    "estimator": "Estimator",
    "cost": "Cost",
    "excitation": "Excitation",
}


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
        raise UnknownPluginError(f"unknown plugin kind {kind!r}; the kinds are {', '.join(GROUPS)}") from None


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
    """Import and return the object (class or factory) behind a plugin name; cached.

    A class is checked against its interface's required methods, and one that does not subclass
    the interface is returned as a subclass of both (module docstring).

    Raises:
        PluginLoadError: importing it failed.
        PluginContractError: a required method is missing (all of them named).
    """
    ep, meta = _lookup(kind, name)
    try:
        loaded = ep.load()
    except Exception as exc:  # any import-time failure of third-party code
        raise PluginLoadError(
            f"{_where(kind, name, meta)} failed to load: {type(exc).__name__}: {exc}"
        ) from exc
    return conform(kind, loaded, _where(kind, name, meta)) if isinstance(loaded, type) else loaded


def create(kind: Kind, name: str, /, **options: Any) -> Any:
    """Build a plugin instance; ``options`` are its constructor's keyword arguments.

    The options are checked against the constructor's signature and annotations first
    (``idkit.options``: unknown keys and wrong types raise ``OptionError``; strings that spell a
    value of the annotated type, as a command line passes them, are converted). The instance is
    then checked for the interface's required attributes (``PluginContractError``).
    """
    factory = load(kind, name)
    checked = check_options(kind, name, factory, options)
    try:
        instance = factory(**checked)
    except TypeError as exc:
        raise TypeError(f"{kind} {name!r} rejected options {checked}: {exc}") from exc
    return conform_instance(kind, instance, _where(kind, name, _lookup(kind, name)[1]))


def interface(kind: Kind) -> type:
    """The ``idkit.interfaces`` class plugins of ``kind`` implement (imported on first use)."""
    from idkit import interfaces

    return getattr(interfaces, INTERFACES[kind])


def required_members(kind: Kind) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """``(methods, attributes)`` every plugin of ``kind`` must have; the rest have defaults.

    Read from the interface: its abstract methods, and its annotated attributes without a value.
    """
    base = interface(kind)
    attributes = tuple(k for k in vars(base).get("__annotations__", {}) if not hasattr(base, k))
    abstract: frozenset[str] = getattr(base, "__abstractmethods__", frozenset())  # ABCMeta sets it
    return tuple(sorted(abstract)), attributes


def conform(kind: Kind, cls: type, where: str) -> type:
    """``cls`` if it subclasses the interface, else a subclass of ``cls`` and the interface.

    Raises:
        PluginContractError: ``cls`` lacks a required method (named), or cannot be combined with
            the interface (e.g. a metaclass conflict).
    """
    base = interface(kind)
    missing = [m for m in required_members(kind)[0] if not _implements(cls, m)]
    if missing:
        raise PluginContractError(_missing_message(where, missing, base))
    try:
        return _with_defaults(cls, base)
    except TypeError as exc:
        raise PluginContractError(
            f"{where} cannot take the defaults of idkit.interfaces.{base.__name__} ({exc}); subclass it"
        ) from None


def conform_instance(kind: Kind, instance: Any, where: str) -> Any:
    """``instance`` once it has the interface's required attributes; an instance that is not one
    of the interface (a factory function's result) is first given the defaults, as ``conform``."""
    base = interface(kind)
    if not isinstance(instance, base):
        adapted = conform(kind, type(instance), where)
        try:
            instance.__class__ = adapted
        except TypeError as exc:
            raise PluginContractError(
                f"{where} returned a {type(instance).__name__} that cannot take the defaults of "
                f"idkit.interfaces.{base.__name__} ({exc}); subclass it"
            ) from None
    missing = [a for a in required_members(kind)[1] if not hasattr(instance, a)]
    if missing:
        raise PluginContractError(_missing_message(where, missing, base))
    return instance


def _where(kind: str, name: str, meta: PluginInfo) -> str:
    return (
        f"{kind} plugin {name!r} (entry point {meta.value!r} in group {_group(kind)!r}, "
        f"distribution {meta.distribution} {meta.version})"
    )


def _missing_message(where: str, missing: list[str], base: type) -> str:
    return (
        f"{where} does not define {', '.join(missing)}, required by idkit.interfaces.{base.__name__} "
        "(see the plugin contract)"
    )


def _implements(cls: type, member: str) -> bool:
    """Whether ``cls`` (not ``object``) defines ``member``, other than as an abstract method."""
    for klass in cls.__mro__[:-1]:
        if member in vars(klass):
            return not getattr(vars(klass)[member], "__isabstractmethod__", False)
    return False


@functools.cache
def _with_defaults(cls: type, base: type) -> type:
    """``cls`` itself if it subclasses ``base``, else ``class cls'(cls, base)`` under ``cls``'s names
    (``TypeError`` when the two cannot be combined)."""
    if issubclass(cls, base):
        return cls
    names = {"__module__": cls.__module__, "__qualname__": cls.__qualname__, "__doc__": cls.__doc__}
    return type(base)(cls.__name__, (cls, base), names)


def refresh() -> None:
    """Forget cached metadata and imports, e.g. after installing a distribution at run time."""
    _entry_points.cache_clear()
    load.cache_clear()
