"""What the command line prints when the input is wrong: one line naming the cause, exit status 1.

Hydra reports a config it cannot compose in many lines (an unknown ``cost=f133`` lists every cost
sorted f1, f10, f11 … and then the config search path; an option typo prints the OmegaConf node).
:func:`one_line` turns those errors, and idkit's own (:data:`USER_ERRORS`, raised by a study or a
plugin), into one line: the unknown name or key and the valid ones, closest first. Anything else is
a bug and keeps its traceback; ``HYDRA_FULL_ERROR=1`` shows the traceback of every error.
"""

from __future__ import annotations

import re
import sys
from importlib.resources import files
from importlib.resources.abc import Traversable
from typing import NoReturn

from hydra.errors import (
    CompactHydraException,
    ConfigCompositionException,
    MissingConfigException,
    OverrideParseException,
)
from omegaconf.errors import ConfigAttributeError, ConfigKeyError

from idkit import registry
from idkit.cli.output import single_line
from idkit.options import closest_first
from idkit.registry import NAME_KEY
from idkit.reports.files import WriteError

#: Errors caused by what the user asked for (a study's or plugin's refusal of its input), or by the
#: place the results go (a full disk: :class:`idkit.reports.files.WriteError`, naming the file).
USER_ERRORS = (
    registry.PluginError,
    ValueError,
    TypeError,
    FileNotFoundError,
    FileExistsError,
    LookupError,
    WriteError,
)

#: Config groups whose options are named like the group (``robot`` → "available robots").
NAMED_GROUPS = ("robot", "estimator", "cost", "scenario", "experiment")

#: Exit status of a refused input.
USAGE = 1

PREFIX = "idkit: "


def fail(message: str) -> NoReturn:
    """Print ``idkit: <message>`` (on one line) on stderr and exit with :data:`USAGE`."""
    message = single_line(message)
    print(message if message.startswith(PREFIX) else PREFIX + message, file=sys.stderr)
    sys.exit(USAGE)


def unknown_key_message(error: ConfigAttributeError | ConfigKeyError) -> str:
    """``estimator 'pso' has no option 'particls'; its options (closest first): particles, …``.

    ``error`` is OmegaConf's refusal of a key a struct node does not have (``parent_node`` is that
    node, ``full_key`` the dotted key the user typed).
    """
    key, node, full_key = str(error.key), error.parent_node, str(error.full_key)
    valid = [str(k) for k in node if k not in (NAME_KEY, "hydra")] if node is not None else []
    listed = ", ".join(closest_first(key, valid)) or "none"
    section = full_key.rpartition(".")[0]
    if not section:
        return f"there is no setting {key!r}; the settings (closest first): {listed}"
    if node is not None and NAME_KEY in node:
        return f"{section} {node[NAME_KEY]!r} has no option {key!r}; its options (closest first): {listed}"
    return f"{section} has no key {key!r}; its keys (closest first): {listed}"


def one_line(exc: BaseException) -> str | None:
    """The one-line message for a refused input, or ``None`` for an error that is not one (a bug).

    Covers Hydra's unknown config name (``MissingConfigException``), an override of a key the
    config does not have (``ConfigCompositionException`` caused by OmegaConf's struct check), an
    override Hydra cannot parse (``OverrideParseException``), any other compact Hydra error, a
    bad override value Hydra refuses with a ``ValueError`` (``cost=null`` for a group),
    :data:`USER_ERRORS`, and running out of memory (:func:`out_of_memory_message`).
    """
    if isinstance(exc, MissingConfigException) and exc.missing_cfg_file and exc.options:
        group, _, name = exc.missing_cfg_file.rpartition("/")
        if group in NAMED_GROUPS:
            return registry.unknown_name_message(group, name, list(exc.options))
        listed = ", ".join(closest_first(name, list(exc.options)))
        return f"unknown {group or 'config'} option {name!r}; the options (closest first): {listed}"
    cause = exc.__cause__
    if isinstance(exc, ConfigCompositionException) and isinstance(
        cause, (ConfigAttributeError, ConfigKeyError)
    ):
        return unknown_key_message(cause)
    if isinstance(exc, OverrideParseException):  # its message does not say which override
        return f"cannot read {exc.override!r}: {str(exc).splitlines()[0]} (see `idkit --hydra-help`)"
    if isinstance(exc, (CompactHydraException, *USER_ERRORS)):
        return single_line(str(exc))
    return out_of_memory_message(exc)


#: Size options, named when memory runs out.
SIZES = "estimator.particles, estimator.iterations, estimator.runs, n_samples, trials"


def out_of_memory_message(exc: BaseException) -> str | None:
    """One line for a run that asked for more memory than there is, else ``None``.

    Python's ``MemoryError``, torch's ``OutOfMemoryError`` (CUDA) and its CPU allocator's
    ``RuntimeError`` ("can't allocate memory") all come from sizes the user chose.
    """
    text = str(exc)
    if not (
        isinstance(exc, MemoryError)
        or type(exc).__name__ == "OutOfMemoryError"
        or "can't allocate memory" in text
    ):
        return None
    start = text.find("can't allocate memory")  # after torch's C++ source location
    said = text[start:] if start > 0 else text
    return f"out of memory: {single_line(said)}; smaller sizes need less ({SIZES})"


def required_message(keys: list[str]) -> str | None:
    """``rollout.model is required: the MJCF (.xml) or URDF (.urdf) file; give rollout.model=…`` for
    the first of ``keys`` (dotted settings still ``???``), or ``None`` for none.

    The description is the comment beside the ``???`` in idkit's config files, so it is written once.
    """
    if not keys:
        return None
    key = keys[0]
    leaf = re.escape(key.rpartition(".")[2])
    pattern = re.compile(rf"^\s*{leaf}:\s*\?\?\?\s*#\s*(.+?)\s*$", re.MULTILINE)
    described = next((m[1] for text in _config_texts() if (m := pattern.search(text))), None)
    more = f" (and {', '.join(keys[1:])})" if len(keys) > 1 else ""
    what = f": {described}" if described else " (it has no default)"
    return f"{key} is required{what}; give {key}=…{more}"


def _config_texts() -> list[str]:
    """The text of every config file idkit ships (``idkit.conf``, wherever the install put it: a
    checkout's editable install maps it to the top-level ``conf/``), in a fixed order."""

    found: list[str] = []

    def walk(folder: Traversable) -> None:
        for entry in sorted(folder.iterdir(), key=lambda e: e.name):
            if entry.is_dir():
                walk(entry)
            elif entry.name.endswith(".yaml"):
                found.append(entry.read_text(encoding="utf-8"))

    walk(files("idkit.conf"))
    return found
