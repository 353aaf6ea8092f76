"""PNG plots for the run directory (matplotlib, headless ``Agg`` backend).

Plots are where people would rather look than read: convergence (best cost vs iteration), the
estimates against the truth, and the robustness study's error distributions.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from idkit.reports.files import save_figure

if TYPE_CHECKING:
    import numpy as np


def _subplots(*args: Any, figsize: tuple[float, float], **kwargs: Any) -> tuple[Any, Any]:
    """``pyplot.subplots`` without pyplot: a bare ``Figure``, rendered by Agg when saved.

    Importing pyplot (backend selection, its state machine) took about a third of matplotlib's
    import time on the single-fit command (``bench/latency.py``); a figure needs none of it.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(*args, **kwargs)


def convergence(header: Sequence[str], rows: Sequence[Sequence[float]], title: str, path: Path) -> Path:
    """Best cost vs iteration, one line per history column, log scale when all values are > 0."""
    fig, ax = _subplots(figsize=(6, 3.5))
    iterations = [row[0] for row in rows]
    positive = True
    for j, name in enumerate(header[1:], start=1):
        values = [row[j] for row in rows]
        positive = positive and all(v is not None and v > 0 for v in values)
        ax.plot(iterations, values, lw=1, label=name)
    if positive:
        ax.set_yscale("log")
    ax.set(xlabel="iteration", ylabel="best cost", title=title)
    if len(header) > 2:
        ax.legend(fontsize="small", ncol=2)
    return save_figure(fig, path)


#: Axis limits hold the values between these quantiles widened by ``ROBUST_REACH`` times their
#: spread (Tukey's fences on the 10th-90th percentile range); a value beyond is drawn at the edge.
ROBUST_QUANTILES = (0.1, 0.9)
ROBUST_REACH = 1.5


def robust_limits(values: Sequence[float], reference: float) -> tuple[float, float]:
    """Axis limits that show the bulk of ``values`` and ``reference``: one wild value (a TLS
    estimate 70 times the truth) must not squeeze every other method onto one line."""
    import numpy as np

    finite = np.asarray([v for v in values if np.isfinite(v)] + [reference], dtype=float)
    low, high = np.quantile(finite, ROBUST_QUANTILES)
    spread = max(high - low, 0.05 * max(abs(reference), 1e-12))
    low = max(low - ROBUST_REACH * spread, finite.min())
    high = min(high + ROBUST_REACH * spread, finite.max())
    low, high = min(low, reference), max(high, reference)
    if high - low < spread:  # values all alike: a window of the minimum spread around them
        middle = (low + high) / 2
        low, high = middle - spread / 2, middle + spread / 2
    pad = 0.05 * (high - low)
    return float(low - pad), float(high + pad)


def mark_beyond(ax: Any, xs: Sequence[float], ys: Sequence[float], limits: tuple[float, float]) -> int:
    """Draw each point outside ``limits`` at the nearer edge, as a red triangle pointing out of the
    plot and labelled with its value; returns how many there were."""
    low, high = limits
    beyond = 0
    for x, y in zip(xs, ys, strict=True):
        if low <= y <= high or y != y:
            continue
        edge, marker, align = (high, "^", "top") if y > high else (low, "v", "bottom")
        ax.scatter([x], [edge], s=40, marker=marker, color="red", zorder=3, clip_on=False)
        ax.annotate(f"{y:.3g}", (x, edge), fontsize=6, color="red", ha="center", va=align,
                    xytext=(0, -6 if align == "top" else 6), textcoords="offset points")  # fmt: skip
        beyond += 1
    return beyond


def estimates_vs_truth(
    estimates: Mapping[str, Mapping[str, float]], truth: Mapping[str, float], title: str, path: Path
) -> Path:
    """Per parameter, each method's estimate divided by the truth (1 = exact), on axes that hold
    the bulk of the estimates (:func:`robust_limits`; the few beyond are marked at the edge)."""
    names = [n for n in truth if truth[n] != 0]
    fig, ax = _subplots(figsize=(max(5, 0.35 * len(estimates) + 3), 3.8))
    markers = "os^Dv<>pP*"
    points = []
    for j, name in enumerate(names):
        xs, ys = [], []
        for i, params in enumerate(estimates.values()):
            xs.append(i + (j - (len(names) - 1) / 2) * 0.12)
            ys.append(params[name] / truth[name])
        points.append((xs, ys))
    limits = robust_limits([y for _, ys in points for y in ys], 1.0)
    for j, (name, (xs, ys)) in enumerate(zip(names, points, strict=True)):
        inside = [(x, y) for x, y in zip(xs, ys, strict=True) if limits[0] <= y <= limits[1]]
        ax.scatter([x for x, _ in inside], [y for _, y in inside], s=18, marker=markers[j % len(markers)],
                   label=name)  # fmt: skip
    beyond = sum(mark_beyond(ax, xs, ys, limits) for xs, ys in points)
    ax.set_ylim(*limits)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xticks(range(len(estimates)), list(estimates), rotation=60, ha="right", fontsize="small")
    if beyond:
        title += f"\n{beyond} beyond the axis: red triangles at the edge, with their values"
    ax.set(ylabel="estimate / true value", title=title)
    ax.legend(fontsize="small")
    return save_figure(fig, path)


def boxplots(
    errors: Mapping[str, Mapping[str, Sequence[float] | np.ndarray]], path: Path, title: str
) -> Path:
    """One panel per scenario: the distribution of each estimator's parameter error (log scale)."""
    import numpy as np

    scenarios = list(errors)
    n_methods = max(len(v) for v in errors.values())
    fig, axes = _subplots(
        1, len(scenarios), figsize=(max(4, 0.45 * n_methods + 1.5) * len(scenarios), 4), squeeze=False
    )
    for ax, scenario in zip(axes[0], scenarios, strict=True):
        labels = list(errors[scenario])
        data = [np.clip(np.asarray(errors[scenario][m], dtype=float), 1e-6, 1e6) for m in labels]
        ax.boxplot(data, whis=(5, 95), showfliers=False)
        ax.set_xticks(range(1, len(labels) + 1), labels, rotation=60, ha="right", fontsize="small")
        ax.set_yscale("log")
        ax.set_title(scenario)
        ax.grid(axis="y", alpha=0.3)
    axes[0][0].set_ylabel("mean |relative parameter error|")
    fig.suptitle(title)
    return save_figure(fig, path)


def traces(
    times: np.ndarray,
    measured: np.ndarray,
    predicted: Mapping[str, np.ndarray],
    title: str,
    path: Path,
    joint_names: Sequence[str] | None = None,
    unit: str | Sequence[str] = "N·m",
    residuals: bool = True,
) -> Path:
    """Per joint, a measured signal ``[N, n]`` against predictions ``[N, n]`` over ``times[N]`` and,
    under it (``residuals``), each prediction's residual ``measured − predicted``: the misfit a
    summary number hides (a joint whose friction model fails) shows there.

    Args:
        joint_names: the ``n`` joints' names for the axes (``None``: ``joint 1``, ``joint 2``, …).
        unit: of the signal, for the axes: one for all joints, or one per joint (N·m on a revolute
            joint, N on a prismatic one).
    """
    n = measured.shape[1]
    names = list(joint_names) if joint_names is not None else [f"joint {j + 1}" for j in range(n)]
    units = [unit] * n if isinstance(unit, str) else list(unit)
    rows = 2 * n if residuals else n
    heights = [3, 1.4] * n if residuals else [1] * n
    fig, axes = _subplots(
        rows, 1, figsize=(10, (2.2 if residuals else 2.0) * n), sharex=True, squeeze=False,
        gridspec_kw={"height_ratios": heights},
    )  # fmt: skip
    step = 2 if residuals else 1
    for j in range(n):
        ax = axes[step * j, 0]
        ax.plot(times, measured[:, j], "k", lw=2.0, label="measured")
        for label, values in predicted.items():
            ax.plot(times, values[:, j], lw=1.0, label=label)
        ax.set_ylabel(f"{names[j]} ({units[j]})", fontsize="small")
        ax.legend(fontsize=7, loc="upper right")
        if residuals:
            below = axes[step * j + 1, 0]
            below.axhline(0.0, color="k", lw=0.6)
            for k, values in enumerate(predicted.values()):
                below.plot(times, measured[:, j] - values[:, j], lw=0.8, color=f"C{k}")
            below.set_ylabel("residual", fontsize="x-small")
    axes[-1, 0].set_xlabel("time (s)")
    fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path)


def motion_against_limits(
    grid: np.ndarray,
    motion: Sequence[np.ndarray],
    lower: np.ndarray,
    upper: np.ndarray,
    samples: tuple[np.ndarray, Sequence[np.ndarray]],
    joint_names: Sequence[str],
    title: str,
    path: Path,
    inner: tuple[np.ndarray, np.ndarray] | None = None,
) -> Path:
    """A motion against its box: rows ``q``, ``q̇``, ``q̈``, one column per joint.

    Args:
        grid: dense times ``[G]``; ``motion``: ``(q, qd, qdd)``, each ``[G, n]``.
        lower, upper: the limits ``[3, n]`` (``±inf`` lines are not drawn).
        samples: ``(t[N], (q, qd, qdd))`` at the sample times, drawn as dots.
        inner: the limits less their safety margins ``(lower, upper)``, each ``[3, n]``, dotted.
    """
    import numpy as np

    n = len(joint_names)
    fig, axes = _subplots(3, n, figsize=(3.2 * n, 6.5), sharex=True, squeeze=False)
    t_samples, at_samples = samples
    for v, label in enumerate(("q", "qd", "qdd")):
        for j, ax in enumerate(axes[v]):
            ax.plot(grid, motion[v][:, j], lw=1.0)
            ax.plot(t_samples, at_samples[v][:, j], "o", ms=3, color="C1")
            for bound in (lower[v, j], upper[v, j]):
                if np.isfinite(bound):
                    ax.axhline(bound, color="r", lw=0.8, ls="--")
            for bound in () if inner is None else (inner[0][v, j], inner[1][v, j]):
                if np.isfinite(bound):
                    ax.axhline(bound, color="r", lw=0.6, ls=":")
            ax.set_ylabel(f"{label} {joint_names[j]}" if j == 0 or n > 1 else label, fontsize="small")
            if v == 0:
                ax.set_title(joint_names[j], fontsize="small")
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path)
