"""Where a standard deviation comes from: one record, written by the estimators, read everywhere.

An estimator that reports σ names its method (``details["uncertainty"]["method"]``, the payload's
``details["payload"]["std_method"]``) and writes :func:`describe`'s sentence beside it
(``"std_source"``), so ``result.json``, the terminal and ``IdentifiedModel.params.note`` say the
same thing, from this one table.

Every σ here is *model-conditional*: it measures how much the data scatter around the model that
was fitted — noise, and the part of a model error that shows in the residuals (correlated in time,
unequal between joints), which the sandwich counts — but not the part of a model error the fitted
parameters absorb (a wrong arm under a payload, a friction law the joint does not follow, noise on
the states): that moves the estimate without widening its σ. :data:`MODEL_CONDITIONAL` says so in
every description.
"""

from __future__ import annotations

#: Said of every σ (module doc).
MODEL_CONDITIONAL = (
    "model-conditional: it counts noise and the model error that shows in the residuals, not a model "
    "error the fitted parameters absorb (a wrong arm model, an unmodelled friction law, noisy states)"
)

#: Method key → what it is, in words (without :data:`MODEL_CONDITIONAL`).
METHODS: dict[str, str] = {
    "hac": (
        "the least-squares sandwich with residuals correlated in time and between joints "
        "(HAC: Newey-West/Driscoll-Kraay, Andrews' bandwidth, residuals leverage-adjusted)"
    ),
    "hac+pull": (
        "the least-squares sandwich with residuals correlated in time and between joints "
        "(HAC: Newey-West/Driscoll-Kraay, Andrews' bandwidth, residuals leverage-adjusted), "
        "plus the estimate's pull from least squares (prior, constraints) in quadrature"
    ),
    "weighted-hac": (
        "the sandwich of the joint-weighted least-squares fit with residuals correlated in time and "
        "between joints (HAC: Newey-West/Driscoll-Kraay, Andrews' bandwidth, residuals "
        "leverage-adjusted; each recording on its own), plus the pull of the constraints in quadrature"
    ),
}


def describe(method: str | None) -> str:
    """One sentence: where the σ of ``method`` come from, and that they are model-conditional. An
    unknown method (a plugin's) is named as given."""
    if method in METHODS:
        return f"σ from {METHODS[method]}; {MODEL_CONDITIONAL}"
    return "σ from the estimator's uncertainty report" + (f" (method {method!r})" if method else "")
