"""``report.html`` of the paper task: the verdicts first (does the paper's final estimate beat
RLS-rel on each table's draw, and did it in the paper), then Tables II–V beside the published
values, then the figures. The numbers are those of ``paper_tables.md``, which stays as it was."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from idkit.reports import html as h
from idkit.reports.units import format_time
from idkit.studies.paper import PaperTables, ScenarioTable


def _outcome(error: float | None, baseline: float | None) -> str:
    if error is None or baseline is None:
        return h.badge("none", "no comparison")
    return h.badge("good", "beats") if error < baseline else h.badge("poor", "loses")


def _verdicts(result: PaperTables, tables: Mapping[str, str]) -> str:
    mine, other = result.compare
    rows = [
        [
            f"{tables.get(c['scenario'], '')} {c['scenario']}".strip(),
            h.num(c["error"], shown=h.percent(c["error"])),
            h.num(c["baseline_error"], shown=h.percent(c["baseline_error"])),
            h.raw(_outcome(c["error"], c["baseline_error"])),
            h.num(c["paper_error"], shown=h.percent(c["paper_error"])),
            h.num(c["paper_baseline_error"], shown=h.percent(c["paper_baseline_error"])),
            h.raw(_outcome(c["paper_error"], c["paper_baseline_error"])),
        ]
        for c in result.comparisons()
    ]
    rule = h.paragraph(
        f"Mean |relative parameter error| of {mine} against {other}, on the one noise draw of each table "
        "(one draw cannot carry a general claim: the robustness study draws a thousand).",
        "rule",
    )
    header = ["table", mine, other, "here", f"paper: {mine}", f"paper: {other}", "in the paper"]
    return rule + h.table(header, rows, "verdicts")


def _table(table: ScenarioTable, columns: list[str], number: str) -> str:
    from idkit.reports.paper import column_value  # paper.py writes this page: imported when drawn

    shown = [c.replace("-", "−") for c in columns]
    header = ["method", *shown, "time", "mean |rel. error|"]
    header += [f"paper {c}" for c in shown] + ["paper time", "paper error"]
    rows: list[list[Any]] = [["real values", *(h.num(column_value(table.truth, c)) for c in columns)]]
    rows[0] += [""] * (len(header) - len(rows[0]))
    for est in table.estimates:
        ref = table.reference.get(est.estimator)
        error, ref_error = table.error(est.estimator), table.reference_error(est.estimator)
        row: list[Any] = [est.estimator]
        row += [h.num(column_value(est.params, c), digits=4) for c in columns]
        row += [
            h.num(est.wall_time_s, shown=format_time(est.wall_time_s)),
            h.num(error, shown=h.percent(error)),
        ]
        if ref is None:
            row += [""] * (len(columns) + 2)
        else:
            row += [h.num(column_value(ref["params"], c), digits=4) for c in columns]
            row += [
                h.num(ref["time_s"], shown=format_time(ref["time_s"])),
                h.num(ref_error, shown=h.percent(ref_error)),
            ]
        rows.append(row)
    return f"<h3>Table {h.escape(number)}: {h.escape(table.scenario)}</h3>" + h.table(
        header, rows, table.scenario
    )


def render(result: PaperTables, document: Mapping[str, Any], folder: str | Path, text: str) -> str:
    """The page: verdicts, Tables II–V, the figures, and the printed report (collapsed)."""
    from idkit.reports.paper import TABLES  # paper.py writes this page: imported when drawn

    p = result.provenance
    sections = []
    if p.status == "partial":
        sections.append(
            h.section(
                "partial", "Partial", h.paragraph(f"Interrupted: {p.done} of {p.requested} tables are in.")
            )
        )
    sections.append(h.section("verdicts", "Verdicts", _verdicts(result, TABLES)))
    tables = [_table(t, list(result.columns), TABLES.get(t.scenario, "")) for t in result.tables]
    sections.append(h.section("tables", "Tables II–V beside the published values", *tables))
    figures = [
        h.png_file(Path(folder) / Path(path).name, key)
        for key, path in (document.get("files") or {}).items()
        if key.startswith("plot_")
    ]
    if figures:
        sections.append(h.section("figures", "Estimates against the truth", *figures))
    sections.append(
        h.section(
            "run",
            "Run",
            h.paragraph(f"Total wall time {result.wall_time_s:.1f} s."),
            h.collapsed("The printed report (paper_tables.md)", h.preformatted(text)),
        )
    )
    return h.page(str(document.get("label") or "The paper's Tables II–V"), h.run_subtitle(document), sections)
