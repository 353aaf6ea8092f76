"""``idkit compare RUN_A RUN_B [--out FILE]``: one self-contained page setting two runs side by side.

Each run is its folder (or its ``result.json``); the page (:mod:`idkit.reports.compare`) is written
atomically to ``--out`` (default ``compare-<run A>-<run B>.html`` in the current folder, the run ids
made safe file-name parts by :func:`idkit.untrusted.safe_basename`: a result folder is something people
send each other, and its ``run_id`` never chooses where a file goes). A folder without a readable
``result.json``, or with one whose content is not a result idkit wrote, is refused in one line, with
exit status 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

from idkit.cli.output import debugging, single_line
from idkit.reports.result_file import RESULT_FILE
from idkit.untrusted import safe_basename

#: Exit status of an input that cannot be compared.
UNUSABLE = 2


def read_run(place: str) -> dict[str, Any]:
    """The ``result.json`` document of a run folder (or of the file itself).

    Raises:
        ValueError: no such file, not JSON, or not a result of idkit (no ``task`` and ``payload``).
    """
    path = Path(place)
    path = path / RESULT_FILE if path.is_dir() else path
    try:
        document = json.loads(path.read_text())
    except FileNotFoundError:
        raise ValueError(f"{place}: no {RESULT_FILE} (give a run folder or its {RESULT_FILE})") from None
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: not a readable {RESULT_FILE} ({exc})") from None
    if not isinstance(document, dict) or "task" not in document or "payload" not in document:
        raise ValueError(f"{path}: not an idkit {RESULT_FILE} (no task and payload)")
    _check_layout(document, path)
    return document


#: A JSON object, or ``null``.
_OBJECT_OR_NULL = (dict, type(None))
#: What each task's compare section reads from ``payload``: key → the JSON type it must have.
_READ: dict[str, dict[str, type | tuple[type, ...]]] = {
    "single": {"estimate": dict, "validation": _OBJECT_OR_NULL},
    "excitation": {"criterion": str, "check": dict},
}
#: Within a single fit's ``payload.estimate``.
_ESTIMATE = dict.fromkeys(("params", "base_params", "details"), _OBJECT_OR_NULL)


def _check_layout(document: dict[str, Any], path: Path) -> None:
    """Refuse, naming the key, a ``result.json`` whose parts the page reads have another JSON type
    (a damaged or hand-edited file: ``"payload": null``, an estimate that is a list)."""

    def refuse(key: str, value: Any, wanted: str) -> NoReturn:
        raise ValueError(f"{path}: {key} is {_json_type(value)}, expected {wanted}: not a result idkit wrote")

    payload = document["payload"]
    if not isinstance(payload, dict):
        refuse("payload", payload, "an object")
    for key, kind in _READ.get(str(document["task"]), {}).items():
        if not isinstance(payload.get(key), kind):
            refuse(f"payload.{key}", payload.get(key), _wanted(kind))
    if document["task"] == "single":
        for key, kind in _ESTIMATE.items():
            if not isinstance(payload["estimate"].get(key), kind):
                refuse(f"payload.estimate.{key}", payload["estimate"].get(key), _wanted(kind))


def _json_type(value: Any) -> str:
    names = {dict: "an object", list: "a list", str: "text", bool: "true/false", type(None): "null"}
    return names.get(type(value), "a number")


def _wanted(kind: type | tuple[type, ...]) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    return " or ".join(_json_type(k()) for k in kinds)


def default_page(a: dict[str, Any], b: dict[str, Any]) -> Path:
    """``compare-<run A>-<run B>.html`` in the current folder, whatever the run ids hold."""
    return Path(f"compare-{safe_basename(a.get('run_id'), 'A')}-{safe_basename(b.get('run_id'), 'B')}.html")


def main(argv: Sequence[str]) -> int:
    """The command (module doc); returns the exit status."""
    from idkit.reports import compare, files

    parser = argparse.ArgumentParser(prog="idkit compare", description=__doc__.splitlines()[0].split(": ")[1])
    parser.add_argument("run_a", metavar="RUN_A", help="run folder (or its result.json)")
    parser.add_argument("run_b", metavar="RUN_B", help="run folder (or its result.json)")
    parser.add_argument("--out", help="the page to write (default: compare-<run A>-<run B>.html here)")
    args = parser.parse_args(list(argv))
    try:
        a, b = read_run(args.run_a), read_run(args.run_b)
        out = Path(args.out) if args.out else default_page(a, b)
        try:
            page = compare.render(a, b, (args.run_a, args.run_b))
        except (KeyError, TypeError, AttributeError, IndexError) as exc:
            if debugging():
                raise
            # a value of another type deeper than _check_layout looks (a parameter that is text)
            raise ValueError(
                f"{args.run_a}, {args.run_b}: a {RESULT_FILE} idkit cannot read "
                f"({type(exc).__name__}: {exc}); written by another version, or edited?"
            ) from None
        written = files.write_text(out, page)
    except (ValueError, OSError) as exc:
        print(f"idkit: compare: {single_line(str(exc))}", file=sys.stderr)
        return UNUSABLE
    print(f"compare page: {written}")
    return 0
