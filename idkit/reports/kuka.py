"""The ``kuka`` task's report: held-out torque tables (Markdown, CSV), the torque plot, result.json."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from idkit.reports import files
from idkit.reports import plots as figures
from idkit.reports.result_file import claim, write_result
from idkit.reports.tables import markdown_table
from idkit.studies.kuka import CAD, KukaStudy, variant


def text(study: KukaStudy) -> str:
    """One table per recording: per joint ``RMS N·m (rel %)``, ``‖E‖/‖T‖``, ``NRMS/limit``."""
    rows = study.rows
    if not rows:
        return "No model variant finished.\n"
    n = sum(1 for k in rows[0] if k.startswith("rms_j"))
    every = "every sample" if study.stride == 1 else f"every {study.stride}th sample"
    lines = [
        f"Identified on `{study.train}` ({every}); RMS torque error per joint, N·m (in brackets: relative "
        "to the measured torque RMS of that joint); ‖E‖/‖T‖ over all joints; NRMS/limit normalised by "
        "the URDF effort limits.",
        "",
    ]
    p = study.provenance
    if p.status == "partial":
        lines += [f"PARTIAL: {p.done} of {p.requested} model variants (interrupted).", ""]
    header = ["model", "friction", "offset", *(f"j{j + 1}" for j in range(n)), "‖E‖/‖T‖", "NRMS/limit"]
    for rec in (*study.test, study.train):
        lines += [f"### {rec}" + (" (training data)" if rec == study.train else " (held out)"), ""]
        table: list[list[Any]] = []
        for r in (r for r in rows if r["recording"] == rec):
            cells = [r["model"], "yes" if r["friction"] else "no", "yes" if r["offset"] else "no"]
            cells += [f"{r[f'rms_j{j + 1}']:.3f} ({100 * r[f'rel_j{j + 1}']:.0f} %)" for j in range(n)]
            cells += [f"{100 * r['rel_all']:.2f} %", f"{100 * r['nrms_limit']:.3f} %"]
            table.append(cells)
        lines += [markdown_table(header, table, align="lll" + "r" * (n + 2)), ""]
    return "\n".join(lines)


def _plot(study: KukaStudy, path: Path) -> Path | None:
    """Measured vs predicted torques on the plot window: CAD, the best rigid and the best overall fit."""
    traces = study.traces
    if traces is None or not traces.predicted:
        return None
    scored = [r for r in study.rows if r["recording"] == traces.recording]
    scored = [r for r in scored if variant(r["model"], r["friction"], r["offset"]) in traces.predicted]
    best = sorted(scored, key=lambda r: r["rel_all"])
    cad = next((r for r in best if r["model"] == CAD), None)
    fitted = [r for r in best if r["model"] != CAD]
    rigid = next((r for r in fitted if not r["friction"]), None)
    chosen = [r for r in (cad, rigid, *fitted[:1]) if r is not None]
    labelled = [variant(r["model"], r["friction"], r["offset"]) for r in chosen]
    predicted = {key: traces.predicted[key] for key in labelled}
    return figures.traces(
        traces.times, traces.measured, predicted, f"KUKA LWR4+ held-out torques, {traces.recording}", path
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
    return write_result(out, study.provenance, study.payload(), written)
