"""The one writer of ``result.json``: the common envelope plus the task's payload, atomically.

Every task's report calls :func:`claim` before it writes anything and :func:`write_result` last, so
a folder never ends up holding a mix of two runs' files: a folder whose ``result.json`` belongs to
another run (another ``run_id``) is refused before a single file is replaced. The same result saved
twice (or a study's checkpoints) replaces its own files. The identified model files go through
:func:`write_result` too: written beside their place first, renamed into it only once ``result.json``
is, so a failure (a full disk, Ctrl-C) never leaves a model without the result that describes it.
"""

from __future__ import annotations

import datetime as _dt
import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import idkit
from idkit.reports import files
from idkit.studies.result import Provenance

RESULT_FILE = "result.json"
#: The run's self-contained page (``idkit.reports.html``), written just before ``result.json``.
REPORT_FILE = "report.html"

#: Renders the page of a run from its ``result.json`` document.
Page = Callable[[dict[str, Any]], str]


def claim(out_dir: str | Path, provenance: Provenance) -> Path:
    """Check that ``out_dir`` is empty of other runs' results; returns it as a ``Path``.

    Raises:
        FileExistsError: ``out_dir/result.json`` belongs to another run.
        idkit.reports.files.FolderError: ``out_dir`` is a file or cannot be written.
    """
    out = Path(out_dir)
    existing = out / RESULT_FILE
    if existing.is_file():
        try:
            other = json.loads(existing.read_text()).get("run_id")
        except (ValueError, AttributeError):
            other = None
        if other != provenance.run_id:
            raise FileExistsError(
                f"{out} already holds the result of another run ({existing}); save into an empty "
                "folder (its files would otherwise mix with this run's)"
            )
    return files.writable_folder(out, "out_dir")


def document(provenance: Provenance, payload: dict[str, Any], written: dict[str, str]) -> dict[str, Any]:
    """The ``result.json`` content: envelope, version, creation time, files and payload."""
    return {
        **provenance.envelope(),
        "idkit_version": idkit.__version__,
        "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "files": written,
        "payload": payload,
    }


def write_result(
    out_dir: str | Path,
    provenance: Provenance,
    payload: dict[str, Any],
    written: dict[str, str],
    page: Page | None = None,
    models: Mapping[str, tuple[str, str]] | None = None,
) -> dict[str, str]:
    """Write ``result.json`` into ``out_dir`` (after :func:`claim`), and first, with ``page``, the
    run's ``report.html`` made from the same document; returns ``written`` + their paths.

    Args:
        models: ``{key: (file name, text)}`` of model files (``identified.urdf``): staged before,
            put in place after ``result.json`` (module doc); listed in ``written`` under ``key``.
    """
    out = claim(out_dir, provenance)
    path = out / RESULT_FILE
    staged: dict[str, files.Staged] = {}
    try:
        for key, (name, text) in (models or {}).items():
            staged[key] = files.stage_text(out / name, text)
        written = {
            **written,
            **{key: str(model.path) for key, model in staged.items()},
            **({"report": str(out / REPORT_FILE)} if page is not None else {}),
            "result": str(path),
        }
        content = document(provenance, payload, written)
        if page is not None:
            files.write_text(out / REPORT_FILE, page(content))
        files.write_json(path, content)
    except BaseException:
        for model in staged.values():
            model.discard()
        raise
    for model in staged.values():
        model.commit()
    return written
