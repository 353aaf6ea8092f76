"""The ``paper`` task's report: Tables II–V in the paper's layout, beside the published values.

One Markdown table per scenario (m2, m3, −s3z, I, computation time, mean |relative error|, the
published value in brackets), the same as CSV, a scatter plot per scenario, and ``result.json``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from idkit.reports import files, paper_page
from idkit.reports import plots as figures
from idkit.reports.result_file import claim, write_result
from idkit.reports.tables import markdown_table
from idkit.reports.units import format_time
from idkit.studies.paper import PaperTables, ScenarioTable
from idkit.untrusted import safe_basename

#: The paper's table number of each scenario.
TABLES = {"state_noise": "II", "torque_noise": "III", "all_noise": "IV", "outliers": "V"}


def column_value(params: Mapping[str, float], column: str) -> float:
    """A display column: a parameter name, or ``-name`` for its negation (the paper's −s3z)."""
    return -params[column[1:]] if column.startswith("-") else params[column]


def _with_reference(mine: str, ref: str | None) -> str:
    return mine if ref is None else f"{mine} ({ref})"


def scenario_markdown(table: ScenarioTable, columns: Sequence[str]) -> str:
    """One scenario's table in the paper's layout; the published value in brackets."""
    header = ["method", *(c.replace("-", "−") for c in columns), "computation time", "mean |rel. error|"]
    rows: list[list[Any]] = [["real values", *(f"{column_value(table.truth, c):g}" for c in columns), "", ""]]
    for est in table.estimates:
        ref = table.reference.get(est.estimator)
        cells = [est.estimator]
        for c in columns:
            cells.append(
                _with_reference(
                    f"{column_value(est.params, c):.2f}",
                    None if ref is None else f"{column_value(ref['params'], c):.2f}",
                )
            )
        ref_time = None if ref is None or ref["time_s"] is None else format_time(ref["time_s"])
        cells.append(_with_reference(format_time(est.wall_time_s), ref_time))
        err, ref_err = table.error(est.estimator), table.reference_error(est.estimator)
        cells.append(
            _with_reference(
                "" if err is None else f"{100 * err:.1f} %",
                None if ref_err is None else f"{100 * ref_err:.1f} %",
            )
        )
        rows.append(cells)
    title = f"### Table {TABLES.get(table.scenario, '')}: `{table.scenario}` — idkit (paper)"
    return title + "\n\n" + markdown_table(header, rows, align="l" + "r" * (len(header) - 1))


def _outcome(error: float, baseline: float) -> str:
    return "beats" if error < baseline else "loses"


def verdicts(result: PaperTables) -> list[str]:
    """Per scenario: does the paper's final estimate beat RLS-rel on this draw (and in the paper)?"""
    mine, other = result.compare
    lines = []
    for c in result.comparisons():
        if c["error"] is None or c["baseline_error"] is None:
            continue
        text = (
            f"- `{c['scenario']}`: {mine} {100 * c['error']:.1f} % vs {other} "
            f"{100 * c['baseline_error']:.1f} % → {_outcome(c['error'], c['baseline_error'])}"
        )
        if c["paper_error"] is not None and c["paper_baseline_error"] is not None:
            text += (
                f" (paper: {100 * c['paper_error']:.1f} % vs {100 * c['paper_baseline_error']:.1f} % → "
                f"{_outcome(c['paper_error'], c['paper_baseline_error'])})"
            )
        lines.append(text)
    return lines


def text(result: PaperTables) -> str:
    """All tables, the comparison with RLS-rel, the wall time (and PARTIAL if interrupted)."""
    parts = [scenario_markdown(t, result.columns) for t in result.tables]
    found = verdicts(result)
    if found:
        parts.append(
            f"Mean |relative parameter error| of {result.compare[0]} vs {result.compare[1]} "
            "(one draw per table):\n\n" + "\n".join(found)
        )
    p = result.provenance
    if p.status == "partial":
        parts.append(f"PARTIAL: {p.done} of {p.requested} tables (interrupted).")
    parts.append(f"Total wall time {result.wall_time_s:.1f} s.")
    return "\n\n".join(parts) + "\n"


def csv_rows(result: PaperTables) -> tuple[list[str], list[list[Any]]]:
    """One row per (scenario, method) with the published values beside."""
    columns = result.columns
    header = ["table", "scenario", "method", *columns, "time_s", "parameter_error"]
    header += [f"paper_{c}" for c in columns] + ["paper_time_s", "paper_parameter_error"]
    rows = []
    for t in result.tables:
        for est in t.estimates:
            ref = t.reference.get(est.estimator)
            row: list[Any] = [TABLES.get(t.scenario, ""), t.scenario, est.estimator]
            row += [column_value(est.params, c) for c in columns]
            row += [est.wall_time_s, t.error(est.estimator)]
            if ref is None:
                row += [None] * (len(columns) + 2)
            else:
                row += [column_value(ref["params"], c) for c in columns]
                row += [ref["time_s"], t.reference_error(est.estimator)]
            rows.append(row)
    return header, rows


def write(result: PaperTables, out_dir: str | Path, plots: bool = True) -> dict[str, str]:
    """Write ``paper_tables.md``, ``paper_tables.csv``, ``paper_<scenario>.png`` and ``result.json``."""
    out = claim(out_dir, result.provenance)
    written = {
        "markdown": str(files.write_text(out / "paper_tables.md", text(result))),
        "csv": str(files.write_csv(out / "paper_tables.csv", *csv_rows(result))),
    }
    if plots:
        for t in result.tables:
            written[f"plot_{t.scenario}"] = str(
                figures.estimates_vs_truth(
                    {e.estimator: e.params for e in t.estimates},
                    t.truth,
                    title=f"Table {TABLES.get(t.scenario, '')} ({t.scenario}): estimate / true value",
                    path=out / f"paper_{safe_basename(t.scenario)}.png",
                )
            )
    return write_result(
        out,
        result.provenance,
        result.payload(),
        written,
        lambda document: paper_page.render(result, document, out, text(result)),
    )
