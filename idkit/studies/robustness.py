"""A Monte-Carlo answer to the paper's conclusion (the ``robustness`` task).

``idkit +experiment=robustness trials=1000``. The paper shows one noise draw per table and concludes
that the mean of PSO-f13 and PSO-f14 is more accurate than RLS-rel "in all four cases of error
type". One draw cannot carry that claim, so this study draws ``trials`` independent noise
realisations per scenario (``simulate_batch``, seeded: trial ``i`` depends only on ``(seed, i)``),
fits every chosen estimator to each, and computes per estimator and scenario:

* the median and 90th percentile of the **parameter error**, the mean absolute relative error
  over the parameters, ``mean_k |p̂_k − p_k| / |p_k|`` (``idkit.studies.metrics``);
* the **win rate** against the baseline (RLS-rel): the share of trials in which the estimator's
  parameter error is smaller, ties left out, with its exact (Clopper-Pearson) 95 % interval and the
  two-sided sign-test p-value (``scipy.stats.binomtest``, H0: win rate = 1/2).

Verdicts (:attr:`Comparison.verdict`), one rule read off the printed interval: ``better`` when the
whole interval lies above 1/2, ``worse`` when below, ``undecided`` when it holds 1/2. The exact
interval is the one the sign test inverts, so the p-value printed beside it is below 5 % exactly when
the interval excludes 1/2 (a Wilson interval, used before, could exclude 1/2 at p ≥ 0.05, and the
line then read "undecided" under an interval of 36.3–49.9 %). The conclusion
(:meth:`RobustnessStudy.conclusion`) "holds" when every scenario is ``better``, "does not hold"
when one is ``worse``, else "undecided".

Trials are fitted in chunks through ``idkit.estimators.trials.fit_trials``: the search estimator
stacks trials × costs × runs into one batched swarm, the LS family and IRLS stack the chunk's
linear systems, and third-party estimators without ``fit_trials`` are fitted trial by trial.
``shard``/``shards`` split the trials into contiguous slices for parallel jobs, which
:func:`merge` joins (the multirun callback does it).

Size: the noise draws of every scenario are made up front (trial ``i`` depends only on ``(seed,
i)``), so memory grows with ``trials``. Before drawing, :func:`memory_needed` estimates the bytes
from the measured model below and ``idkit.memory.check_memory`` refuses, in one line with the
estimate and the machine's available memory, a study that cannot fit (the default study with
``trials=1e9``: ~21 TB).
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
from idkit.estimators.aggregate import average_label, average_params
from idkit.memory import check_memory
from idkit.registry import NAME_KEY
from idkit.seeds import Seed, trial_seed
from idkit.studies import robustness_trials as trials_csv
from idkit.studies.build import Spec, build, constructor_options, describe, name_and_options
from idkit.studies.labels import unique_labels
from idkit.studies.metrics import parameter_error
from idkit.studies.result import Provenance, StudyInterrupted, new_run_id

#: Trials per step of the study (``run(chunk=...)``).
DEFAULT_CHUNK = 50
CONFIDENCE = 0.95
ALPHA = 1 - CONFIDENCE
#: The study's memory model, in bytes per trial. The draws of every scenario stay for the whole
#: study: 17 B per sample component (one joint's q, qd, qdd or tau at one sample: the noisy value
#: and the drawn error in float64, the outlier flag), and drawing one scenario needs about 40 B per
#: component more for a moment. The estimates kept per trial, scenario and label are a row of Python
#: floats and, at the end, an array. How the constants were measured, and the model checked against
#: a study's peak memory: docs/studies.md, "The robustness study in batches and in shards".
DRAW_BYTES_KEPT = 17
DRAW_BYTES_PEAK = 40
ESTIMATE_BYTES = 64
PARAMETER_BYTES = 40


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
        ci = test.proportion_ci(confidence_level=CONFIDENCE, method="exact")
        return cls(wins, losses, ties, wins / n, float(ci.low), float(ci.high), float(test.pvalue))

    @property
    def verdict(self) -> str:
        """``better``/``worse`` when the interval lies wholly above/below 1/2; else ``undecided``."""
        if math.isnan(self.win_rate):
            return "undecided"
        if self.ci_low > 0.5:
            return "better"
        if self.ci_high < 0.5:
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
    sharding: dict[str, int] = field(default_factory=dict)

    @property
    def first_trial(self) -> int:
        """Index of this study's first trial (non-zero for a shard)."""
        return self.sharding.get("first_trial", 0)

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
            "sharding": self.sharding,
        }


def load(run_dir: str | Path) -> RobustnessStudy:
    """Read a study back from its run directory (``result.json`` + the per-trial CSV,
    ``idkit.studies.robustness_trials``).

    Works on the files of an interrupted study too; use it to re-render tables and plots or to
    :func:`merge` parts that ran in parallel.

    Raises:
        ValueError: the per-trial CSV does not hold the trials ``result.json`` says were done.
    """
    import json

    run_dir = Path(run_dir)
    document = json.loads((run_dir / "result.json").read_text())
    meta, progress = document["payload"], document["progress"]
    first = (meta.get("sharding") or {}).get("first_trial", 0)
    names = list(meta["param_names"])
    params = trials_csv.read(run_dir / trials_csv.FILE, names, range(first, first + progress["done"]))
    fit_time = {r["estimator"]: r["mean_fit_time_s"] for r in meta["summary"] if r.get("mean_fit_time_s")}
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
        params=params,
        baseline=meta["baseline"],
        focus=meta["focus"],
        skipped=meta.get("skipped", []),
        wall_time_s=meta["wall_time_s"],
        fit_time_s=fit_time,
        sharding=meta.get("sharding") or {},
    )


def merge(studies: Sequence[RobustnessStudy]) -> RobustnessStudy:
    """One study from several that ran in parallel: disjoint scenarios, or shards of the trials.

    Each draw depends only on the seed and the trial index, so the merge equals one run over
    everything when the seeds agree (checked). Shards (``run(shard=k, shards=K)``) must cover the
    same scenarios with contiguous trials; their trials are concatenated in order (an interrupted
    shard is kept only as the last). Studies over disjoint scenarios must have equal trial counts.
    ``wall_time_s`` is the longest of the parts (they ran side by side).
    """
    if not studies:
        raise ValueError("robustness.merge: nothing to merge")
    first = studies[0]
    for other in studies[1:]:
        if (other.seed, other.baseline) != (first.seed, first.baseline):
            raise ValueError("robustness.merge: the studies differ in seed or baseline")
        if (other.provenance.data or {}).get("scenario") != (first.provenance.data or {}).get("scenario"):
            raise ValueError("robustness.merge: the studies set different scenario fields (e.g. excitation)")
    if all(set(s.params) == set(first.params) for s in studies) and len(studies) > 1:
        return _merge_shards(sorted(studies, key=lambda s: s.first_trial))
    for other in studies[1:]:
        if other.trials != first.trials or set(other.params) & set(first.params):
            raise ValueError("robustness.merge: the studies differ in trials or share a scenario")
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


def _merge_shards(shards: Sequence[RobustnessStudy]) -> RobustnessStudy:
    """Shards sorted by their first trial, concatenated into one study from trial 0."""
    expected = 0
    for index, shard in enumerate(shards):
        if shard.first_trial != expected:
            raise ValueError(
                f"robustness.merge: shards must cover contiguous trials; trial {expected} is missing "
                f"(a shard starts at {shard.first_trial})"
            )
        if shard.trials < shard.provenance.requested and index < len(shards) - 1:
            raise ValueError(f"robustness.merge: the shard starting at trial {shard.first_trial} is partial")
        expected += shard.trials
    first, total = shards[0], sum(s.trials for s in shards)
    requested = max(s.sharding.get("total_trials", s.first_trial + s.provenance.requested) for s in shards)
    params = {
        scenario: {label: np.concatenate([s.params[scenario][label] for s in shards]) for label in by}
        for scenario, by in first.params.items()
    }
    fit_time = {
        label: sum(s.fit_time_s.get(label, 0.0) * s.trials for s in shards) / max(total, 1)
        for label in first.fit_time_s
    }
    return replace(
        first,
        provenance=replace(first.provenance, requested=requested, done=total, run_id=new_run_id()),
        params=params,
        wall_time_s=max(s.wall_time_s for s in shards),
        fit_time_s=fit_time,
        sharding={
            "shard": 0,
            "shards": 1,
            "first_trial": 0,
            "total_trials": requested,
            "merged": len(shards),
        },
    )


def _installed(kind: registry.Kind, spec: Any, optional: Sequence[str], skipped: list[str]) -> bool:
    name = name_and_options(kind, spec)[0]
    if name in optional and name not in registry.available(kind):
        skipped.append(f"{kind} {name}")
        return False
    return True


def _without_history(spec: Spec | None) -> Spec | None:
    """``spec`` with ``history=False`` where its estimator takes that option: the study reports each
    fit's parameters only, never its record of every run's convergence, which would cost a share of
    its time (docs/speed.md). A ready object is kept as it is."""
    name, options = name_and_options("estimator", spec) if spec is not None else (None, {})
    if name is None or "history" not in constructor_options(registry.load("estimator", name)):
        return spec
    return {NAME_KEY: name, **options, "history": False}


def shard_trials(trials: int, shard: int, shards: int) -> range:
    """The trials shard ``shard`` of ``shards`` fits: a contiguous slice of ``range(trials)``.

    Contiguous slices in shard order concatenate to ``range(trials)``, so :func:`merge` of the
    shards is the one-process study.

    Raises:
        ValueError: ``trials`` or ``shards`` below 1, ``shard`` outside ``[0, shards)``, or more
            shards than trials.
    """
    for name, value, low in (
        ("trials", trials, 1),
        ("robustness.shards", shards, 1),
        ("robustness.shard", shard, 0),
    ):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    if shard >= shards:
        raise ValueError(f"robustness.shard must be below robustness.shards={shards}, got {shard}")
    if shards > trials:
        raise ValueError(
            f"robustness.shards={shards} exceeds trials={trials}: a shard would have no trial; use at "
            f"most {trials} shard{'s' if trials > 1 else ''}"
        )
    return range(trials * shard // shards, trials * (shard + 1) // shards)


def memory_needed(
    robot: Any, scenarios: Sequence[Any], common: Mapping[str, Any], drawn: int, fitted: int, labels: int
) -> int:
    """Bytes the study needs at its peak for ``drawn`` trials' noise draws and ``fitted`` trials'
    estimates under ``labels`` labels, by the measured model of the module's constants: the kept
    draws, plus the larger of the moment one scenario is drawn and the estimates that grow after it.

    Args:
        robot: the study's robot (joints and parameters).
        scenarios: the scenarios (names, ``Scenario`` or mappings), ``common`` set on each.
        drawn: trials drawn (a shard draws every trial up to its last).
        fitted: trials fitted (the shard's).
        labels: estimate columns kept per scenario.
    """
    from idkit.data.scenarios import get_scenario
    from idkit.problem import SAMPLE_ARRAYS

    components = [
        len(SAMPLE_ARRAYS) * get_scenario(s, **common).n_samples * robot.n_joints for s in scenarios
    ]
    drawing = drawn * DRAW_BYTES_PEAK * max(components)
    estimates = fitted * len(scenarios) * labels * (ESTIMATE_BYTES + PARAMETER_BYTES * robot.n_params)
    return drawn * DRAW_BYTES_KEPT * sum(components) + max(drawing, estimates)


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
    chunk: int = DEFAULT_CHUNK,
    shard: int = 0,
    shards: int = 1,
    seed: Seed = 0,
    device: str = "cpu",
    dtype: str = "float64",
    progress: bool = True,
    checkpoint: Callable[[RobustnessStudy], Any] | None = None,
    checkpoint_every_s: float = 60.0,
) -> RobustnessStudy:
    """Run the Monte-Carlo study.

    Trials are fitted ``chunk`` at a time: per scenario, every estimator gets the chunk's trials
    in one ``fit_trials`` call (``idkit.estimators.trials``), so the search estimator stacks
    trials × costs × runs into one batched swarm and the others batch as far as they know how.
    Each trial's numbers depend only on ``(seed, trial)`` and the configuration — not on ``chunk``
    nor on the sharding (tested).

    Args:
        robot: robot spec; its ``nominal_params`` are the truth.
        estimator: spec of the search estimator that runs ``pso_costs`` (``None``: none).
        trials: noise draws per scenario.
        estimators: other estimators (specs), fitted to every trial.
        pso_costs: costs of the search estimator, all batched together.
        average_of: costs whose estimates are averaged (the paper's final estimate).
        baseline: label the others are compared with.
        optional: plugin names skipped (and reported) when not installed, e.g. third-party IRLS.
        scenario: fields set on every scenario, e.g. ``{"excitation": "excitation.yaml"}`` (the
            motion, ``idkit.data.scenarios.shared_fields``).
        chunk: trials per step: bounds memory, and sets how often the progress bar moves and a
            checkpoint or Ctrl-C can take the finished trials.
        shard, shards: fit only shard ``shard`` of ``shards`` contiguous slices of the trials
            (Hydra multirun jobs; the sweep's callback merges them into one report).
        seed: seed of the noise draws; trial ``i``'s estimators use ``seed + i`` (modulo ``2**64``).
        checkpoint: called with the study so far every ``checkpoint_every_s`` seconds (the command
            line writes the partial report, so a long study that dies still reports).

    Raises:
        StudyInterrupted: on Ctrl-C, carrying the chunks finished so far in every scenario.
    """
    from tqdm import tqdm

    from idkit.data.scenarios import get_scenario, shared_fields, simulate_batch
    from idkit.estimators.trials import check_chunk, fit_trials
    from idkit.excitation.spec import scenario_excitation
    from idkit.problem import Problem

    common = shared_fields(scenario, "robustness")
    started = time.perf_counter()
    check_chunk(chunk)
    mine = shard_trials(trials, shard, shards)
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
    estimator = _without_history(estimator)
    search = build("estimator", estimator) if cost_objs else None
    focus = average_label(average_of) if average_of and set(average_of) <= set(cost_names) else None
    columns = len(labels) + (focus is not None)
    compared = [*labels, *([focus] if focus else [])]
    if baseline not in compared:
        absent = f" (skipped, not installed: {', '.join(skipped)})" if skipped else ""
        raise ValueError(
            f"robustness: baseline {baseline!r} is none of the study's estimates: {', '.join(compared)}"
            f"{absent}; the win rates are against the baseline, name one of them"
        )
    check_memory(
        f"robustness: trials={trials} ({len(scenarios)} scenario(s) x {columns} estimates per trial)",
        memory_needed(robot_obj, scenarios, common, mine.stop, len(mine), columns),
        "lower trials",
    )
    truth = robot_obj.nominal_params().numpy()
    found: dict[str, dict[str, list]] = {scenario: {} for scenario in scenarios}
    fit_time: dict[str, float] = {}
    # Trial i's draws depend only on (seed, i): draw up to the shard's end, keep its slice.
    resolved = {s: get_scenario(s, **common) for s in scenarios}
    batches = {
        s: simulate_batch(
            robot_obj, sc, trials=mine.stop, seed=seed, excitation=scenario_excitation(sc, robot_obj)
        )
        for s, sc in resolved.items()
    }
    provenance = Provenance(
        task="robustness",
        label=f"robustness vs {baseline}",
        seed=seed,
        data={"scenarios": list(scenarios), **({"scenario": common} if common else {})},
        plugins={
            "robot": describe("robot", robot),
            "estimator": describe("estimator", estimator) if search is not None else None,
        },
        requested=len(mine),
        done=0,
        unit="trial",
    )
    sharding = {"shard": shard, "shards": shards, "first_trial": mine.start, "total_trials": trials}

    def snapshot(done: int) -> RobustnessStudy:
        return RobustnessStudy(
            provenance=replace(provenance, done=done),
            param_names=list(robot_obj.param_names),
            truth=truth,
            params={
                # [done, P] also when no trial is done (Ctrl-C in the first chunk): a flat empty array
                # would not index like the others
                s: {k: np.asarray(v[:done], dtype=float).reshape(-1, len(truth)) for k, v in by.items()}
                for s, by in found.items()
            },
            baseline=baseline,
            focus=focus,
            skipped=skipped,
            wall_time_s=time.perf_counter() - started,
            fit_time_s={k: v / max(done * len(scenarios), 1) for k, v in fit_time.items()},
            sharding=sharding,
        )

    def fit_chunk(scenario: str, chosen: range) -> None:
        """Every estimator on trials ``chosen`` of ``scenario``, appended to ``found``."""
        problems = [
            Problem(
                robot_obj, batches[scenario][t], None, seed=trial_seed(seed, t), device=device, dtype=dtype
            )
            for t in chosen
        ]
        # The study's chunk is the batch (it bounds memory already): one batched call per estimator.
        columns = [[e for (e,) in fit_trials(est, problems, chunk=len(problems))] for est in est_objs]
        if search is not None:
            fitted = fit_trials(search, problems, cost_objs, chunk=len(problems))
            columns += [list(c) for c in zip(*fitted, strict=True)]
        for label, column in zip(labels, columns, strict=True):
            found[scenario].setdefault(label, []).extend(list(e.params.values()) for e in column)
            fit_time[label] = fit_time.get(label, 0.0) + sum(e.wall_time_s for e in column)
        if focus is not None:
            searched = columns[len(est_objs) :]
            chosen_costs = [searched[cost_names.index(c)] for c in average_of]
            found[scenario].setdefault(focus, []).extend(
                list(average_params(parts, robot_obj).values()) for parts in zip(*chosen_costs, strict=True)
            )

    saved = time.perf_counter()
    bar = tqdm(total=len(mine), desc="robustness", unit="trial", disable=not progress)
    done = 0
    try:
        # Chunk-major order: an interrupted study has the same trials in every scenario.
        for start in range(mine.start, mine.stop, chunk):
            chosen = range(start, min(start + chunk, mine.stop))
            for name in scenarios:  # not `scenario`: that is the option overriding the presets
                fit_chunk(name, chosen)
            done += len(chosen)
            bar.update(len(chosen))
            if (
                checkpoint is not None
                and time.perf_counter() - saved > checkpoint_every_s
                and done < len(mine)
            ):
                checkpoint(snapshot(done))
                saved = time.perf_counter()
    except KeyboardInterrupt:
        raise StudyInterrupted(snapshot(done)) from None
    finally:
        bar.close()
    return snapshot(len(mine))
