"""The ``kuka`` task's report: held-out torque tables (Markdown, CSV), the torque plot, result.json."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from idkit.reports import files, html
from idkit.reports import plots as figures
from idkit.reports.result_file import claim, write_result
from idkit.reports.tables import markdown_table
from idkit.studies.kuka import CAD, KukaStudy, variant


def text(study: KukaStudy) -> str:
    """One table per recording: per joint ``RMS N·m (rel %)``, ``‖E‖/‖T‖``, ``NRMS/limit`` and the
    smallest pseudo-inertia eigenvalue over the links (how many links are negative)."""
    rows = study.rows
    if not rows:
        return "No model variant finished.\n"
    n = sum(1 for k in rows[0] if k.startswith("rms_j"))
    every = "every sample" if study.stride == 1 else f"every {study.stride}th sample"
    lines = [
        f"Identified on `{study.train}` ({every}); RMS torque error per joint, N·m (in brackets: relative "
        "to the measured torque RMS of that joint); ‖E‖/‖T‖ over all joints; NRMS/limit normalised by "
        "the URDF effort limits; min eig: the smallest pseudo-inertia eigenvalue over the links (in "
        "brackets: links with a negative one, i.e. not physically consistent).",
        "",
    ]
    p = study.provenance
    if p.status == "partial":
        lines += [f"PARTIAL: {p.done} of {p.requested} model variants (interrupted).", ""]
    named = study.traces.joint_names if study.traces is not None else ()
    joints = list(named) if len(named) == n else [f"j{j + 1}" for j in range(n)]
    header = ["model", "friction", "offset", *joints, "‖E‖/‖T‖", "NRMS/limit", "min eig"]
    for rec in (*study.test, study.train):
        lines += [f"### {rec}" + (" (training data)" if rec == study.train else " (held out)"), ""]
        table: list[list[Any]] = []
        for r in (r for r in rows if r["recording"] == rec):
            cells = [r["model"], _friction(r), "yes" if r["offset"] else "no"]
            cells += [f"{r[f'rms_j{j + 1}']:.3f} ({100 * r[f'rel_j{j + 1}']:.0f} %)" for j in range(n)]
            cells += [f"{100 * r['rel_all']:.2f} %", _percent(r["nrms_limit"]), _eigenvalue(r)]
            table.append(cells)
        lines += [markdown_table(header, table, align="lll" + "r" * (n + 3)), ""]
    return "\n".join(lines)


def _variant(row: dict[str, Any]) -> str:
    return variant(row["model"], row["friction"], row["offset"], row.get("stribeck"))


def _friction(row: dict[str, Any]) -> str:
    if not row["friction"]:
        return "no"
    return f"yes + low-speed ({row['stribeck']:g} rad/s)" if row.get("stribeck") else "yes"


def _percent(value: float | None) -> str:
    return "–" if value is None else f"{100 * value:.3f} %"


def _eigenvalue(row: dict[str, Any]) -> str:
    if row.get("min_eig") is None:
        return "–"
    return f"{row['min_eig']:.1e} ({row['links_negative']})"


def _plot(study: KukaStudy, path: Path) -> Path | None:
    """Measured vs predicted torques on the plot window: CAD, the best rigid and the best overall fit."""
    traces = study.traces
    if traces is None or not traces.predicted:
        return None
    scored = [r for r in study.rows if r["recording"] == traces.recording]
    scored = [r for r in scored if _variant(r) in traces.predicted]
    best = sorted(scored, key=lambda r: r["rel_all"])
    cad = next((r for r in best if r["model"] == CAD), None)
    fitted = [r for r in best if r["model"] != CAD]
    rigid = next((r for r in fitted if not r["friction"]), None)
    chosen = [r for r in (cad, rigid, *fitted[:1]) if r is not None]
    labelled = [_variant(r) for r in chosen]
    predicted = {key: traces.predicted[key] for key in labelled}
    return figures.traces(
        traces.times,
        traces.measured,
        predicted,
        f"KUKA LWR4+ held-out torques, {traces.recording}",
        path,
        traces.joint_names or None,
    )


def write(study: KukaStudy, out_dir: str | Path, plots: bool = True) -> dict[str, str]:
    """Write ``kuka_heldout.md``, ``kuka_heldout.csv``, ``kuka_heldout_torques.png``, ``result.json``."""
    out = claim(out_dir, study.provenance)
    header = list(study.rows[0]) if study.rows else []
    written = {
        "markdown": str(files.write_text(out / "kuka_heldout.md", text(study))),
        "csv": str(
            files.write_csv(out / "kuka_heldout.csv", header, ([r[k] for k in header] for r in study.rows))
        ),
    }
    if plots:
        plot = _plot(study, out / "kuka_heldout_torques.png")
        if plot is not None:
            written["plot"] = str(plot)
    return write_result(
        out,
        study.provenance,
        study.payload(),
        written,
        lambda document: html.text_page(document, text(study), out),
    )
