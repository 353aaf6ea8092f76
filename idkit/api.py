"""``idkit.run(...)``: one fit from Python, with its report written when ``out_dir`` is given."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from idkit.studies.build import Spec
from idkit.studies.single import RunResult


def run(
    robot: Spec = "cylindrical",
    estimator: Spec = "pso",
    cost: Spec | None = "f13",
    scenario: Any = None,
    *,
    out_dir: str | Path | None = None,
    plots: bool = False,
    **options: Any,
) -> RunResult:
    """``idkit.studies.single.run(robot, estimator, cost, scenario, **options)``, then, if
    ``out_dir`` is given, ``idkit.reports.single.write`` into it (``plots``: also the PNG plots).

    Example: ``idkit.run(estimator="pso", cost="f13", scenario="outliers", seed=0).table()``.
    """
    from idkit.reports import files
    from idkit.reports import single as report
    from idkit.studies import single

    if out_dir is not None:  # a folder it cannot write into fails now, not after the fit
        files.writable_folder(out_dir, "out_dir")
    result = single.run(robot, estimator, cost, scenario, **options)
    if out_dir is not None:
        report.write(result, out_dir, plots=plots)
    return result
