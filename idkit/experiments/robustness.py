"""``idkit +experiment=robustness trials=1000``: a Monte-Carlo answer to the paper's conclusion.

The paper shows one noise draw per table and concludes that the mean of PSO-f13 and PSO-f14 is
more accurate than RLS-rel "in all four cases of error type". One draw cannot carry that claim, so
this study draws ``trials`` independent noise realisations per scenario (``simulate_batch``,
seeded: trial ``i`` depends only on ``(seed, i)``), fits every chosen estimator to each, and
reports per estimator and scenario:

* the median and 90th percentile of the **parameter error**, the mean absolute relative error
  over the parameters, ``mean_k |p̂_k − p_k| / |p_k|`` (``idkit.experiments.metrics``);
* the **win rate** against the baseline (RLS-rel): the share of trials in which the estimator's
  parameter error is smaller, ties left out, with a 95 % Wilson interval and the two-sided
  sign-test p-value (``scipy.stats.binomtest``, H0: win rate = 1/2).

The conclusion "holds" in a scenario when the whole Wilson interval lies above 1/2.

The PSO estimator's ``fit_costs`` batches all PSO costs of one trial into one computation; trials
are separate calls (the estimator API takes one sample set per problem).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from idkit import registry
from idkit.experiments import files, plots
from idkit.experiments.build import Spec, build, plain, split
from idkit.experiments.metrics import parameter_error
from idkit.experiments.paper import average_label, format_time

log = logging.getLogger(__name__)

SCENARIOS = ("state_noise", "torque_noise", "all_noise", "outliers")
CONFIDENCE = 0.95


@dataclass
class Comparison:
    """Sign test of one estimator against the baseline over paired trials."""

    wins: int
    losses: int
    ties: int
    win_rate: float
    ci_low: float
    ci_high: float
    p_value: float

    @classmethod
    def of(cls, errors: np.ndarray, baseline: np.ndarray) -> Comparison:
        from scipy.stats import binomtest

        wins, losses = int((errors < baseline).sum()), int((errors > baseline).sum())
        ties = len(errors) - wins - losses
        n = wins + losses
        if n == 0:
            return cls(wins, losses, ties, math.nan, math.nan, math.nan, math.nan)
        test = binomtest(wins, n, 0.5)
        ci = test.proportion_ci(confidence_level=CONFIDENCE, method="wilson")
        return cls(wins, losses, ties, wins / n, float(ci.low), float(ci.high), float(test.pvalue))

    @property
    def verdict(self) -> str:
        if math.isnan(self.win_rate):
            return "tie"
        if self.ci_low > 0.5:
            return "better"
        if self.ci_high < 0.5:
            return "worse"
        return "undecided"


@dataclass
class RobustnessStudy:
    """Per scenario and estimator: the trials' parameters ``[T, P]`` and parameter errors ``[T]``."""

    trials: int
    seed: int
    param_names: list[str]
    truth: np.ndarray
    params: dict[str, dict[str, np.ndarray]]
    baseline: str
    focus: str | None
    skipped: list[str] = field(default_factory=list)
    wall_time_s: float = 0.0
    fit_time_s: dict[str, float] = field(default_factory=dict)

    def errors(self, scenario: str, label: str) -> np.ndarray:
        return parameter_error(self.params[scenario][label], self.truth)

    def comparison(self, scenario: str, label: str) -> Comparison | None:
        if label == self.baseline or self.baseline not in self.params[scenario]:
            return None
        return Comparison.of(self.errors(scenario, label), self.errors(scenario, self.baseline))

    def rows(self) -> list[dict[str, Any]]:
        rows = []
        for scenario, by_label in self.params.items():
            for label in by_label:
                err = self.errors(scenario, label)
                cmp = self.comparison(scenario, label)
                rows.append(
                    {
                        "scenario": scenario,
                        "estimator": label,
                        "median": float(np.median(err)),
                        "p90": float(np.percentile(err, 90)),
                        "wins": None if cmp is None else cmp.wins,
                        "losses": None if cmp is None else cmp.losses,
                        "ties": None if cmp is None else cmp.ties,
                        "win_rate": None if cmp is None else cmp.win_rate,
                        "ci_low": None if cmp is None else cmp.ci_low,
                        "ci_high": None if cmp is None else cmp.ci_high,
                        "p_value": None if cmp is None else cmp.p_value,
                        "verdict": None if cmp is None else cmp.verdict,
                        "mean_fit_time_s": self.fit_time_s.get(label),
                    }
                )
        return rows

    def answer(self) -> str:
        """Does ``focus`` (the paper's f13/f14 average) beat the baseline in every scenario?"""
        if self.focus is None:
            return ""
        lines = []
        verdicts = []
        for scenario in self.params:
            cmp = self.comparison(scenario, self.focus)
            if cmp is None:
                continue
            verdicts.append(cmp.verdict)
            lines.append(
                f"- `{scenario}`: {self.focus} wins {100 * cmp.win_rate:.1f} % of {cmp.wins + cmp.losses} "
                f"trials against {self.baseline} (95 % CI {100 * cmp.ci_low:.1f}–{100 * cmp.ci_high:.1f} %, "
                f"sign test p = {cmp.p_value:.2g}) → {cmp.verdict}"
            )
        holds = bool(verdicts) and all(v == "better" for v in verdicts)
        head = (
            f"**Paper's conclusion ({self.focus} beats {self.baseline} in all four error cases): "
            f"{'holds' if holds else 'does not hold'}** over {self.trials} trials per scenario."
        )
        return "\n".join([head, "", *lines])

    def markdown(self) -> str:
        head = [
            "scenario",
            "estimator",
            "median",
            "90th pct",
            f"win rate vs {self.baseline} [95 % CI]",
            "sign test p",
            "mean fit time",
        ]
        lines = [
            f"### Robustness: {self.trials} noise draws per scenario (seed {self.seed})",
            "",
            "Parameter error = mean over parameters of |estimate − truth| / |truth|.",
            "",
            "| " + " | ".join(head) + " |",
            "|---|---|---:|---:|---:|---:|---:|",
        ]
        for row in self.rows():
            win = (
                ""
                if row["win_rate"] is None
                else f"{100 * row['win_rate']:.1f} % [{100 * row['ci_low']:.1f}, {100 * row['ci_high']:.1f}]"
            )
            p = "" if row["p_value"] is None else f"{row['p_value']:.2g}"
            fit = row["mean_fit_time_s"]
            fit_text = "" if fit is None else format_time(fit)
            lines.append(
                f"| {row['scenario']} | {row['estimator']} | {100 * row['median']:.2f} % | "
                f"{100 * row['p90']:.2f} % | {win} | {p} | {fit_text} |"
            )
        parts = ["\n".join(lines)]
        answer = self.answer()
        if answer:
            parts.append(answer)
        if self.skipped:
            parts.append(f"Skipped (plugin not installed): {', '.join(self.skipped)}.")
        parts.append(f"Wall time {self.wall_time_s:.1f} s.")
        return "\n\n".join(parts) + "\n"

    def save(self, out_dir: str | Path, make_plots: bool = True) -> dict[str, str]:
        out = Path(out_dir)
        rows = self.rows()
        header = list(rows[0]) if rows else []
        written = {
            "markdown": str(files.write_text(out / "robustness.md", self.markdown())),
            "csv": str(
                files.write_csv(out / "robustness.csv", header, ([r[k] for k in header] for r in rows))
            ),
        }
        trial_rows = []
        for scenario, by_label in self.params.items():
            for label, values in by_label.items():
                err = self.errors(scenario, label)
                trial_rows += [[scenario, t, label, *values[t].tolist(), err[t]] for t in range(len(values))]
        written["trials_csv"] = str(
            files.write_csv(
                out / "robustness_trials.csv",
                ["scenario", "trial", "estimator", *self.param_names, "error"],
                trial_rows,
            )
        )
        if make_plots:
            errors = {s: {label: self.errors(s, label) for label in by} for s, by in self.params.items()}
            written["boxplot"] = str(
                plots.boxplots(
                    errors,
                    out / "robustness_boxplot.png",
                    f"parameter error over {self.trials} noise draws"
                    " (boxes: quartiles; whiskers: 5th-95th percentile)",
                )
            )
        files.write_json(
            out / "result.json",
            {
                "task": "robustness",
                "trials": self.trials,
                "seed": self.seed,
                "baseline": self.baseline,
                "focus": self.focus,
                "truth": self.truth,
                "metric": "mean over parameters of |estimate - truth| / |truth|",
                "summary": rows,
                "skipped": self.skipped,
                "wall_time_s": self.wall_time_s,
                "files": written,
            },
        )
        return written


def load(run_dir: str | Path) -> RobustnessStudy:
    """Read a study back from its run directory (``result.json`` + ``robustness_trials.csv``).

    Works on a checkpoint of an interrupted study too; use it to re-render tables and plots.
    """
    import csv
    import json

    run_dir = Path(run_dir)
    meta = json.loads((run_dir / "result.json").read_text())
    found: dict[str, dict[str, list]] = {}
    with open(run_dir / "robustness_trials.csv", newline="") as handle:
        reader = csv.reader(handle)
        header = next(reader)
        names = header[3:-1]
        for row in reader:
            found.setdefault(row[0], {}).setdefault(row[2], []).append([float(v) for v in row[3:-1]])
    summary = meta.get("summary") or []
    fit_time = {r["estimator"]: r["mean_fit_time_s"] for r in summary if r.get("mean_fit_time_s") is not None}
    return RobustnessStudy(
        trials=meta["trials"],
        seed=meta["seed"],
        param_names=names,
        truth=np.asarray(meta["truth"], dtype=float),
        params={s: {k: np.asarray(v, dtype=float) for k, v in by.items()} for s, by in found.items()},
        baseline=meta["baseline"],
        focus=meta["focus"],
        skipped=meta.get("skipped", []),
        wall_time_s=meta["wall_time_s"],
        fit_time_s=fit_time,
    )


def merge(studies: Sequence[RobustnessStudy]) -> RobustnessStudy:
    """One study from several that ran disjoint scenarios (e.g. in parallel processes).

    Each scenario's draws depend only on the seed and the trial index, so the merge equals one
    run over all scenarios when the seeds and trial counts agree (checked). ``wall_time_s`` is the
    longest of the parts (they ran side by side).
    """
    first = studies[0]
    for other in studies[1:]:
        if (other.trials, other.seed, other.baseline) != (first.trials, first.seed, first.baseline):
            raise ValueError("robustness.merge: the studies differ in trials, seed or baseline")
        if set(other.params) & set(first.params):
            raise ValueError("robustness.merge: the studies share a scenario")
    params = {s: by for study in studies for s, by in study.params.items()}
    fit_time = {k: v for study in studies for k, v in study.fit_time_s.items()}
    return RobustnessStudy(
        trials=first.trials,
        seed=first.seed,
        param_names=first.param_names,
        truth=first.truth,
        params=params,
        baseline=first.baseline,
        focus=first.focus,
        skipped=first.skipped,
        wall_time_s=max(study.wall_time_s for study in studies),
        fit_time_s=fit_time,
    )


def _installed(kind: registry.Kind, spec: Any, optional: Sequence[str], skipped: list[str]) -> bool:
    spec = plain(spec)
    name = spec if isinstance(spec, str) else split(kind, spec)[0]
    if name in optional and name not in registry.available(kind):
        skipped.append(f"{kind} {name}")
        return False
    return True


def run(
    robot: Spec = "cylindrical",
    pso: Spec | None = "pso",
    *,
    trials: int = 100,
    scenarios: Sequence[str] = SCENARIOS,
    estimators: Sequence[Spec] = (
        {"_name_": "ls", "relative": True},
        "rls",
        {"_name_": "rls", "relative": True},
    ),
    pso_costs: Sequence[Spec] = ("f13", "f14"),
    average_of: Sequence[str] = ("f13", "f14"),
    baseline: str = "RLS-rel",
    optional: Sequence[str] = ("irls", "huber", "trimmed"),
    seed: int = 0,
    device: str = "cpu",
    dtype: str = "float64",
    progress: bool = True,
    checkpoint: str | Path | None = None,
    checkpoint_every_s: float = 60.0,
) -> RobustnessStudy:
    """Run the Monte-Carlo study.

    Args:
        robot: robot spec; its ``nominal_params`` are the truth.
        pso: spec of the estimator whose ``fit_costs`` runs ``pso_costs`` (``None``: no PSO).
        trials: noise draws per scenario.
        estimators: other estimators (specs), fitted to each trial one by one.
        pso_costs: costs for the PSO, all in one batched call per trial.
        average_of: costs whose PSO estimates are averaged (the paper's final estimate).
        baseline: label the others are compared with.
        optional: plugin names skipped (and reported) when not installed, e.g. third-party IRLS.
        seed: seed of the noise draws; trial ``i``'s estimators use ``seed + i``.
        checkpoint: folder where the tables of the trials done so far are saved, every
            ``checkpoint_every_s`` seconds (a long study that is interrupted still reports).
    """
    from tqdm import tqdm

    from idkit.data.scenarios import simulate_batch
    from idkit.problem import Problem

    started = time.perf_counter()
    skipped: list[str] = []
    robot_obj = build("robot", robot)
    est_objs = [build("estimator", s) for s in estimators if _installed("estimator", s, optional, skipped)]
    cost_specs = [c for c in pso_costs if _installed("cost", c, optional, skipped)]
    cost_objs = [build("cost", c) for c in cost_specs]
    cost_names = [type(c).__name__ for c in cost_objs]
    pso_obj = build("estimator", pso) if pso is not None and cost_objs else None
    focus = average_label(average_of) if pso_obj is not None and set(average_of) <= set(cost_names) else None
    truth = robot_obj.nominal_params().numpy()
    found: dict[str, dict[str, list]] = {scenario: {} for scenario in scenarios}
    fit_time: dict[str, float] = {}
    batches = {s: simulate_batch(robot_obj, s, trials=trials, seed=seed) for s in scenarios}

    def snapshot(done: int) -> RobustnessStudy:
        return RobustnessStudy(
            trials=done,
            seed=seed,
            param_names=list(robot_obj.param_names),
            truth=truth,
            params={s: {k: np.asarray(v, dtype=float) for k, v in by.items()} for s, by in found.items()},
            baseline=baseline,
            focus=focus,
            skipped=skipped,
            wall_time_s=time.perf_counter() - started,
            fit_time_s={k: v / (done * len(scenarios)) for k, v in fit_time.items()},
        )

    saved = time.perf_counter()
    bar = tqdm(total=trials * len(scenarios), desc="robustness", unit="trial", disable=not progress)
    # Trial-major order: an interrupted study has the same number of trials in every scenario.
    for t in range(trials):
        for scenario in scenarios:
            problem = Problem(
                robot_obj, batches[scenario][t], None, seed=seed + t, device=device, dtype=dtype
            )
            estimates = [est.fit(problem) for est in est_objs]
            if pso_obj is not None:
                by_cost = pso_obj.fit_costs(problem, cost_objs)
                estimates += by_cost
            for e in estimates:
                found[scenario].setdefault(e.estimator, []).append(list(e.params.values()))
                fit_time[e.estimator] = fit_time.get(e.estimator, 0.0) + e.wall_time_s
            if focus is not None:
                chosen = [by_cost[cost_names.index(c)].params for c in average_of]
                found[scenario].setdefault(focus, []).append(
                    np.mean([list(p.values()) for p in chosen], axis=0)
                )
            bar.update()
        if checkpoint is not None and time.perf_counter() - saved > checkpoint_every_s and t + 1 < trials:
            snapshot(t + 1).save(checkpoint, make_plots=False)  # survives an interrupted study
            saved = time.perf_counter()
    bar.close()
    return snapshot(trials)


def run_config(cfg: Any, run_dir: Path) -> RobustnessStudy:
    """The ``task=robustness`` entry of the command line."""
    r = cfg.robustness
    study = run(
        cfg.robot,
        cfg.estimator if r.pso_costs else None,
        trials=int(cfg.trials),
        scenarios=list(r.scenarios),
        estimators=plain(r.estimators),
        pso_costs=plain(r.pso_costs),
        average_of=list(r.average_of),
        baseline=r.baseline,
        optional=list(r.optional),
        seed=cfg.seed,
        device=cfg.device,
        dtype=cfg.dtype,
        checkpoint=run_dir,
    )
    written = study.save(run_dir, make_plots=cfg.plots)
    print(study.markdown())
    print(f"tables: {written['markdown']} and {written['csv']}")
    return study
