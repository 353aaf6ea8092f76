"""``pcls``: physically consistent least squares, with the pull towards CAD chosen from the data.

The program (pseudo-inertia LMIs, the entropic prior, plausibility bounds, the solver chain) is
:mod:`idkit.conic.program`; this module is the estimator around it: the QR-compressed data term,
``prior_weight="auto"`` by cross-validation over contiguous blocks of the training recording
(:func:`cross_validated_weight`), and what the estimate reports.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Literal

import numpy as np
import torch
from torch import Tensor

from idkit.conic.plausible import PLAUSIBLE_MASS_RATIO, Plausibility, plausibility_report
from idkit.conic.prior import cad_reference
from idkit.conic.program import (
    NOISE_FLOOR,
    ConsistentProgram,
    ConsistentSettings,
    Solver,
    compress,
)
from idkit.estimate import Estimate, to_python
from idkit.estimators.linear.uncertainty import base_uncertainty
from idkit.interfaces import Estimator
from idkit.notes import Note
from idkit.problem import IdentificationError, Problem
from idkit.progress import report
from idkit.robots.inertia import linked

if TYPE_CHECKING:
    from idkit.robots.urdf import URDFRobot

#: Prior weights tried by ``prior_weight="auto"`` (half-decades; 0 = the data alone, with the tie-break).
PRIOR_CANDIDATES = (0.0, 1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0, 3000.0, 10000.0)
#: Contiguous blocks of the training samples for ``prior_weight="auto"``.
PRIOR_FOLDS = 5


class PriorWeightWarning(UserWarning):
    """``prior_weight=auto`` could not cross-validate and fell back to a fixed weight: which, and why."""


class PriorWeightNote(Note):
    """``prior_weight=auto`` chose a weight by cross-validation: which, and why (as the cut-off's note)."""


@dataclass(frozen=True)
class WeightChoice:
    """How ``prior_weight="auto"`` chose: :func:`cross_validated_weight`.

    Attributes:
        weight: the chosen prior weight.
        scores: per candidate, the pooled held-out ``‖E‖/‖T‖`` over the folds (``inf``: a solve failed).
        per_fold: per candidate, each fold's held-out ``‖E_k‖/‖T_k‖``.
        standard_errors: per candidate, its pooled squared error's excess over the lowest, in standard
            errors of that excess (paired over the folds; ``<= 1``: as good as the best).
        folds: the number of contiguous blocks.
        reason: one line (why this weight, or why no cross-validation was possible).
    """

    weight: float
    scores: dict[float, float]
    per_fold: dict[float, list[float]]
    standard_errors: dict[float, float]
    folds: int
    reason: str

    def to_details(self) -> dict[str, Any]:
        """For ``Estimate.details["prior_weight_cv"]``."""
        return {
            "chosen": self.weight,
            "candidates": list(self.scores),
            "scores": list(self.scores.values()),
            "standard_errors_from_best": [self.standard_errors.get(w) for w in self.scores],
            "per_fold": list(self.per_fold.values()),
            "folds": self.folds,
            "reason": self.reason,
        }


def cross_validated_weight(
    programs: Callable[[bool], ConsistentProgram],
    robot: URDFRobot,
    W: Tensor,
    tau: Tensor,
    scale2: float,
    folds: int = PRIOR_FOLDS,
    candidates: Sequence[float] = PRIOR_CANDIDATES,
) -> WeightChoice:
    """The prior weight whose fit predicts held-out blocks of the training data best.

    The ``N`` samples (in time order; rows ``W[N n, B]``, ``tau[N n]``) are cut into ``folds``
    contiguous blocks of whole samples. For every candidate weight and every block, the consistent
    program is solved on the other blocks (their ``[W | tau]`` QR-compressed per block and stacked,
    so a fold costs one small QR; the data scale ``scale2`` is the full data's) and scored on the
    block: ``‖W_k alpha − tau_k‖²`` from the block's own compression. Contiguous blocks, because
    neighbouring samples are correlated: a held-out sample whose neighbours were fitted is no test.
    ``programs(prior)`` hands out the two (cached) programs, so each is canonicalised once.

    The choice is the one-standard-error rule (Breiman et al. 1984; Hastie, Tibshirani & Friedman,
    §7.10): the *largest* weight — the model closest to CAD — whose pooled squared error
    ``Σ_k ‖E_k‖² / Σ_k ‖T_k‖²`` exceeds the lowest by at most one standard error of that excess,
    estimated from its per-fold parts (paired: each block is scored under both weights, so the
    blocks' very different difficulty cancels). Why lean to the prior: blocks of one recording are
    more alike than a new trajectory is, so the folds reward following the data more than new motion
    will; where they cannot tell two weights apart, the one that trusts CAD more is the safer bet.
    """
    n = robot.n_joints
    samples = W.shape[0] // n
    B = W.shape[1]
    if samples < folds * -(-(B + 1) // n) * 2:
        reason = f"{samples} samples are too few to cross-validate over {folds} blocks; prior weight 0"
        return WeightChoice(0.0, {}, {}, {}, folds, reason)
    bounds = np.linspace(0, samples, folds + 1).round().astype(int) * n
    blocks = [compress(W[a:z], tau[a:z]) for a, z in zip(bounds[:-1], bounds[1:], strict=True)]
    totals = [float(tau[a:z].double().square().sum()) for a, z in zip(bounds[:-1], bounds[1:], strict=True)]
    training = []
    for k in range(folds):
        rest = [blocks[j] for j in range(folds) if j != k]
        training.append(
            compress(
                torch.from_numpy(np.vstack([r for r, _, _ in rest])),
                torch.from_numpy(np.concatenate([b for _, b, _ in rest])),
            )
        )
    K = robot.base_map.numpy()
    scores: dict[float, float] = {}
    per_fold: dict[float, list[float]] = {}
    squared: dict[float, np.ndarray] = {}
    failures: list[IdentificationError] = []
    fits, of = 0, len(candidates) * folds  # said to a study that listens (idkit.progress)
    for weight in candidates:
        errors = []
        try:
            for k in range(folds):
                R, b, _ = training[k]
                params = programs(weight > 0).solve(R, b, scale2, weight).params.numpy()
                Rk, bk, rest_k = blocks[k]
                residual = Rk @ (K @ params) - bk
                errors.append(float(residual @ residual) + rest_k)
                fits += 1
                report("prior_weight=auto: cross-validation", fits, of)
        except IdentificationError as exc:  # a weight the solver cannot handle drops out
            failures.append(exc)
            scores[weight], per_fold[weight] = float("inf"), []
            continue
        squared[weight] = np.array(errors) / sum(totals)
        scores[weight] = float(np.sqrt(squared[weight].sum()))
        per_fold[weight] = [float(np.sqrt(e / t)) for e, t in zip(errors, totals, strict=True)]
    if not squared:  # infeasible constraints, or a solver that fails whatever the weight: its own words
        raise failures[0]
    best = min(squared, key=lambda w: scores[w])
    distance = {}
    for weight, parts in squared.items():
        excess = parts - squared[best]
        error = np.sqrt(folds) * float(np.std(excess, ddof=1))
        distance[weight] = float(excess.sum() / error) if error > 0 else 0.0
    chosen = max(w for w in squared if distance[w] <= 1.0)
    reason = (
        f"the largest prior weight whose {folds}-fold cross-validated torque error on contiguous blocks of "
        f"the training data is within one standard error of the lowest ({100 * scores[best]:.3g} % at "
        f"{best:g}): {chosen:g} ({100 * scores[chosen]:.3g} %), among "
        + ", ".join(f"{w:g}" for w in candidates)
    )
    failed = [w for w in candidates if w not in squared]
    if failed:  # chosen without them: a warning, not a note — the choice may have been shaped by it
        warnings.warn(
            f"pcls prior_weight=auto: the solve failed for weight {', '.join(f'{w:g}' for w in failed)}, "
            f"left out of the choice ({failures[0]}); set estimator.prior_weight to fix one",
            PriorWeightWarning,
            stacklevel=3,
        )
        reason += f"; {', '.join(f'{w:g}' for w in failed)} left out (the solve failed)"
    return WeightChoice(chosen, scores, per_fold, distance, folds, reason)


def misfit_scale(scale2: float, consistent: float, shape: tuple[int, ...]) -> float:
    """The data term's variance ``s²``: the least-squares residual variance ``scale2``, unless the best
    consistent fit (residual ``consistent = ‖W alpha − tau‖²``, rows and columns ``shape``) misses by
    more than twice that — data no rigid bodies explain (a model error, or noise-free simulations of
    impossible parameters). Then that misfit is the noise the χ² counts: otherwise a data term of
    1e9 χ² units would swamp the prior and leave the conic solver no digits to work with."""
    misfit = consistent / max(shape[0] - shape[1], 1)
    return misfit if misfit > 2 * scale2 else scale2


class PhysicallyConsistentLS(Estimator):
    """``pcls``: least squares on the standard parameters under the pseudo-inertia LMIs
    (:mod:`idkit.conic.program`).

    Args:
        prior_weight: weight of the entropic divergence to the CAD model; 0 = data only (a tie-break
            still resolves the unidentifiable part towards CAD); ``"auto"`` (the default): the
            candidate of :data:`PRIOR_CANDIDATES` that predicts held-out contiguous blocks of the
            training data best (:func:`cross_validated_weight`).
        min_mass: lower bound on every link mass (kg); ``None`` = 1 % of the smallest CAD mass.
        plausible: keep every link plausible, not only consistent (:mod:`idkit.conic.plausible`):
            its mass within ``mass_ratio`` times CAD and inside the ellipsoid bounding its collision
            (or visual) geometry where the model has some. Off by default: it trades held-out accuracy for
            physical realism, and the report shows both (every fit flags links outside
            :data:`~idkit.conic.plausible.PLAUSIBLE_MASS_RATIO`).
        mass_ratio: ``[lo, hi]``, the bound ``plausible`` enforces.
        total_mass: the moving links' total mass in kg (from a data sheet), or ``None``; enforced
            whenever given.
        solver: ``"auto"`` (Clarabel, Clarabel relaxed, then SCS), ``"clarabel"`` or ``"scs"``.

    ``details``: ``min_eigenvalue`` per link, ``divergence`` per link, solver, status, times,
    ``rel_error_train`` (‖E‖/‖T‖ on the training samples), ``prior_weight`` (the one used) and, for
    ``"auto"``, ``prior_weight_cv`` (candidates, pooled and per-fold scores, the reason, its time),
    ``plausibility`` (masses beside CAD, the implausible links, what was enforced, the links at a
    bound), ``cad_reference`` (CAD bodies the prior thickened or replaced), and the base-parameter
    uncertainty of :func:`idkit.estimators.linear.uncertainty.base_uncertainty` (the data's scatter at
    the pcls estimate, plus the prior's and the constraints' pull from least squares as a bias).
    """

    #: The conformance suite's problem: pcls needs a ``urdf`` robot (the cylindrical one from its URDF).
    conformance_robot: ClassVar[tuple[str, dict[str, Any]]] = (
        "urdf",
        {"urdf": "cylindrical", "friction": True},
    )

    def __init__(
        self,
        prior_weight: float | Literal["auto"] = "auto",
        min_mass: float | None = None,
        plausible: bool = False,
        mass_ratio: Sequence[float] = PLAUSIBLE_MASS_RATIO,
        total_mass: float | None = None,
        solver: Solver = "auto",
    ) -> None:
        self.prior_weight = prior_weight
        self.min_mass = min_mass
        self.plausible = plausible
        self.mass_ratio = mass_ratio
        self.total_mass = total_mass
        self.solver = solver
        self.resolve()  # refused now, not after loading the data

    def resolve(self) -> ConsistentSettings:
        """The options checked and resolved; at construction and at every fit, so an assigned option
        counts."""
        if not isinstance(self.plausible, bool):
            raise ValueError(f"pcls: plausible must be true or false, got {self.plausible!r}")
        ratio = Plausibility.checked("pcls", mass_ratio=self.mass_ratio).mass_ratio
        bounds = Plausibility.checked(
            "pcls", ratio if self.plausible else None, self.total_mass, geometry=self.plausible
        )
        return ConsistentSettings.checked(
            "pcls", self.prior_weight, self.min_mass, self.solver, auto=True, plausibility=bounds
        )

    @property
    def name(self) -> str:
        weight = self.prior_weight
        if weight == "auto":
            return "PCLS"
        return "PCLS" + (f"-prior{float(weight):g}" if float(weight) > 0 else "")

    def fit(self, problem: Problem) -> Estimate:
        start = time.perf_counter()
        settings = self.resolve()
        problem.check_identifiable()
        robot = linked(problem.robot)
        reference = cad_reference(robot)
        reference.announce("pcls")
        s = problem.tensors()
        W = problem.base_regressor()
        tau = s.tau.reshape(-1)
        R, b, rest = compress(W, tau)
        norm2 = float(tau.double().square().sum())
        if norm2 == 0.0:
            raise IdentificationError("pcls: the measured torques are all zero; nothing to fit")
        scale2 = max(rest, NOISE_FLOOR * norm2) / max(W.shape[0] - W.shape[1], 1)
        built: dict[bool, ConsistentProgram] = {}

        def programs(prior: bool) -> ConsistentProgram:
            if prior not in built:
                built[prior] = ConsistentProgram(robot, settings, R.shape[0], prior, reference=reference)
            return built[prior]

        once = settings.prior_weight != "auto"  # only cross-validation solves a program many times
        first = programs(False).solve(R, b, scale2, 0.0, once=once)
        ls_scale2, scale2 = scale2, misfit_scale(scale2, first.data_term * scale2 + rest, W.shape)
        if scale2 != ls_scale2:  # the tie-break's weight is relative to the data's: solve again
            first = programs(False).solve(R, b, scale2, 0.0, once=once)
        cross_validation: dict[str, Any] | None = None
        if settings.prior_weight == "auto":
            started = time.perf_counter()
            chosen = cross_validated_weight(programs, robot, W, tau, scale2)
            weight = chosen.weight
            if not chosen.scores:  # no candidate was scored: a fallback, not a choice the data made
                warnings.warn(
                    f"pcls prior_weight=auto: {chosen.reason} (the data alone, no pull towards the CAD "
                    "prior; set estimator.prior_weight to choose one)",
                    PriorWeightWarning,
                    stacklevel=2,
                )
            else:
                warnings.warn(f"pcls prior_weight=auto: {chosen.reason}", PriorWeightNote, stacklevel=2)
            solution = programs(weight > 0).solve(R, b, scale2, weight)
            cross_validation = {**chosen.to_details(), "time_s": time.perf_counter() - started}
        else:
            weight = float(settings.prior_weight)
            solution = programs(True).solve(R, b, scale2, weight, once=True) if weight > 0 else first
        params = solution.params.to(device=s.q.device, dtype=s.q.dtype)
        alpha = robot.base_params(params)
        residual = float(np.sqrt(max(solution.data_term * scale2 + rest, 0.0)))
        cost = residual if problem.cost is None else float(problem.evaluate(params))
        names = robot.link_names
        details: dict[str, Any] = {
            "criterion": "||tau_s - W alpha||_2 s.t. pseudo-inertias PSD",
            "criterion_value": residual,
            "rel_error_train": residual / np.sqrt(norm2),
            "prior_weight": weight,
            "min_eigenvalue": dict(zip(names, solution.min_eigenvalues.tolist(), strict=True)),
            "divergence": dict(zip(names, solution.divergence.tolist(), strict=True)),
            "solver": solution.solver,
            "status": solution.status,
            "solve_time_s": solution.solve_time_s,
            "equations": int(W.shape[0]),
            "data_scale": {"least_squares": np.sqrt(ls_scale2), "used": np.sqrt(scale2)},
            "cad_reference": {"thickened": list(reference.thickened), "replaced": list(reference.replaced)},
            **base_uncertainty(
                W, tau, alpha, robot.base_param_names, robot.unidentifiable, robot.n_joints, pulled=True
            ).to_details(),
        }
        if solution.repaired:
            details["repaired"] = list(solution.repaired)
        details["plausibility"] = plausibility_report(robot, settings.plausibility, params)
        if cross_validation is not None:
            details["prior_weight_cv"] = cross_validation
        return Estimate(
            estimator=self.name,
            params=dict(zip(robot.param_names, params.tolist(), strict=True)),
            cost=cost,
            wall_time_s=time.perf_counter() - start,
            base_params=dict(zip(robot.base_param_names, alpha.tolist(), strict=True)),
            details=to_python(details),
        )
