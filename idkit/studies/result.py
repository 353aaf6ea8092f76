"""The envelope every study result carries, and the interruption that keeps a partial result.

Every task writes one ``result.json`` with the same top-level keys (see ``docs/studies.md``)::

    task, label, status, progress {done, requested, unit}, seed, data, plugins, config,
    run_id, idkit_version, created, files, payload

``payload`` is the task's own content (``single``: one estimate and its errors; ``paper``: the
tables; ``robustness``: the summary rows; ``kuka``: the held-out scores). A study fills the
envelope's facts in :class:`Provenance`; ``idkit.reports.result_file`` writes the document.
"""

from __future__ import annotations

import uuid
from dataclasses import dataclass, field
from typing import Any

COMPLETE = "complete"
PARTIAL = "partial"


def new_run_id() -> str:
    """Twelve hex digits naming one result's files."""
    return uuid.uuid4().hex[:12]


@dataclass
class Provenance:
    """What ran, on which data, with which plugins — and how much of it finished.

    Attributes:
        task: ``"single"``, ``"paper"``, ``"robustness"``, ``"kuka"``, ...
        label: what the result is called in tables (an estimator label or the task name).
        seed: seed of every random draw.
        data: where the samples came from (``{"scenario": {...}}``, ``{"file": path}``, ...).
        plugins: per role, ``build.describe`` of the plugin (name, options, entry point, version).
        requested: units of work asked for (trials, tables, model variants; 1 for a single fit).
        done: units finished; ``done < requested`` marks a partial (interrupted) result.
        unit: what a unit is, e.g. ``"trial"``.
        config: the resolved command-line config, set by the command line (``None`` from Python).
        run_id: identifies this result's files: a folder holding another ``run_id`` is refused.
    """

    task: str
    label: str
    seed: int
    data: dict[str, Any] | None
    plugins: dict[str, Any]
    requested: int = 1
    done: int = 1
    unit: str = "fit"
    config: dict[str, Any] | None = None
    run_id: str = field(default_factory=new_run_id)

    @property
    def status(self) -> str:
        return COMPLETE if self.done >= self.requested else PARTIAL

    def envelope(self) -> dict[str, Any]:
        """The common ``result.json`` keys (without ``files``, ``created`` and ``payload``)."""
        return {
            "task": self.task,
            "label": self.label,
            "status": self.status,
            "progress": {"done": self.done, "requested": self.requested, "unit": self.unit},
            "seed": self.seed,
            "data": self.data,
            "plugins": self.plugins,
            "config": self.config,
            "run_id": self.run_id,
        }


class StudyInterrupted(KeyboardInterrupt):
    """Ctrl-C during a study: carries the result of the work done so far (``partial``).

    A ``KeyboardInterrupt``, so code that does not know it still stops; the command line writes the
    partial result (its ``status`` is ``"partial"``) and says where in one line.
    """

    def __init__(self, partial: Any) -> None:
        super().__init__(f"interrupted after {partial.provenance.done} of {partial.provenance.requested}")
        self.partial = partial
