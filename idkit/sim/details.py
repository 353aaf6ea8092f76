"""What a rollout fit records beside its values: a typed record, read by attribute.

``Estimate.details`` of the ``rollout`` estimator is a :class:`RolloutDetails`. idkit's own code (the
study, the reports) reads its attributes; it is also a read-only mapping of :meth:`to_dict`'s keys, so
that whatever reads any estimate's details generically (``Estimate.to_json``, ``history_table``, the
conformance suite) reads it as it reads a dict, and ``result.json`` holds :meth:`to_dict`.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from idkit.sim.uncertainty import Uncertainty


@dataclass(frozen=True)
class States:
    """Joint positions and velocities ``q``, ``qd`` ``[S, n]``: one row per segment start."""

    q: np.ndarray
    qd: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        return {"q": np.asarray(self.q).tolist(), "qd": np.asarray(self.qd).tolist()}


@dataclass(frozen=True)
class SearchSummary:
    """The swarm search's outcome: its best ``cost``, the candidates it evaluated, and the values it
    handed to the polish (``start``, in the unknowns' order)."""

    cost: float
    evaluations: int
    start: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        return {"cost": self.cost, "evaluations": self.evaluations, "start": np.asarray(self.start).tolist()}


@dataclass(frozen=True)
class PolishSolve:
    """One Levenberg–Marquardt solve of the polish.

    Attributes:
        segments: segments it rolled out.
        initial_states_free: whether the segments' initial states were fitted too.
        iterations: accepted and rejected steps taken (``len(losses) - 1``).
        losses: the loss after each accepted step (the last is the solve's polish cost).
        stop: why it stopped (``ftol``, ``xtol``, ``max_iter``, ...).
        scales: ``[2n]`` the robust scale of each channel it divided by (the channels' units).
        jacobians: finite-difference Jacobians computed (between two, Broyden updates follow the steps).
    """

    segments: int
    initial_states_free: bool
    iterations: int
    losses: list[float]
    stop: str
    scales: list[float]
    jacobians: int = 0

    @property
    def cost(self) -> float:
        """The loss it ended at."""
        return self.losses[-1] if self.losses else float("nan")

    def to_dict(self) -> dict[str, Any]:
        return {
            "segments": self.segments,
            "initial_states_free": self.initial_states_free,
            "iterations": self.iterations,
            "losses": list(self.losses),
            "stop": self.stop,
            "scales": list(self.scales),
            "jacobians": self.jacobians,
        }


@dataclass(frozen=True)
class RolloutDetails(Mapping[str, Any]):
    """Everything a rollout fit records besides its values and cost.

    Attributes:
        loss: the polish's loss (``huber``, ``cauchy``, ``linear``).
        criterion: what ``Estimate.cost`` is (the problem's cost, or the default robust score).
        search: the swarm search's outcome (``None``: no search, the polish started at the starts).
        history: the search's best cost per evaluation (``Estimate.details["history"]``'s format).
        polish: the polish's solves, in order.
        uncertainty: standard deviations, 95 % intervals, flat directions (:mod:`idkit.sim.uncertainty`).
        exact_fit: the log is reproduced within a tenth of its noise (a noiseless log).
        segments: ``(first, last)`` sample of every segment of the log.
        initial_states: each segment's initial state as fitted by the polish.
        search_initial_states: each segment's initial state as the search started it (glitches
            replaced, :mod:`idkit.sim.initial`).
        bodies: each fitted body's mass, centre of mass and inertia about it.
        rollouts: segment rollouts run.
        simulated_seconds: seconds of motion simulated in all.
        outliers: log samples left out of the error as a driver's artefact (stalled or dropped rows),
            by kind (:mod:`idkit.data.artefacts`).
    """

    loss: str
    criterion: str
    search: SearchSummary | None
    history: list[float]
    polish: tuple[PolishSolve, ...]
    uncertainty: Uncertainty
    exact_fit: bool
    segments: tuple[tuple[int, int], ...]
    initial_states: States
    search_initial_states: States
    bodies: dict[str, dict[str, Any]] = field(default_factory=dict)
    rollouts: int = 0
    simulated_seconds: float = 0.0
    outliers: dict[str, int] = field(default_factory=dict)

    @property
    def polish_cost(self) -> float:
        """The loss the last polish solve ended at (``nan`` without a solve)."""
        return self.polish[-1].cost if self.polish else float("nan")

    def to_dict(self) -> dict[str, Any]:
        """Plain data for ``result.json``."""
        return self._plain

    @cached_property
    def _plain(self) -> dict[str, Any]:
        return {
            "loss": self.loss,
            "criterion": self.criterion,
            "search": None if self.search is None else self.search.to_dict(),
            "history": list(self.history),
            "polish": [solve.to_dict() for solve in self.polish],
            "polish_cost": self.polish_cost,
            "uncertainty": self.uncertainty.to_dict(),
            "exact_fit": self.exact_fit,
            "segments": [list(s) for s in self.segments],
            "initial_states": self.initial_states.to_dict(),
            "search_initial_states": self.search_initial_states.to_dict(),
            "bodies": self.bodies,
            "rollouts": self.rollouts,
            "simulated_seconds": self.simulated_seconds,
            "outliers": dict(self.outliers),
        }

    def __getitem__(self, key: str) -> Any:
        return self._plain[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._plain)

    def __len__(self) -> int:
        return len(self._plain)
