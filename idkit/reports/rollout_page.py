"""``report.html`` of a rollout run: verdicts first, then the numbers they rest on.

Built from the run's ``result.json`` document and the figures beside it, so the page of a finished run
can be made again from its folder. :func:`record` is the one reader of a rollout payload (the compare
page reads it too); the rules that grade it are here, once. In order:

1. **Verdicts**: each held-out log's error per joint against its own noise level, in the mode it was
   scored in (named); whether the fit is model-limited; unknowns that ended at a bound; flat directions;
   the fit log's residual against its noise;
2. **parameters**: start, estimate, σ, 95 % interval and bounds of every unknown;
3. **logged vs simulated** per log, the residual under each joint;
4. **the fit** (search and polish) and **the run** (data, plugins, config, files).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from idkit.reports import html as h
from idkit.reports.single_page import run_details
from idkit.sim.uncertainty import LINKS

#: A record without verdicts (written before :mod:`idkit.sim.validation` scored held-out logs) is graded by
#: its threshold: a joint is ``within noise`` when its robust position error is at most this many times
#: the log's noise level.
WITHIN = 2.0
#: An estimate within this fraction of its bounds' width from a bound ended on it (a record that does not
#: name its unknowns at a bound).
AT_BOUND = 1e-6


def grade(verdict: str) -> str:
    """The colour of a recorded verdict: ``good`` within the noise, else ``poor``."""
    return "good" if verdict == "within noise" else "poor"


def _verdict(ratio: float) -> str:
    if not math.isfinite(ratio):
        return "diverged"
    return "within noise" if ratio <= WITHIN else f"{ratio:.2g}× noise"


@dataclass(frozen=True)
class LogScore:
    """One log simulated one way at one set of values, per joint: ``robust`` (1.4826 × median absolute
    error), ``rms``, the log's ``noise`` level, each ``{joint: (position, velocity)}``; ``reference``: what
    the position error is held against (a perfect model's error, or the noise level), ``ratio`` and
    ``verdicts`` as recorded (or by :data:`WITHIN`).

    Attributes:
        mode: ``segments`` or ``whole``; ``described``: how it was simulated, in words.
        values: ``fitted``, or ``start`` (the model before the fit).
        default: the mode the log's verdict is read from; ``reason``: why.
    """

    file: str
    mode: str
    described: str
    values: str
    default: bool
    reason: str
    robust: dict[str, tuple[float, float]]
    rms: dict[str, tuple[float, float]]
    noise: dict[str, tuple[float, float]]
    reference: dict[str, float]
    reference_name: str
    ratio: dict[str, float]
    verdicts: dict[str, str]

    @property
    def worst(self) -> str:
        """The joint with the largest ratio."""
        return max(self.ratio, key=lambda j: self.ratio[j] if math.isfinite(self.ratio[j]) else math.inf)

    @property
    def verdict(self) -> str:
        joint = self.worst
        said = self.verdicts[joint]
        return said if said == "within noise" else f"{said} ({joint})"


@dataclass(frozen=True)
class Unknown:
    name: str
    kind: str
    start: float
    value: float
    std: float | None
    interval: tuple[float, float] | None
    bounds: tuple[float, float]
    at_bound: str | None  # "lower" or "upper"


@dataclass(frozen=True)
class RolloutRecord:
    """What a rollout run's ``result.json`` says, read once (:func:`record`)."""

    estimator: str
    unknowns: list[Unknown]
    flat: list[dict[str, Any]]
    model_limited: bool | None
    misfit: float | None
    uncertainty_reason: str
    heavier_links: dict[str, float]
    fit: list[LogScore]
    held_out: list[LogScore]
    rollouts: Any
    wall_time_s: float | None
    identified_xml_problem: str | None
    polish: list[dict[str, Any]] = field(default_factory=list)

    def verdicts(self) -> list[LogScore]:
        """Per held-out log, the score its verdict is read from: the default mode at the fitted values."""
        return [s for s in self.held_out if s.default and s.values == "fitted"]


def _described(mode: str, segments: Any, horizon: Any, start: str) -> str:
    if mode == "whole":
        return f"whole: one rollout from its first {start}"
    span = f" of {horizon:g} s" if isinstance(horizon, (int, float)) else ""
    return f"in {segments} segments{span}, each from its {start}"


def _score(file: str, s: Mapping[str, Any], start: str = "logged state") -> LogScore:
    """A log's score: the held-out record of :mod:`idkit.sim.validation` (``robust_q`` …, ``ratio``,
    ``verdicts``), or the older per-log record (``robust: {q, qd}`` …) graded by :data:`WITHIN`."""
    if "robust_q" in s:
        joints = list(s["robust_q"])

        def pair(q: str, qd: str) -> dict[str, tuple[float, float]]:
            return {j: (float(s[q][j]), float(s[qd][j])) for j in joints}

        mode = str(s["mode"])
        return LogScore(
            file, mode, _described(mode, s.get("segments"), s.get("horizon"), "logged state"),
            str(s.get("values", "fitted")), bool(s.get("default", True)), str(s.get("reason") or ""),
            pair("robust_q", "robust_qd"), pair("rms_q", "rms_qd"), pair("noise_q", "noise_qd"),
            {j: float(v) for j, v in (s.get("expected_q") or s["noise_q"]).items()},
            "perfect model's error" if s.get("expected_q") else "noise level",
            {j: float(v) for j, v in s["ratio"].items()}, dict(s["verdicts"]),
        )  # fmt: skip

    def pairs(part: Mapping[str, Any]) -> dict[str, tuple[float, float]]:
        return {j: (float(part["q"][j]), float(part["qd"][j])) for j in part["q"]}

    robust, noise = pairs(s["robust"]), pairs(s["noise"])
    ratio = {
        j: robust[j][0] / noise[j][0] if noise[j][0] > 0 else (0.0 if robust[j][0] == 0 else math.inf)
        for j in robust
    }
    mode = "whole" if s.get("segments") == 1 else "segments"
    return LogScore(
        file, mode, _described(mode, s.get("segments"), None, start), "fitted", True, "",
        robust, pairs(s["rms"]), noise, {j: n[0] for j, n in noise.items()}, "noise level",
        ratio, {j: _verdict(r) for j, r in ratio.items()},
    )  # fmt: skip


def _side(value: float, bounds: tuple[float, float]) -> str | None:
    low, high = bounds
    width = high - low
    if not math.isfinite(width):
        return None
    return (
        "lower" if value - low <= AT_BOUND * width else "upper" if high - value <= AT_BOUND * width else None
    )


def record(document: Mapping[str, Any]) -> RolloutRecord:
    """The rollout payload of a ``result.json`` document, typed: the one place that reads one."""
    payload = document["payload"]
    estimate = payload["estimate"]
    details = estimate.get("details") or {}
    nested = details.get("uncertainty")
    uncertainty: Mapping[str, Any] = nested if isinstance(nested, Mapping) else details
    std = uncertainty.get("std") or uncertainty.get("sigma") or {}
    intervals = uncertainty.get("interval95") or uncertainty.get("ci95") or {}
    named_at_bound = uncertainty.get("at_bound")
    described = payload.get("unknowns") or {}
    unknowns = []
    for name, value in estimate["params"].items():
        about = described.get(name) or {}
        low, high = about.get("bounds") or [-math.inf, math.inf]
        bounds, interval = (float(low), float(high)), intervals.get(name)
        side = _side(float(value), bounds)
        if named_at_bound is not None:  # the fit's own list is the rule; the side is the nearer bound
            side = (
                (side or ("lower" if value - low <= high - value else "upper"))
                if name in named_at_bound
                else None
            )
        unknowns.append(
            Unknown(
                name, str(about.get("kind", "")), float(about.get("start", math.nan)), float(value),
                None if std.get(name) is None else float(std[name]),
                None if interval is None else (float(interval[0]), float(interval[1])), bounds, side,
            )
        )  # fmt: skip
    polish = list(details.get("polish") or [])
    fitted = bool(polish and polish[-1].get("initial_states_free"))
    fit_start = "initial state the fit estimated" if fitted else "logged state (a glitched one replaced)"
    held_out = [
        _score(file, s)
        for file, scores in (payload.get("validation") or {}).items()
        for s in (scores if isinstance(scores, list) else [scores])
    ]
    misfit = uncertainty.get("misfit")
    return RolloutRecord(
        str(estimate.get("estimator")),
        unknowns,
        list(uncertainty.get("flat") or uncertainty.get("flat_directions") or []),
        uncertainty.get("model_limited"),
        None if misfit is None else float(misfit),
        str(uncertainty.get("uncertainty_reason") or uncertainty.get("reason") or ""),
        {k: float(v) for k, v in (uncertainty.get("heavier_links") or {}).items()},
        [_score(f, s, fit_start) for f, s in (payload.get("fit") or {}).items()],
        held_out,
        details.get("rollouts"),
        estimate.get("wall_time_s"),
        payload.get("identified_xml_problem"),
        polish,
    )


def flat_text(direction: Mapping[str, Any]) -> str:
    """A flat direction as a combination of unknowns (``j1.damping + 0.9·p1.kv``)."""
    return " + ".join(f"{w:g}·{n}" for n, w in direction["direction"].items())


def _scores_table(score: LogScore, start: LogScore | None = None) -> str:
    """Per joint: the position error against its reference, the verdict, the start values' error beside
    (the model before the fit, where recorded), the RMS, the velocity error and noise."""
    rows = []
    for joint, (q, qd) in score.robust.items():
        verdict = score.verdicts[joint]
        ratio = score.ratio[joint]
        row = [
            joint,
            h.num(q, digits=3),
            h.num(score.reference[joint], digits=3),
            h.num(ratio, grade(verdict), digits=3, shown=f"{ratio:.3g}×"),
            h.Cell(h.escape(verdict), None, grade(verdict)),
        ]
        if start is not None:
            row.append(h.num(start.robust[joint][0], digits=3))
        row += [
            h.num(score.rms[joint][0], digits=3),
            h.num(qd, digits=3),
            h.num(score.noise[joint][1], digits=3),
        ]
        rows.append(row)
    header = ["joint", "q error", score.reference_name, "ratio", "verdict"]
    header += ["q error, start values"] if start is not None else []
    return h.table(header + ["q RMS", "qd error", "qd noise"], rows, "log-scores")


def _held_out(found: RolloutRecord) -> str:
    rule = h.paragraph(
        "Per joint: the position error (1.4826 × the median absolute error, rad or m; a few glitched "
        "samples do not move it) against what it is held to — a perfect model's error on this log (its "
        "noise, and in segments the start state's noise carried forward), or the log's noise level — "
        "within noise up to twice that. RMS: every sample counted. Velocities (rad/s or m/s) beside.",
        "rule",
    )
    if not found.held_out:
        return h.paragraph(
            "No held-out log (validate=): the model was not scored on a motion it did not see."
        ) + "".join(_log_part(s, []) for s in found.fit)
    return rule + "".join(_log_part(score, found.held_out) for score in found.verdicts())


def _log_part(score: LogScore, every: list[LogScore]) -> str:
    """A log's verdict (its default mode at the fitted values), then its other modes."""
    same = [s for s in every if s.file == score.file]
    start = next((s for s in same if s.mode == score.mode and s.values == "start"), None)
    badge = h.badge(grade(score.verdict), score.verdict)
    parts = [
        f"<h3>{h.escape(score.file)} {badge}</h3>",
        h.paragraph(
            f"Simulated {score.described}" + (f" — the default: {score.reason}" if score.reason else "."),
            "rule",
        ),
        _scores_table(score, start),
    ]
    for other in (s for s in same if s.mode != score.mode and s.values == "fitted"):
        other_start = next((s for s in same if s.mode == other.mode and s.values == "start"), None)
        parts += [
            h.paragraph(f"Also simulated {other.described}: {other.verdict}.", "rule"),
            _scores_table(other, other_start),
        ]
    return "".join(parts)


def _model_limited(found: RolloutRecord) -> str:
    said = found.uncertainty_reason or (
        "" if found.misfit is None else f"Residual {found.misfit:.3g}× the noise level."
    )
    if found.model_limited is None:
        verdict = h.paragraph(
            "Not assessed by this run: compare the fit log's error with its noise below (an error far "
            "above the noise means the model, not the noise, limits the fit, and the intervals are too "
            "narrow)."
        )
    elif found.model_limited:
        verdict = h.badge("poor", "model-limited") + h.paragraph(
            "The model, not the noise, limits the fit: its residual is far above the noise or structured. "
            + said
        )
    else:
        verdict = h.badge("good", "noise-limited") + h.paragraph(said or "The fit's residual is the noise.")
    if found.heavier_links:
        moves = sorted(found.heavier_links.items(), key=lambda item: -abs(item[1]))
        rows = [[name, h.num(move, digits=3, shown=f"{100 * move:+.3g} %")] for name, move in moves]
        verdict += h.paragraph(
            f"Were every link {100 * LINKS:g} % heavier (a model error a log may not show), the estimates "
            "would move by:",
            "rule",
        ) + h.table(["unknown", "move"], rows, "heavier-links")
    return verdict


def _bounds(found: RolloutRecord) -> str:
    hits = [(u, u.at_bound) for u in found.unknowns if u.at_bound]
    if not hits:
        return h.paragraph("None: every estimate ended inside its bounds.")
    rows = [[u.name, side, h.num(u.value), h.num(u.bounds[0]), h.num(u.bounds[1])] for u, side in hits]
    return h.paragraph(
        "An estimate on a bound is the bound, not what the log says: widen it (rollout.bounds) or ask "
        "why the log pushes there (units, a stalled log, a missing effect).",
        "rule",
    ) + h.table(["unknown", "bound", "estimate", "lower", "upper"], rows, "bound-hits")


def _flat(found: RolloutRecord) -> str:
    if not found.flat:
        return h.paragraph("None: the log separates every unknown.")
    items = [
        f"{h.escape(flat_text(d))} <span class='rule'>(σ {h.number(d.get('sigma'), 3)} in log "
        "coordinates)</span>"
        for d in found.flat
    ]
    return h.paragraph(
        "Combinations the log cannot tell from noise: those unknowns are not separately identifiable "
        "from this motion (a richer motion, or fixing one of them, helps).",
        "rule",
    ) + h.listing(items)


def _parameters(found: RolloutRecord) -> str:
    rows = []
    for u in found.unknowns:
        low, high = u.interval if u.interval is not None else (None, None)
        interval = "—" if low is None else f"[{h.number(low, 5)}, {h.number(high, 5)}]"
        rows.append(
            [
                u.name,
                u.kind,
                h.num(u.start, digits=4),
                h.num(u.value, "poor" if u.at_bound else ""),
                h.num(u.std, digits=3),
                h.Cell(h.escape(interval), None, "num"),
                h.Cell(h.escape(f"[{h.number(u.bounds[0], 4)}, {h.number(u.bounds[1], 4)}]"), None, "num"),
            ]
        )
    header = ["unknown", "kind", "start", "estimate", "σ", "95 % interval", "bounds"]
    return h.table(header, rows, "parameters")


def _traces(document: Mapping[str, Any], found: RolloutRecord, folder: Path) -> str:
    plots = document.get("files") or {}
    if not any(key == "fit_plot" or key.startswith("validation_plot") for key in plots):
        return h.paragraph("Plots were not written for this run (plots=false).")
    parts = []
    for k, score in enumerate(found.verdicts(), start=1):
        if f"validation_plot_{k}" in plots:
            name = Path(plots[f"validation_plot_{k}"]).name
            parts.append(
                f"<h3>held out: {h.escape(score.file)}</h3>"
                + h.paragraph(f"Simulated {score.described}.", "rule")
                + h.png_file(folder / name, f"held-out {score.file}")
            )
    if "fit_plot" in plots:
        mode = found.fit[0].described if found.fit else ""
        parts.append(
            "<h3>fit log</h3>"
            + h.paragraph(f"Simulated {mode}.", "rule")
            + h.png_file(folder / Path(plots["fit_plot"]).name, "fit log")
        )
    return "".join(parts)


def _fit(document: Mapping[str, Any], found: RolloutRecord, folder: Path) -> str:
    lines = [
        f"{found.rollouts} rollouts in {h.number(found.wall_time_s, 3)} s.",
    ]
    for k, stage in enumerate(found.polish, start=1):
        losses = stage.get("losses") or []
        last = f", loss {h.number(losses[-1], 4)}" if losses else ""
        lines.append(
            f"Polish solve {k}: {stage.get('segments')} segments, initial states "
            f"{'free' if stage.get('initial_states_free') else 'logged'}, {stage.get('iterations')} "
            f"Jacobians{last}, stopped: {stage.get('stop')}."
        )
    parts = [h.listing(h.escape(line) for line in lines)]
    plots = document.get("files") or {}
    if "convergence_plot" in plots:
        parts.append(h.png_file(folder / Path(plots["convergence_plot"]).name, "search convergence"))
    return "".join(parts)


def render(document: Mapping[str, Any], folder: str | Path) -> str:
    """The page of a ``rollout`` run's ``result.json`` ``document``; figures from ``folder``."""
    found = record(document)
    folder = Path(folder)
    model = (document.get("data") or {}).get("model", "?")
    verdicts = [
        "<h3>Held-out prediction</h3>" if found.held_out else "<h3>Prediction of the fit log</h3>",
        _held_out(found),
        "<h3>Model-limited?</h3>",
        _model_limited(found),
        "<h3>Estimates on a bound</h3>",
        _bounds(found),
        "<h3>Flat directions</h3>",
        _flat(found),
    ]
    if found.held_out and found.fit:
        verdicts += ["<h3>The fit log, against its noise</h3>", *(_log_part(s, []) for s in found.fit)]
    if found.identified_xml_problem:
        verdicts.append(h.paragraph(f"identified.xml not written: {found.identified_xml_problem}", "poor"))
    return h.page(
        f"{document.get('label')} · model {model}",
        h.run_subtitle(document),
        [
            h.section("verdicts", "Verdicts", *verdicts),
            h.section("parameters", "Parameters", _parameters(found)),
            h.section("prediction", "Logged vs simulated", _traces(document, found, folder)),
            h.section("fit", "The fit", _fit(document, found, folder)),
            h.section("run", "The run", run_details(document)),
        ],
    )
