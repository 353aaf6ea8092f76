"""The sizes of a batched search: a cap on its evaluations, a bound on its history, and the bytes
it will allocate (checked by ``idkit.memory.check_memory`` before anything is allocated).

Why: a size option of ``1e9`` (``runs``, ``particles``, ``iterations``, ``starts``) otherwise
reaches the allocator and ends in a many-line traceback, runs for hours unasked, or writes
gigabytes of history. The estimates below are the largest arrays a batched search allocates.

A search's time is about ``steps × (a + b × width)``: ``width`` evaluations per step, each taking
``b``, and a fixed ``a`` per step (the swarm update and kernel call; Adam's autograd pass). The cap
counts a step as the evaluations it costs (``bench/step_cost.py``): ``iterations=1e8`` of 4
particles is 4e8 evaluations but takes as long as 2.4e9. An evaluation's time grows with the
residuals it reads (samples × joints), so a search that will take minutes (a big recording, many
trials) says so up front (:func:`announce_long_search`). The measurements behind the constants:
docs/estimators.md, "Sizes".
"""

from __future__ import annotations

import math
import warnings

from idkit.memory import check_memory as check_machine_memory

#: Most cost evaluations one search may plan per cost and trial (``runs × particles × iterations``,
#: ``starts × steps``, plus the steps' own cost below): about a minute of one core on the fast
#: kernel on the paper's problem, many on the eager engine or on big recordings. A bigger request
#: is refused when the estimator is built, rather than running for hours unasked.
MAX_EVALUATIONS = 10**9
#: The fixed time of one swarm iteration (over all runs) on the fast kernel, in evaluations, on the
#: paper's problem, where an evaluation is the cheapest (``bench/step_cost.py``).
PSO_STEP_EVALUATIONS = 20
#: The fixed time of one Adam step (eager torch, autograd) in evaluations, measured likewise.
ADAM_STEP_EVALUATIONS = 1000
#: Nanoseconds of one core per residual (sample × joint) of one cost evaluation, about the fewest
#: measured on 30 to 30,000 residuals (``bench/step_cost.py``): the fast kernel's and Adam's (eager
#: torch with autograd). A long search's notice estimates its time with them, so its estimate is a
#: lower bound.
PSO_RESIDUAL_NS = 2.0
ADAM_RESIDUAL_NS = 50.0
#: A search whose estimated time passes this says so in one line before it starts (seconds).
LONG_SEARCH_SECONDS = 60.0
#: Most rows a search's history keeps per run (``history_stride``).
HISTORY_ROWS = 1000
#: Bytes per float64.
FLOAT = 8
#: Allocations below this are not checked against the machine's free memory: reading what the
#: system has (``/proc/meminfo``, cgroup files) costs more than a small fit, and a size that small
#: is not what exhausts a machine.
UNCHECKED_BYTES = 1 << 20


def check_evaluations(who: str, sizes: dict[str, int], step: str, step_evaluations: int) -> int:
    """The evaluations a search plans per cost and trial, or ``ValueError`` (one line) above
    ``MAX_EVALUATIONS``: the product of ``sizes`` (option names to values, e.g. ``{"runs": 10, ...}``)
    plus ``sizes[step]`` steps (``"iterations"``, ``"steps"``) costing ``step_evaluations`` each."""
    evaluations = math.prod(sizes.values())
    planned = evaluations + sizes[step] * step_evaluations
    if planned > MAX_EVALUATIONS:
        product = " × ".join(sizes)
        values = " × ".join(str(v) for v in sizes.values())
        raise ValueError(
            f"{who}: {product} = {values} = {evaluations:.1e} cost evaluations per cost, and {step}="
            f"{sizes[step]} steps that each take as long as about {step_evaluations} evaluations: "
            f"{planned:.1e} in all, above idkit's cap of {MAX_EVALUATIONS:.0e} (about a minute of one "
            "core on the fast kernel); lower one of them"
        )
    return planned


class LongSearchWarning(UserWarning):
    """A search will take minutes or more: said before it starts (:func:`announce_long_search`)."""


def announce_long_search(
    who: str, evaluations: int, costs: int, residuals: list[int], nanoseconds: float
) -> None:
    """Say in one line, before a search starts, that it will take more than ``LONG_SEARCH_SECONDS``:
    ``evaluations`` per cost and trial (the budget's product, without the steps' own cost) for each
    of ``costs`` costs on trials of ``residuals`` (samples × joints, one per trial), at ``nanoseconds``
    of one core per residual (``PSO_RESIDUAL_NS``, ``ADAM_RESIDUAL_NS``): a lower bound."""
    total = evaluations * costs * sum(residuals)
    seconds = total * nanoseconds * 1e-9
    if seconds > LONG_SEARCH_SECONDS:
        trials = f"{len(residuals)} trials × " if len(residuals) > 1 else ""
        warnings.warn(
            f"{who}: a long search: {trials}{costs} cost(s) × {evaluations:.1e} cost evaluations on "
            f"{max(residuals)} residuals (samples × joints) each, {total:.1e} residual evaluations: about "
            f"{_duration(seconds)} of one core or more (at {nanoseconds:g} ns each)",
            LongSearchWarning,
            stacklevel=3,
        )


def _duration(seconds: float) -> str:
    """``45 minutes``, ``3.2 hours``."""
    return f"{seconds / 60:.2g} minutes" if seconds < 3600 else f"{seconds / 3600:.2g} hours"


def history_stride(iterations: int) -> int:
    """Keep every ``stride``-th iteration (and the last) so a history has at most ``HISTORY_ROWS``
    rows (+ 1): 1 up to ``HISTORY_ROWS`` iterations."""
    return max(1, math.ceil(iterations / HISTORY_ROWS))


def swarm_bytes(swarms: int, runs: int, particles: int, dimension: int, history_rows: int) -> int:
    """A batch of ``swarms × runs`` swarms: positions, velocities, personal bests and the initial
    draw (``[S, R, K, D]`` each), personal best costs, and the history ``[rows, S, R]``."""
    members = swarms * runs
    return FLOAT * (members * particles * (4 * dimension + 1) + history_rows * members)


def error_bytes(evaluations: int, entries: int, copies: int = 4) -> int:
    """The error tensors of one eager move: ``evaluations`` error matrices of ``entries`` entries,
    ``copies`` of them alive at once (the error, its absolute value, squares, sums)."""
    return FLOAT * evaluations * entries * copies


def check_memory(what: str, needed: float, hint: str = "") -> None:
    """``idkit.memory.check_memory`` for allocations of at least ``UNCHECKED_BYTES``."""
    if needed >= UNCHECKED_BYTES:
        check_machine_memory(what, needed, hint)
