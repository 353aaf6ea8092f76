"""The library's one-line entries: ``idkit.identify`` (a robot's logs → a model) and ``idkit.run``
(one fit of any kind → its result), each writing its report when ``out_dir`` is given."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from idkit.studies.build import Spec
from idkit.studies.single import RunResult

if TYPE_CHECKING:
    from idkit.model import IdentifiedModel


def identify(
    robot: Spec,
    data: Any,
    *,
    validate: Any = None,
    out_dir: str | Path | None = None,
    plots: bool = False,
    **options: Any,
) -> IdentifiedModel:
    """Identify ``robot`` from the recordings ``data``; the library's form of
    ``idkit robot=... data=... validate=...``.

    It runs the same study as that command (:func:`idkit.studies.single.run`, with the same
    defaults: ``estimator``, ``cost``, ``preprocess`` ... are ``options``) and returns the model::

        import idkit
        m = idkit.identify({"_name_": "urdf", "urdf": "arm.urdf", "friction": True}, "train.csv",
                           validate=["test.csv"], estimator="pcls")
        tau = m.predict(q, qd, qdd)         # numpy or torch, any leading dimensions
        m.params["link2.m"], m.params.std["link2.m"]
        m.validation[0].scores.rel_all      # held-out score of test.csv
        m.save("identified.urdf")           # or .xml (MJCF)
        m.result.table()                    # the run: provenance, cost, the command's report

    Args:
        robot: a registry name, a config mapping or a ready robot object.
        data: the training recordings: a path (CSV, ``.npz``, ROS log), ``Samples``, or a list.
        validate: held-out recordings the model is scored on (``m.validation``).
        out_dir: also write the command's report (``result.json``, ``identified.urdf`` ...) here.
        plots: with ``out_dir``, also the PNG plots.
        options: the rest of :func:`idkit.studies.single.run`'s keywords (``estimator``, ``cost``,
            ``seed``, ``preprocess``, ``recording``, ``device``, ``dtype`` ...).
    """
    result = run(robot, data=data, validate=validate, out_dir=out_dir, plots=plots, **options)
    return result.model


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
