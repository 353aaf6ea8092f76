"""``pcls``: physically consistent least squares, with the pull towards CAD chosen from the data.

The program (pseudo-inertia LMIs, the entropic prior, plausibility bounds, the solver chain) is
:mod:`idkit.conic.program`; this module is the estimator around it: the QR-compressed data term,
``prior_weight="auto"`` by cross-validation over contiguous blocks of the training recording
(:func:`cross_validated_weight`), ``plausible="auto"`` decided by the same cross-validation
(:func:`plausibility_choice`), and what the estimate reports.

Why these rules (``bench/pcls_prior_rule.py``, held-out ‖E‖/‖T‖ in the 6 Hz band): the weight with the
lowest cross-validated error, not the largest within one standard error of it. On the KUKA both pick
the same fit once links are kept plausible (1000: 2.45 % / 4.74 % on measurements_2 / _3), but with a
poor CAD prior (a UR5e simulated from links 0.5–2× and 3 cm off CAD) leaning towards CAD costs: 0.45 %
against 0.36 %. The entropic prior, not the Euclidean one: the Euclidean fit predicted held out a
little better (KUKA, bounded: 4.72 % against 4.74 %; half the KUKA log, bounded: 4.81 % against
4.85 %; the UR5e of another seed 0.76 % against 0.87 %), but at every weight but the largest it left
a link a rod or a point mass (thinnest radius of gyration under 1e-3 of CAD's), a body no simulator
should be handed. Where data are thin the lowest error may leave a link degenerate: then the weight
moves up to the first that leaves none, within the noise where one does (:func:`cross_validated_weight`).
Plausibility bounds cost the KUKA nothing in cross-validation (2.68 % with, 2.70 % without) and gain
held out (4.74 % against 4.93 % on measurements_3).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, ClassVar, Literal

import numpy as np
import torch
from torch import Tensor

from idkit.conic.plausible import PLAUSIBLE_MASS_RATIO, Plausibility, degenerate, plausibility_report
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


class PlausibleNote(Note):
    """``plausible=auto`` kept the links plausible or not, with the cross-validated figure both ways."""


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
        squared: per candidate, each fold's squared error over the pooled squared torque (they sum to
            the pooled score squared): what two choices are compared by, fold by fold.
    """

    weight: float
    scores: dict[float, float]
    per_fold: dict[float, list[float]]
    standard_errors: dict[float, float]
    folds: int
    reason: str
    squared: dict[float, np.ndarray] = field(default_factory=dict)

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
    degenerate: Callable[[float], list[str]] | None = None,
) -> WeightChoice:
    """The prior weight whose fit predicts held-out blocks of the training data best.

    The ``N`` samples (in time order; rows ``W[N n, B]``, ``tau[N n]``) are cut into ``folds``
    contiguous blocks of whole samples. For every candidate weight and every block, the consistent
    program is solved on the other blocks (their ``[W | tau]`` QR-compressed per block and stacked,
    so a fold costs one small QR; the data scale ``scale2`` is the full data's) and scored on the
    block: ``‖W_k alpha − tau_k‖²`` from the block's own compression. Contiguous blocks, because
    neighbouring samples are correlated: a held-out sample whose neighbours were fitted is no test.
    ``programs(prior)`` hands out the two (cached) programs, so each is canonicalised once.

    The choice is the weight of lowest pooled squared error ``Σ_k ‖E_k‖² / Σ_k ‖T_k‖²`` (the module
    doc says why not the largest within one standard error, which leaned on a poor CAD prior). One
    exception, for thin data: when the fit at that weight leaves a link degenerate (``degenerate(w)``
    names them: rods, plates, point masses), the smallest larger weight whose fit has none is taken
    instead — preferably one whose error exceeds the lowest by at most one standard error (paired over
    the blocks, so their very different difficulty cancels: the data cannot tell the two apart, a
    simulator can), else the first that leaves none at all, its cost said in the reason.
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
    distance = {weight: standard_errors_above(parts, squared[best]) for weight, parts in squared.items()}
    chosen = best
    reason = (
        f"the lowest {folds}-fold cross-validated torque error on contiguous blocks of the training data: "
        f"{100 * scores[best]:.3g} % at {best:g}, among " + ", ".join(f"{w:g}" for w in candidates)
    )
    if degenerate is not None:
        chosen, moved = _off_degenerate(best, scores, distance, degenerate)
        reason += moved
    failed = [w for w in candidates if w not in squared]
    if failed:  # chosen without them: a warning, not a note — the choice may have been shaped by it
        warnings.warn(
            f"pcls prior_weight=auto: the solve failed for weight {', '.join(f'{w:g}' for w in failed)}, "
            f"left out of the choice ({failures[0]}); set estimator.prior_weight to fix one",
            PriorWeightWarning,
            stacklevel=3,
        )
        reason += f"; {', '.join(f'{w:g}' for w in failed)} left out (the solve failed)"
    return WeightChoice(chosen, scores, per_fold, distance, folds, reason, squared)


def _off_degenerate(
    best: float,
    scores: dict[float, float],
    distance: dict[float, float],
    degenerate: Callable[[float], list[str]],
) -> tuple[float, str]:
    """The weight to report instead of ``best`` when its fit leaves a link degenerate, and what to add to
    the reason (:func:`cross_validated_weight`)."""
    thin = degenerate(best)
    if not thin:
        return best, ""
    sound = [w for w in sorted(distance) if w > best and not degenerate(w)]
    near = [w for w in sound if distance[w] <= 1.0]
    chosen = (near or sound or [best])[0]
    verb = "is" if len(thin) == 1 else "are"
    there = f"; there {', '.join(thin)} {verb} degenerate (a rod, plate or point mass)"
    if near:
        return chosen, (
            f"{there}, so {chosen:g}, the smallest larger weight that leaves none, within one standard error "
            f"({100 * scores[chosen]:.3g} %)"
        )
    if sound:
        return chosen, (
            f"{there}, so {chosen:g}, the smallest larger weight that leaves none, though "
            f"{distance[chosen]:.2g} standard errors worse ({100 * scores[chosen]:.3g} %)"
        )
    return best, f"{there}, and stay so at every weight"


def standard_errors_above(parts: np.ndarray, reference: np.ndarray) -> float:
    """How far the pooled squared error ``Σ parts`` lies above ``Σ reference`` (per fold, paired), in
    standard errors of that excess (``0`` when every fold agrees exactly)."""
    excess = parts - reference
    error = np.sqrt(len(excess)) * float(np.std(excess, ddof=1))
    return float(excess.sum() / error) if error > 0 else 0.0


def plausibility_choice(free: WeightChoice, bounded: WeightChoice, bounds: Plausibility) -> tuple[bool, str]:
    """``plausible="auto"``: keep the links plausible unless the cross-validated error of the bounded
    fit (at its own chosen weight) exceeds the free fit's by more than one standard error (paired over
    the blocks) — more than the noise. Also the reason, with the figure both ways. Without
    cross-validation (too few samples): plausible, said so."""
    what = f"links kept plausible ({bounds.describe()})"
    if not free.squared or not bounded.squared:
        return True, f"{what}: too few samples to cross-validate the choice, so the bounds are kept"
    with_, without = bounded.scores[bounded.weight], free.scores[free.weight]
    distance = standard_errors_above(bounded.squared[bounded.weight], free.squared[free.weight])
    figures = (
        f"{free.folds}-fold cross-validated torque error {100 * with_:.3g} % with the bounds (prior weight "
        f"{bounded.weight:g}), {100 * without:.3g} % without ({free.weight:g})"
    )
    if distance <= 1.0:
        return True, f"{what}: {figures}; within one standard error, so plausible costs nothing"
    return False, (
        f"not kept plausible: {figures}; the bounds cost {distance:.2g} standard errors (the CAD or "
        "the geometry may be wrong), so estimator.plausible=true is the alternative"
    )


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
            (or visual) geometry where the model has real geometry. ``"auto"`` (the default): kept
            unless the same cross-validation says it costs accuracy beyond the noise
            (:func:`plausibility_choice`); the other choice is fitted too (its own prior weight) and
            recorded in ``details["plausible_choice"]``, so a report can set both side by side.
        mass_ratio: ``[lo, hi]``, the bound ``plausible`` enforces (``None``:
            :data:`~idkit.conic.plausible.PLAUSIBLE_MASS_RATIO`); a band given is enforced (with
            ``plausible="auto"`` it is not cross-validated away; ``plausible=false`` refuses it).
        total_mass: the moving links' total mass in kg (from a data sheet), or ``None``; enforced
            whenever given.
        solver: ``"auto"`` (Clarabel, Clarabel relaxed, then SCS), ``"clarabel"`` or ``"scs"``.

    ``details``: ``min_eigenvalue`` per link, ``divergence`` per link, solver, status, times,
    ``rel_error_train`` (‖E‖/‖T‖ on the training samples), ``prior_weight`` (the one used) and, for
    ``"auto"``, ``prior_weight_cv`` (candidates, pooled and per-fold scores, the reason, its time),
    ``plausible_choice`` (for ``plausible="auto"``: the choice, why, and the other choice's fit),
    ``plausibility`` (each link's verdict and reasons: :func:`~idkit.conic.plausible.plausibility_report`),
    ``cad_reference`` (CAD bodies the prior thickened or replaced), and the base-parameter
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
        plausible: bool | Literal["auto"] = "auto",
        mass_ratio: Sequence[float] | None = None,
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
        counts. The settings' plausibility is the one enforced for sure (``plausible=true``, a given
        band, ``total_mass``); :meth:`bounded` is the plausible variant ``"auto"`` weighs against it."""
        if self.plausible not in (True, False, "auto"):
            raise ValueError(f"pcls: plausible must be true, false or auto, got {self.plausible!r}")
        if self.mass_ratio is not None and self.plausible is False:
            raise ValueError(
                "pcls: mass_ratio is the band plausible=true enforces; with plausible=false it would be "
                "ignored (drop one of them)"
            )
        ratio = Plausibility.checked("pcls", mass_ratio=self.mass_ratio or PLAUSIBLE_MASS_RATIO).mass_ratio
        enforced = self.plausible is True or self.mass_ratio is not None
        bounds = Plausibility.checked("pcls", ratio if enforced else None, self.total_mass, geometry=enforced)
        return ConsistentSettings.checked(
            "pcls", self.prior_weight, self.min_mass, self.solver, auto=True, plausibility=bounds
        )

    def bounded(self, settings: ConsistentSettings) -> ConsistentSettings | None:
        """The plausible variant of ``settings`` that ``plausible="auto"`` cross-validates against
        them, or ``None`` when there is no choice to make (plausibility set, or a band given)."""
        if self.plausible != "auto" or settings.plausibility.geometry:
            return None
        ratio = self.mass_ratio or PLAUSIBLE_MASS_RATIO
        bounds = Plausibility.checked("pcls", ratio, self.total_mass, geometry=True)
        return replace(settings, plausibility=bounds)

    def _band_fits_total(self, robot: URDFRobot, bounds: Plausibility) -> bool:
        """Whether ``plausible="auto"``'s mass band can hold with the ``total_mass`` given; if not, the
        given total is honoured, the band dropped, and a note says so."""
        if bounds.total_mass is None or bounds.mass_ratio is None:
            return True
        nb = len(robot.link_names)
        cad = float(robot.nominal_params()[0 : 10 * nb : 10].sum())
        lo, hi = bounds.mass_ratio
        if lo * cad <= bounds.total_mass <= hi * cad:
            return True
        warnings.warn(
            f"pcls plausible=auto: total_mass={bounds.total_mass:g} kg is outside [{lo:g}, {hi:g}] x the CAD "
            f"total {cad:g} kg, so the links' mass band is not tried; total_mass is enforced",
            PlausibleNote,
            stacklevel=3,
        )
        return False

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
        variants = {False: settings}
        plausible_variant = self.bounded(settings)
        if plausible_variant is not None and self._band_fits_total(robot, plausible_variant.plausibility):
            variants[True] = plausible_variant
        fitter = _Fitter(robot, reference, R, b, rest, W, tau, scale2, variants)
        chosen, choice_reason = fitter.choose(settings.prior_weight)
        params, solution, weight = fitter.final(chosen)
        alpha = robot.base_params(params.to(device=s.q.device, dtype=s.q.dtype))
        residual = float(np.sqrt(max(solution.data_term * fitter.scale2 + rest, 0.0)))
        params = params.to(device=s.q.device, dtype=s.q.dtype)
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
            "data_scale": {"least_squares": np.sqrt(scale2), "used": np.sqrt(fitter.scale2)},
            "cad_reference": {"thickened": list(reference.thickened), "replaced": list(reference.replaced)},
            **base_uncertainty(
                W, tau, alpha, robot.base_param_names, robot.unidentifiable, robot.n_joints, pulled=True
            ).to_details(),
        }
        if solution.repaired:
            details["repaired"] = list(solution.repaired)
        details["plausibility"] = plausibility_report(robot, variants[chosen].plausibility, params)
        cross_validation = fitter.cross_validation(chosen)
        if cross_validation is not None:
            details["prior_weight_cv"] = cross_validation
        if len(variants) > 1:
            other, _, other_weight = fitter.final(not chosen)
            details["plausible_choice"] = {
                "plausible": chosen,
                "reason": choice_reason,
                "alternative": {
                    "option": f"estimator.plausible={'false' if chosen else 'true'}",
                    "prior_weight": other_weight,
                    "params": dict(zip(robot.param_names, other.tolist(), strict=True)),
                    "plausibility": plausibility_report(robot, variants[not chosen].plausibility, other),
                },
            }
        return Estimate(
            estimator=self.name,
            params=dict(zip(robot.param_names, params.tolist(), strict=True)),
            cost=cost,
            wall_time_s=time.perf_counter() - start,
            base_params=dict(zip(robot.base_param_names, alpha.tolist(), strict=True)),
            details=to_python(details),
        )


class _Fitter:
    """One pcls fit's programs and choices: per plausibility variant (``False``: the settings as given,
    ``True``: kept plausible), the programs, the cross-validated weight and the final solve."""

    def __init__(
        self,
        robot: URDFRobot,
        reference: Any,
        R: np.ndarray,
        b: np.ndarray,
        rest: float,
        W: Tensor,
        tau: Tensor,
        scale2: float,
        variants: dict[bool, ConsistentSettings],
    ) -> None:
        self.robot, self.reference, self.R, self.b, self.W, self.tau = robot, reference, R, b, W, tau
        self.variants = variants
        self.built: dict[tuple[bool, bool], ConsistentProgram] = {}
        self.auto = next(iter(variants.values())).prior_weight == "auto"
        once = not self.auto and len(variants) == 1  # only cross-validation solves a program many times
        # the data scale is what no rigid bodies explain, whatever plausibility asks: the same χ² unit
        # for both variants, and for plausible=true alone (so its fit is the one plausible=auto records)
        settings = variants[False]
        free = replace(settings, plausibility=Plausibility(None, settings.plausibility.total_mass))
        physical = ConsistentProgram(robot, free, R.shape[0], False, reference=reference)
        first = physical.solve(R, b, scale2, 0.0, once=once)
        self.scale2 = misfit_scale(scale2, first.data_term * scale2 + rest, W.shape)
        self.solved: dict[tuple[bool, float], Any] = {}
        if self.scale2 == scale2 and free == settings:  # else the tie-break's weight moved: solve again
            self.built[False, False], self.solved[False, 0.0] = physical, first
        self.choices: dict[bool, WeightChoice] = {}
        self.said: set[str] = set()
        self.cv_time = 0.0

    def program(self, plausible: bool, prior: bool) -> ConsistentProgram:
        if (plausible, prior) not in self.built:
            self.built[plausible, prior] = ConsistentProgram(
                self.robot, self.variants[plausible], self.R.shape[0], prior, reference=self.reference
            )
        return self.built[plausible, prior]

    def solve(self, plausible: bool, weight: float) -> Any:
        if (plausible, weight) not in self.solved:
            once = not self.auto and len(self.variants) == 1
            self.solved[plausible, weight] = self.program(plausible, weight > 0).solve(
                self.R, self.b, self.scale2, weight, once=once
            )
        return self.solved[plausible, weight]

    def degenerate(self, plausible: bool, weight: float) -> list[str]:
        """The links the full-data fit at ``weight`` leaves degenerate (rods, plates, point masses)."""
        return list(degenerate(self.robot, self.solve(plausible, weight).params.numpy()))

    def weight_choice(self, plausible: bool, fixed: float | None) -> WeightChoice:
        """The cross-validated weight of a variant; at a fixed weight, that weight's cross-validated
        error alone (what ``plausible="auto"`` compares)."""
        if plausible not in self.choices:
            started = time.perf_counter()
            with warnings.catch_warnings(record=True) as said:  # a failed weight: said once, not per variant
                warnings.simplefilter("always")
                self.choices[plausible] = cross_validated_weight(
                    lambda prior: self.program(plausible, prior),
                    self.robot,
                    self.W,
                    self.tau,
                    self.scale2,
                    candidates=PRIOR_CANDIDATES if fixed is None else (fixed,),
                    degenerate=None if fixed is not None else lambda w: self.degenerate(plausible, w),
                )
            for warning in said:
                if str(warning.message) not in self.said:
                    self.said.add(str(warning.message))
                    warnings.warn(warning.message, stacklevel=4)
            self.cv_time += time.perf_counter() - started
        return self.choices[plausible]

    def choose(self, prior_weight: float | str) -> tuple[bool, str]:
        """Which variant is reported, and why (said in a note; ``""`` when there was no choice)."""
        fixed = None if prior_weight == "auto" else float(prior_weight)
        if self.auto:
            for plausible in self.variants:
                self.weight_choice(plausible, None)
            self._say_weights()
        if len(self.variants) == 1:
            return next(iter(self.variants)), ""
        free, bounded = (self.weight_choice(p, fixed) for p in (False, True))
        chosen, reason = plausibility_choice(free, bounded, self.variants[True].plausibility)
        warnings.warn(f"pcls plausible=auto: {reason}", PlausibleNote, stacklevel=3)
        return chosen, reason

    def _say_weights(self) -> None:
        """One line for the weight(s) chosen: a note, or a warning where no candidate could be scored."""
        both = len(self.choices) > 1
        if any(not choice.scores for choice in self.choices.values()):  # a fallback, not the data's choice
            reason = next(choice.reason for choice in self.choices.values())
            warnings.warn(
                f"pcls prior_weight=auto: {reason} (the data alone, no pull towards the CAD prior; set "
                "estimator.prior_weight to choose one)",
                PriorWeightWarning,
                stacklevel=4,
            )
        elif both:
            free, bounded = self.choices[False], self.choices[True]
            warnings.warn(
                f"pcls prior_weight=auto: with plausibility bounds {bounded.reason}; without them "
                f"{free.weight:g} ({100 * free.scores[free.weight]:.3g} %)",
                PriorWeightNote,
                stacklevel=4,
            )
        else:
            (only,) = self.choices.values()
            warnings.warn(f"pcls prior_weight=auto: {only.reason}", PriorWeightNote, stacklevel=4)

    def final(self, plausible: bool) -> tuple[Tensor, Any, float]:
        """The variant's full-data fit: parameters (float64), the solution and its weight."""
        weight = self.choices[plausible].weight if self.auto else float(self.variants[plausible].prior_weight)
        solution = self.solve(plausible, weight)
        return solution.params, solution, weight

    def cross_validation(self, plausible: bool) -> dict[str, Any] | None:
        if not self.auto:
            return None
        return {**self.choices[plausible].to_details(), "time_s": self.cv_time}
