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

#: A held-out (or fit) position error up to the first multiple of the log's noise level is ``good`` (the
#: model reproduces the log as well as it is measured), above the second ``poor``; ``fair`` between.
NOISE_BANDS = (2.0, 5.0)
#: An estimate within this fraction of its bounds' width from a bound ended on it.
AT_BOUND = 1e-6


def grade(ratio: float) -> str:
    """``good``, ``fair`` or ``poor`` for an error over the noise level (:data:`NOISE_BANDS`)."""
    good, poor = NOISE_BANDS
    if not math.isfinite(ratio):
        return "poor"
    return "good" if ratio <= good else "fair" if ratio <= poor else "poor"


@dataclass(frozen=True)
class LogScore:
    """One log's errors per joint: ``robust`` (1.4826 × median absolute), ``rms`` and the log's ``noise``
    level, each ``{joint: (position, velocity)}``; ``mode``: how it was simulated, in words."""

    file: str
    mode: str
    robust: dict[str, tuple[float, float]]
    rms: dict[str, tuple[float, float]]
    noise: dict[str, tuple[float, float]]

    def ratio(self, joint: str) -> float:
        """The joint's robust position error over its position noise level."""
        error, noise = self.robust[joint][0], self.noise[joint][0]
        return error / noise if noise > 0 else (0.0 if error == 0 else math.inf)

    def worst(self) -> float:
        return max((self.ratio(j) for j in self.robust), default=math.nan)


@dataclass(frozen=True)
class Unknown:
    name: str
    kind: str
    start: float
    value: float
    std: float | None
    interval: tuple[float, float] | None
    bounds: tuple[float, float]

    @property
    def at_bound(self) -> str | None:
        """``"lower"`` or ``"upper"`` when the estimate ended on that bound."""
        low, high = self.bounds
        width = high - low
        if not math.isfinite(width):
            return None
        if self.value - low <= AT_BOUND * width:
            return "lower"
        if high - self.value <= AT_BOUND * width:
            return "upper"
        return None


@dataclass(frozen=True)
class RolloutRecord:
    """What a rollout run's ``result.json`` says, read once (:func:`record`)."""

    estimator: str
    unknowns: list[Unknown]
    flat: list[dict[str, Any]]
    model_limited: bool | None
    fit: list[LogScore]
    held_out: list[LogScore]
    rollouts: Any
    wall_time_s: float | None
    identified_xml_problem: str | None
    polish: list[dict[str, Any]] = field(default_factory=list)


def _mode(scores: Mapping[str, Any], start: str) -> str:
    if scores.get("mode"):
        return str(scores["mode"])
    count = scores.get("segments")
    if count == 1:
        return f"whole: one rollout from its first {start}"
    return f"in {count} segments, each from its {start}"


def _log_score(file: str, scores: Mapping[str, Any], start: str = "logged state") -> LogScore:
    def pairs(part: Mapping[str, Any]) -> dict[str, tuple[float, float]]:
        return {j: (float(part["q"][j]), float(part["qd"][j])) for j in part["q"]}

    return LogScore(
        file, _mode(scores, start), pairs(scores["robust"]), pairs(scores["rms"]), pairs(scores["noise"])
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
    described = payload.get("unknowns") or {}
    unknowns = []
    for name, value in estimate["params"].items():
        about = described.get(name) or {}
        bounds = about.get("bounds") or [-math.inf, math.inf]
        interval = intervals.get(name)
        unknowns.append(
            Unknown(
                name,
                str(about.get("kind", "")),
                float(about.get("start", math.nan)),
                float(value),
                None if std.get(name) is None else float(std[name]),
                None if interval is None else (float(interval[0]), float(interval[1])),
                (float(bounds[0]), float(bounds[1])),
            )
        )
    polish = list(details.get("polish") or [])
    fitted = bool(polish and polish[-1].get("initial_states_free"))
    fit_start = "initial state the fit estimated" if fitted else "logged state (a glitched one replaced)"
    return RolloutRecord(
        str(estimate.get("estimator")),
        unknowns,
        list(uncertainty.get("flat") or uncertainty.get("flat_directions") or []),
        uncertainty.get("model_limited"),
        [_log_score(f, s, fit_start) for f, s in (payload.get("fit") or {}).items()],
        [_log_score(f, s) for f, s in (payload.get("validation") or {}).items()],
        details.get("rollouts"),
        estimate.get("wall_time_s"),
        payload.get("identified_xml_problem"),
        polish,
    )


def flat_text(direction: Mapping[str, Any]) -> str:
    """A flat direction as a combination of unknowns (``j1.damping + 0.9·p1.kv``)."""
    return " + ".join(f"{w:g}·{n}" for n, w in direction["direction"].items())


def _scores_table(score: LogScore) -> str:
    rows = []
    for joint, (q, qd) in score.robust.items():
        ratio = score.ratio(joint)
        nq, nqd = score.noise[joint]
        rows.append(
            [
                joint,
                h.num(q, digits=3),
                h.num(nq, digits=3),
                h.num(ratio, grade(ratio), digits=3, shown=f"{ratio:.3g}×"),
                h.num(score.rms[joint][0], digits=3),
                h.num(qd, digits=3),
                h.num(nqd, digits=3),
            ]
        )
    header = ["joint", "q error", "q noise", "error / noise", "q RMS", "qd error", "qd noise"]
    return h.table(header, rows, "log-scores")


def _held_out(found: RolloutRecord) -> str:
    good, poor = NOISE_BANDS
    rule = h.paragraph(
        "Per joint: the position error (1.4826 × the median absolute error, rad or m; a few glitched "
        "samples do not move it) over the log's own noise level (from its 4th differences): at most "
        f"{good:g}× is good (the model follows the log as well as it is measured), above {poor:g}× poor. "
        "RMS: every sample counted. Velocities (rad/s or m/s) beside.",
        "rule",
    )
    if not found.held_out:
        return h.paragraph(
            "No held-out log (validate=): the model was not scored on a motion it did not see."
        ) + "".join(_log_part(s) for s in found.fit)
    return rule + "".join(_log_part(s) for s in found.held_out)


def _log_part(score: LogScore) -> str:
    worst = score.worst()
    badge = h.badge(grade(worst), f"worst joint {worst:.3g}× the noise")
    return (
        f"<h3>{h.escape(score.file)} {badge}</h3>"
        + h.paragraph(f"Simulated {score.mode}.", "rule")
        + _scores_table(score)
    )


def _model_limited(found: RolloutRecord) -> str:
    if found.model_limited is None:
        return h.paragraph(
            "Not assessed by this run: compare the fit log's error with its noise below (an error far "
            "above the noise means the model, not the noise, limits the fit, and the intervals are too "
            "narrow)."
        )
    if found.model_limited:
        return h.badge("poor", "model-limited") + h.paragraph(
            "The fit's residual is well above the noise: the model, not the noise, limits the fit; the "
            "intervals were widened for it."
        )
    return h.badge("good", "noise-limited") + h.paragraph("The fit's residual is at the noise level.")


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
    for k, score in enumerate(found.held_out, start=1):
        if f"validation_plot_{k}" in plots:
            name = Path(plots[f"validation_plot_{k}"]).name
            parts.append(
                f"<h3>held out: {h.escape(score.file)}</h3>"
                + h.paragraph(f"Simulated {score.mode}.", "rule")
                + h.png_file(folder / name, f"held-out {score.file}")
            )
    if "fit_plot" in plots:
        mode = found.fit[0].mode if found.fit else ""
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
        verdicts += ["<h3>The fit log, against its noise</h3>", *(_log_part(s) for s in found.fit)]
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
