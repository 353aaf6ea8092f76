"""One identification run: data → problem → estimate → table, ``result.json``, history, plots.

This is what ``idkit`` does by default, and ``idkit.run(...)`` from Python::

    import idkit
    result = idkit.run(estimator="pso", cost="f13", scenario="outliers", seed=0)
    print(result.table())
    result.estimate.params            # {"m2": ..., "m3": ..., "s3z": ..., "I": ...}

``result.json`` (written by :meth:`RunResult.save`) is a contract; its keys are listed in
:meth:`RunResult.to_dict`.
"""

from __future__ import annotations

import datetime as _dt
import logging
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import idkit
from idkit.estimate import Estimate, jsonable
from idkit.experiments import files, plots
from idkit.experiments.build import Spec, build, describe, plain
from idkit.experiments.metrics import mean_abs_relative_error, relative_errors

log = logging.getLogger(__name__)

RESULT_FILE = "result.json"
HISTORY_FILE = "history.csv"


@dataclass
class RunResult:
    """An estimate with everything needed to judge and reproduce it.

    Attributes:
        estimate: what the estimator returned.
        truth: the parameters the data were simulated with (``None`` for measured data).
        seed: seed of the noise draw and of the estimator.
        data: where the samples came from: ``{"scenario": {...}}`` or ``{"file": path}``.
        plugins: per kind, the plugin name, entry point, distribution and version.
        config: the resolved config of the run (command line) or ``None`` (library call).
    """

    estimate: Estimate
    truth: dict[str, float] | None
    seed: int
    data: dict[str, Any]
    plugins: dict[str, dict[str, Any] | None]
    config: dict[str, Any] | None = None
    files: dict[str, str] = field(default_factory=dict)

    @property
    def relative_error(self) -> dict[str, float | None] | None:
        """Signed ``(estimate − truth) / |truth|`` per parameter (see ``idkit.experiments.metrics``)."""
        return None if self.truth is None else relative_errors(self.estimate.params, self.truth)

    @property
    def parameter_error(self) -> float | None:
        """Mean absolute relative error over the parameters."""
        rel = self.relative_error
        return None if rel is None else mean_abs_relative_error(rel)

    def to_dict(self) -> dict[str, Any]:
        """The ``result.json`` contract (all values JSON-ready; non-finite numbers are ``null``).

        Keys: ``estimator`` (label, e.g. "PSO-f13"), ``estimate`` / ``truth`` /
        ``relative_error`` (maps parameter name → value; ``truth`` and ``relative_error`` are
        ``null`` for measured data), ``parameter_error`` (mean |relative error|), ``base_estimate``
        (base parameters or ``null``), ``cost``, ``wall_time_s``, ``seed``, ``data``, ``plugins``
        (per kind: ``name``, ``entry_point``, ``distribution``, ``version``), ``details`` (the
        estimator's own record), ``config`` (resolved), ``idkit_version``, ``created`` (UTC).
        """
        return jsonable(
            {
                "estimator": self.estimate.estimator,
                "estimate": self.estimate.params,
                "truth": self.truth,
                "relative_error": self.relative_error,
                "parameter_error": self.parameter_error,
                "base_estimate": self.estimate.base_params,
                "cost": self.estimate.cost,
                "wall_time_s": self.estimate.wall_time_s,
                "seed": self.seed,
                "data": self.data,
                "plugins": self.plugins,
                "details": self.estimate.details,
                "config": self.config,
                "idkit_version": idkit.__version__,
                "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            }
        )

    def table(self) -> str:
        """A compact text table: estimate, true value and relative error per parameter."""
        est = self.estimate
        rel = self.relative_error or {}
        source = (
            self.data.get("scenario", {}).get("name") if "scenario" in self.data else self.data.get("file")
        )
        meta = self.plugins.get("robot") or {}
        robot = meta.get("name") or meta.get("entry_point", "?")
        lines = [
            f"{est.estimator} · robot {robot} · data {source} · seed {self.seed}",
            f"{'parameter':<12}{'estimate':>12}{'true':>12}{'rel. error':>12}",
        ]
        for name, value in est.params.items():
            true = "" if self.truth is None else f"{self.truth[name]:12.4f}"
            r = rel.get(name)
            rtext = "" if r is None else f"{100 * r:+10.2f} %"
            lines.append(f"{name:<12}{value:12.4f}{true:>12}{rtext:>12}")
        cost = "n/a" if est.cost is None else f"{est.cost:.6g}"
        tail = f"cost {cost} · wall time {est.wall_time_s:.3f} s"
        if self.parameter_error is not None:
            tail += f" · mean |rel. error| {100 * self.parameter_error:.2f} %"
        lines.append(tail)
        return "\n".join(lines)

    def history(self) -> tuple[list[str], list[list[float]]] | None:
        """Convergence history as CSV ``(header, rows)``: best cost per iteration, one column per run.

        Reads ``details["history"]``: a list (one run), a list of lists ``[runs][iterations]`` or a
        mapping of named columns.
        """
        history = self.estimate.details.get("history")
        if not history:
            return None
        if isinstance(history, Mapping):  # {"best_cost": [...], ...}: one column per entry
            keys = list(history)
            columns = [list(history[k]) for k in keys]
            rows = [[i, *(c[i] for c in columns)] for i in range(len(columns[0]))]
            return ["iteration", *keys], rows
        if isinstance(history[0], (list, tuple)):  # [runs][iterations], as the PSO keeps it
            header = ["iteration", *(f"run_{r}" for r in range(len(history)))]
            return header, [[i, *step] for i, step in enumerate(zip(*history, strict=True))]
        return ["iteration", "best_cost"], [[i, value] for i, value in enumerate(history)]

    def save(self, out_dir: str | Path, make_plots: bool = True) -> dict[str, str]:
        """Write ``result.json``, ``history.csv`` and (optionally) PNG plots into ``out_dir``."""
        out = Path(out_dir)
        written: dict[str, str] = {}
        history = self.history()
        if history is not None:
            written["history"] = str(files.write_csv(out / HISTORY_FILE, *history))
        if make_plots:
            written.update(plots.single_run(self, out))
        self.files = written
        written["result"] = str(files.write_json(out / RESULT_FILE, {**self.to_dict(), "files": written}))
        return written


def _scenario_spec(scenario: Any) -> Any:
    """Config nodes list every Scenario field, ``null`` meaning "the preset's value"."""
    scenario = plain(scenario)
    if isinstance(scenario, Mapping):
        return {k: v for k, v in scenario.items() if v is not None}
    return scenario


def load_data(
    robot: Any,
    scenario: Any = "clean",
    *,
    seed: int = 0,
    data: Any = None,
    n_samples: int | None = None,
    params: Any = None,
) -> tuple[Any, dict[str, float] | None, dict[str, Any]]:
    """``(samples, truth, description)``: measured ``data`` (a path or ``Samples``) or a simulation."""
    from idkit.problem import Samples

    if data is not None:
        if isinstance(data, Samples):
            return data, None, {"file": None}
        from idkit.data.io import load_samples

        return load_samples(os.fspath(data)), None, {"file": os.fspath(data)}
    import torch

    from idkit.data.scenarios import get_scenario, simulate

    sc = get_scenario(_scenario_spec(scenario), n_samples=n_samples)
    samples = simulate(robot, sc, seed=seed, params=params)
    true = torch.as_tensor(params, dtype=torch.float64) if params is not None else robot.nominal_params()
    truth = dict(zip(robot.param_names, true.tolist(), strict=True))
    return samples, truth, {"scenario": sc.as_dict()}


def run(
    robot: Spec = "cylindrical",
    estimator: Spec = "pso",
    cost: Spec | None = "f13",
    scenario: Any = "clean",
    *,
    seed: int = 0,
    data: Any = None,
    n_samples: int | None = None,
    params: Any = None,
    device: str = "cpu",
    dtype: str = "float64",
    out_dir: str | Path | None = None,
    plots: bool = False,
    config: dict[str, Any] | None = None,
) -> RunResult:
    """Identify a robot's parameters once.

    Args:
        robot, estimator, cost: a registry name (``"pso"``), a config mapping
            (``{"_name_": "pso", "particles": 40}``) or a ready object. ``cost=None`` for
            estimators with a fixed criterion (LS, TLS, RLS).
        scenario: noise scenario name, ``Scenario`` or mapping (``idkit.data.scenarios``); ignored
            when ``data`` is given.
        seed: seeds the noise draw and the estimator.
        data: measured samples instead of a simulation: a ``.npz``/``.csv`` path or ``Samples``.
        n_samples: override the scenario's number of samples.
        params: true parameters ``[P]`` to simulate with (default ``robot.nominal_params()``).
        device, dtype: where and in which precision the estimator computes.
        out_dir: if given, write ``result.json``, ``history.csv`` (and plots) there.
        plots: write PNG plots into ``out_dir``.
        config: the resolved config to record in ``result.json`` (the command line passes it).
    """
    from idkit.problem import Problem

    robot_obj = build("robot", robot)
    samples, truth, source = load_data(
        robot_obj, scenario, seed=seed, data=data, n_samples=n_samples, params=params
    )
    problem = Problem(robot_obj, samples, build("cost", cost), seed=seed, device=device, dtype=dtype)
    estimate = build("estimator", estimator).fit(problem)
    result = RunResult(
        estimate=estimate,
        truth=truth,
        seed=seed,
        data=source,
        plugins={
            kind: describe(kind, spec)
            for kind, spec in (("robot", robot), ("estimator", estimator), ("cost", cost))
        },
        config=config,
    )
    if out_dir is not None:
        result.save(out_dir, make_plots=plots)
    return result


def run_config(cfg: Any, run_dir: Path) -> RunResult:
    """The ``task=single`` entry of the command line."""
    from omegaconf import OmegaConf

    resolved = OmegaConf.to_container(cfg, resolve=True)
    result = run(
        cfg.robot,
        cfg.estimator,
        cfg.get("cost"),
        cfg.get("scenario") or "clean",
        seed=cfg.seed,
        data=cfg.get("data"),
        n_samples=cfg.get("n_samples"),
        device=cfg.device,
        dtype=cfg.dtype,
        out_dir=run_dir,
        plots=cfg.plots,
        config=resolved,
    )
    print(result.table())
    print(f"results: {result.files['result']}")
    return result
