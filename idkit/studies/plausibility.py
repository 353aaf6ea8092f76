"""Plausibility in a run: every link's verdict for any fit of a model robot, and the other choice
beside the one reported, scored on the same held-out recordings.

The verdict is :func:`idkit.conic.plausible.plausibility_report`'s — one rule, computed once per fit
and recorded in ``details["plausibility"]``; the terminal table, ``result.json``, ``report.html`` and
``idkit compare`` only read it. Estimators that do not record one (``ls``, ``pso``, a plugin) get it
here, so every fit of a ``urdf`` or ``mjcf`` robot is judged by the same rule.

The alternative is the fit the other ``plausible`` option gives — its own fit, prior weight included:
``pcls`` with ``plausible=auto`` fitted both and recorded the one it did not report
(``details["plausible_choice"]``); with ``plausible=false`` and implausible links, the estimator is
fitted again with ``plausible=true`` and its other options as given.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

from idkit.data.load import DataFile
from idkit.estimate import Estimate, to_python
from idkit.interfaces import Estimator
from idkit.model import IdentifiedModel
from idkit.problem import Problem
from idkit.studies.validation import Validation, validate_files


@dataclass(frozen=True)
class PlausibleAlternative:
    """The fit with the other ``plausible`` option beside the one reported.

    Attributes:
        option: the option that gives it (``"estimator.plausible=true"``).
        estimate: its fit (its own ``details["plausibility"]`` verdict).
        scores: its held-out scores, in the order of the ``validate=`` files.
        implausible: the reported fit's implausible links.
        differs: what differs from the reported fit besides the bounds, in words (its prior weight).
    """

    option: str
    estimate: Estimate
    scores: list[Validation]
    implausible: tuple[str, ...]
    differs: str

    def to_dict(self, files: Sequence[str]) -> dict[str, Any]:
        plausibility = self.estimate.details.get("plausibility", {})
        return {
            "option": self.option,
            "differs": self.differs,
            "implausible_in_reported_fit": list(self.implausible),
            "implausible": plausibility.get("implausible"),
            "enforced": plausibility.get("enforced"),
            "prior_weight": self.estimate.details.get("prior_weight"),
            "mass": plausibility.get("mass"),
            "at_bound": plausibility.get("at_bound"),
            "validation": {f: s.to_dict() for f, s in zip(files, self.scores, strict=True)},
        }


def judged(robot: Any, fitted: Estimate) -> Estimate:
    """``fitted`` with its plausibility verdict recorded (``details["plausibility"]``) when the robot
    has CAD links to judge against and the estimator did not record one; otherwise as it is."""
    from idkit.conic.plausible import plausibility_report
    from idkit.robots.urdf import URDFRobot

    if not isinstance(robot, URDFRobot) or "plausibility" in fitted.details or "payload" in fitted.details:
        return fitted
    params = [fitted.params[name] for name in robot.param_names]
    record = to_python(plausibility_report(robot, None, params))
    return replace(fitted, details={**fitted.details, "plausibility": record})


def plausible_alternative(
    estimator: Estimator, fitted: Estimate, problem: Problem, held_out: Sequence[DataFile]
) -> PlausibleAlternative | None:
    """The other choice's fit and its held-out scores, or ``None`` when there is nothing to compare:
    no held-out file, or an estimator that neither recorded one nor has a ``plausible=false`` to flip
    for implausible links."""
    if not held_out:
        return None
    implausible = tuple(fitted.details.get("plausibility", {}).get("implausible", ()))
    weight = fitted.details.get("prior_weight")
    choice = fitted.details.get("plausible_choice")
    if choice is not None:
        other = choice["alternative"]
        estimate = _recorded(problem, fitted, other)
        option = other["option"]
    elif implausible and getattr(estimator, "plausible", None) is False:
        flipped = copy.copy(estimator)  # options are resolved at every fit
        flipped.plausible = True  # type: ignore[attr-defined]  # it has the option: checked above
        estimate = flipped.fit(problem)
        option = "estimator.plausible=true"
    else:
        return None
    own = estimate.details.get("prior_weight")
    differs = (
        ""
        if own is None or weight is None or own == weight
        else f"its own cross-validated prior weight {own:g} (this fit: {weight:g})"
    )
    scores = validate_files(IdentifiedModel(problem.robot, estimate), held_out)
    return PlausibleAlternative(option, estimate, scores, implausible, differs)


def _recorded(problem: Problem, fitted: Estimate, other: dict[str, Any]) -> Estimate:
    """The alternative ``pcls`` recorded (its parameters, prior weight and verdict), as an estimate."""
    details = {"prior_weight": other.get("prior_weight"), "plausibility": other.get("plausibility", {})}
    return Estimate(
        estimator=f"{fitted.estimator} ({other['option']})",
        params=dict(other["params"]),
        cost=None,
        wall_time_s=0.0,
        details=details,
    )
