"""``report.html`` of a single fit: verdicts first, then the numbers they rest on.

Built from the run's ``result.json`` document and the figures beside it (the validation plots the
report wrote), so the page of a finished run can be made again from its folder. In order:

1. **Verdicts**: the held-out scores per joint (graded by :data:`HELD_OUT_BANDS`), each link's
   plausibility verdict as the run recorded it (:func:`idkit.conic.plausible.plausibility_report`),
   identifiability (rank, conditioning, free combinations, poorly determined base parameters,
   parameters that ended at a search bound),
   what was chosen automatically and why (every ``reason`` the run recorded: cut-off, prior weight,
   torque delay …), and a payload's verdict with its SDK lines;
2. **parameters** beside CAD (and the truth of a simulation), base parameters with their σ;
3. **measured vs predicted** per joint with the residual under each, per held-out file;
4. **the run**: data, plugins, the config, the files.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from idkit.reports import html as h
from idkit.reports.units import effort_units

#: Per-joint relative RMS error on held-out data: at most the first share is ``good`` (a rigid-body
#: model with friction on a real arm: the KUKA's best fits reach 2.4–4.9 %), above the second
#: ``poor`` (worse than a CAD model usually predicts: the KUKA's CAD model 11.6 %); ``fair`` between.
HELD_OUT_BANDS = (0.05, 0.15)
#: A base parameter is poorly determined above this relative standard deviation (%).
POOR_STD_PCT = 10.0
#: Where a run records its automatic choices, as the page names them.
CHOICES = {
    "data.preprocess.cutoff_choice": "low-pass cut-off (preprocess.cutoff=auto)",
    "payload.estimate.details.prior_weight_cv": "prior weight (estimator.prior_weight=auto)",
}


def grade(share: float) -> str:
    """``good``, ``fair`` or ``poor`` for a relative error (:data:`HELD_OUT_BANDS`)."""
    good, poor = HELD_OUT_BANDS
    return "good" if share <= good else "fair" if share <= poor else "poor"


def joint_names(payload: Mapping[str, Any], n: int) -> list[str]:
    names = list(payload.get("joint_names") or [])
    return names if len(names) == n else [f"j{j + 1}" for j in range(n)]


def joint_units(document: Mapping[str, Any], n: int) -> list[str]:
    """Per joint, the unit its efforts were fitted in: N·m on a revolute joint, N on a prismatic one
    (``payload.joint_kinds``; both where the run did not record the kinds)."""
    return effort_units((document.get("payload") or {}).get("joint_kinds"), n)


def _held_out(document: Mapping[str, Any]) -> str:
    payload = document["payload"]
    validation = payload.get("validation") or {}
    if not validation:
        return h.paragraph("No held-out file (validate=): the model was not scored on data it did not see.")
    good, poor = HELD_OUT_BANDS
    parts = [
        h.paragraph(
            f"Relative RMS error per joint (RMS error over the joint's RMS measured torque): good ≤ "
            f"{100 * good:g} %, poor > {100 * poor:g} %.",
            "rule",
        )
    ]
    for file, scores in validation.items():
        names = joint_names(payload, len(scores["rms"]))
        overall = scores["rel_all"]
        parts.append(f"<h3>{h.escape(file)} {h.badge(grade(overall), f'‖E‖/‖T‖ {100 * overall:.3g} %')}</h3>")
        units = joint_units(document, len(names))
        rows = [
            [name, h.num(rms, shown=f"{h.number(rms)} {unit}"), h.num(rel, grade(rel), shown=h.percent(rel))]
            for name, unit, rms, rel in zip(names, units, scores["rms"], scores["relative"], strict=True)
        ]
        rows.append(["all joints (‖E‖/‖T‖)", "", h.num(overall, grade(overall), shown=h.percent(overall))])
        parts.append(h.table(["joint", "RMS error", "relative"], rows, "held-out"))
        parts.append(h.paragraph(scores.get("metric", ""), "rule"))
    return "".join(parts)


def _plausibility(payload: Mapping[str, Any]) -> str:
    """Each link's verdict as the run recorded it (``details["plausibility"]``, the one rule of
    :func:`idkit.conic.plausible.plausibility_report`): read, never judged again here."""
    details = payload["estimate"].get("details") or {}
    if "payload" in details:
        return h.paragraph(
            "A payload fit keeps the arm as given (its model is the one compared with CAD when it was "
            "identified); the payload's own verdict is above."
        )
    recorded = details.get("plausibility") or {}
    if "links" not in recorded:
        return h.paragraph(
            "No plausibility verdict recorded (this robot has no per-link CAD model, or the run predates "
            "the record)."
        )
    wrong = recorded["implausible"]
    head = (
        h.badge("good", "every link plausible")
        if not wrong
        else h.badge("poor", f"implausible: {', '.join(wrong)}")
    )
    rule = h.paragraph(
        f"{recorded['rule'][0].upper()}{recorded['rule'][1:]}. Only combinations of a link's parameters are "
        "identified: where the data leave the rest free, the estimator's prior (pcls) or its minimum-norm "
        f"choice (ls) decides them. Enforced by the fit: {recorded['enforced']}.",
        "rule",
    )
    low, high = recorded.get("flagged_outside") or (0.5, 2.0)
    rows = [
        [
            link,
            h.num(row["cad_mass"]),
            h.num(row["mass"]),
            h.num(row["ratio"], "" if low <= row["ratio"] <= high else "poor", 4),
            h.num(row["min_eigenvalue"], "" if row["min_eigenvalue"] >= 0 else "poor", 3),
            row["bounded_by"],
            "yes" if row["at_bound"] else "",
            h.raw(h.badge("good" if row["plausible"] else "poor", "yes" if row["plausible"] else "no")),
            "; ".join(row["reasons"]),
        ]
        for link, row in recorded["links"].items()
    ]
    header = [
        "link",
        "CAD mass (kg)",
        "mass (kg)",
        "ratio",
        "min eig J",
        "bounded by",
        "at a bound",
        "plausible",
        "why not",
    ]
    choice = details.get("plausible_choice")
    said = h.paragraph(f"plausible=auto: {choice['reason']}.", "rule") if choice else ""
    return f"<p>{head}</p>" + rule + h.table(header, rows, "plausibility") + said + _alternative(payload)


def _alternative(payload: Mapping[str, Any]) -> str:
    """The other plausibility choice's held-out figures, when the study computed them."""
    other = payload.get("plausible_alternative")
    if not other:
        return ""
    ours = payload.get("validation") or {}
    rows = [
        [file, h.num(ours.get(file, {}).get("rel_all"), shown=h.percent(ours.get(file, {}).get("rel_all"))),
         h.num(scores["rel_all"], shown=h.percent(scores["rel_all"]))]
        for file, scores in (other.get("validation") or {}).items()
    ]  # fmt: skip
    kept = other.get("implausible")
    verdict = f"implausible: {', '.join(kept)}" if kept else "every link plausible"
    differs = f"; {other['differs']}" if other.get("differs") else ""
    return h.paragraph(
        f"With {other.get('option')} (enforced: {other.get('enforced')}; {verdict}{differs}), its held-out "
        "‖E‖/‖T‖ beside this fit's:"
    ) + h.table(["file", "this fit", "other choice"], rows, "plausible-alternative")


def _identifiability(details: Mapping[str, Any]) -> str:
    parts = []
    uncertainty = details.get("uncertainty") or {}
    if uncertainty:
        rel = uncertainty.get("std_rel_pct") or {}
        count = len(rel)
        rank = uncertainty.get("rank")
        full = rank == count
        parts.append(
            f"<p>{h.badge('good' if full else 'poor', f'rank {rank} of {count} base parameters')} "
            f"condition number {h.number(uncertainty.get('cond'), 4)} (column-equilibrated regressor)</p>"
        )
        free = uncertainty.get("unidentifiable") or []
        if free:
            parts.append("<p>Combinations the data cannot identify:</p>" + h.listing(map(h.escape, free)))
        poor = [
            (name, pct)
            for name, pct in rel.items()
            if isinstance(pct, (int, float)) and not pct <= POOR_STD_PCT
        ]
        if poor:
            shown = [f"{h.escape(name)} (σ {h.number(pct, 3)} %)" for name, pct in poor]
            parts.append(
                f"<p>Poorly determined (σ above {POOR_STD_PCT:g} % of the value):</p>" + h.listing(shown)
            )
        else:
            parts.append(h.paragraph(f"Every base parameter has σ at most {POOR_STD_PCT:g} % of its value."))
    bound = details.get("at_bound")
    if bound:
        items = bound.items() if isinstance(bound, Mapping) else ((name, "") for name in bound)
        parts.append(
            "<p>Ended at a bound of the search (the data may want a value outside it):</p>"
            + h.listing(f"{h.escape(name)} {h.escape(where)}".strip() for name, where in items)
        )
    if not parts and "payload" in details:
        parts.append(
            h.paragraph("The payload's standard deviations and what it leaves free are in its verdict above.")
        )
    elif not parts:
        parts.append(h.paragraph("This estimator reports no uncertainty or identifiability figures."))
    return "".join(parts)


def recorded_choices(document: Mapping[str, Any]) -> Iterator[tuple[str, Any, str]]:
    """Every automatic choice the run recorded: ``(what, chosen value, reason)`` for each mapping with
    a ``reason`` (outside the config), and every estimated torque delay."""

    def walk(node: Any, path: str) -> Iterator[tuple[str, Any, str]]:
        if isinstance(node, Mapping):
            if isinstance(node.get("reason"), str):
                chosen = next((node[k] for k in ("chosen", "cutoff", "value") if k in node), None)
                yield CHOICES.get(path, path), chosen, node["reason"]
            for key, value in node.items():
                if key not in ("config", "reason"):
                    yield from walk(value, f"{path}.{key}" if path else str(key))

    yield from walk({k: v for k, v in document.items() if k != "config"}, "")
    for file, delay in ((document.get("data") or {}).get("delays") or {}).items():
        if isinstance(delay, Mapping) and delay.get("estimated"):
            seconds = next((delay[k] for k in ("seconds", "delay", "s") if k in delay), None)
            yield (
                f"torque delay of {file} (recording.torque_lag=auto)",
                seconds,
                "estimated from the recording",
            )


def _choices(document: Mapping[str, Any]) -> str:
    found = list(recorded_choices(document))
    if not found:
        return h.paragraph("Nothing was chosen automatically: every setting was given.")
    rows = [[what, h.num(value) if value is not None else "", reason] for what, value, reason in found]
    return h.table(["what", "chosen", "why"], rows, "choices")


def _payload(details: Mapping[str, Any]) -> str:
    """The payload's verdict per quantity, what is not identified and why, and the SDK calls."""
    from idkit.estimators.payload_verdict import AXES, INERTIA_ENTRIES
    from idkit.reports import payload as payload_report

    block = details.get("payload")
    if not isinstance(block, Mapping) or "sdk" not in block:
        return ""
    judged = block.get("verdict")
    notes = list((block.get("recordings") or {}).get("notes", []))
    context = payload_report.arm_lines(details.get("arm_model") or {})
    context += payload_report.reference_lines(details.get("reference"))
    if judged is None or block["com"] is None:
        return h.paragraph("No payload mass found: centre of mass and inertia undefined, nothing to set.")

    def state(ok: bool) -> Any:
        return h.raw(h.badge("good" if ok else "poor", "identified" if ok else "not identified"))

    def values(pairs: list[tuple[str, float, float]]) -> str:
        return ", ".join(
            f"{name} free" if std == float("inf") else f"{name} {h.number(v)} ± {h.number(std, 2)}"
            for name, v, std in pairs
        )

    rows = [
        ["mass (kg)", state(judged["mass"]), values([("m", block["mass"], block["mass_std"])])],
        [
            "centre of mass (m)",
            state(judged["com"]),
            values([(a, c, s) for a, c, s in zip(AXES, block["com"], block["com_std"], strict=True)]),
        ],
        [
            "inertia about the centre of mass (kg·m²)",
            state(judged["inertia"]),
            values([(n, block["inertia"][i][j], block["inertia_std"][i][j]) for n, i, j in INERTIA_ENTRIES]),
        ],
    ]
    why = (
        [judged["unusable"]]
        if judged.get("unusable")
        else payload_report.not_identified(judged, block.get("free") or ())
    )
    return (
        h.paragraph(f"On {block['link']}; {judged['rule']}.", "rule")
        + h.table(["quantity", "verdict", "values ± σ"], rows, "payload")
        + (h.listing(map(h.escape, notes + why)) if notes or why else "")
        + h.preformatted("\n".join(payload_report.sdk_lines(block["link"], block["sdk"])))
        + h.listing(map(h.escape, context))
    )


def _parameters(payload: Mapping[str, Any]) -> str:
    estimate = payload["estimate"]
    params, nominal, truth = estimate["params"], payload.get("nominal") or {}, payload.get("truth") or {}
    header = ["parameter", "estimate", "CAD", "estimate − CAD"] + (["truth"] if truth else [])
    rows = []
    for name, value in params.items():
        cad = nominal.get(name)
        row = [name, h.num(value), h.num(cad), h.num(None if cad is None else value - cad, digits=4)]
        rows.append(row + ([h.num(truth.get(name))] if truth else []))
    parts = ["<h3>Parameters beside CAD</h3>", h.table(header, rows, "parameters")]
    base = estimate.get("base_params") or {}
    uncertainty = (estimate.get("details") or {}).get("uncertainty") or {}
    std, rel = uncertainty.get("std") or {}, uncertainty.get("std_rel_pct") or {}
    if base:
        parts.append("<h3>Base parameters (the identifiable combinations) with their σ</h3>")
        base_rows = [
            [
                name,
                h.num(value),
                h.num(std.get(name), digits=3),
                h.num(rel.get(name), "poor" if (rel.get(name) or 0) > POOR_STD_PCT else "", 3),
            ]
            for name, value in base.items()
        ]
        parts.append(h.table(["base parameter", "estimate", "σ", "σ (%)"], base_rows, "base-parameters"))
    return "".join(parts)


def _traces(document: Mapping[str, Any], folder: Path) -> str:
    plots = {
        key: path for key, path in (document.get("files") or {}).items() if key.startswith("validation_plot")
    }
    files = list(document["payload"].get("validation") or {})
    if not files:
        return h.paragraph("No held-out file, no prediction to show.")
    if not plots:
        return h.paragraph("Plots were not written for this run (plots=false).")
    parts = []
    for k, file in enumerate(files):
        path = plots.get(f"validation_plot_{k + 1}")
        if path is not None:
            parts.append(
                f"<h3>{h.escape(file)}</h3>" + h.png_file(folder / Path(path).name, f"held-out {file}")
            )
    return "".join(parts)


def run_details(document: Mapping[str, Any]) -> str:
    """The run's plugins, data, files and (collapsed) config: every page's last section."""
    import json

    plugins = document.get("plugins") or {}
    rows = [
        [role, (spec or {}).get("name", ""), json.dumps((spec or {}).get("options", {}))]
        for role, spec in plugins.items()
    ]
    files = [[key, Path(path).name] for key, path in (document.get("files") or {}).items()]
    config = document.get("config")
    return (
        h.table(["role", "plugin", "options"], rows, "plugins")
        + h.preformatted(json.dumps(document.get("data"), indent=2))
        + h.table(["file", "name"], files, "files")
        + (
            h.collapsed("the config this run ran with", h.preformatted(json.dumps(config, indent=2)))
            if config
            else ""
        )
    )


def render(document: Mapping[str, Any], folder: str | Path) -> str:
    """The page of a ``single`` run's ``result.json`` ``document``; figures from ``folder``."""
    payload = document["payload"]
    details = payload["estimate"].get("details") or {}
    robot = ((document.get("plugins") or {}).get("robot") or {}).get("name", "?")
    payload_part = _payload(details)
    verdicts = ["<h3>Payload</h3>", payload_part] if payload_part else []
    verdicts += [
        "<h3>Held-out prediction</h3>",
        _held_out(document),
        "<h3>Plausibility against CAD</h3>",
        _plausibility(payload),
        "<h3>Identifiability</h3>",
        _identifiability(details),
        "<h3>Chosen automatically</h3>",
        _choices(document),
    ]
    if payload.get("parameter_error") is not None:
        verdicts.append(
            h.paragraph(
                f"Simulated data: mean |relative parameter error| {100 * payload['parameter_error']:.3g} %."
            )
        )
    return h.page(
        f"{document.get('label')} · robot {robot}",
        h.run_subtitle(document),
        [
            h.section("verdicts", "Verdicts", *verdicts),
            h.section("parameters", "Parameters", _parameters(payload)),
            h.section("prediction", "Measured vs predicted", _traces(document, Path(folder))),
            h.section("run", "The run", run_details(document)),
        ],
    )
