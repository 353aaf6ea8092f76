"""``report.html`` of the robustness study: the verdicts first, then the table and the box plot.

The verdicts are the study's own (:attr:`idkit.studies.robustness.Comparison.verdict`, one rule read
off the printed interval), never recomputed here: the page, ``robustness.md`` and ``result.json``
say the same thing.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from idkit.reports import html as h
from idkit.reports.units import format_time
from idkit.studies.robustness import RobustnessStudy

#: Each verdict's colour.
GRADES = {"better": "good", "holds": "good", "worse": "poor", "does not hold": "poor", "undecided": "fair"}


def verdict_badge(verdict: str | None) -> str:
    return h.badge(GRADES.get(verdict or "", "none"), verdict or "no comparison")


def interval(row: Mapping[str, Any]) -> h.Cell:
    """``[low, high] %`` with the pair in ``data-value``."""
    if row.get("ci_low") is None or (row.get("wins") or 0) + (row.get("losses") or 0) == 0:
        return h.Cell("—")
    low, high = row["ci_low"], row["ci_high"]
    return h.Cell(f"{100 * low:.1f}–{100 * high:.1f} %", [low, high], "num")


def _verdicts(study: RobustnessStudy) -> str:
    rule = h.paragraph(
        f"{study.focus} against {study.baseline}, over {study.trials} noise draws per scenario: the share "
        "of draws with the smaller parameter error (ties left out) and its exact 95 % interval. Better "
        "when the whole interval lies above 50 %, worse when below, undecided when it holds 50 % (the "
        "sign test's p-value is below 5 % exactly when the interval excludes 50 %).",
        "rule",
    )
    found = study.focus_comparisons()
    if not found:
        return h.paragraph("No comparison: the focus or the baseline is not among the estimators.")
    rows = [
        [
            scenario,
            h.num(cmp.win_rate, shown=h.percent(cmp.win_rate)),
            interval({"ci_low": cmp.ci_low, "ci_high": cmp.ci_high, "wins": cmp.wins, "losses": cmp.losses}),
            h.num(cmp.p_value, digits=2),
            h.raw(verdict_badge(cmp.verdict)),
        ]
        for scenario, cmp in found.items()
    ]
    conclusion = study.conclusion()
    head = (
        f"<p><strong>The paper's conclusion ({h.escape(study.focus)} beats {h.escape(study.baseline)} "
        f"in every error case):</strong> {verdict_badge(conclusion)}</p>"
    )
    table = h.table(["scenario", "win rate", "95 % interval", "sign test p", "verdict"], rows, "verdicts")
    return head + rule + table


def _summary(study: RobustnessStudy) -> str:
    rows = []
    for row in study.rows():
        compared = row["win_rate"] is not None and row["wins"] + row["losses"] > 0
        fit = row["mean_fit_time_s"]
        rows.append(
            [
                row["scenario"],
                row["estimator"],
                h.num(row["median"], shown=h.percent(row["median"])),
                h.num(row["p90"], shown=h.percent(row["p90"])),
                h.num(row["win_rate"], shown=h.percent(row["win_rate"])) if compared else "",
                interval(row),
                h.num(row["p_value"], digits=2) if compared else "",
                h.raw(verdict_badge(row["verdict"])) if row["verdict"] else "baseline",
                h.num(fit, shown=format_time(fit)) if fit is not None else "",
            ]
        )
    header = ["scenario", "estimator", "median error", "90th pct", f"win rate vs {study.baseline}"]
    header += ["95 % interval", "sign test p", "verdict", "mean fit time"]
    return h.paragraph(
        "Parameter error = mean over parameters of |estimate − truth| / |truth|.", "rule"
    ) + h.table(header, rows, "summary")


def render(study: RobustnessStudy, document: Mapping[str, Any], folder: str | Path, text: str) -> str:
    """The page: verdicts, the summary table, the box plot, and the printed report (collapsed)."""
    progress = study.provenance
    sections = []
    if progress.status == "partial":
        sections.append(
            h.section(
                "partial",
                "Partial",
                h.paragraph(f"Interrupted: {progress.done} of {progress.requested} trials are in."),
            )
        )
    sections.append(h.section("verdicts", "Verdicts", _verdicts(study)))
    sections.append(h.section("summary", "Every estimator", _summary(study)))
    box = (document.get("files") or {}).get("boxplot")
    if box:
        figure = h.png_file(Path(folder) / Path(box).name, "parameter error distributions")
        sections.append(h.section("figures", "Distributions", figure))
    notes = [f"Skipped (plugin not installed): {', '.join(study.skipped)}."] if study.skipped else []
    notes.append(f"Wall time {study.wall_time_s:.1f} s.")
    sections.append(
        h.section(
            "run",
            "Run",
            *(h.paragraph(note) for note in notes),
            h.collapsed("The printed report (robustness.md)", h.preformatted(text)),
        )
    )
    title = str(document.get("label") or f"Robustness: {study.trials} noise draws per scenario")
    return h.page(title, h.run_subtitle(document), sections)
