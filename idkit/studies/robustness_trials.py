"""The robustness study's per-trial CSV (``robustness_trials.csv``): its format, both ways, here only.

One row per scenario, estimate and trial: ``scenario, trial, estimator, <each parameter>, error``
(the trial's index in the whole study, so a shard's rows carry their own numbers; ``error`` the
parameter error of ``idkit.studies.metrics``). ``idkit.reports.robustness`` writes the rows
:func:`table` renders (atomically, with the other report files); ``idkit.studies.robustness.load``
reads them back through :func:`read`, which finds every column by its name in the header and
refuses, naming the file and what is wrong, a file that lacks a column or whose trials are not the
ones its ``result.json`` says were done.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from idkit.untrusted import csv_text

if TYPE_CHECKING:
    from idkit.studies.robustness import RobustnessStudy

#: The file's name in a run directory.
FILE = "robustness_trials.csv"
#: The columns before the parameters, and the one after them.
KEYS = ("scenario", "trial", "estimator")
ERROR = "error"


def header(param_names: list[str]) -> list[str]:
    """The CSV's header for a robot with parameters ``param_names``."""
    return [*KEYS, *param_names, ERROR]


def table(study: RobustnessStudy) -> tuple[list[str], list[list[Any]]]:
    """The header and rows of ``study``'s per-trial CSV: scenario by scenario, estimate by estimate,
    trial by trial, in the study's order."""
    rows: list[list[Any]] = []
    for scenario, by_label in study.params.items():
        for label, values in by_label.items():
            errors = study.errors(scenario, label).tolist()
            trials = range(study.first_trial, study.first_trial + len(values))
            rows += [
                [scenario, trial, label, *row, error]
                for trial, row, error in zip(trials, values.tolist(), errors, strict=True)
            ]
    return header(study.param_names), rows


def read(path: str | Path, param_names: list[str], trials: range) -> dict[str, dict[str, np.ndarray]]:
    """Per scenario and estimate, the parameters ``[T, P]`` of a study's trials ``trials``, in the
    order of ``param_names``, read from its per-trial CSV at ``path``.

    Raises:
        ValueError: a column is missing, a value is not a number, or an estimate's trials are not
            ``trials`` in order (a file edited by hand, or not this run's).
    """
    path = Path(path)
    with open(path, newline="") as handle:
        reader = csv.reader(handle)
        columns = [csv_text(cell) for cell in next(reader, [])]  # names as written, escapes undone
        missing = [name for name in header(param_names) if name not in columns]
        if missing:
            raise ValueError(f"{path}: no column {', '.join(map(repr, missing))} in its header")
        scenario, trial, estimator = (columns.index(key) for key in KEYS)
        wanted = [columns.index(name) for name in param_names]
        found: dict[str, dict[str, list[list[float]]]] = {}
        numbers: dict[tuple[str, str], list[int]] = {}
        for line, row in enumerate(reader, start=2):
            if len(row) != len(columns):
                raise ValueError(f"{path}, line {line}: {len(row)} values for {len(columns)} columns")
            try:
                values = [float(row[i]) for i in wanted]
                index = int(row[trial])
            except ValueError as error:
                raise ValueError(f"{path}, line {line}: {error}") from None
            name, label = csv_text(row[scenario]), csv_text(row[estimator])
            found.setdefault(name, {}).setdefault(label, []).append(values)
            numbers.setdefault((name, label), []).append(index)
    for (name, label), indices in numbers.items():
        if indices != list(trials):
            raise ValueError(
                f"{path}: {name} / {label} has trials {_span(indices)}; its result.json says "
                f"{_span(list(trials))} were done"
            )
    width = len(param_names)
    return {
        name: {label: np.asarray(rows, dtype=float).reshape(-1, width) for label, rows in by.items()}
        for name, by in found.items()
    }


def _span(indices: list[int]) -> str:
    """``0..2``, ``none`` or ``0, 2, 1`` (not consecutive), for a message."""
    if not indices:
        return "none"
    if indices == list(range(indices[0], indices[0] + len(indices))):
        return f"{indices[0]}..{indices[-1]}"
    shown = ", ".join(map(str, indices[:6]))
    return f"{shown}{', ...' if len(indices) > 6 else ''} (not consecutive)"
