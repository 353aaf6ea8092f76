"""The ``robustness`` task's report: summary table (Markdown, CSV), per-trial CSV, box plot, result.json."""

from __future__ import annotations

from pathlib import Path

from idkit.reports import files, robustness_page
from idkit.reports import plots as figures
from idkit.reports.result_file import claim, write_result
from idkit.reports.tables import markdown_table
from idkit.reports.units import format_time
from idkit.studies import robustness_trials
from idkit.studies.robustness import RobustnessStudy


def _pct(value: float | None, digits: int = 2) -> str:
    return "" if value is None else f"{100 * value:.{digits}f} %"


def answer(study: RobustnessStudy) -> str:
    """The paper's claim, scenario by scenario, and the overall conclusion."""
    found = study.focus_comparisons()
    if not found:
        return ""
    lines = []
    for scenario, cmp in found.items():
        if cmp.wins + cmp.losses == 0:
            lines.append(f"- `{scenario}`: every trial tied → undecided")
            continue
        lines.append(
            f"- `{scenario}`: {study.focus} wins {100 * cmp.win_rate:.1f} % of {cmp.wins + cmp.losses} "
            f"trials against {study.baseline} (95 % CI {100 * cmp.ci_low:.1f}–{100 * cmp.ci_high:.1f} %, "
            f"sign test p = {cmp.p_value:.2g}) → {cmp.verdict}"
        )
    head = (
        f"**Paper's conclusion ({study.focus} beats {study.baseline} in all four error cases): "
        f"{study.conclusion()}** over {study.trials} trials per scenario."
    )
    return "\n".join([head, "", *lines])


def text(study: RobustnessStudy) -> str:
    """The Markdown report: summary table, the paper's claim, skipped plugins, wall time."""
    header = [
        "scenario",
        "estimator",
        "median",
        "90th pct",
        f"win rate vs {study.baseline} [95 % CI]",
        "sign test p",
        "mean fit time",
    ]
    rows = []
    for row in study.rows():
        win = (
            ""
            if row["win_rate"] is None or row["wins"] + row["losses"] == 0
            else f"{_pct(row['win_rate'], 1)} [{100 * row['ci_low']:.1f}, {100 * row['ci_high']:.1f}]"
        )
        p = "" if row["p_value"] is None or row["wins"] + row["losses"] == 0 else f"{row['p_value']:.2g}"
        fit = row["mean_fit_time_s"]
        rows.append(
            [
                row["scenario"],
                row["estimator"],
                _pct(row["median"]),
                _pct(row["p90"]),
                win,
                p,
                "" if fit is None else format_time(fit),
            ]
        )
    progress = study.provenance
    title = f"### Robustness: {study.trials} noise draws per scenario (seed {study.seed})"
    if progress.status == "partial":
        title += f" — PARTIAL: {progress.done} of {progress.requested} trials"
    parts = [
        "\n".join(
            [
                title,
                "",
                "Parameter error = mean over parameters of |estimate − truth| / |truth|.",
                "",
                markdown_table(header, rows, align="llrrrrr"),
            ]
        )
    ]
    found = answer(study)
    if found:
        parts.append(found)
    if study.skipped:
        parts.append(f"Skipped (plugin not installed): {', '.join(study.skipped)}.")
    parts.append(f"Wall time {study.wall_time_s:.1f} s.")
    return "\n\n".join(parts) + "\n"


def write(study: RobustnessStudy, out_dir: str | Path, plots: bool = True) -> dict[str, str]:
    """Write ``robustness.md``, ``robustness.csv``, the per-trial CSV, the box plot and ``result.json``."""
    out = claim(out_dir, study.provenance)
    rows = study.rows()
    header = list(rows[0]) if rows else []
    written = {
        "markdown": str(files.write_text(out / "robustness.md", text(study))),
        "csv": str(files.write_csv(out / "robustness.csv", header, ([r[k] for k in header] for r in rows))),
    }
    trials_file = out / robustness_trials.FILE
    written["trials_csv"] = str(files.write_csv(trials_file, *robustness_trials.table(study)))
    if plots and study.trials:
        errors = {s: {label: study.errors(s, label) for label in by} for s, by in study.params.items()}
        written["boxplot"] = str(
            figures.boxplots(
                errors,
                out / "robustness_boxplot.png",
                f"parameter error over {study.trials} noise draws"
                " (boxes: quartiles; whiskers: 5th-95th percentile)",
            )
        )
    return write_result(
        out,
        study.provenance,
        study.payload(),
        written,
        lambda document: robustness_page.render(study, document, out, text(study)),
    )
