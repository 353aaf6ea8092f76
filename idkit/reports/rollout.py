"""The ``rollout`` task's report: a text table, ``result.json``, ``report.html``
(:mod:`idkit.reports.rollout_page`), ``identified.xml`` and trajectory plots.

The table lists each unknown's start, estimate, standard deviation and 95 % interval, then the flat
directions (what the log cannot separate) and whether the noise or the model limits the fit, then the
fit log's errors per joint beside its noise level (robust: 1.4826 × the median absolute error, which
glitched samples do not move), then each held-out log in every mode that applies
(:mod:`idkit.sim.validation`), the fitted and the start values side by side, the default verdict
first. Plots: per log (a held-out log in its default mode), each
joint's logged and simulated position and the residual
below it (``fit.png``; ``validation_<k>.png``), and the search's convergence (``convergence.png``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from idkit.estimate import history_table
from idkit.reports import files, rollout_page
from idkit.reports import plots as figures
from idkit.reports.result_file import claim, write_result
from idkit.sim.uncertainty import LINKS
from idkit.sim.validation import HeldOut
from idkit.studies.rollout import Replay, RolloutResult

MJCF_FILE = "identified.xml"


def text(result: RolloutResult) -> str:
    """Estimate with uncertainty, flat directions, and the replayed logs' errors."""
    est, details = result.estimate, result.details
    sigma = {} if details is None else details.uncertainty.std
    interval = {} if details is None else details.uncertainty.interval95
    lines = [
        f"{est.estimator} · model {(result.provenance.data or {}).get('model')} · seed {result.seed}",
        f"{'unknown':<22}{'start':>11}{'estimate':>12}{'std':>11}{'95 % interval':>26}",
    ]
    for name, value in est.params.items():
        low, high = interval.get(name, (math.nan, math.nan))
        start = result.unknowns[name]["start"]
        lines.append(
            f"{name:<22}{start:11.4g}{value:12.6g}{sigma.get(name, math.nan):11.3g}"
            f"  [{low:11.5g}, {high:11.5g}]"
        )
    flat = [] if details is None else details.uncertainty.flat
    lines.append("flat directions: " + ("none" if not flat else ""))
    for direction in flat:
        combination = " + ".join(f"{w:g}·{n}" for n, w in direction["direction"].items())
        lines.append(f"  {combination} (std {direction['sigma']:.3g} in log coordinates)")
    rollouts = "?" if details is None else details.rollouts
    if details is not None and details.uncertainty.reason:
        u = details.uncertainty
        limited = "MODEL-LIMITED" if u.model_limited else "noise-limited"
        lines.append(
            f"uncertainty: {limited} (residual {u.misfit:.3g}× the noise level, lag-1 autocorrelation "
            f"{u.autocorrelation:.2f}, stretches disagree {u.disagreement:.3g}× what noise explains)"
        )
        lines.append(f"  {u.reason}")
        if u.heavier_links:
            moves = ", ".join(
                f"{k} {v:+.2%}" for k, v in sorted(u.heavier_links.items(), key=lambda i: -abs(i[1]))[:6]
            )
            lines.append(
                f"were every link {LINKS:.0%} heavier (a model error a log may not show), "
                f"the fit would move: {moves}"
            )
        if u.at_bound:
            lines.append(
                "at a bound of its box (the log may want a value beyond it): " + ", ".join(u.at_bound)
            )
    lines.append(f"wall time {est.wall_time_s:.2f} s · {rollouts} rollouts")
    if details is not None and any(details.outliers.values()):
        found = details.outliers
        lines.append(
            f"left out as the driver's: {found.get('stalled', 0)} stalled rows in {found.get('stalls', 0)} "
            f"stretches, {found.get('dropped', 0)} samples missing in gaps"
        )
    lines += ["", f"fit log, in segments: {result.fit.file}", _errors(result.fit)]
    for file in dict.fromkeys(r.file for r in result.validation):
        lines += ["", *_held_out([r for r in result.validation if r.file == file])]
    if result.mjcf_problem:
        lines += ["", f"identified.xml not written: {result.mjcf_problem}"]
    return "\n".join(lines)


def _held_out(records: list[HeldOut]) -> list[str]:
    """One held-out log: per mode, each joint's robust position error at the fitted and at the start
    values beside what a perfect model scores, and the verdicts; the default mode first and named."""
    default = next(r for r in records if r.default)
    lines = [f"held out: {default.file} · default {default.mode}: {default.reason}"]
    for mode in sorted({r.mode for r in records}, key=lambda m: m != default.mode):
        fitted = next(r for r in records if r.mode == mode and r.values == "fitted")
        start = next((r for r in records if r.mode == mode and r.values == "start"), None)
        span = f"{fitted.segments} segments of {fitted.horizon:g} s" if mode == "segments" else "whole"
        marker = "default verdict" if mode == default.mode else "also"
        lines.append(
            f"  {span} ({marker}): fitted {fitted.verdict}" + (f" · start {start.verdict}" if start else "")
        )
        heads = ("q fitted", "q start", "RMS fitted", "RMS start", "perfect", "verdict (fitted)")
        lines.append(f"  {'joint':<12}" + "".join(f"{h:>12}" for h in heads[:5]) + f"  {heads[5]}")
        for j, joint in enumerate(fitted.joints):
            cells = (
                fitted.robust[j],
                start.robust[j] if start else math.nan,
                fitted.rms[j],
                start.rms[j] if start else math.nan,
                fitted.expected[j],
            )
            lines.append(
                f"  {joint:<12}" + "".join(f"{c:12.3g}" for c in cells) + f"  {fitted.verdicts[joint]}"
            )
    return lines


def _errors(replayed: Replay) -> str:
    """Per joint: the robust and RMS error of position and velocity, beside the log's noise level."""
    n = len(replayed.joints)
    rms, robust, noise = replayed.rms, replayed.robust, replayed.noise
    rows = [
        f"{'joint':<12}"
        + "".join(f"{h:>10}" for h in ("q robust", "q RMS", "q noise", "qd robust", "qd RMS", "qd noise"))
    ]
    for j, joint in enumerate(replayed.joints):
        cells = (robust[j], rms[j], noise[j], robust[n + j], rms[n + j], noise[n + j])
        rows.append(f"{joint:<12}" + "".join(f"{c:10.3g}" for c in cells))
    return "\n".join(rows)


def write(result: RolloutResult, out_dir: str | Path, plots: bool = True) -> dict[str, str]:
    """Write ``identified.xml``, ``history.csv``, plots and ``result.json``.

    Raises:
        FileExistsError: ``out_dir`` holds another run's result (nothing is written).
    """
    out = claim(out_dir, result.provenance)
    written: dict[str, str] = {}
    found = history_table(result.estimate.details.get("history"))
    if found is not None:
        written["history"] = str(files.write_csv(out / "history.csv", *found))
    if plots:
        label = result.estimate.estimator
        written["fit_plot"] = str(trajectories(result.fit, f"{label}: fit log (segments)", out / "fit.png"))
        shown = [r for r in result.validation if r.default and r.values == "fitted"]
        for k, replayed in enumerate(shown, start=1):
            path = out / f"validation_{k}.png"
            written[f"validation_plot_{k}"] = str(
                trajectories(replayed, f"{label}: held out {replayed.file} ({replayed.mode})", path)
            )
        if found is not None:
            written["convergence_plot"] = str(
                figures.convergence(*found, title=f"{label}: search", path=out / "convergence.png")
            )
    models = {"identified_mjcf": (MJCF_FILE, result.mjcf)} if result.mjcf is not None else None
    return write_result(
        out,
        result.provenance,
        result.payload(),
        written,
        lambda document: rollout_page.render(document, out),
        models=models,
    )


def trajectories(replayed: Replay | HeldOut, title: str, path: Path) -> Path:
    """Each joint's logged and simulated position, and the residual below it."""
    import matplotlib.pyplot as plt

    n = len(replayed.joints)
    fig, axes = plt.subplots(2 * n, 1, figsize=(9, 2.2 * n + 1), sharex=True, squeeze=False)
    t = replayed.t
    for j, joint in enumerate(replayed.joints):
        top, bottom = axes[2 * j, 0], axes[2 * j + 1, 0]
        top.plot(t, replayed.measured[:, j], ".", markersize=1.5, label="logged")
        top.plot(t, replayed.simulated[:, j], "-", linewidth=0.8, label="simulated")
        top.set_ylabel(f"{joint} q")
        residual = replayed.measured[:, j] - replayed.simulated[:, j]
        bottom.plot(t, residual, ".", markersize=1.5, color="tab:red")
        limit = 5 * max(float(np.median(np.abs(residual))) * 1.4826, replayed.noise[j], 1e-12)
        bottom.set_ylim(-limit, limit)  # glitches beyond the noise level are clipped, not scaled to
        bottom.set_ylabel("residual")
    axes[0, 0].legend(loc="upper right", fontsize="small")
    axes[-1, 0].set_xlabel("t (s)")
    fig.suptitle(title)
    fig.tight_layout()
    return files.save_figure(fig, path)
