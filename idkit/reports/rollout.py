"""The ``rollout`` task's report: a text table, ``result.json``, ``identified.xml`` and trajectory plots.

The table lists each unknown's start, estimate, standard deviation and 95 % interval, then the flat
directions (what the log cannot separate), then per log the RMS error of each joint's position beside
the log's noise level (robust: 1.4826 × the median absolute error, which glitched samples do not
move; it is the noise level when the model reproduces the log within the noise). Plots: per log, each
joint's logged and simulated position and the residual
below it (``fit.png``; ``validation_<k>.png``), and the search's convergence (``convergence.png``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from idkit.estimate import history_table
from idkit.reports import files
from idkit.reports import plots as figures
from idkit.reports.result_file import claim, write_result
from idkit.studies.rollout import Replay, RolloutResult

MJCF_FILE = "identified.xml"


def text(result: RolloutResult) -> str:
    """Estimate with uncertainty, flat directions, and the replayed logs' errors."""
    est = result.estimate
    sigma = est.details.get("sigma", {})
    interval = est.details.get("ci95", {})
    lines = [
        f"{est.estimator} · model {(result.provenance.data or {}).get('model')} · seed {result.seed}",
        f"{'unknown':<22}{'start':>11}{'estimate':>12}{'std':>11}{'95 % interval':>26}",
    ]
    for name, value in est.params.items():
        low, high = interval.get(name, [math.nan, math.nan])
        start = result.unknowns[name]["start"]
        lines.append(
            f"{name:<22}{start:11.4g}{value:12.6g}{sigma.get(name, math.nan):11.3g}"
            f"  [{low:11.5g}, {high:11.5g}]"
        )
    flat = est.details.get("flat_directions") or []
    lines.append("flat directions: " + ("none" if not flat else ""))
    for direction in flat:
        combination = " + ".join(f"{w:g}·{n}" for n, w in direction["direction"].items())
        lines.append(f"  {combination} (std {direction['sigma']:.3g} in log coordinates)")
    lines.append(f"wall time {est.wall_time_s:.2f} s · {est.details.get('rollouts')} rollouts")
    for label, replayed in [
        ("fit log, in segments", result.fit),
        *(("held out, whole", r) for r in result.validation),
    ]:
        lines += ["", f"{label}: {replayed.file}", _errors(replayed)]
    if result.mjcf_problem:
        lines += ["", f"identified.xml not written: {result.mjcf_problem}"]
    return "\n".join(lines)


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
        for k, replayed in enumerate(result.validation, start=1):
            path = out / f"validation_{k}.png"
            written[f"validation_plot_{k}"] = str(
                trajectories(replayed, f"{label}: held out {replayed.file}", path)
            )
        if found is not None:
            written["convergence_plot"] = str(
                figures.convergence(*found, title=f"{label}: search", path=out / "convergence.png")
            )
    models = {"identified_mjcf": (MJCF_FILE, result.mjcf)} if result.mjcf is not None else None
    return write_result(out, result.provenance, result.payload(), written, models=models)


def trajectories(replayed: Replay, title: str, path: Path) -> Path:
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
