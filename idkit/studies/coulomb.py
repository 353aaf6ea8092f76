"""``robot.coulomb_velocity=auto``: the velocity scale of the Coulomb friction chosen from the data.

``sign(q̇)`` makes a joint at rest flip between ``±fc`` with the sign of its velocity noise;
``tanh(q̇ / v_c)`` (:mod:`idkit.robots.drives`) does not, but a ``v_c`` too large smears real
friction over slow motion. Which ``v_c`` a recording calls for depends on its velocity noise and on
how long its joints rest, so it is chosen as the prior weight is (:mod:`idkit.estimators.physical`):
the training samples are cut into contiguous blocks, least squares on the base regressor is fitted
on all blocks but one and scored on that one (pooled ``‖E‖/‖T‖``) for every candidate in
:data:`CANDIDATES` (0: the sign). The choice is the one-standard-error rule leaning towards the sign:
the *smallest* scale whose cross-validated error exceeds the lowest by at most one standard error of
that excess (paired over the blocks) — a smoothing the data cannot show to help is not applied.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from idkit.conic.program import compress
from idkit.notes import Note
from idkit.problem import Samples

#: Velocity scales tried (rad/s or m/s); 0 is the sign.
CANDIDATES: tuple[float, ...] = (0.0, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2)
#: The drive terms whose ``sign(q̇)`` a velocity scale smooths (:func:`idkit.robots.drives.coulomb_sign`).
COULOMB_TERMS = ("fc", "fc_pos", "fc_neg", "fs")
#: Contiguous blocks of the training samples (as for the prior weight).
FOLDS = 5


class CoulombVelocityNote(Note):
    """``robot.coulomb_velocity=auto`` chose a velocity scale: which, and why."""


@dataclass(frozen=True)
class CoulombChoice:
    """How ``coulomb_velocity=auto`` chose.

    Attributes:
        value: the chosen scale (0: the sign).
        scores: per candidate, the pooled cross-validated ``‖E‖/‖T‖``.
        folds: the number of contiguous blocks.
        reason: one line: why this scale (or why no cross-validation was possible).
    """

    value: float
    scores: dict[float, float]
    folds: int
    reason: str

    def to_dict(self) -> dict[str, Any]:
        """For ``result.json`` (``data.coulomb_velocity``)."""
        return {
            "value": self.value,
            "scores": {str(k): v for k, v in self.scores.items()},
            "folds": self.folds,
            "reason": self.reason,
        }


def wants_choice(robot: Any) -> bool:
    """Whether ``robot`` asks for ``coulomb_velocity=auto`` and has a Coulomb term to smooth."""
    value, friction = getattr(robot, "coulomb_velocity", None), getattr(robot, "friction", False)
    return isinstance(value, str) and value == "auto" and (friction is True or friction == "asymmetric")


def choose_coulomb_velocity(
    robot: Any, samples: Samples, candidates: Sequence[float] = CANDIDATES, folds: int = FOLDS
) -> tuple[Any, CoulombChoice]:
    """The robot with the chosen ``coulomb_velocity`` (module doc) and how it was chosen."""
    n = robot.n_joints
    N, B = samples.q.shape[0], len(robot.base_param_names)
    if N < folds * -(-(B + 1) // n) * 2:  # noqa: SIM300 (as the prior weight's rule reads)
        reason = f"{N} samples are too few to cross-validate over {folds} blocks; Coulomb friction by sign(q̇)"
        return robot, CoulombChoice(0.0, {}, folds, reason)  # "auto" until chosen: the sign
    bounds = np.linspace(0, N, folds + 1).round().astype(int)
    tau = samples.tau.double()
    totals = np.array([float(tau[a:z].square().sum()) for a, z in zip(bounds[:-1], bounds[1:], strict=True)])
    X, columns = _candidate_columns(robot, samples, candidates)
    blocks = [
        compress(X[a:z].reshape(-1, X.shape[-1]), tau[a:z].reshape(-1))
        for a, z in zip(bounds[:-1], bounds[1:], strict=True)
    ]
    squared: dict[float, np.ndarray] = {}
    for value, used in zip(candidates, columns, strict=True):
        errors = []
        for k, (R_k, b_k, rest_k) in enumerate(blocks):  # fit the other blocks, score this one
            others = [blocks[j] for j in range(folds) if j != k]
            R = np.vstack([r[:, used] for r, _, _ in others])
            fit = np.linalg.lstsq(R, np.concatenate([b for _, b, _ in others]), rcond=None)[0]
            residual = R_k[:, used] @ fit - b_k
            errors.append(float(residual @ residual) + rest_k)
        squared[value] = np.array(errors) / totals.sum()
    scores = {value: float(np.sqrt(parts.sum())) for value, parts in squared.items()}
    best = min(scores, key=lambda v: scores[v])
    distance = {}
    for value, parts in squared.items():
        excess = parts - squared[best]
        spread = np.sqrt(folds) * float(np.std(excess, ddof=1))
        distance[value] = float(excess.sum() / spread) if spread > 0 else 0.0
    chosen = min(v for v in candidates if distance[v] <= 1.0)
    choice = CoulombChoice(float(chosen), scores, folds, _reason(chosen, best, scores, folds))
    if chosen == 0:  # "auto" is the sign until a scale is chosen
        return robot, choice
    return robot.with_options(coulomb_velocity=float(chosen)), choice


def _candidate_columns(
    robot: Any, samples: Samples, candidates: Sequence[float]
) -> tuple[torch.Tensor, list[list[int]]]:
    """One wide regressor ``X[N, n, B + c]`` holding the base regressor with ``sign(q̇)`` and, for every
    other candidate, its own Coulomb columns; and each candidate's base regressor as column indices
    into ``X``. One QR of ``[X | τ]`` per block then scores every candidate: for columns ``S``,
    ``‖X_S a − τ‖² = ‖R_S a − b‖² + r²`` (what :func:`~idkit.conic.program.compress` keeps)."""
    base = list(robot.base.indices)
    qd, qdd = samples.qd.double(), samples.qdd.double()
    sign = robot.standard_regressor(samples.q, samples.qd, samples.qdd).double()[..., base]  # [N, n, B]
    first = len(robot.param_names) - robot.drives.size  # the drive parameters come last
    coulomb = set(robot.drives.names_where(lambda term: term.suffix in COULOMB_TERMS))
    moving = [j for j, k in enumerate(base) if robot.param_names[k] in coulomb]
    wide, columns, width = [sign], [], len(base)
    for value in candidates:
        used = list(range(len(base)))
        if value > 0:
            smoothed = copy.copy(
                robot.drives
            )  # the same terms at this scale: only the Coulomb columns change
            smoothed.coulomb_scales = np.full(robot.n_joints, float(value))
            wide.append(smoothed.columns(qd, qdd)[..., [base[j] - first for j in moving]])
            for i, j in enumerate(moving):
                used[j] = width + i
            width += len(moving)
        columns.append(used)
    return torch.cat(wide, dim=-1), columns


def _reason(chosen: float, best: float, scores: dict[float, float], folds: int) -> str:
    """The note's line: the choice, the cross-validated figures both ways, and how to override it."""
    how = f"{folds}-fold cross-validated torque error (least squares, contiguous blocks of the training data)"
    among = ", ".join(f"{v:g}" for v in scores) + " rad/s"
    sign = scores.get(0.0, float("nan"))
    if chosen == 0:
        return (
            f"Coulomb friction as sign(q̇): no velocity scale ({among}) lowers the {how} by more than one "
            f"standard error ({100 * sign:.3g} % with the sign, {100 * scores[best]:.3g} % at the best, "
            f"{best:g}); robot.coulomb_velocity=<scale> sets one"
        )
    return (
        f"Coulomb friction as tanh(q̇ / {chosen:g}): the smallest velocity scale ({among}) whose {how} is "
        f"within one standard error of the lowest ({100 * scores[best]:.3g} % at {best:g}): "
        f"{100 * scores[chosen]:.3g} % against {100 * sign:.3g} % with sign(q̇); robot.coulomb_velocity=0 "
        "keeps the sign"
    )
