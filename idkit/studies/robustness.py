"""A Monte-Carlo answer to the paper's conclusion (the ``robustness`` task).

``idkit +experiment=robustness trials=1000``. The paper shows one noise draw per table and concludes
that the mean of PSO-f13 and PSO-f14 is more accurate than RLS-rel "in all four cases of error
type". One draw cannot carry that claim, so this study draws ``trials`` independent noise
realisations per scenario (``simulate_batch``, seeded: trial ``i`` depends only on ``(seed, i)``),
fits every chosen estimator to each, and computes per estimator and scenario:

* the median and 90th percentile of the **parameter error**, the mean absolute relative error
  over the parameters, ``mean_k |p̂_k − p_k| / |p_k|`` (``idkit.studies.metrics``);
* the **win rate** against the baseline (RLS-rel): the share of trials in which the estimator's
  parameter error is smaller, ties left out, with a 95 % Wilson interval and the two-sided
  sign-test p-value (``scipy.stats.binomtest``, H0: win rate = 1/2).

Verdicts (:attr:`Comparison.verdict`): ``better`` when the sign test rejects H0 at 5 % *and* the
whole interval lies above 1/2, ``worse`` likewise below, ``undecided`` otherwise — an interval that
straddles 1/2 never counts as a loss. The conclusion (:meth:`RobustnessStudy.conclusion`) "holds"
when every scenario is ``better``, "does not hold" when one is ``worse``, else "undecided".

The search estimator's ``fit_costs`` batches all its costs of one trial into one computation; trials
are separate calls (the estimator API takes one sample set per problem).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from idkit import registry
from idkit.data.presets import PAPER_SCENARIOS
from idkit.studies.average import average_label, mean_params
from idkit.studies.build import Spec, build, describe, name_and_options
from idkit.studies.labels import unique_labels
from idkit.studies.metrics import parameter_error
from idkit.studies.result import Provenance, StudyInterrupted, new_run_id

#: Per-trial parameters and errors, written by ``idkit.reports.robustness`` and read by :func:`load`.
TRIALS_FILE = "robustness_trials.csv"
CONFIDENCE = 0.95
ALPHA = 1 - CONFIDENCE


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
        """Compare parameter errors ``[T]`` with the baseline's ``[T]`` (same trials)."""
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
        """``better``/``worse`` only when the interval and the sign test agree; else ``undecided``."""
        if math.isnan(self.win_rate):
            return "undecided"
        significant = self.p_value < ALPHA
        if significant and self.ci_low > 0.5:
            return "better"
        if significant and self.ci_high < 0.5:
            return "worse"
        return "undecided"


def conclusion(verdicts: Sequence[str]) -> str:
    """``holds`` if every verdict is ``better``, ``does not hold`` if one is ``worse``, else ``undecided``."""
    if verdicts and all(v == "better" for v in verdicts):
        return "holds"
    if "worse" in verdicts:
        return "does not hold"
    return "undecided"


@dataclass
class RobustnessStudy:
    """Per scenario and estimator: the trials' parameters ``[T, P]`` and parameter errors ``[T]``.

    ``provenance.done`` trials of ``provenance.requested`` are in (fewer: interrupted).
    """

    provenance: Provenance
    param_names: list[str]
    truth: np.ndarray
    params: dict[str, dict[str, np.ndarray]]
    baseline: str
    focus: str | None
    skipped: list[str] = field(default_factory=list)
    wall_time_s: float = 0.0
    fit_time_s: dict[str, float] = field(default_factory=dict)

    @property
    def trials(self) -> int:
        return self.provenance.done

    @property
    def seed(self) -> int:
        return self.provenance.seed

    def errors(self, scenario: str, label: str) -> np.ndarray:
        return parameter_error(self.params[scenario][label], self.truth)

    def comparison(self, scenario: str, label: str) -> Comparison | None:
        if label == self.baseline or self.baseline not in self.params[scenario]:
            return None
        return Comparison.of(self.errors(scenario, label), self.errors(scenario, self.baseline))

    def rows(self) -> list[dict[str, Any]]:
        """One summary row per (scenario, estimator)."""
        rows = []
        for scenario, by_label in self.params.items():
            for label in by_label:
                err = self.errors(scenario, label)
                cmp = self.comparison(scenario, label)
                row: dict[str, Any] = {
                    "scenario": scenario,
                    "estimator": label,
                    "median": float(np.median(err)) if len(err) else None,
                    "p90": float(np.percentile(err, 90)) if len(err) else None,
                }
                for key in ("wins", "losses", "ties", "win_rate", "ci_low", "ci_high", "p_value"):
                    row[key] = None if cmp is None else getattr(cmp, key)
                row["verdict"] = None if cmp is None else cmp.verdict
                row["mean_fit_time_s"] = self.fit_time_s.get(label)
                rows.append(row)
        return rows

    def focus_comparisons(self) -> dict[str, Comparison]:
        """Per scenario, ``focus`` against the baseline."""
        if self.focus is None:
            return {}
        found = {s: self.comparison(s, self.focus) for s in self.params if self.focus in self.params[s]}
        return {s: c for s, c in found.items() if c is not None}

    def conclusion(self) -> str | None:
        """Does ``focus`` beat the baseline in every scenario? (see the module docstring)."""
        found = self.focus_comparisons()
        return conclusion([c.verdict for c in found.values()]) if found else None

    def payload(self) -> dict[str, Any]:
        return {
            "trials": self.trials,
            "baseline": self.baseline,
            "focus": self.focus,
            "conclusion": self.conclusion(),
            "param_names": self.param_names,
            "truth": self.truth,
            "metric": "mean over parameters of |estimate - truth| / |truth|",
            "summary": self.rows(),
            "skipped": self.skipped,
            "wall_time_s": self.wall_time_s,
        }


def load(run_dir: str | Path) -> RobustnessStudy:
    """Read a study back from its run directory (``result.json`` + ``robustness_trials.csv``).

    Works on the files of an interrupted study too; use it to re-render tables and plots or to
    :func:`merge` parts that ran in parallel.
    """
    import csv
    import json

    run_dir = Path(run_dir)
    document = json.loads((run_dir / "result.json").read_text())
    meta = document["payload"]
    found: dict[str, dict[str, list]] = {}
    with open(run_dir / TRIALS_FILE, newline="") as handle:
        reader = csv.reader(handle)
        header = next(reader)
        names = header[3:-1]
        for row in reader:
            found.setdefault(row[0], {}).setdefault(row[2], []).append([float(v) for v in row[3:-1]])
    fit_time = {r["estimator"]: r["mean_fit_time_s"] for r in meta["summary"] if r.get("mean_fit_time_s")}
    progress = document["progress"]
    provenance = Provenance(
        task="robustness",
        label=document["label"],
        seed=document["seed"],
        data=document["data"],
        plugins=document["plugins"],
        requested=progress["requested"],
        done=progress["done"],
        unit=progress["unit"],
        config=document["config"],
        run_id=document["run_id"],
    )
    return RobustnessStudy(
        provenance=provenance,
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
        if (other.provenance.data or {}).get("scenario") != (first.provenance.data or {}).get("scenario"):
            raise ValueError("robustness.merge: the studies set different scenario fields (e.g. excitation)")
    params = {s: by for study in studies for s, by in study.params.items()}
    scenarios = [s for study in studies for s in (study.provenance.data or {}).get("scenarios", [])]
    return replace(
        first,
        provenance=replace(
            first.provenance,
            data={**(first.provenance.data or {}), "scenarios": scenarios},
            requested=min(s.provenance.requested for s in studies),
            run_id=new_run_id(),
        ),
        params=params,
        wall_time_s=max(study.wall_time_s for study in studies),
        fit_time_s={k: v for study in studies for k, v in study.fit_time_s.items()},
    )


def _installed(kind: registry.Kind, spec: Any, optional: Sequence[str], skipped: list[str]) -> bool:
    name = name_and_options(kind, spec)[0]
    if name in optional and name not in registry.available(kind):
        skipped.append(f"{kind} {name}")
        return False
    return True


def run(
    robot: Spec = "cylindrical",
    estimator: Spec | None = "pso",
    *,
    trials: int = 100,
    scenarios: Sequence[str] = PAPER_SCENARIOS,
    estimators: Sequence[Spec] = (
        {"_name_": "ls", "relative": True},
        "rls",
        {"_name_": "rls", "relative": True},
    ),
    pso_costs: Sequence[Spec] = ("f13", "f14"),
    average_of: Sequence[str] = ("f13", "f14"),
    baseline: str = "RLS-rel",
    optional: Sequence[str] = ("irls", "huber", "trimmed"),
    scenario: Mapping[str, Any] | None = None,
    seed: int = 0,
    device: str = "cpu",
    dtype: str = "float64",
    progress: bool = True,
    checkpoint: Callable[[RobustnessStudy], Any] | None = None,
    checkpoint_every_s: float = 60.0,
) -> RobustnessStudy:
    """Run the Monte-Carlo study.

    Args:
        robot: robot spec; its ``nominal_params`` are the truth.
        estimator: spec of the search estimator whose ``fit_costs`` runs ``pso_costs`` (``None``:
            none).
        trials: noise draws per scenario.
        estimators: other estimators (specs), fitted to each trial one by one.
        pso_costs: costs of the search estimator, all in one batched call per trial.
        average_of: costs whose estimates are averaged (the paper's final estimate).
        baseline: label the others are compared with.
        optional: plugin names skipped (and reported) when not installed, e.g. third-party IRLS.
        scenario: fields set on every scenario, e.g. ``{"excitation": "excitation.yaml"}`` (the
            motion, ``idkit.data.scenarios.shared_fields``).
        seed: seed of the noise draws; trial ``i``'s estimators use ``seed + i``.
        checkpoint: called with the study so far every ``checkpoint_every_s`` seconds (the command
            line writes the partial report, so a long study that dies still reports).

    Raises:
        StudyInterrupted: on Ctrl-C, carrying the trials finished so far in every scenario.
    """
    from tqdm import tqdm

    from idkit.data.scenarios import shared_fields, simulate_batch
    from idkit.problem import Problem

    common = shared_fields(scenario, "robustness")
    started = time.perf_counter()
    skipped: list[str] = []
    robot_obj = build("robot", robot)
    est_specs = [s for s in estimators if _installed("estimator", s, optional, skipped)]
    cost_specs = [c for c in pso_costs if _installed("cost", c, optional, skipped)] if estimator else []
    labels = unique_labels(
        [(s, None, False) for s in est_specs] + [(estimator, c, True) for c in cost_specs], "robustness"
    )
    est_objs = [build("estimator", s) for s in est_specs]
    cost_objs = [build("cost", c) for c in cost_specs]
    cost_names = [name_and_options("cost", c)[0] for c in cost_specs]
    search = build("estimator", estimator) if cost_objs else None
    focus = average_label(average_of) if average_of and set(average_of) <= set(cost_names) else None
    truth = robot_obj.nominal_params().numpy()
    found: dict[str, dict[str, list]] = {scenario: {} for scenario in scenarios}
    fit_time: dict[str, float] = {}
    batches = {s: simulate_batch(robot_obj, s, trials=trials, seed=seed, **common) for s in scenarios}
    provenance = Provenance(
        task="robustness",
        label=f"robustness vs {baseline}",
        seed=seed,
        data={"scenarios": list(scenarios), **({"scenario": common} if common else {})},
        plugins={
            "robot": describe("robot", robot),
            "estimator": describe("estimator", estimator) if search is not None else None,
        },
        requested=trials,
        done=0,
        unit="trial",
    )

    def snapshot(done: int) -> RobustnessStudy:
        return RobustnessStudy(
            provenance=replace(provenance, done=done),
            param_names=list(robot_obj.param_names),
            truth=truth,
            params={
                s: {k: np.asarray(v[:done], dtype=float) for k, v in by.items()} for s, by in found.items()
            },
            baseline=baseline,
            focus=focus,
            skipped=skipped,
            wall_time_s=time.perf_counter() - started,
            fit_time_s={k: v / max(done * len(scenarios), 1) for k, v in fit_time.items()},
        )

    saved = time.perf_counter()
    bar = tqdm(total=trials * len(scenarios), desc="robustness", unit="trial", disable=not progress)
    done = 0
    try:
        # Trial-major order: an interrupted study has the same number of trials in every scenario.
        for t in range(trials):
            for scenario in scenarios:
                problem = Problem(
                    robot_obj, batches[scenario][t], None, seed=seed + t, device=device, dtype=dtype
                )
                fitted = [est.fit(problem) for est in est_objs]
                if search is not None:
                    fitted += search.fit_costs(problem, cost_objs)
                for label, e in zip(labels, fitted, strict=True):
                    found[scenario].setdefault(label, []).append(list(e.params.values()))
                    fit_time[label] = fit_time.get(label, 0.0) + e.wall_time_s
                if focus is not None:
                    searched = fitted[len(est_objs) :]
                    chosen = [searched[cost_names.index(c)].params for c in average_of]
                    found[scenario].setdefault(focus, []).append(list(mean_params(chosen).values()))
                bar.update()
            done = t + 1
            if checkpoint is not None and time.perf_counter() - saved > checkpoint_every_s and done < trials:
                checkpoint(snapshot(done))
                saved = time.perf_counter()
    except KeyboardInterrupt:
        raise StudyInterrupted(snapshot(done)) from None
    finally:
        bar.close()
    return snapshot(trials)
