"""The result of one fit, as plain data that survives a round trip through JSON."""

from __future__ import annotations

import json
import math
import numbers
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from typing import Any

#: How a non-finite float is written in JSON (strict JSON has no token for it). The spellings are
#: JavaScript's and Python's ``float()`` reads them back; ``from_json_numbers`` restores them.
NON_FINITE_JSON = {"Infinity": math.inf, "-Infinity": -math.inf, "NaN": math.nan}


def to_python(value: Any) -> Any:
    """Tensors, numpy arrays and numpy scalars nested in dicts/lists as plain Python.

    Floats stay floats, infinities and NaN included: an ``Estimate`` keeps its numbers typed in
    memory (a link's divergence at the PSD boundary is ``inf``, a sum of them too), and only the
    JSON writers encode the non-finite ones (``json_safe``).
    """
    if hasattr(value, "tolist"):  # torch.Tensor, numpy arrays and numpy scalars
        return value.tolist()
    # Leaves that are plain already are kept in place, not recursed into (estimates of a big study
    # hold many short lists).
    if isinstance(value, dict):
        return {str(k): v if type(v) in _ATOMS else to_python(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [v if type(v) in _ATOMS else to_python(v) for v in value]
    return value


def json_safe(value: Any) -> Any:
    """``to_python``, with each non-finite float written as ``"Infinity"``, ``"-Infinity"`` or ``"NaN"``."""
    value = to_python(value)
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list):
        return [json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")
    return value


def from_json_numbers(value: Any) -> Any:
    """Undo ``json_safe``'s encoding: the strings of ``NON_FINITE_JSON`` become floats again."""
    if isinstance(value, dict):
        return {k: from_json_numbers(v) for k, v in value.items()}
    if isinstance(value, list):
        return [from_json_numbers(v) for v in value]
    if isinstance(value, str):
        return NON_FINITE_JSON.get(value, value)
    return value


_ATOMS = frozenset((int, bool, str, float, type(None)))


@dataclass
class Estimate:
    """Physical parameters (and base parameters where defined) identified by one estimator.

    ``cost`` is the final value of the criterion the estimator minimised; ``details`` carries the
    per-run record (each run's parameters and cost, which runs were kept and why, convergence
    history, threads, device) that an estimator chooses to keep: a dict, or a typed record that reads
    as a mapping (``rollout``'s :class:`idkit.sim.details.RolloutDetails`). ``details["history"]``, if
    present, follows the format of ``history_table``.
    """

    estimator: str
    params: dict[str, float]
    cost: float | None
    wall_time_s: float
    base_params: dict[str, float] | None = None
    details: Mapping[str, Any] = field(default_factory=dict)

    def vector(self) -> list[float]:
        """Parameter values in the robot's ``param_names`` order."""
        return list(self.params.values())

    def to_dict(self) -> dict[str, Any]:
        """Plain Python (floats stay typed, non-finite ones included); ``to_json`` encodes those.
        ``details`` may be any mapping (a typed record that reads as one, e.g.
        :class:`idkit.sim.details.RolloutDetails`): its items are what is written."""
        if isinstance(self.details, dict):
            return to_python(asdict(self))
        plain = asdict(replace(self, details={}))
        plain["details"] = dict(self.details)
        return to_python(plain)

    def to_json(self, **kwargs: Any) -> str:
        """Strict JSON; a non-finite number is written as a string (``NON_FINITE_JSON``)."""
        return json.dumps(json_safe(self.to_dict()), allow_nan=False, **kwargs)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Estimate:
        """From ``to_dict`` or parsed ``to_json`` output (the non-finite strings become floats)."""
        return cls(**from_json_numbers(data))

    @classmethod
    def from_json(cls, text: str) -> Estimate:
        return cls.from_dict(json.loads(text))


class HistoryError(ValueError):
    """``details["history"]`` does not follow the documented format (see ``history_table``)."""


def history_table(history: Any) -> tuple[list[str], list[list[Any]]] | None:
    """Convergence history as a table ``(header, rows)``, one row per iteration; ``None`` if empty.

    The format of ``Estimate.details["history"]`` (tensors and numpy arrays are read as lists):

    - a list of numbers ``[iterations]``: one run → columns ``iteration, best_cost``;
    - a list of equal-length lists ``[runs][iterations]`` → ``iteration, run_0, run_1, …``;
    - a mapping of names to equal-length lists of numbers → ``iteration, <name>, …``.

    Numbers are ints or floats (non-finite ones included); ``None`` marks a missing value.
    Validated here, before a file is written, so a bad history is reported as one message instead
    of breaking a run's output after the fit.

    Raises:
        HistoryError: another shape (runs of unequal length, nested deeper, non-numbers), naming
            the run or column and the iteration.
    """
    history = to_python(history)
    if history is None or (isinstance(history, (list, dict)) and not history):
        return None
    # (header name, what to call it in a message, values)
    if isinstance(history, Mapping):
        columns = [(str(name), f"column {name!r}", values) for name, values in history.items()]
    elif isinstance(history, list) and all(isinstance(run, list) for run in history):
        columns = [(f"run_{r}", f"run {r}", values) for r, values in enumerate(history)]
    elif isinstance(history, list):
        columns = [("best_cost", "the history", history)]
    else:
        raise HistoryError(
            'details["history"] must be a list, a list of lists [runs][iterations] or a mapping of '
            f"names to lists, got {type(history).__name__}"
        )
    for _, where, values in columns:
        _check_numbers(where, values)
    (_, first, reference), *others = columns
    for _, where, values in others:
        if len(values) != len(reference):
            raise HistoryError(
                f'details["history"]: {where} has {len(values)} iterations but {first} has '
                f"{len(reference)}; every run (column) must have the same number of iterations"
            )
    if not reference:
        return None
    header = ["iteration", *(name for name, _, _ in columns)]
    return header, [[i, *row] for i, row in enumerate(zip(*(v for _, _, v in columns), strict=True))]


def _check_numbers(where: str, values: Any) -> None:
    if not isinstance(values, list):
        raise HistoryError(
            f'details["history"]: {where} must be a list of numbers, got {type(values).__name__}'
        )
    for i, value in enumerate(values):
        if value is not None and (isinstance(value, bool) or not isinstance(value, numbers.Real)):
            raise HistoryError(
                f'details["history"]: {where} has {value!r} ({type(value).__name__}) at iteration {i}; '
                "expected a number (a list of lists [runs][iterations] nests one level only)"
            )
