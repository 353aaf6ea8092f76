"""The result of one fit, as plain data that survives a round trip through JSON."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from typing import Any


def jsonable(value: Any) -> Any:
    """Convert tensors, numpy arrays and scalars nested in dicts/lists to JSON-ready Python.

    Non-finite floats become ``None`` so that the output is strict JSON (no ``NaN`` tokens).
    """
    if hasattr(value, "tolist"):  # torch.Tensor, numpy arrays and numpy scalars
        value = value.tolist()
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


@dataclass
class Estimate:
    """Physical parameters (and base parameters where defined) identified by one estimator.

    ``cost`` is the final value of the criterion the estimator minimised; ``details`` carries the
    per-run record (each run's parameters and cost, which runs were kept and why, convergence
    history, threads, device) that an estimator chooses to keep.
    """

    estimator: str
    params: dict[str, float]
    cost: float | None
    wall_time_s: float
    base_params: dict[str, float] | None = None
    details: dict[str, Any] = field(default_factory=dict)

    def vector(self) -> list[float]:
        """Parameter values in the robot's ``param_names`` order."""
        return list(self.params.values())

    def to_dict(self) -> dict[str, Any]:
        return jsonable(asdict(self))

    def to_json(self, **kwargs: Any) -> str:
        return json.dumps(self.to_dict(), allow_nan=False, **kwargs)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Estimate:
        return cls(**data)

    @classmethod
    def from_json(cls, text: str) -> Estimate:
        return cls.from_dict(json.loads(text))
