"""Physically consistent least squares (``pcls``) and the projection onto consistent parameters.

A rigid body's 10 standard parameters ``pi = (m, h = m c, I_O)`` (inertia about the link-frame
origin, the order of :mod:`idkit.robots.urdf_model`) describe a real mass distribution iff its
4×4 *pseudo-inertia* is positive semidefinite (Wensing, Kim & Slotine 2017; the rigid-body side,
shared with the URDF reader and writer, is :mod:`idkit.robots.inertia`)::

    J(pi) = [[Sigma, h], [h^T, m]],    Sigma = tr(I_O)/2 * 1 - I_O   (the second moment of mass).

``J`` is linear in ``pi``, so "every link physical" is a linear matrix inequality and a least-squares
fit under it is a convex semidefinite program. Both tools here solve

    min_p  ‖R (K p) − b‖² / s²  +  w Σ_links D(J_i(p) ‖ J_i0)
    s.t.   J_i(p) ⪰ 0,  m_i ≥ min_mass,  friction and armature ≥ 0,  fc + fs ≥ 0 (Stribeck term),
           p_k = p0_k for the robot's ``a_priori_params`` (merged armatures, sigmoid shapes),

with ``p`` the standard parameters ``[P]`` of a ``urdf`` robot, ``K`` its base map (``alpha = K p``)
and ``(R, b, s²)`` a QR-compressed data term: for ``pcls`` the regressor and torques of the samples,
``[W | tau] = Q [[R, b], [0, r]]``, so ``‖W alpha − tau‖² = ‖R alpha − b‖² + r²``, and
``s² = r² / (M − B)``, the residual variance of unconstrained LS (``r²`` floored at ``1e-10 ‖tau‖²``
for noise-free data). The data term is then a χ² (−2 log-likelihood for Gaussian noise, up to a
constant): moving the fit by one standard deviation of a base parameter costs 1, whatever the noise
level and the number of samples, so weights and solver tolerances mean the same on clean and noisy
data. The 35,000 × 57 system of a 7-joint arm becomes 57 × 57 before cvxpy sees it, which is what
keeps the solve at a fraction of a second.

**Prior** ``D(J ‖ J0) = −log det J + log det J0 + tr(J0⁻¹ J) − 4``, the *entropic* (log-det Bregman)
divergence of Lee, Wensing & Park (2020, "Geometric robot dynamic identification: a convex
programming approach") to the CAD pseudo-inertia ``J0``. Chosen over a Euclidean distance on scaled
parameters because it needs no hand-picked scales (it is invariant to the units and to the choice of
link frame, and a link's divergence is the KL divergence between the two mass distributions' Gaussian
moments), and ``−log det J`` is a barrier that keeps every pseudo-inertia strictly positive definite.
``prior_weight = w``: one nat of summed divergence costs ``w`` units of χ², so the objective is a
MAP estimate with the prior ``exp(−w D / 2)``. Friction and offset parameters have no prior.

With ``prior_weight = 0`` a tie-break ``TIE_BREAK ‖(p − p0) / u‖²`` remains (``u`` the CAD magnitudes
``m0, m0 L, m0 L²`` of each link's parameters, so the term counts relative deviations; weight 1 in
χ² units): the data fix only the base parameters, and among the standard parameters that fit
equally well it picks those closest to the CAD model. It is as weak as the data's own uncertainty
(on simulated data with 0.1 % noise it moved the base parameters by < 0.01 standard deviation). It
is Euclidean rather than entropic on purpose: where an LMI is active the log-det barrier with so small
a weight pushes an eigenvalue to ~1e-6 of its scale, and Clarabel then failed (the SCS fallback took
20 s and ended outside the cone). Directions the data barely excite are set by the data's noise:
that is what ``prior_weight`` is for.

Solved by cvxpy with Clarabel (interior point, accurate), falling back to SCS; an infeasible program
or a failed solver raises :class:`~idkit.estimators.linear.observation.IdentificationError` in one line.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Literal, get_args

import numpy as np
import torch
from torch import Tensor

from idkit.estimate import Estimate, to_python
from idkit.estimators.linear.observation import IdentificationError
from idkit.estimators.linear.uncertainty import base_uncertainty
from idkit.interfaces import Estimator, Robot
from idkit.notes import Note
from idkit.problem import Problem, Samples
from idkit.robots.drives import NONNEGATIVE
from idkit.robots.inertia import link_count, pseudo_inertia, pseudo_inertia_rows
from idkit.robots.model_checks import nonphysical_links
from idkit.seeds import torch_generator

#: Weight (χ² per squared relative deviation) of the pull to CAD when ``prior_weight = 0`` (module doc).
TIE_BREAK = 1.0
#: Conic solvers tried for ``solver="auto"``, in order, and their options (Clarabel's defaults of
#: 1e-8 leave the base parameters ~1e-5 (relative) off the LS ones on consistent clean data).
AUTO_SOLVERS = ("CLARABEL", "SCS")
SOLVER_OPTIONS = {
    "CLARABEL": {"tol_gap_abs": 1e-9, "tol_gap_rel": 1e-9, "tol_feas": 1e-9},
    "SCS": {"eps": 1e-9},
}
#: ``nearest_consistent`` counts the change of predicted torque in units of this fraction of them.
PROJECTION_UNIT = 1e-3
#: Floor of the pcls data scale ``s²``, relative to ``‖tau‖²`` (noise-free data).
NOISE_FLOOR = 1e-10
#: Parameter-name suffixes constrained to be non-negative (friction, armature: ``idkit.robots.drives``).
#: A Stribeck coefficient ``fs`` may be negative (friction building up over ``v_s`` after a reversal)
#: as long as the friction at low speed opposes the motion: ``fc + fs >= 0``.
NONNEGATIVE_SUFFIXES = tuple(f".{suffix}" for suffix in NONNEGATIVE)
#: A solution whose pseudo-inertia eigenvalue is below ``-PSD_TOLERANCE × max|J|`` of its link is
#: not consistent: an inaccurate solver status ended outside the cone (refused, not returned).
PSD_TOLERANCE = 1e-6
#: A CAD pseudo-inertia is lifted to ``J0 + eps λ_max(J0) 1`` when it is (nearly) singular, e.g. a
#: thin rod or a point mass, so that the divergence to it is finite.
PRIOR_REGULARISATION = 1e-6


#: Prior weights tried by ``prior_weight="auto"`` (half-decades; 0 = the data alone, with the tie-break).
PRIOR_CANDIDATES = (0.0, 1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0, 3000.0, 10000.0)
#: Contiguous blocks of the training samples for ``prior_weight="auto"``.
PRIOR_FOLDS = 5

#: The conic solver choice: ``"auto"`` tries ``AUTO_SOLVERS`` in order.
Solver = Literal["auto", "clarabel", "scs"]


@dataclass(frozen=True)
class ConsistentSettings:
    """The options of the consistent program (``pcls``, ``nearest_consistent``), checked once.

    Attributes:
        prior_weight: ``w >= 0`` of the entropic divergence to the CAD model (``TIE_BREAK`` if 0), or
            ``"auto"`` (``pcls`` only): chosen by cross-validation on the training data
            (:func:`cross_validated_weight`).
        min_mass: lower bound ``>= 0`` on every link mass (kg); ``None`` = 1 % of the smallest CAD
            mass (the robot's, known at the fit).
        solver: the choice as given.
        conic_solvers: the cvxpy solvers ``solver`` stands for, tried in order.
    """

    prior_weight: float | Literal["auto"]
    min_mass: float | None
    solver: Solver
    conic_solvers: tuple[str, ...]

    @classmethod
    def checked(
        cls,
        who: str,
        prior_weight: float | str = 0.0,
        min_mass: float | None = None,
        solver: Solver = "auto",
        auto: bool = False,
    ) -> ConsistentSettings:
        """The settings, or ``ValueError`` naming ``who`` and the option; ``auto``: whether
        ``prior_weight="auto"`` is accepted (a fit has the data to choose it, a projection has not)."""
        if not (auto and prior_weight == "auto"):
            if isinstance(prior_weight, str) or not (math.isfinite(prior_weight) and prior_weight >= 0):
                allowed = "a finite number >= 0" + (" or 'auto'" if auto else "")
                raise ValueError(f"{who}: prior_weight must be {allowed}, got {prior_weight!r}")
            prior_weight = float(prior_weight)
        if min_mass is not None and not (math.isfinite(min_mass) and min_mass >= 0):
            raise ValueError(f"{who}: min_mass must be None or a finite number >= 0 (kg), got {min_mass!r}")
        choices = get_args(Solver)
        if solver not in choices:
            listed = ", ".join(map(repr, choices))
            raise ValueError(f"{who}: solver must be one of {listed}, got {solver!r}")
        conic = AUTO_SOLVERS if solver == "auto" else (solver.upper(),)
        return cls(prior_weight, min_mass, solver, conic)


def cad_pseudo_inertias(robot: Robot) -> np.ndarray:
    """The CAD pseudo-inertias ``[nb, 4, 4]``, lifted where singular (``PRIOR_REGULARISATION``).

    Raises:
        ValueError: a link has no ``<inertial>`` in the URDF (CAD mass 0), or an inertia no rigid
            body has (``idkit.robots.model_checks.nonphysical_links``): pcls needs physical
            a-priori inertials to resolve the unidentifiable directions and for the prior.
    """
    nb = link_count(robot)
    nonphysical = nonphysical_links(robot.tree)
    if nonphysical:
        more = f" (and {len(nonphysical) - 1} more links)" if len(nonphysical) > 1 else ""
        raise ValueError(
            f"urdf: {nonphysical[0]}{more}; physically consistent fitting needs a physical CAD model "
            "(fix the URDF's <inertia>, or use another estimator)"
        )
    nominal = robot.nominal_params()[: 10 * nb].reshape(nb, 10)
    empty = [name for name, row in zip(robot.link_names, nominal, strict=True) if float(row[0]) <= 0.0]
    if empty:
        raise ValueError(
            f"urdf: link(s) {', '.join(map(repr, empty))} have no <inertial> (CAD mass 0); physically "
            "consistent fitting needs a-priori inertials in the URDF (any rough mass and box inertia)"
        )
    out = []
    for j in pseudo_inertia(nominal).numpy():
        eig = np.linalg.eigvalsh(j)
        lift = max(0.0, PRIOR_REGULARISATION * eig[-1] - eig[0])
        out.append(j + lift * np.eye(4))
    return np.stack(out)


@dataclass(frozen=True)
class ConsistentSolution:
    """A solved physically consistent program.

    Attributes:
        params: standard parameters ``[P]`` (float64, CPU).
        min_eigenvalues: smallest pseudo-inertia eigenvalue per link ``[nb]``.
        divergence: entropic divergence to the CAD pseudo-inertia per link ``[nb]`` (nats).
        data_term: ``‖R K p − b‖² / s²`` at the solution.
        status, solver: cvxpy's status and the conic solver that produced it.
        solve_time_s: wall time of cvxpy (canonicalisation + solver).
    """

    params: Tensor
    min_eigenvalues: Tensor
    divergence: Tensor
    data_term: float
    status: str
    solver: str
    solve_time_s: float


def _divergence(j: np.ndarray, j0: np.ndarray) -> float:
    inv0 = np.linalg.inv(j0)
    sign, logdet = np.linalg.slogdet(j)
    if sign <= 0:
        return float("inf")
    return float(-logdet + np.linalg.slogdet(j0)[1] + np.trace(inv0 @ j) - 4.0)


def solve_consistent(
    robot: Robot,
    R: np.ndarray,
    b: np.ndarray,
    scale2: float,
    settings: ConsistentSettings,
    who: str = "pcls",
) -> ConsistentSolution:
    """Solve the program of the module doc for a ``urdf`` robot, once (:class:`ConsistentProgram`).

    Args:
        robot: a ``urdf`` robot (standard parameters ``[P]``, base map ``K[B, P]``).
        R: ``[B, B]`` (or any ``[r, B]``) compressed regressor acting on the base parameters.
        b: ``[r]`` compressed target.
        scale2: ``s² > 0`` dividing the data term.
        settings: prior weight (a number), mass floor and conic solvers (:class:`ConsistentSettings`).
        who: name used in error messages.

    Raises:
        IdentificationError: infeasible constraints or a failed solver (one line, with the cause).
        ValueError: a robot that is not ``urdf``, a link without CAD inertial.
    """
    weight = float(settings.prior_weight)
    program = ConsistentProgram(robot, settings, R.shape[0], prior=weight > 0, who=who)
    return program.solve(R, b, scale2, weight, once=True)


class ConsistentProgram:
    """The program of the module doc for one robot, built once and solved for any data and prior weight.

    The data ``(R, b) / s`` and the weight ``w`` are cvxpy parameters, so cvxpy canonicalises the
    program once (it is DPP): a later solve only hands the conic solver new numbers. Cross-validating
    ``prior_weight`` solves it tens of times; a canonicalisation costs ~0.5 s on a 7-joint arm, the
    conic solve ~0.05 s.

    Args:
        robot: a ``urdf`` robot.
        settings: mass floor and conic solvers (the weight is given to :meth:`solve`).
        rows: the number of rows ``r`` of the compressed data ``R[r, B]``.
        prior: the entropic prior (solved with ``w > 0``), else the tie-break (``w = 0``).
        who: name used in error messages.
    """

    def __init__(
        self, robot: Robot, settings: ConsistentSettings, rows: int, prior: bool, who: str = "pcls"
    ) -> None:
        import cvxpy as cp

        self.robot, self.settings, self.prior, self.who = robot, settings, prior, who
        nb = self.links = link_count(robot)
        self.j0 = j0 = cad_pseudo_inertias(robot)
        cad_masses = robot.nominal_params()[0 : 10 * nb : 10].numpy()
        min_mass = settings.min_mass
        self.floor = floor = 0.01 * float(cad_masses.min()) if min_mass is None else float(min_mass)
        K = robot.base_map.numpy()
        nominal = robot.nominal_params().numpy()
        # Variables scaled by the CAD magnitudes so that the conic solver sees O(1) unknowns.
        self.unit = unit = _parameter_units(robot, cad_masses)
        self.z = z = cp.Variable(K.shape[1])
        p = cp.multiply(unit, z)
        self.R = cp.Parameter((rows, K.shape[0]))
        self.b = cp.Parameter(rows)
        self.weight = cp.Parameter(nonneg=True)
        data = cp.sum_squares(self.R @ (K * unit) @ z - self.b)
        constraints, pseudo = [], []
        for i in range(nb):
            pseudo.append(pseudo_inertia_expression(p[10 * i : 10 * i + 10], cp))
            constraints += [pseudo[i] >> 0, p[10 * i] >= floor]
        nonnegative = [k for k, name in enumerate(robot.param_names) if name.endswith(NONNEGATIVE_SUFFIXES)]
        if nonnegative:
            constraints.append(z[nonnegative] >= 0)
        index = {name: k for k, name in enumerate(robot.param_names)}
        held = [index[name] for name in getattr(robot, "a_priori_params", ())]  # merged armatures, shapes
        if held:
            constraints.append(z[held] == nominal[held] / unit[held])
        for joint in robot.joint_names:
            if f"{joint}.fs" in index:
                constraints.append(p[index[f"{joint}.fc"]] + p[index[f"{joint}.fs"]] >= 0)
        if prior:  # the entropic divergence, without its constants
            divergence = sum(
                -cp.log_det(j) + cp.trace(np.linalg.inv(j0[i]) @ j) for i, j in enumerate(pseudo)
            )
            objective = data + self.weight * divergence
        else:  # a barrier-free tie-break: the log-det barrier is ill-conditioned where the LMIs are active
            objective = data + TIE_BREAK * cp.sum_squares(z[: 10 * nb] - nominal[: 10 * nb] / unit[: 10 * nb])
        self.program = cp.Problem(cp.Minimize(objective), constraints)

    def solve(
        self, R: np.ndarray, b: np.ndarray, scale2: float, weight: float = 0.0, once: bool = False
    ) -> ConsistentSolution:
        """Solve for the data ``‖R alpha − b‖² / scale2`` and prior weight ``weight`` (``> 0`` exactly
        when the program was built with ``prior``); ``once``: skip the reusable canonicalisation.

        Raises:
            IdentificationError: infeasible constraints, a failed solver, or a solution outside the cone.
        """
        if (weight > 0) != self.prior:
            raise ValueError(f"{self.who}: weight {weight:g} for a program built with prior={self.prior}")
        robot, nb, j0 = self.robot, self.links, self.j0
        scale = np.sqrt(scale2)
        self.R.value, self.b.value = R / scale, b / scale
        self.weight.value = weight
        started = time.perf_counter()
        infeasible = (
            f"no link mass can be >= min_mass={self.floor:g} kg with a positive semidefinite "
            "pseudo-inertia and friction >= 0 — check min_mass"
        )
        used, status = solve_program(self.program, self.settings.conic_solvers, self.who, infeasible, once)
        elapsed = time.perf_counter() - started
        params = torch.as_tensor(self.unit * self.z.value, dtype=torch.float64)
        inertials = params[: 10 * nb].reshape(nb, 10)
        jv = pseudo_inertia(inertials).numpy()
        lowest, outside = cone_violations(robot.link_names, jv)
        if outside:
            smallest = float(np.linalg.eigvalsh(j0)[:, 0].min())
            hint = (
                f"the CAD pseudo-inertias are near-singular (smallest eigenvalue {smallest:.3g}): lower "
                "prior_weight or give the URDF's links non-degenerate inertias"
                if weight > 0
                else "try the other solver (solver=clarabel or scs)"
            )
            raise IdentificationError(
                f"{self.who}: {used} ended with status {status!r} outside the constraints: pseudo-inertia "
                f"not positive semidefinite for {', '.join(outside)}; {hint}"
            )
        residual = (R @ robot.base_map.numpy() @ params.numpy() - b) / scale
        return ConsistentSolution(
            params=params,
            min_eigenvalues=torch.as_tensor(lowest),
            divergence=torch.as_tensor([_divergence(jv[i], j0[i]) for i in range(nb)]),
            data_term=float(residual @ residual),
            status=status,
            solver=used,
            solve_time_s=elapsed,
        )


def cone_violations(names: Sequence[str], pseudo: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Smallest eigenvalue ``[nb]`` of each solved pseudo-inertia ``pseudo[nb, 4, 4]``, and the
    bodies (``"name (eigenvalue)"``) whose eigenvalue is below ``-PSD_TOLERANCE`` of their scale:
    a solver that stopped inaccurate outside the cone, which the caller refuses."""
    lowest = np.linalg.eigvalsh(pseudo)[:, 0]
    sizes = np.abs(pseudo).max((1, 2))
    outside = [
        f"{name} ({value:.3g})"
        for name, value, size in zip(names, lowest, sizes, strict=True)
        if value < -PSD_TOLERANCE * size
    ]
    return lowest, outside


def solve_program(
    program: Any, solvers: tuple[str, ...], who: str, infeasible: str, once: bool = False
) -> tuple[str, str]:
    """Solve the cvxpy ``program`` with the first of ``solvers`` that succeeds; ``(solver, status)``.
    ``once``: the program is solved a single time, so its parameters are taken as constants (no DPP
    canonicalisation).

    Shared by ``pcls`` and the payload fit (:mod:`idkit.estimators.payload`).

    Raises:
        IdentificationError: infeasible (``infeasible`` says why that can be), or every solver
            failed (one line naming each cause).
    """
    import cvxpy as cp

    failures = []
    for name in solvers:
        try:
            with warnings.catch_warnings():  # "may be inaccurate": the status says it, and is reported
                warnings.simplefilter("ignore", UserWarning)
                program.solve(solver=name, ignore_dpp=once, **SOLVER_OPTIONS[name])
        except cp.error.SolverError as exc:
            failures.append(f"{name}: {str(exc).splitlines()[0]}")
            continue
        if program.status in (cp.INFEASIBLE, cp.INFEASIBLE_INACCURATE):
            raise IdentificationError(
                f"{who}: the constraints are infeasible ({name} status {program.status!r}): {infeasible}"
            )
        if program.status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) and program.variables()[0].value is not None:
            return name, str(program.status)
        failures.append(f"{name}: status {program.status!r}")
    raise IdentificationError(f"{who}: the conic solver failed ({'; '.join(failures)})")


def _parameter_units(robot: Robot, cad_masses: np.ndarray) -> np.ndarray:
    """Typical magnitude ``[P]`` of each parameter: ``m0``, ``m0 L``, ``m0 L²`` per link (``L`` the
    CAD radius of gyration about the origin, at least 0.05 m); 1 for friction and offset."""
    nb = len(cad_masses)
    nominal = robot.nominal_params().numpy()
    unit = np.ones(robot.n_params)
    for i in range(nb):
        m0 = cad_masses[i]
        trace = nominal[10 * i + 4] + nominal[10 * i + 7] + nominal[10 * i + 9]
        length = max(np.sqrt(trace / (2 * m0)), 0.05)
        unit[10 * i : 10 * i + 10] = [m0, *[m0 * length] * 3, *[m0 * length**2] * 6]
    return unit


def pseudo_inertia_expression(pi: Any, cp: Any) -> Any:
    """``J(pi)`` as a symmetric 4×4 cvxpy expression."""
    return cp.bmat(pseudo_inertia_rows([pi[k] for k in range(10)]))


def compress(W: Tensor, tau: Tensor | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """QR-compress ``W[M, B]`` (and ``tau[M]``): ``(R[B, B], b[B], r²)`` with ``‖W a − tau‖² =
    ‖R a − b‖² + r²`` for every ``a``. Without ``tau``, ``b = 0`` and ``r² = 0``."""
    W = W.detach().to("cpu", torch.float64)
    target = (
        torch.zeros(W.shape[0], dtype=torch.float64) if tau is None else tau.detach().to("cpu", torch.float64)
    )
    r_aug = torch.linalg.qr(torch.cat([W, target[:, None]], 1), mode="r").R
    B = W.shape[1]
    rest = float(r_aug[B, B]) ** 2 if r_aug.shape[0] > B else 0.0
    return r_aug[:B, :B].numpy(), r_aug[:B, B].numpy(), rest


def nearest_consistent(
    robot: Robot,
    params: Tensor | None = None,
    *,
    base_params: Tensor | None = None,
    samples: Samples | None = None,
    prior_weight: float = 0.0,
    min_mass: float | None = None,
    solver: Solver = "auto",
) -> ConsistentSolution:
    """The physically consistent standard parameters that predict torques closest to an estimate's.

    Any estimate (LS, PSO, Adam; standard ``params[P]`` or ``base_params[B]``) is projected in the
    metric that matters, the torques it predicts: minimise ``‖W (K p − alpha_hat)‖² / ‖W alpha_hat‖²``
    (the squared relative change of the predicted torques, in units of ``PROJECTION_UNIT`` = 0.1 %)
    under the constraints of the module doc.
    ``W`` is the base regressor on ``samples`` when given (e.g. the training data), otherwise on the
    robot's own random states (``robot.n_states`` states, seed ``robot.seed``: joint positions within
    the limits, unit-normal rates), which weighs every base parameter by how much it moves the torque
    over the robot's workspace. An estimate that is already consistent is returned (up to the
    ``TIE_BREAK`` pull), and its unidentifiable part is resolved towards the CAD model.

    Returns:
        The :class:`ConsistentSolution`; ``data_term`` is the squared relative torque change.
    """
    if (params is None) == (base_params is None):
        raise ValueError("nearest_consistent: give exactly one of params [P] or base_params [B]")
    settings = ConsistentSettings.checked("nearest_consistent", prior_weight, min_mass, solver)
    link_count(robot)
    if params is not None:
        params = torch.as_tensor(params, dtype=torch.float64)
        if params.shape != (robot.n_params,):
            raise ValueError(
                f"nearest_consistent: params must be [{robot.n_params}], got {tuple(params.shape)}"
            )
        target = robot.base_params(params)
    else:
        target = torch.as_tensor(base_params, dtype=torch.float64)
        if target.shape != (len(robot.base_param_names),):
            raise ValueError(
                f"nearest_consistent: base_params must be [{len(robot.base_param_names)}], got "
                f"{tuple(target.shape)}"
            )
    if samples is None:
        generator = torch_generator(getattr(robot, "seed", 0))
        states = robot.random_states(int(getattr(robot, "n_states", 200)), generator)
    else:
        s = samples.to(dtype=torch.float64)
        states = (s.q, s.qd, s.qdd)
    W = robot.regressor(*states).reshape(-1, len(robot.base_param_names))
    R, _, _ = compress(W)
    b = R @ target.numpy()
    scale2 = PROJECTION_UNIT**2 * float(b @ b) if float(b @ b) > 0 else 1.0
    return solve_consistent(robot, R, b, scale2, settings, who="nearest_consistent")


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
    robot: Robot,
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
    scores, per_fold, squared = {}, {}, {}
    failures: list[IdentificationError] = []
    for weight in candidates:
        errors = []
        try:
            for k in range(folds):
                R, b, _ = training[k]
                params = programs(weight > 0).solve(R, b, scale2, weight).params.numpy()
                Rk, bk, rest_k = blocks[k]
                residual = Rk @ (K @ params) - bk
                errors.append(float(residual @ residual) + rest_k)
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
    if failed:  # chosen without them: say which, and why
        reason += f"; {', '.join(f'{w:g}' for w in failed)} left out (the solve failed: {failures[0]})"
    return WeightChoice(chosen, scores, per_fold, distance, folds, reason)


class PhysicallyConsistentLS(Estimator):
    """``pcls``: least squares on the standard parameters under the pseudo-inertia LMIs.

    Args:
        prior_weight: weight of the entropic divergence to the CAD model (module doc); 0 = data
            only (the tie-break still resolves the unidentifiable part towards CAD); ``"auto"`` (the
            default): the candidate of :data:`PRIOR_CANDIDATES` that predicts held-out contiguous
            blocks of the training data best (:func:`cross_validated_weight`).
        min_mass: lower bound on every link mass (kg); ``None`` = 1 % of the smallest CAD mass.
        solver: ``"auto"`` (Clarabel, then SCS), ``"clarabel"`` or ``"scs"``.

    ``details``: ``min_eigenvalue`` per link, ``divergence`` per link, solver, status, times,
    ``rel_error_train`` (‖E‖/‖T‖ on the training samples), ``prior_weight`` (the one used) and, for
    ``"auto"``, ``prior_weight_cv`` (candidates, pooled and per-fold scores, the reason, its time), and
    the base-parameter uncertainty of
    :func:`idkit.estimators.linear.uncertainty.base_uncertainty` (the LS formula at the pcls estimate; the
    constraints make it conservative where they are active).
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
        solver: Solver = "auto",
    ) -> None:
        self.prior_weight = prior_weight
        self.min_mass = min_mass
        self.solver = solver
        self.settings = ConsistentSettings.checked("pcls", prior_weight, min_mass, solver, auto=True)

    @property
    def name(self) -> str:
        weight = self.settings.prior_weight
        if weight == "auto":
            return "PCLS"
        return "PCLS" + (f"-prior{weight:g}" if weight > 0 else "")

    def fit(self, problem: Problem) -> Estimate:
        start = time.perf_counter()
        problem.check_identifiable()
        robot = problem.robot
        link_count(robot)
        s = problem.tensors()
        W = robot.regressor(s.q, s.qd, s.qdd).reshape(-1, len(robot.base_param_names))
        tau = s.tau.reshape(-1)
        R, b, rest = compress(W, tau)
        norm2 = float(tau.double().square().sum())
        if norm2 == 0.0:
            raise IdentificationError("pcls: the measured torques are all zero; nothing to fit")
        scale2 = max(rest, NOISE_FLOOR * norm2) / max(W.shape[0] - W.shape[1], 1)
        chosen = None
        if self.settings.prior_weight == "auto":
            started = time.perf_counter()
            built: dict[bool, ConsistentProgram] = {}

            def programs(prior: bool) -> ConsistentProgram:
                if prior not in built:
                    built[prior] = ConsistentProgram(robot, self.settings, R.shape[0], prior)
                return built[prior]

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
            cv_time = time.perf_counter() - started
        else:
            weight = float(self.settings.prior_weight)
            solution = solve_consistent(robot, R, b, scale2, self.settings)
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
            **base_uncertainty(W, tau, alpha, robot.base_param_names, robot.unidentifiable).to_details(),
        }
        if chosen is not None:
            details["prior_weight_cv"] = {**chosen.to_details(), "time_s": cv_time}
        return Estimate(
            estimator=self.name,
            params=dict(zip(robot.param_names, params.tolist(), strict=True)),
            cost=cost,
            wall_time_s=time.perf_counter() - start,
            base_params=dict(zip(robot.base_param_names, alpha.tolist(), strict=True)),
            details=to_python(details),
        )
