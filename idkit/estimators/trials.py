"""Fitting many trials (e.g. a study's noise draws) of one setting in few batched computations.

A robustness study fits the same estimators to thousands of problems that differ only in their
samples. Fitted one after another, a paper-sized PSO is dominated by per-call overhead; stacked,
trials × costs × runs are one batch. ``fit_trials`` is the one entry point a study calls:

- estimators with a ``fit_trials(problems, costs, chunk)`` method (``pso``, ``adam``,
  ``pso_f13_f14``) stack the trials themselves, in chunks of ``chunk`` trials (bounded memory);
- any other estimator is fitted trial by trial (its ``fit``), so third-party estimators work too.
  That includes the least-squares family: a fit is 0.2–1 ms (about 5 s for 1,000 trials × 6
  variants), small beside the searches, and its ``fit`` is where its diagnostics are made.

Every number depends only on each trial's problem (its samples and ``seed``) and the estimator's
options, never on ``chunk`` or on the other trials in the batch (tested with chunks of 1, 3 and all).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import replace

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


def batches(problems: Sequence[Problem], chunk: Callable[[Problem], int]) -> Iterator[list[int]]:
    """Indices of trials that can share one batch: same sample shape, at most ``chunk(trial)``.

    Trials are grouped by their samples' shape (a stack needs equal sample counts), in order of
    first appearance, then cut into chunks of the size ``chunk`` gives for that shape.
    """
    groups: dict[tuple[int, ...], list[int]] = {}
    for index, problem in enumerate(problems):
        groups.setdefault(tuple(problem.samples.q.shape), []).append(index)
    for members in groups.values():
        size = chunk(problems[members[0]])
        for start in range(0, len(members), size):
            yield members[start : start + size]


def fit_in_batches(
    problems: Sequence[Problem],
    chunk: Callable[[Problem], int],
    fit_batch: Callable[[list[Problem]], list[list[Estimate]]],
) -> list[list[Estimate]]:
    """``fit_batch`` over ``batches(problems, chunk)``, results back in the order of ``problems``."""
    results: list[list[Estimate]] = [[] for _ in problems]
    for members in batches(problems, chunk):
        for index, estimates in zip(members, fit_batch([problems[i] for i in members]), strict=True):
            results[index] = estimates
    return results


def criteria(problems: Sequence[Problem], costs: Sequence[Cost] | None) -> list[Cost]:
    """``costs``, or (``None``) the one cost object every problem shares."""
    if costs is not None:
        costs = list(costs)
        if not costs:
            raise ValueError("fit_trials needs at least one cost")
        return costs
    first = problems[0].cost if problems else None
    if first is None or any(p.cost is not first for p in problems):
        raise ValueError("fit_trials: give costs, or problems that all share one cost object")
    return [first]


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
    problems = list(problems)
    if not problems:
        return []
    if hasattr(estimator, "fit_trials"):
        return estimator.fit_trials(problems, costs, chunk=chunk)
    if costs is None:
        return [[estimator.fit(p)] for p in problems]
    return [[estimator.fit(replace(p, cost=c)) for c in costs] for p in problems]
