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

from idkit.conic.program import compress
from idkit.notes import Note
from idkit.problem import Samples

#: Velocity scales tried (rad/s or m/s); 0 is the sign.
CANDIDATES: tuple[float, ...] = (0.0, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2)
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
        return {
            "value": self.value,
            "scores": {str(k): v for k, v in self.scores.items()},
            "folds": self.folds,
            "reason": self.reason,
        }


def wants_choice(robot: Any) -> bool:
    """Whether ``robot`` asks for ``coulomb_velocity=auto`` and has a Coulomb term to smooth."""
    return getattr(robot, "coulomb_velocity", None) == "auto" and getattr(robot, "friction", False) in (
        True,
        "asymmetric",
    )


def choose_coulomb_velocity(
    robot: Any, samples: Samples, candidates: Sequence[float] = CANDIDATES, folds: int = FOLDS
) -> tuple[Any, CoulombChoice]:
    """The robot with the chosen ``coulomb_velocity`` (module doc) and how it was chosen."""
    n = robot.n_joints
    N, B = samples.q.shape[0], len(robot.base_param_names)
    if N < folds * -(-(B + 1) // n) * 2:  # noqa: SIM300 (as the prior weight's rule reads)
        reason = f"{N} samples are too few to cross-validate over {folds} blocks; Coulomb friction by sign(q̇)"
        return robot.with_options(coulomb_velocity=0.0), CoulombChoice(0.0, {}, folds, reason)
    bounds = np.linspace(0, N, folds + 1).round().astype(int)
    tau = samples.tau.double()
    totals = np.array([float(tau[a:z].square().sum()) for a, z in zip(bounds[:-1], bounds[1:], strict=True)])
    standard = robot.standard_regressor(samples.q, samples.qd, samples.qdd).double()  # [N, n, P], sign(q̇)
    drives = slice(len(robot.param_names) - robot.drives.size, len(robot.param_names))
    squared: dict[float, np.ndarray] = {}
    for value in candidates:
        smoothed = copy.copy(robot.drives)  # the same terms with this scale: only the friction columns change
        smoothed.coulomb_scales = np.full(n, float(value)) if value > 0 else None
        standard[..., drives] = smoothed.columns(samples.qd.double(), samples.qdd.double())
        W = standard[..., list(robot.base.indices)]  # [N, n, B]: the base regressor (URDFRobot.regressor)
        blocks = [
            compress(W[a:z].reshape(-1, B), tau[a:z].reshape(-1))
            for a, z in zip(bounds[:-1], bounds[1:], strict=True)
        ]
        errors = []
        for k, (R_k, b_k, rest_k) in enumerate(blocks):  # fit the other blocks, score this one
            others = [blocks[j] for j in range(folds) if j != k]
            R = np.vstack([r for r, _, _ in others])
            fit = np.linalg.lstsq(R, np.concatenate([b for _, b, _ in others]), rcond=None)[0]
            residual = R_k @ fit - b_k
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
    shown = "sign(q̇)" if chosen == 0 else f"tanh(q̇ / {chosen:g})"
    reason = (
        f"Coulomb friction as {shown}: the smallest velocity scale whose {folds}-fold cross-validated "
        f"torque error (least squares, contiguous blocks of the training data) is within one standard error "
        f"of the lowest ({100 * scores[best]:.3g} % at {best:g}); {100 * scores[chosen]:.3g} % here, "
        f"{100 * scores[0.0]:.3g} % with sign(q̇) — among "
        + ", ".join(f"{v:g}" for v in candidates)
        + " rad/s"
        if 0.0 in scores
        else ""
    )
    return robot.with_options(coulomb_velocity=float(chosen)), CoulombChoice(
        float(chosen), scores, folds, reason
    )
