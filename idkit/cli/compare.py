"""``idkit compare RUN_A RUN_B [--out FILE]``: one self-contained page setting two runs side by side.

Each run is its folder (or its ``result.json``); the page (:mod:`idkit.reports.compare`) is written
atomically to ``--out`` (default ``compare-<run A>-<run B>.html`` in the current folder). A folder
without a readable ``result.json`` is refused in one line, with exit status 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from idkit.reports.result_file import RESULT_FILE

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
    return document


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
        out = Path(args.out or f"compare-{a.get('run_id')}-{b.get('run_id')}.html")
        written = files.write_text(out, compare.render(a, b, (args.run_a, args.run_b)))
    except (ValueError, OSError) as exc:
        print(f"idkit: compare: {exc}", file=sys.stderr)
        return UNUSABLE
    print(f"compare page: {written}")
    return 0
