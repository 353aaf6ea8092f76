"""Fitting many trials (e.g. a study's noise draws) of one setting in few batched computations.

A robustness study fits the same estimators to thousands of problems that differ only in their
samples. Fitted one after another, a paper-sized fit is dominated by per-call overhead; stacked,
trials are one batch. ``fit_trials`` is the one entry point a study calls:

- estimators with a ``fit_trials(problems, costs, chunk)`` method stack the trials themselves, in
  chunks of ``chunk`` trials (bounded memory): the searches (``pso``, ``adam``, ``pso_f13_f14``)
  as trials × costs × runs, the least-squares family (``ls``, ``tls``, ``rls``, their relative
  variants) as ``[T, M, B]`` systems solved by batched decompositions, and the third-party
  ``irls`` as batched reweighting steps;
- any other estimator is fitted trial by trial (its ``fit``), so third-party estimators work too.

Every number depends only on each trial's problem (its samples and ``seed``) and the estimator's
options, never on ``chunk`` or on the other trials in the batch (tested with chunks of 1, 3 and all).
The helpers below are what a batched estimator needs besides its arithmetic: cutting the trials
into batches (``fit_in_batches``, ``fit_stacked_systems``), checking that they can share one
(``check_same_setting``), keeping each trial's warnings apart (``TrialWarnings``) and naming the
trial that fails (``in_trial``): a trial whose data cannot be fitted raises the error its own
``fit`` raises, its message prefixed with ``trial <index> (seed <seed>): `` — never a result
computed from the others.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import replace
from typing import TypeVar

from idkit.estimate import Estimate
from idkit.interfaces import BatchedEstimator, Cost, Estimator
from idkit.problem import Problem

E = TypeVar("E", bound=BaseException)

#: Error-tensor elements per chunk of a batched search (about 2 MB of float64): big batches run
#: as consecutive chunks whose tensors stay in the CPU cache.
CHUNK_ELEMENTS = 1 << 18


def check_chunk(chunk: int | None) -> int | None:
    """``chunk`` (trials per batch) if it is ``None`` or an integer >= 1, else ``ValueError``:
    called before any work, so a bad option fails at once."""
    if chunk is not None and (isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1):
        raise ValueError(f"chunk (trials per batch) must be an integer >= 1 or None, got {chunk!r}")
    return chunk


def trial_chunk(chunk: int | None, per_trial: int) -> int:
    """Trials per batch: ``chunk`` if given (checked), else as many as fit ``CHUNK_ELEMENTS``.

    Args:
        chunk: explicit trials per batch, or ``None``.
        per_trial: error-tensor elements one trial needs (costs × runs × particles × n × N).
    """
    checked = check_chunk(chunk)
    if checked is not None:
        return checked
    return max(1, CHUNK_ELEMENTS // max(per_trial, 1))


def batches(problems: Sequence[Problem], chunk: Callable[[Problem], int]) -> Iterator[list[int]]:
    """Indices of trials that can share one batch: same robot and sample shape, at most ``chunk(trial)``.

    Trials are grouped by robot object (a stack uses one robot's regressor and parameter maps; two
    objects of one class may differ in their constants) and samples' shape (a stack needs equal
    sample counts), in order of first appearance, then cut into chunks of the size ``chunk`` gives.
    """
    groups: dict[tuple[int, tuple[int, ...]], list[int]] = {}
    for index, problem in enumerate(problems):
        groups.setdefault((id(problem.robot), tuple(problem.samples.q.shape)), []).append(index)
    for members in groups.values():
        size = chunk(problems[members[0]])
        for start in range(0, len(members), size):
            yield members[start : start + size]


def in_trial(error: E, position: int) -> E:
    """Mark ``error`` as caused by trial ``position`` of the batch being fitted.

    ``fit_in_batches`` prefixes the message of a marked error with ``trial <index> (seed <seed>): ``
    (the trial's index in the caller's list), so a study says which draw failed; ``fit`` — a batch
    of one — raises it unchanged, exactly as before batching.
    """
    error.trial = position  # type: ignore[attr-defined]  # a mark on any exception type; fit_in_batches removes it
    return error


def fit_in_batches(
    problems: Sequence[Problem],
    chunk: Callable[[Problem], int],
    fit_batch: Callable[[list[Problem]], list[list[Estimate]]],
) -> list[list[Estimate]]:
    """``fit_batch`` over ``batches(problems, chunk)``, results back in the order of ``problems``.

    An error that ``fit_batch`` marked with ``in_trial`` gets the trial's index and seed in front
    of its message (same exception type, same traceback).
    """
    results: list[list[Estimate]] = [[] for _ in problems]
    for members in batches(problems, chunk):
        batch = [problems[i] for i in members]
        try:
            fitted = fit_batch(batch)
        except Exception as error:
            position = getattr(error, "trial", None)
            if isinstance(position, int) and error.args and isinstance(error.args[0], str):
                seed = batch[position].seed
                error.args = (f"trial {members[position]} (seed {seed}): {error.args[0]}", *error.args[1:])
                delattr(error, "trial")  # named once, for the list the caller passed
            raise
        for index, estimates in zip(members, fitted, strict=True):
            results[index] = estimates
    return results


def fit_stacked_systems(
    problems: Sequence[Problem],
    chunk: int | None,
    fit_stack: Callable[[list[Problem]], list[list[Estimate]]],
) -> list[list[Estimate]]:
    """``fit_trials`` of an estimator that solves the trials' stacked linear systems ``W[T, M, B]``
    (the least-squares family, ``irls``): ``fit_stack`` on stacks of trials of equal sample
    counts, at most ``chunk`` of them (``None``: as many as fit ``CHUNK_ELEMENTS`` elements of
    ``W``), results in the order of ``problems``.
    """
    problems = list(problems)
    if not problems:
        return []
    check_same_setting(problems)
    check_chunk(chunk)

    def trials_per_stack(problem: Problem) -> int:
        return trial_chunk(chunk, problem.samples.tau.numel() * len(problem.robot.base_param_names))

    return fit_in_batches(problems, trials_per_stack, fit_stack)


def check_same_setting(problems: Sequence[Problem]) -> None:
    """Raise ``ValueError`` unless every trial can share stacked computations with the first: the
    same robot class, device and dtype (stacking with another robot's regressor would be silently
    wrong; the rest would fail inside torch without naming a trial). Sample counts may differ:
    ``batches`` stacks only trials of equal shape.
    """
    first = problems[0]
    for index, other in enumerate(problems[1:], start=1):
        if other.robot is not first.robot and type(other.robot) is not type(first.robot):
            raise ValueError(f"trial {index}: robot {type(other.robot).__name__} differs from trial 0's")
        if str(other.device) != str(first.device) or other.torch_dtype != first.torch_dtype:
            raise ValueError(f"trial {index}: device/dtype differ from trial 0's")


class TrialWarnings:
    """The warnings raised while handling each trial of a batch, kept per trial.

    A batched fit must report what each trial's own ``fit`` would: its warnings (in its
    ``details["warnings"]``) and only its own. Per-trial work runs inside ``recording(t)``;
    ``reissue`` then passes every recorded warning on to the caller, trial by trial.
    """

    def __init__(self, trials: int) -> None:
        self.caught: list[list[warnings.WarningMessage]] = [[] for _ in range(trials)]

    @contextmanager
    def recording(self, trial: int) -> Iterator[None]:
        """Record the warnings of the block as trial ``trial``'s."""
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                yield
            finally:
                self.caught[trial].extend(caught)

    def messages(self, trial: int) -> list[str]:
        """``"<Category>: <message>"`` of each warning of trial ``trial``."""
        return [f"{w.category.__name__}: {w.message}" for w in self.caught[trial]]

    def reissue(self) -> None:
        """Warn the caller of every recorded warning (outside any ``recording`` block)."""
        for caught in self.caught:
            for w in caught:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)


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
            estimate per trial); ignored by estimators with a fixed criterion (the LS family,
            ``irls``), which return one estimate per trial, as their ``fit`` of that trial.
        chunk: trials per batched computation (``None``: chosen from the problem size).
    """
    problems = list(problems)
    if not problems:
        return []
    if isinstance(estimator, BatchedEstimator):
        return estimator.fit_trials(problems, costs, chunk=chunk)
    if costs is None:
        return [[estimator.fit(p)] for p in problems]
    return [[estimator.fit(replace(p, cost=c)) for c in costs] for p in problems]
