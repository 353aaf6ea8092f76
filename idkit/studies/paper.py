"""The paper's Tables II–V, recomputed (the ``paper`` task): ``idkit +experiment=paper``.

For each noise scenario (Table II ``state_noise``, III ``torque_noise``, IV ``all_noise``, V
``outliers``) one noisy sample set is drawn (``seed``), and every method of the paper estimates the
cylindrical robot's parameters from it: LS, TLS, RLS and their relative variants, PSO with each of
the costs f1…f16 — all sixteen in ONE batched ``fit_costs`` call — and the paper's final estimate,
the mean of PSO-f13 and PSO-f14 (``idkit.estimators.aggregate``, in their search space). The
published values are loaded for comparison; ``idkit.reports.paper`` lays the tables out.

The paper's numbers come from one noise draw each, and its sampling instants are not stated, so
digits will differ; what should carry over is the pattern (see the robustness study for
distributions instead of single draws).
"""

from __future__ import annotations

import csv
import re
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

from idkit.data.presets import PAPER_SCENARIOS
from idkit.estimate import Estimate
from idkit.estimators.aggregate import average_estimates, average_label, mean_params
from idkit.seeds import Seed
from idkit.studies.build import Spec, build, describe, name_and_options
from idkit.studies.labels import unique_labels
from idkit.studies.metrics import mean_abs_relative_error, relative_errors
from idkit.studies.result import Provenance, StudyInterrupted

COSTS = tuple(f"f{i}" for i in range(1, 17))
COLUMNS = ("m2", "m3", "-s3z", "I")  # the paper prints -s3z


def _unit_time(text: str) -> float | None:
    """Parse the paper's "2 us" / "3.23 s" into seconds."""
    match = re.fullmatch(r"\s*([0-9.]+)\s*(us|µs|μs|ms|s)\s*", text or "")
    if not match:
        return None
    value, unit = float(match[1]), match[2]
    return value * {"s": 1.0, "ms": 1e-3}.get(unit, 1e-6)


def _reference_key(column: str) -> str:
    return f"minus_{column[1:]}" if column.startswith("-") else column


def load_reference(
    path: str | Path | None = None, columns: Sequence[str] = COLUMNS
) -> dict[str, dict[str, dict]]:
    """The published tables as ``{scenario: {method: {"params": {...}, "time_s": ...}}}``.

    ``path=None`` reads the copy shipped with idkit (``idkit/studies/data/paper-tables.csv``,
    transcribed from the paper). ``params`` are physical parameter values (−s3z turned back into
    s3z). The paper's final estimate, the mean of PSO-f13 and PSO-f14, is added as a derived row.
    """
    if path is None:
        text = resources.files("idkit.studies").joinpath("data/paper-tables.csv").read_text()
    else:
        text = Path(path).read_text()
    tables: dict[str, dict[str, dict]] = {}
    for row in csv.DictReader(text.splitlines()):
        params = {}
        for column in columns:
            value = float(row[_reference_key(column)])
            params[column.lstrip("-")] = -value if column.startswith("-") else value
        tables.setdefault(row["scenario"], {})[row["method"]] = {
            "params": params,
            "time_s": _unit_time(row["time"]),
        }
    pair = ("f13", "f14")
    for methods in tables.values():
        if all(f"PSO-{c}" in methods for c in pair):
            methods[average_label(pair)] = {
                "params": mean_params([methods[f"PSO-{c}"]["params"] for c in pair]),
                "time_s": None,
            }
    return tables


@dataclass
class ScenarioTable:
    """All methods' estimates on one scenario's sample set, and the published rows."""

    scenario: str
    truth: dict[str, float]
    estimates: list[Estimate]
    reference: dict[str, dict] = field(default_factory=dict)

    def error(self, label: str) -> float | None:
        """Mean |relative error| of the estimate labelled ``label``."""
        est = next(e for e in self.estimates if e.estimator == label)
        return mean_abs_relative_error(relative_errors(est.params, self.truth))

    def reference_error(self, label: str) -> float | None:
        """The same for the published row, ``None`` if the paper has no such row."""
        ref = self.reference.get(label)
        return None if ref is None else mean_abs_relative_error(relative_errors(ref["params"], self.truth))


@dataclass
class PaperTables:
    """Tables II–V recomputed (``idkit.reports.paper`` formats them)."""

    tables: list[ScenarioTable]
    provenance: Provenance
    columns: Sequence[str] = COLUMNS
    compare: tuple[str, str] = (average_label(("f13", "f14")), "RLS-rel")
    wall_time_s: float = 0.0

    def comparisons(self) -> list[dict[str, Any]]:
        """Per scenario: the errors of ``compare[0]`` and ``compare[1]``, here and in the paper."""
        mine, other = self.compare
        rows = []
        for t in self.tables:
            labels = {e.estimator for e in t.estimates}
            if mine not in labels or other not in labels:
                continue
            rows.append(
                {
                    "scenario": t.scenario,
                    "error": t.error(mine),
                    "baseline_error": t.error(other),
                    "paper_error": t.reference_error(mine),
                    "paper_baseline_error": t.reference_error(other),
                }
            )
        return rows

    def payload(self) -> dict[str, Any]:
        return {
            "wall_time_s": self.wall_time_s,
            "compare": list(self.compare),
            "comparisons": self.comparisons(),
            "tables": {
                t.scenario: {"truth": t.truth, "estimates": [e.to_dict() for e in t.estimates]}
                for t in self.tables
            },
        }


def run(
    robot: Spec = "cylindrical",
    estimator: Spec = "pso",
    *,
    scenarios: Sequence[str] = PAPER_SCENARIOS,
    linear: Sequence[Spec] = ("ls", "tls", "rls"),
    costs: Sequence[Spec] = COSTS,
    average_of: Sequence[str] = ("f13", "f14"),
    scenario: Mapping[str, Any] | None = None,
    seed: Seed = 0,
    columns: Sequence[str] = COLUMNS,
    reference: str | Path | None = None,
    device: str = "cpu",
    dtype: str = "float64",
    progress: bool = True,
) -> PaperTables:
    """Recompute Tables II–V.

    Args:
        robot: robot spec (the paper's is ``"cylindrical"``).
        estimator: spec of the search estimator with ``fit_costs(problem, costs)`` (all costs in
            one batch), the paper's PSO.
        scenarios: scenario names; each draws one noisy sample set with ``seed``.
        linear: estimators fitted twice, plain and with ``relative=True`` ("-rel").
        costs: the search's costs (names or specs).
        average_of: cost names whose estimates are averaged into the final estimate.
        scenario: fields set on every scenario, e.g. ``{"excitation": "excitation.yaml"}`` (the
            motion, ``idkit.data.scenarios.shared_fields``).
        reference: CSV of the published tables (``None``: the shipped copy; ``""``: none).

    Raises:
        StudyInterrupted: on Ctrl-C, carrying the tables finished so far.
    """
    from tqdm import tqdm

    from idkit.data.scenarios import get_scenario, shared_fields, simulate
    from idkit.excitation.spec import scenario_excitation
    from idkit.problem import Problem

    common = shared_fields(scenario, "paper")
    started = time.perf_counter()
    robot_obj = build("robot", robot)
    published = load_reference(reference, columns) if reference != "" else {}
    truth = dict(zip(robot_obj.param_names, robot_obj.nominal_params().tolist(), strict=True))
    named = [name_and_options("estimator", s) for s in linear]
    linear_specs = [
        {"_name_": name, **options, "relative": relative}
        for relative in (False, True)  # the paper's order: LS, TLS, RLS, then LS-rel, TLS-rel, RLS-rel
        for name, options in named
    ]
    cost_names = [name_and_options("cost", c)[0] for c in costs]
    missing = sorted(set(average_of) - set(cost_names))
    if missing:
        raise ValueError(f"paper: average_of names {missing}, which are not among the costs {cost_names}")
    labels = unique_labels(
        [(s, None, False) for s in linear_specs] + [(estimator, c, True) for c in costs], where="paper"
    )
    linear_objs = [build("estimator", s) for s in linear_specs]
    cost_objs = [build("cost", c) for c in costs]
    search = build("estimator", estimator)
    final = average_label(average_of)
    provenance = Provenance(
        task="paper",
        label="paper tables",
        seed=seed,
        data={"scenarios": list(scenarios), **({"scenario": common} if common else {})},
        plugins={"robot": describe("robot", robot), "estimator": describe("estimator", estimator)},
        requested=len(scenarios),
        done=0,
        unit="table",
    )
    result = PaperTables([], provenance, columns, compare=(final, "RLS-rel"))
    try:
        for name in tqdm(scenarios, desc="paper tables", unit="table", disable=not progress):
            sc = get_scenario(name, **common)
            samples = simulate(robot_obj, sc, seed=seed, excitation=scenario_excitation(sc, robot_obj))
            problem = Problem(robot_obj, samples, None, seed=seed, device=device, dtype=dtype)
            fitted = [e.fit(problem) for e in linear_objs] + search.fit_costs(problem, cost_objs)
            estimates = [replace(e, estimator=label) for e, label in zip(fitted, labels, strict=True)]
            searched = estimates[len(linear_objs) :]
            chosen = [searched[cost_names.index(c)] for c in average_of]
            if chosen:
                criteria = [cost_objs[cost_names.index(c)] for c in average_of]
                estimates.append(average_estimates(problem, chosen, criteria, final))
            result.tables.append(ScenarioTable(name, truth, estimates, published.get(name, {})))
            provenance.done += 1
    except KeyboardInterrupt:
        result.wall_time_s = time.perf_counter() - started
        raise StudyInterrupted(result) from None
    result.wall_time_s = time.perf_counter() - started
    return result
