"""``idkit +experiment=paper``: the paper's Tables II–V, recomputed and set beside the published ones.

For each noise scenario (Table II ``state_noise``, III ``torque_noise``, IV ``all_noise``, V
``outliers``) one noisy sample set is drawn (``seed``), and every method of the paper estimates the
cylindrical robot's parameters from it: LS, TLS, RLS and their relative variants, PSO with each of
the costs f1…f16 — all sixteen in ONE batched ``fit_costs`` call — and the paper's final estimate,
the mean of PSO-f13 and PSO-f14. Output: one Markdown table per scenario in the paper's layout
(m2, m3, −s3z, I, computation time) with the published value in parentheses, the same as CSV, and
a scatter plot of the estimates.

The paper's numbers come from one noise draw each, and its sampling instants are not stated, so
digits will differ; what should carry over is the pattern (see the robustness study for
distributions instead of single draws).
"""

from __future__ import annotations

import csv
import logging
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from idkit.estimate import Estimate
from idkit.experiments import files, plots
from idkit.experiments.build import Spec, build, plain
from idkit.experiments.metrics import mean_abs_relative_error, relative_errors

log = logging.getLogger(__name__)

SCENARIOS = ("state_noise", "torque_noise", "all_noise", "outliers")
TABLES = {"state_noise": "II", "torque_noise": "III", "all_noise": "IV", "outliers": "V"}
COSTS = tuple(f"f{i}" for i in range(1, 17))
COLUMNS = ("m2", "m3", "-s3z", "I")  # the paper prints -s3z
AVERAGE_LABEL = "PSO-f13/f14"


def average_label(costs: Sequence[str]) -> str:
    return "PSO-" + "/".join(costs)


def _unit_time(text: str) -> float | None:
    """Parse the paper's "2 us" / "3.23 s" into seconds."""
    match = re.fullmatch(r"\s*([0-9.]+)\s*(us|µs|μs|ms|s)\s*", text or "")
    if not match:
        return None
    value, unit = float(match[1]), match[2]
    return value * {"s": 1.0, "ms": 1e-3}.get(unit, 1e-6)


def format_time(seconds: float | None) -> str:
    """Seconds in the paper's style: µs below a millisecond, ms below a second."""
    if seconds is None:
        return ""
    if seconds < 1e-3:
        return f"{seconds * 1e6:.0f} µs"
    if seconds < 1:
        return f"{seconds * 1e3:.1f} ms"
    return f"{seconds:.2f} s"


def column_value(params: Mapping[str, float], column: str) -> float:
    """A display column: a parameter name, or ``-name`` for its negation (the paper's −s3z)."""
    return -params[column[1:]] if column.startswith("-") else params[column]


def _reference_key(column: str) -> str:
    return f"minus_{column[1:]}" if column.startswith("-") else column


def load_reference(
    path: str | Path | None = None, columns: Sequence[str] = COLUMNS
) -> dict[str, dict[str, dict]]:
    """The published tables as ``{scenario: {method: {"params": {...}, "time_s": ...}}}``.

    ``path=None`` reads the copy shipped with idkit (``idkit/experiments/data/paper-tables.csv``,
    transcribed from the paper). ``params`` are physical parameter values (−s3z turned back into
    s3z). The paper's final estimate, the mean of PSO-f13 and PSO-f14, is added as a derived row.
    """
    if path is None:
        text = resources.files("idkit.experiments").joinpath("data/paper-tables.csv").read_text()
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
    for methods in tables.values():
        if "PSO-f13" in methods and "PSO-f14" in methods:
            a, b = methods["PSO-f13"]["params"], methods["PSO-f14"]["params"]
            methods[AVERAGE_LABEL] = {"params": {k: (a[k] + b[k]) / 2 for k in a}, "time_s": None}
    return tables


def average(estimates: Sequence[Estimate], label: str) -> Estimate:
    """The mean of several estimates' physical parameters (the paper's final estimate)."""
    names = list(estimates[0].params)
    params = {k: sum(e.params[k] for e in estimates) / len(estimates) for k in names}
    return Estimate(
        estimator=label,
        params=params,
        cost=None,
        wall_time_s=sum(e.wall_time_s for e in estimates),
        details={"mean_of": [e.estimator for e in estimates]},
    )


@dataclass
class ScenarioTable:
    """All methods' estimates on one scenario's sample set."""

    scenario: str
    truth: dict[str, float]
    estimates: list[Estimate]
    reference: dict[str, dict] = field(default_factory=dict)

    def error(self, label: str) -> float | None:
        est = next(e for e in self.estimates if e.estimator == label)
        return mean_abs_relative_error(relative_errors(est.params, self.truth))

    def reference_error(self, label: str) -> float | None:
        ref = self.reference.get(label)
        return None if ref is None else mean_abs_relative_error(relative_errors(ref["params"], self.truth))

    def markdown(self, columns: Sequence[str] = COLUMNS) -> str:
        table = TABLES.get(self.scenario, "")
        head = [
            "method",
            *(c.replace("-", "−") for c in columns),
            "computation time",
            "mean \\|rel. error\\|",
        ]
        lines = [
            f"### Table {table}: `{self.scenario}` — idkit (paper)",
            "",
            "| " + " | ".join(head) + " |",
            "|---|" + "---:|" * (len(head) - 1),
            "| real values | " + " | ".join(f"{column_value(self.truth, c):g}" for c in columns) + " | | |",
        ]
        for est in self.estimates:
            ref = self.reference.get(est.estimator)
            cells = [est.estimator]
            for c in columns:
                mine = f"{column_value(est.params, c):.2f}"
                cells.append(mine if ref is None else f"{mine} ({column_value(ref['params'], c):.2f})")
            time = format_time(est.wall_time_s)
            if ref is not None and ref["time_s"] is not None:
                time += f" ({format_time(ref['time_s'])})"
            cells.append(time)
            err, ref_err = self.error(est.estimator), self.reference_error(est.estimator)
            text = "" if err is None else f"{100 * err:.1f} %"
            if ref_err is not None:
                text += f" ({100 * ref_err:.1f} %)"
            cells.append(text)
            lines.append("| " + " | ".join(cells) + " |")
        return "\n".join(lines)


@dataclass
class PaperTables:
    """Tables II–V recomputed. ``markdown()`` is what the command prints."""

    tables: list[ScenarioTable]
    columns: Sequence[str] = COLUMNS
    compare: tuple[str, str] = (AVERAGE_LABEL, "RLS-rel")
    wall_time_s: float = 0.0

    def verdicts(self) -> list[str]:
        """Per scenario: does the paper's final estimate beat RLS-rel on this draw (and in the paper)?"""
        mine, other = self.compare
        lines = []
        for t in self.tables:
            a, b = t.error(mine), t.error(other)
            ra, rb = t.reference_error(mine), t.reference_error(other)
            if a is None or b is None:
                continue
            outcome = "beats" if a < b else "loses"
            text = f"- `{t.scenario}`: {mine} {100 * a:.1f} % vs {other} {100 * b:.1f} % → {outcome}"
            if ra is not None and rb is not None:
                text += f" (paper: {100 * ra:.1f} % vs {100 * rb:.1f} % → {'beats' if ra < rb else 'loses'})"
            lines.append(text)
        return lines

    def markdown(self) -> str:
        parts = [t.markdown(self.columns) for t in self.tables]
        verdicts = self.verdicts()
        if verdicts:
            parts.append(
                f"Mean |relative parameter error| of {self.compare[0]} vs {self.compare[1]} "
                "(one draw per table):\n\n"
                + "\n".join(verdicts)
            )
        parts.append(f"Total wall time {self.wall_time_s:.1f} s.")
        return "\n\n".join(parts) + "\n"

    def csv_rows(self) -> tuple[list[str], list[list[Any]]]:
        header = ["table", "scenario", "method", *self.columns, "time_s", "parameter_error"]
        header += [f"paper_{c}" for c in self.columns] + ["paper_time_s", "paper_parameter_error"]
        rows = []
        for t in self.tables:
            for est in t.estimates:
                ref = t.reference.get(est.estimator)
                row = [TABLES.get(t.scenario, ""), t.scenario, est.estimator]
                row += [column_value(est.params, c) for c in self.columns]
                row += [est.wall_time_s, t.error(est.estimator)]
                if ref is None:
                    row += [None] * (len(self.columns) + 2)
                else:
                    row += [column_value(ref["params"], c) for c in self.columns]
                    row += [ref["time_s"], t.reference_error(est.estimator)]
                rows.append(row)
        return header, rows

    def save(self, out_dir: str | Path, make_plots: bool = True) -> dict[str, str]:
        out = Path(out_dir)
        written = {
            "markdown": str(files.write_text(out / "paper_tables.md", self.markdown())),
            "csv": str(files.write_csv(out / "paper_tables.csv", *self.csv_rows())),
        }
        if make_plots:
            for t in self.tables:
                written[f"plot_{t.scenario}"] = str(
                    plots.estimates_vs_truth(
                        {e.estimator: e.params for e in t.estimates},
                        t.truth,
                        title=f"Table {TABLES.get(t.scenario, '')} ({t.scenario}): estimate / true value",
                        path=out / f"paper_{t.scenario}.png",
                    )
                )
        files.write_json(
            out / "result.json",
            {
                "task": "paper",
                "wall_time_s": self.wall_time_s,
                "tables": {
                    t.scenario: {"truth": t.truth, "estimates": [e.to_dict() for e in t.estimates]}
                    for t in self.tables
                },
                "files": written,
            },
        )
        return written


def run(
    robot: Spec = "cylindrical",
    pso: Spec = "pso",
    *,
    scenarios: Sequence[str] = SCENARIOS,
    linear: Sequence[Spec] = ("ls", "tls", "rls"),
    costs: Sequence[Spec] = COSTS,
    average_of: Sequence[str] = ("f13", "f14"),
    seed: int = 0,
    columns: Sequence[str] = COLUMNS,
    reference: str | Path | None = None,
    device: str = "cpu",
    dtype: str = "float64",
    progress: bool = True,
) -> PaperTables:
    """Recompute Tables II–V.

    Args:
        robot: robot spec (the paper's is ``"cylindrical"``).
        pso: spec of an estimator with ``fit_costs(problem, costs)`` (all costs in one batch).
        scenarios: scenario names; each draws one noisy sample set with ``seed``.
        linear: estimators fitted twice, plain and with ``relative=True`` ("-rel").
        costs: the PSO costs (names or specs).
        average_of: cost names whose PSO estimates are averaged into the final estimate.
        reference: CSV of the published tables (``None``: the shipped copy; ``""``: none).
    """
    import time

    from tqdm import tqdm

    from idkit.data.scenarios import simulate
    from idkit.problem import Problem

    started = time.perf_counter()
    robot_obj = build("robot", robot)
    published = load_reference(reference, columns) if reference != "" else {}
    truth = dict(zip(robot_obj.param_names, robot_obj.nominal_params().tolist(), strict=True))
    linear_specs = [plain(s) for s in linear]
    cost_objs = [build("cost", c) for c in costs]
    cost_names = [
        plain(c) if isinstance(plain(c), str) else type(o).__name__
        for c, o in zip(costs, cost_objs, strict=True)
    ]
    tables = []
    for scenario in tqdm(scenarios, desc="paper tables", unit="table", disable=not progress):
        samples = simulate(robot_obj, scenario, seed=seed)
        problem = Problem(robot_obj, samples, None, seed=seed, device=device, dtype=dtype)
        estimates = []
        for relative in (False, True):
            for spec in linear_specs:
                options = {"_name_": spec} if isinstance(spec, str) else dict(spec)
                estimates.append(build("estimator", {**options, "relative": relative}).fit(problem))
        by_cost = build("estimator", pso).fit_costs(problem, cost_objs)
        estimates += by_cost
        chosen = [e for name, e in zip(cost_names, by_cost, strict=True) if name in average_of]
        if len(chosen) == len(average_of) and chosen:
            estimates.append(average(chosen, average_label(average_of)))
        tables.append(ScenarioTable(scenario, truth, estimates, published.get(scenario, {})))
    return PaperTables(
        tables,
        columns,
        compare=(average_label(average_of), "RLS-rel"),
        wall_time_s=time.perf_counter() - started,
    )


def run_config(cfg: Any, run_dir: Path) -> PaperTables:
    """The ``task=paper`` entry of the command line (``idkit +experiment=paper``)."""
    p = cfg.paper
    result = run(
        cfg.robot,
        cfg.estimator,
        scenarios=list(p.scenarios),
        linear=plain(p.linear),
        costs=plain(p.costs),
        average_of=list(p.average_of),
        seed=cfg.seed,
        columns=list(p.columns),
        reference=p.reference,
        device=cfg.device,
        dtype=cfg.dtype,
    )
    written = result.save(run_dir, make_plots=cfg.plots)
    print(result.markdown())
    print(f"tables: {written['markdown']} and {written['csv']}")
    return result
