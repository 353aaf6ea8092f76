"""The paper's final estimate: the mean of several estimates' physical parameters (PSO-f13, PSO-f14).

One function for the paper study, the robustness study and the published reference rows. The mean
is taken in the **physical-parameter space** ``Estimate.params`` (not the base parameters):

* it is what the paper prints and averages (Tables II–V list m2, m3, −s3z, I);
* it is the space the parameter error is measured in (``idkit.studies.metrics``), so the average
  and its error are about the same numbers;
* ``pso_f13_f14`` (``idkit.estimators.paper``) averages the same space, so the study's average and
  that estimator agree on the same runs.

For the cylindrical robot the two spaces coincide (every parameter is identifiable); for a robot
whose physical parameters come from ``params_from_base`` the mean is still linear in the base
parameters when that map is linear.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from idkit.estimate import Estimate


def average_label(costs: Sequence[str]) -> str:
    """``PSO-f13/f14`` for ``("f13", "f14")``."""
    return "PSO-" + "/".join(costs)


def mean_params(params: Sequence[Mapping[str, float]]) -> dict[str, float]:
    """Per parameter name, the mean over ``params`` (each a ``name -> value`` map, same names)."""
    if not params:
        raise ValueError("mean_params: nothing to average")
    return {k: sum(p[k] for p in params) / len(params) for k in params[0]}


def average(estimates: Sequence[Estimate], label: str) -> Estimate:
    """The mean of several estimates (the paper's final estimate); wall time is their sum."""
    return Estimate(
        estimator=label,
        params=mean_params([e.params for e in estimates]),
        cost=None,
        wall_time_s=sum(e.wall_time_s for e in estimates),
        details={"mean_of": [e.estimator for e in estimates], "space": "physical parameters"},
    )
