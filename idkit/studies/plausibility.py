"""The held-out cost of plausibility: when a consistent fit leaves a link implausible, what keeping
it plausible would cost on the recordings the fit never saw.

A fit that predicts held-out torques best can still put an upper arm at four times its CAD mass;
the torques cannot see it, a controller or a simulator will. idkit does not choose between the two
for the owner: when the default fit flags implausible links (masses outside
:data:`~idkit.conic.plausible.PLAUSIBLE_MASS_RATIO` times CAD) and ``validate=`` files are given, the
same estimator is fitted again with ``plausible=true`` and scored on the same files, so the report
can say both figures and the option that gives the other model.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from idkit.data.load import DataFile
from idkit.estimate import Estimate
from idkit.interfaces import Estimator
from idkit.model import IdentifiedModel
from idkit.problem import Problem
from idkit.studies.validation import Validation, validate_files


@dataclass(frozen=True)
class PlausibleAlternative:
    """The fit with ``plausible=true`` beside the one reported.

    Attributes:
        estimate: the plausible fit.
        scores: its held-out scores, in the order of the ``validate=`` files.
        implausible: the reported fit's implausible links (why this was computed).
    """

    estimate: Estimate
    scores: list[Validation]
    implausible: tuple[str, ...]

    def to_dict(self, files: Sequence[str]) -> dict[str, Any]:
        plausibility = self.estimate.details.get("plausibility", {})
        return {
            "option": "estimator.plausible=true",
            "implausible_in_reported_fit": list(self.implausible),
            "mass": plausibility.get("mass"),
            "at_bound": plausibility.get("at_bound"),
            "validation": {f: s.to_dict() for f, s in zip(files, self.scores, strict=True)},
        }


def plausible_alternative(
    estimator: Estimator, fitted: Estimate, problem: Problem, held_out: Sequence[DataFile]
) -> PlausibleAlternative | None:
    """The plausible fit and its held-out scores, or ``None`` when there is nothing to compare:
    no held-out file, an estimator without a ``plausible`` option, already plausible, or no link
    flagged implausible."""
    implausible = tuple(fitted.details.get("plausibility", {}).get("implausible", ()))
    if not held_out or not implausible or getattr(estimator, "plausible", True) is not False:
        return None
    other = copy.copy(estimator)  # options are resolved at every fit
    other.plausible = True  # type: ignore[attr-defined]  # it has the option: checked above
    if "prior_weight" in fitted.details:  # the same pull towards CAD: the comparison is the bounds alone
        other.prior_weight = fitted.details["prior_weight"]  # type: ignore[attr-defined]  # its fit reported one
    estimate = other.fit(problem)
    scores = validate_files(IdentifiedModel(problem.robot, estimate), held_out)
    return PlausibleAlternative(estimate, scores, implausible)
