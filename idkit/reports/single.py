"""The ``single`` task's report: a text table, ``result.json``, ``history.csv``, plots, ``identified.urdf``
and ``identified.xml``.

The table lists the estimate; for least-squares-type fits (``details["uncertainty"]``) each base
parameter's relative standard deviation, the regressor's rank and condition number and the
combinations the data cannot identify; with ``validate=`` files, their per-joint RMS errors and
``‖E‖/‖T‖``.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from idkit.estimate import HistoryError, history_table
from idkit.reports import files, single_page
from idkit.reports import payload as payload_report
from idkit.reports import plots as figures
from idkit.reports.result_file import claim, write_result
from idkit.reports.units import effort_units
from idkit.studies.single import HeldOut, RunResult

HISTORY_FILE = "history.csv"
URDF_FILE = "identified.urdf"
MJCF_FILE = "identified.xml"
#: Held-out torque plots show the first this many seconds (files with timestamps) or samples.
PLOT_SECONDS = 20.0
PLOT_SAMPLES = 2000


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
        *_torque_lines(result.data),
        f"{'parameter':<12}{'estimate':>12}{'true':>12}{'rel. error':>12}",
    ]
    held = set(est.details.get("held") or ())  # kept at the robot's reference, not fitted
    for name, value in est.params.items():
        true = "" if result.truth is None else f"{result.truth[name]:12.4f}"
        r = rel.get(name)
        rtext = "" if r is None else f"{100 * r:+10.2f} %"
        lines.append(f"{name:<12}{value:12.4f}{true:>12}{rtext:>12}" + ("  held" if name in held else ""))
    cost = "n/a" if est.cost is None else f"{est.cost:.6g}"
    tail = f"cost ({result.cost_name}) {cost} · wall time {est.wall_time_s:.3f} s"
    if result.parameter_error is not None:
        tail += f" · mean |rel. error| {100 * result.parameter_error:.2f} %"
    lines.append(tail)
    lines += _uncertainty_lines(est.details.get("uncertainty"), {**est.params, **(est.base_params or {})})
    lines += payload_report.lines(est.details)
    lines += _validation_lines(result)
    lines += _plausibility_lines(result)
    return "\n".join(lines)


def _torque_lines(data: Mapping[str, Any] | None) -> list[str]:
    """What the recorded torques were and what was fitted, when they differ (``effort_scale``)."""
    torques = (data or {}).get("torques")
    if not torques or torques["recorded"] == torques["fitted"]:
        return []
    scale = torques.get("effort_scale")
    factors = f" [{', '.join(f'{k:g}' for k in scale)}]" if scale else ""
    return [f"torques: {torques['recorded']}{factors} → fitted and scored in {torques['fitted']}"]


def _plausibility_lines(result: RunResult) -> list[str]:
    """Each link's verdict as the run recorded it (:func:`idkit.conic.plausible.plausibility_report`: mass
    and centre of mass beside CAD, the reasons), what bounds each body, how ``plausible=auto`` chose,
    and the other choice's held-out figures (when computed). Read, never judged again here."""
    found = result.estimate.details.get("plausibility")
    if not found or "links" not in found:
        return []
    choice = result.estimate.details.get("plausible_choice")
    if not (found["implausible"] or found.get("enforced", "none") != "none" or choice):
        return []
    lines = [
        "",
        f"{found['rule']}; enforced: {found['enforced']}",
        f"{'link':<24}{'mass (kg)':>11}{'CAD':>9}{'ratio':>8}   {'centre of mass (m)':<26}{'CAD':<24}",
    ]
    for link, verdict in found["links"].items():
        com = "(" + ", ".join(f"{x:.3f}" for x in verdict["com"]) + ")"
        cad_com = "(" + ", ".join(f"{x:.3f}" for x in verdict["cad_com"]) + ")"
        notes = [*verdict["reasons"], *(["at its mass bound"] if verdict["at_bound"] else [])]
        lines.append(
            f"{link:<24}{verdict['mass']:11.4g}{verdict['cad_mass']:9.4g}{verdict['ratio']:7.3g}x   "
            f"{com:<26}{cad_com:<24}{'' if verdict['plausible'] else ' !'}"
            + (f" ({'; '.join(notes)})" if notes else "")
        )
    lines.append("bounded by: " + "; ".join(f"{link}: {what}" for link, what in found["bounded_by"].items()))
    if choice:
        lines.append(f"plausible=auto: {choice['reason']}")
    other = result.plausible
    if other is not None:
        now = " / ".join(f"{100 * h.scores.rel_all:.2f} %" for h in result.validation)
        then = " / ".join(f"{100 * s.rel_all:.2f} %" for s in other.scores)
        kept = other.estimate.details.get("plausibility", {}).get("implausible")
        verdict = f"implausible: {', '.join(kept)}" if kept else "every link plausible"
        enforced = other.estimate.details.get("plausibility", {}).get("enforced", "?")
        differs = f"; {other.differs}" if other.differs else ""
        lines.append(
            f"with {other.option} (enforced: {enforced}; {verdict}{differs}) the held-out ‖E‖/‖T‖ is "
            f"{then} (this fit: {now})"
        )
    elif found["implausible"]:
        lines.append(
            f"implausible: {', '.join(found['implausible'])}; estimator.plausible=true keeps every link mass "
            "within its band and inside its geometry (give validate= files to see the cost)"
        )
    return lines


def _uncertainty_lines(uncertainty: Mapping[str, Any] | None, base: Mapping[str, float]) -> list[str]:
    """Base parameters (and any other parameter the uncertainty covers, such as varpro's shapes) with
    their relative standard deviation, rank, condition, unidentifiable part."""
    if not uncertainty:
        return []
    rel = uncertainty.get("std_rel_pct") or {}
    std = uncertainty.get("std") or {}
    # the std itself beside its share of the estimate: a share alone reads 1e10 % for a friction
    # coefficient held at its bound 0 (a value of 1e-9), where only the std says what the data allow
    lines = ["", f"{'base parameter':<24}{'estimate':>12}{'std':>12}{'relative':>12}"]
    for name, pct in rel.items():
        value = base.get(name)
        shown = "" if value is None else f"{value:12.5g}"
        spread = std.get(name)
        spread_shown = "" if spread is None else f"{spread:12.3g}"
        lines.append(f"{name:<24}{shown:>12}{spread_shown:>12}{_percent(pct):>12}")
    cond = uncertainty.get("cond", float("nan"))
    if uncertainty.get("std_source"):  # the estimate's record of its std (idkit.std_source)
        lines.append(f"std: {uncertainty['std_source']}")
    lines.append(f"regressor rank {uncertainty.get('rank')} · condition number {cond:.3g}")
    unidentifiable = uncertainty.get("unidentifiable") or []
    lines.append("unidentifiable: " + ("; ".join(unidentifiable) if unidentifiable else "none"))
    return lines


def _percent(value: Any) -> str:
    if value is None or not isinstance(value, (int, float)) or value != value:
        return "n/a"
    return "inf" if value == float("inf") else f"{value:.3g} %"


def joint_labels(result: RunResult, n: int) -> list[str]:
    """The robot's joint names (``j1``, ``j2``, … for a result that does not carry them)."""
    names = list(result.joint_names)
    return names if len(names) == n else [f"j{j + 1}" for j in range(n)]


def _validation_lines(result: RunResult) -> list[str]:
    """Per held-out file: ``‖E‖/‖T‖`` over all joints, then each joint's RMS error and relative error."""
    if not result.validation:
        return []
    n = len(result.validation[0].scores.rms)
    bands = {held.scores.band for held in result.validation}
    band = bands.pop() if len(bands) == 1 else "mixed"
    compared = (
        "unfiltered torques"
        if band is None
        else "torques compared below the scoring band, per file"
        if band == "mixed"
        else f"torques compared below {band:g} Hz"
    )
    names = joint_labels(result, n)
    units = effort_units(result.joint_kinds, n)  # N·m for a revolute joint, N for a sliding one
    width = max(12, *(len(name) + 2 for name in names))
    lines = [
        "",
        f"held-out validation ({compared}): ‖E‖/‖T‖ over all joints; per joint the RMS torque error and "
        "its share of the joint's RMS measured torque",
    ]
    for held in result.validation:
        lines.append(f"{_short(held.file, 60)}: ‖E‖/‖T‖ {100 * held.scores.rel_all:.2f} %")
        lines.append(f"  {'joint':<{width}}{'RMS error':>17}{'relative':>11}")
        for name, unit, rms, relative in zip(
            names, units, held.scores.rms, held.scores.relative, strict=True
        ):
            lines.append(f"  {name:<{width}}{rms:12.4g} {unit:<4}{100 * relative:9.2f} %")
    return lines


def _short(path: str, width: int = 31) -> str:
    return path if len(path) <= width else "…" + path[-(width - 1) :]


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
    if plots:
        for k, held in enumerate(result.validation):
            path = out / f"validation_{k + 1}.png"
            n = held.scores.measured.shape[1]
            names, units = joint_labels(result, n), effort_units(result.joint_kinds, n)
            written[f"validation_plot_{k + 1}"] = str(_validation_plot(label, held, path, names, units))
    models = {
        key: (name, text)
        for key, name, text in (
            ("identified_urdf", URDF_FILE, result.urdf),
            ("identified_mjcf", MJCF_FILE, result.mjcf),
        )
        if text is not None
    }
    return write_result(
        out,
        result.provenance,
        result.payload(),
        written,
        lambda document: single_page.render(document, out),
        models=models,
    )


def _validation_plot(label: str, held: HeldOut, path: Path, joint_names: list[str], units: list[str]) -> Path:
    """Measured vs predicted torques on the start of a held-out file, with the residual under each
    joint (x: time, else sample index)."""
    scores = held.scores
    if held.times is not None:
        times = held.times
        keep = times - times[0] <= PLOT_SECONDS
    else:
        times = np.arange(scores.measured.shape[0], dtype=np.float64)
        keep = times < PLOT_SAMPLES
    title = f"{label}: held-out {held.file} (‖E‖/‖T‖ {100 * scores.rel_all:.2f} %)"
    return figures.traces(
        times[keep], scores.measured[keep], {label: scores.predicted[keep]}, title, path, joint_names, units
    )
