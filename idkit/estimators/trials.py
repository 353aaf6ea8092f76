"""Fitting many trials (e.g. a study's noise draws) of one setting in few batched computations.

A robustness study fits the same estimators to thousands of problems that differ only in their
samples. Fitted one after another, a paper-sized PSO is dominated by per-call overhead; stacked,
trials × costs × runs are one batch. ``fit_trials`` is the one entry point a study calls:

- estimators with a ``fit_trials(problems, costs, chunk)`` method (``pso``, ``adam``) stack the
  trials themselves, in chunks of ``chunk`` trials (bounded memory);
- the least-squares family (``ls``, ``tls``, ``rls`` without a solver) is solved on the stacked
  systems by ``idkit.estimators.batched_linear``;
- any other estimator is fitted trial by trial (its ``fit``), so third-party estimators work too.

Every number depends only on each trial's problem (its samples and ``seed``) and the estimator's
options, never on ``chunk`` or on the other trials in the batch (tested with chunks of 1, 3 and all).
"""

from __future__ import annotations

from collections.abc import Sequence

from idkit.estimate import Estimate
from idkit.interfaces import Cost, Estimator
from idkit.problem import Problem

#: Error-tensor elements per chunk of a batched search (about 2 MB of float64): big batches run
#: as consecutive chunks whose tensors stay in the CPU cache.
CHUNK_ELEMENTS = 1 << 18


def trial_chunk(chunk: int | None, per_trial: int) -> int:
    """Trials per batch: ``chunk`` if given (checked), else as many as fit ``CHUNK_ELEMENTS``.

    Args:
        chunk: explicit trials per batch, or ``None``.
        per_trial: error-tensor elements one trial needs (costs × runs × particles × n × N).
    """
    if chunk is not None:
        if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
            raise ValueError(f"chunk (trials per batch) must be an integer >= 1 or None, got {chunk!r}")
        return chunk
    return max(1, CHUNK_ELEMENTS // max(per_trial, 1))


def fit_trials(
    estimator: Estimator,
    problems: Sequence[Problem],
    costs: Sequence[Cost] | None = None,
    chunk: int | None = None,
) -> list[list[Estimate]]:
    """Fit ``estimator`` to every trial: ``T`` lists of one estimate per cost.

    Args:
        estimator: any estimator; batched where it knows how (module docstring).
        problems: ``T`` trials of the same robot, sample count, device and dtype.
        costs: the criteria for search estimators (``None``: each problem's own ``cost``, one
            estimate per trial); ignored by estimators with a fixed criterion (the LS family),
            which return one estimate per trial.
        chunk: trials per batched computation (``None``: chosen from the problem size).
    """
    from idkit.estimators import batched_linear

    problems = list(problems)
    if not problems:
        return []
    if hasattr(estimator, "fit_trials"):
        if costs is None:
            first = problems[0].cost
            if first is None or any(p.cost is not first for p in problems):
                raise ValueError("fit_trials: give costs, or problems that share one cost object")
            costs = [first]
        return estimator.fit_trials(problems, list(costs), chunk=chunk)
    if batched_linear.supports(estimator):
        return [[e] for e in batched_linear.fit_trials(estimator, problems, chunk=chunk)]
    if costs is None:
        return [[estimator.fit(p)] for p in problems]
    from dataclasses import replace

    return [[estimator.fit(replace(p, cost=c)) for c in costs] for p in problems]
