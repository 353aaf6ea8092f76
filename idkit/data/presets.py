"""The scenario presets (the paper's Tables II–V and a clean run), importable without torch.

The command line's ``scenario`` config group is generated from :data:`SCENARIOS` (``idkit.cli.source``),
and ``idkit --help`` lists it without importing torch, hence this module apart from
:mod:`idkit.data.scenarios` (which simulates them).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields, replace
from types import MappingProxyType
from typing import Any

__all__ = ["PAPER_SCENARIOS", "SCENARIOS", "Scenario", "UnknownScenarioError"]


class UnknownScenarioError(LookupError):
    """A scenario name that is not in ``SCENARIOS``; the message lists the available ones."""


@dataclass(frozen=True)
class Scenario:
    """How many samples to take and how to corrupt them (levels are fractions: 0.2 = 20 %).

    Attributes:
        name: label, e.g. ``"outliers"``.
        n_samples: number of samples ``N`` over ``0 < t <= t_end``.
        state_noise: level ``X`` of the multiplicative error on ``q``, ``qd``, ``qdd``.
        torque_noise: level ``X`` of the multiplicative error on ``tau``.
        n_outliers: how many of the ``N · 4 · n`` components get ``outlier_noise`` instead (a
            count, not a share: overriding ``n_samples`` keeps it).
        outlier_noise: level of the error on those components.
        t_end: length of the excitation window in seconds.
        description: one line for tables and logs.
        excitation: the motion to sample instead of the robot's default one: a family name
            (``fourier``, ``paper``) or an excitation file (``excitation.yaml`` of
            ``idkit +experiment=excitation``); ``None``: the robot's default.
    """

    name: str = "custom"
    n_samples: int = 10
    state_noise: float = 0.0
    torque_noise: float = 0.0
    n_outliers: int = 0
    outlier_noise: float = 0.0
    t_end: float = 10.0
    description: str = ""
    excitation: str | None = None

    def __post_init__(self) -> None:
        where = f"scenario {self.name!r}"
        if self.excitation is not None and (not isinstance(self.excitation, str) or not self.excitation):
            raise ValueError(
                f"{where}: excitation must be a family name or the path of an excitation file, "
                f"got {self.excitation!r}"
            )
        for key, least in (("n_samples", 1), ("n_outliers", 0)):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int) or value < least:
                raise ValueError(f"{where}: {key} must be an integer >= {least}, got {value!r}")
        for key in ("state_noise", "torque_noise", "outlier_noise", "t_end"):
            value = getattr(self, key)
            number = isinstance(value, (int, float)) and not isinstance(value, bool)
            if not number or not math.isfinite(value) or value < 0:
                raise ValueError(f"{where}: {key} must be a finite number >= 0, got {value!r}")
        if self.t_end == 0:
            raise ValueError(f"{where}: t_end must be > 0")

    def replace(self, **overrides: Any) -> Scenario:
        """A copy with some fields changed (unknown names are an error listing the valid ones)."""
        valid = [f.name for f in fields(self)]
        unknown = sorted(set(overrides) - set(valid))
        if unknown:
            raise TypeError(f"scenario: unknown field(s) {unknown}; valid fields: {', '.join(valid)}")
        return replace(self, **overrides)

    def as_dict(self) -> dict[str, Any]:
        """Plain dict (JSON/Hydra-friendly); ``Scenario(**s.as_dict()) == s``."""
        return asdict(self)


SCENARIOS: Mapping[str, Scenario] = MappingProxyType(
    {
        s.name: s
        for s in (
            Scenario("clean", 10, description="no error"),
            Scenario("state_noise", 10, state_noise=0.2, description="Table II: up to 20 % on q, qd, qdd"),
            Scenario("torque_noise", 10, torque_noise=0.2, description="Table III: up to 20 % on tau"),
            Scenario("all_noise", 20, 0.2, 0.2, description="Table IV: up to 20 % on everything"),
            Scenario(
                "outliers",
                10,
                state_noise=0.05,
                torque_noise=0.05,
                n_outliers=10,
                outlier_noise=0.7,
                description="Table V: up to 70 % on 10 of 120 components, up to 5 % on the rest",
            ),
        )
    }
)

#: The four noisy scenarios of the paper's Tables II–V, in table order.
PAPER_SCENARIOS: tuple[str, ...] = ("state_noise", "torque_noise", "all_noise", "outliers")
