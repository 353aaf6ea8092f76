"""The ``single`` task's report: a text table, ``result.json``, ``history.csv`` and plots."""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from idkit.estimate import HistoryError, history_table
from idkit.reports import files
from idkit.reports import plots as figures
from idkit.reports.result_file import claim, write_result
from idkit.studies.single import RunResult

HISTORY_FILE = "history.csv"


def _source(data: Mapping[str, Any] | None) -> Any:
    data = data or {}
    return data["scenario"].get("name") if "scenario" in data else data.get("file")


def text(result: RunResult) -> str:
    """A compact table: estimate, true value and relative error per parameter, then the cost."""
    est = result.estimate
    rel = result.relative_error or {}
    robot = (result.plugins.get("robot") or {}).get("name") or "?"
    lines = [
        f"{est.estimator} · robot {robot} · data {_source(result.data)} · seed {result.seed}",
        f"{'parameter':<12}{'estimate':>12}{'true':>12}{'rel. error':>12}",
    ]
    for name, value in est.params.items():
        true = "" if result.truth is None else f"{result.truth[name]:12.4f}"
        r = rel.get(name)
        rtext = "" if r is None else f"{100 * r:+10.2f} %"
        lines.append(f"{name:<12}{value:12.4f}{true:>12}{rtext:>12}")
    cost = "n/a" if est.cost is None else f"{est.cost:.6g}"
    tail = f"cost ({result.cost_name}) {cost} · wall time {est.wall_time_s:.3f} s"
    if result.parameter_error is not None:
        tail += f" · mean |rel. error| {100 * result.parameter_error:.2f} %"
    lines.append(tail)
    return "\n".join(lines)


def write(result: RunResult, out_dir: str | Path, plots: bool = True) -> dict[str, str]:
    """Write ``history.csv``, plots (``convergence.png``, ``estimate.png``) and ``result.json``.

    Raises:
        FileExistsError: ``out_dir`` holds another run's result (nothing is written).
    """
    out = claim(out_dir, result.provenance)
    written: dict[str, str] = {}
    label = result.estimate.estimator
    try:
        found = history_table(result.estimate.details.get("history"))
    except HistoryError as exc:  # a plugin's malformed history must not cost the run its result.json
        warnings.warn(f"{label}: history.csv not written: {exc}", stacklevel=2)
        found = None
    if found is not None:
        written["history"] = str(files.write_csv(out / HISTORY_FILE, *found))
        if plots:
            written["convergence_plot"] = str(
                figures.convergence(*found, title=f"{label}: convergence", path=out / "convergence.png")
            )
    if plots and result.truth is not None:
        written["estimate_plot"] = str(
            figures.estimates_vs_truth(
                {label: result.estimate.params},
                result.truth,
                title="estimate / true value",
                path=out / "estimate.png",
            )
        )
    return write_result(out, result.provenance, result.payload(), written)
