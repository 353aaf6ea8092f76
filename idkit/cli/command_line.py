"""The command line's words before Hydra reads them: flags anywhere, refusals in one line.

Hydra parses ``sys.argv`` with :mod:`argparse`, which prints its usage block (eight lines) for a
mistyped flag and cannot take overrides after a flag that follows overrides (``idkit estimator=ls
-m seed=1,2`` fails with "unrecognized arguments"). :func:`arrange` parses the words with Hydra's
own parser first, interleaved, and hands Hydra the same words as overrides first and flags after;
a mistake is a :class:`UsageError` the command prints as one line. A bare word where an override
belongs (``idkit paper``) is refused with the override it most likely meant (``+experiment=paper``).
"""

from __future__ import annotations

import difflib
from collections.abc import Iterator
from typing import NoReturn

from idkit import registry

#: Flags idkit answers itself: Hydra would print its own version.
VERSION_FLAG = "--version"


class UsageError(ValueError):
    """The words of the command line cannot be read; the message says which and why."""


def arrange(words: list[str]) -> list[str]:
    """``words`` (``sys.argv[1:]``) as Hydra reads them best: the overrides, then the flags.

    Raises:
        UsageError: a flag Hydra does not know or with a wrong value, or a bare word that is not
            an override.
    """
    from hydra._internal.utils import get_args_parser

    parser = get_args_parser()
    parser.error = _refuse  # type: ignore[method-assign]  # argparse prints usage and exits
    overrides = list(parser.parse_intermixed_args(words).overrides)
    for word in overrides:
        if _bare(word):
            raise UsageError(bare_word_message(word))
    flags, pending = [], list(overrides)
    for word in words:
        if pending and word == pending[0]:
            pending.pop(0)
        else:
            flags.append(word)
    return overrides + flags


def _refuse(message: str) -> NoReturn:
    raise UsageError(f"{message} (see idkit --help)")


def _bare(word: str) -> bool:
    """A word that is no override: no ``=``, and not a deletion (``~seed``)."""
    return "=" not in word and not word.startswith("~")


def group_choices() -> Iterator[tuple[str, str]]:
    """``(override, name)`` for every option of the groups a bare word may mean, and two flags."""
    from importlib.resources import files

    from idkit.cli.source import PLUGIN_GROUPS, SCENARIO_GROUP, group_options

    experiments = files("idkit.conf").joinpath("experiment")
    for entry in sorted(experiments.iterdir(), key=lambda e: e.name):
        if entry.name.endswith(".yaml"):
            name = entry.name.removesuffix(".yaml")
            yield f"+experiment={name}", name
    for name in group_options(SCENARIO_GROUP):
        yield f"+{SCENARIO_GROUP}={name}", name
    for group in PLUGIN_GROUPS:
        for name in registry.available(group):
            yield f"{group}={name}", name
    yield "--help", "help"
    yield VERSION_FLAG, "version"


def bare_word_message(word: str) -> str:
    """``'paper' is not an override (key=value); did you mean +experiment=paper?``."""
    choices = list(group_choices())
    meant = [override for override, name in choices if name == word]
    if not meant:
        close = set(difflib.get_close_matches(word, [name for _, name in choices], n=3, cutoff=0.75))
        meant = [override for override, name in choices if name in close]
    if meant:
        return f"{word!r} is not an override (key=value); did you mean {' or '.join(meant)}?"
    return (
        f"{word!r} is not an override: write key=value (seed=1), group=option (estimator=ls), "
        "+group=option (+experiment=paper) or ~key (see idkit --help)"
    )
