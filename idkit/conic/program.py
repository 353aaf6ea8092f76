"""The physically consistent least-squares program, solved so that its guarantees hold on any machine.

A rigid body's 10 standard parameters ``pi = (m, h = m c, I_O)`` (inertia about the link-frame
origin, the order of :mod:`idkit.robots.urdf_model`) describe a real mass distribution iff its
4×4 *pseudo-inertia* is positive semidefinite (Wensing, Kim & Slotine 2017; the rigid-body side,
shared with the URDF reader and writer, is :mod:`idkit.robots.inertia`)::

    J(pi) = [[Sigma, h], [h^T, m]],    Sigma = tr(I_O)/2 * 1 - I_O   (the second moment of mass).

``J`` is linear in ``pi``, so "every link physical" is a linear matrix inequality and a least-squares
fit under it is a convex semidefinite program. :class:`ConsistentProgram` solves

    min_p  ‖R (K p) − b‖² / s²  +  w Σ_links D(J_i(p) ‖ J_i0)
    s.t.   J_i(p) ⪰ 0,  m_i ≥ min_mass,  friction and armature ≥ 0,  fc + fs ≥ 0 (Stribeck term),
           p_k = p0_k for the robot's ``a_priori_params`` (merged armatures, sigmoid shapes),
           and the plausibility bounds asked for (:mod:`idkit.conic.plausible`),

with ``p`` the standard parameters ``[P]`` of a ``urdf`` robot, ``K`` its base map (``alpha = K p``)
and ``(R, b, s²)`` a QR-compressed data term (:func:`compress`): ``‖W alpha − tau‖² = ‖R alpha − b‖²
+ r²`` and ``s² = r² / (M − B)``, the residual variance of unconstrained LS. The data term is then a
χ²: moving the fit by one standard deviation of a base parameter costs 1, whatever the noise level
and the number of samples, so weights and tolerances mean the same on clean and noisy data.

**Prior** ``D(J ‖ J0) = −log det J + log det J0 + tr(J0⁻¹ J) − 4``, the entropic (log-det Bregman)
divergence of Lee, Wensing & Park (2020) to the CAD pseudo-inertia ``J0`` (made well-posed by
:mod:`idkit.conic.prior`): invariant to units and link frame, a link's divergence is the KL divergence
between the two mass distributions' Gaussian moments, and ``−log det J`` is a barrier. ``w`` is
``prior_weight``: one nat of summed divergence costs ``w`` units of χ² (a MAP estimate with prior
``exp(−w D / 2)``). Friction and offsets have no prior. With ``w = 0`` a Euclidean tie-break
``TIE_BREAK ‖(p − p0) / u‖²`` remains: the data fix only the base parameters, and among the standard
parameters that fit equally well it picks those closest to CAD.

**Why the result does not depend on a solver's last digits.**

* The program is solved in scaled units (:mod:`idkit.conic.prior`): unknowns O(1), every LMI a
  congruence of the physical one with O(1) entries, the reference bodies' conditioning bounded.
* The LMIs ask for ``J(z) ⪰ CONE_MARGIN · 1`` (scaled units: a body a few 1e-4 of its link's size
  thick), far above a conic solver's feasibility tolerance, so an interior-point solution that stops
  a little outside its cone is still inside the physical one.
* Every solution is checked on the physical cone; one still outside by less than ``REPAIR_LIMIT``
  (scaled) has its negative eigenvalues set to zero (a change far below any torque noise, recorded
  in ``repaired``); one further outside is refused and the next solver configuration is tried.
  So "every link PSD" is a guarantee of this module, not of the solver.
"""

from __future__ import annotations

import functools
import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal, get_args

import numpy as np
import torch
from torch import Tensor

from idkit.conic.plausible import Plausibility, plausibility_constraints
from idkit.conic.prior import CadReference, cad_reference
from idkit.interfaces import Robot
from idkit.problem import IdentificationError, Samples
from idkit.robots.drives import NONNEGATIVE
from idkit.robots.inertia import link_count, linked, pseudo_inertia, pseudo_inertia_rows
from idkit.seeds import torch_generator

if TYPE_CHECKING:
    from idkit.robots.urdf import URDFRobot

#: Weight (χ² per squared relative deviation) of the pull to CAD when ``prior_weight = 0`` (module doc).
TIE_BREAK = 1.0
#: The conic solver configurations ``solver="auto"`` tries, in order: Clarabel tight, Clarabel at its
#: default tolerances, then SCS (first-order, slower, for what Clarabel cannot do).
AUTO_SOLVERS = ("CLARABEL", "CLARABEL_RELAXED", "SCS")
#: cvxpy solver and options per configuration.
SOLVER_CONFIGS: dict[str, tuple[str, dict[str, Any]]] = {
    "CLARABEL": ("CLARABEL", {"tol_gap_abs": 1e-9, "tol_gap_rel": 1e-9, "tol_feas": 1e-9}),
    "CLARABEL_RELAXED": ("CLARABEL", {"max_iter": 400}),
    "SCS": ("SCS", {"eps": 1e-8, "max_iters": 50_000}),
}
#: The scaled LMIs are ``J(z) ⪰ CONE_MARGIN 1`` (module doc).
CONE_MARGIN = 1e-7
#: A scaled pseudo-inertia eigenvalue in ``[-REPAIR_LIMIT, 0)`` is set to 0; below, the solve is refused.
REPAIR_LIMIT = 1e-5
#: ``nearest_consistent`` counts the change of predicted torque in units of this fraction of them.
PROJECTION_UNIT = 1e-3
#: Floor of the pcls data scale ``s²``, relative to ``‖tau‖²`` (noise-free data).
NOISE_FLOOR = 1e-10
#: Parameter-name suffixes constrained to be non-negative (friction, armature: ``idkit.robots.drives``).
#: A Stribeck coefficient ``fs`` may be negative as long as ``fc + fs >= 0``.
NONNEGATIVE_SUFFIXES = tuple(f".{suffix}" for suffix in NONNEGATIVE)
#: A payload's (raw-unit) pseudo-inertia eigenvalue below ``-PSD_TOLERANCE × max|J|`` is outside the cone.
PSD_TOLERANCE = 1e-6

#: The conic solver choice: ``"auto"`` tries ``AUTO_SOLVERS`` in order.
Solver = Literal["auto", "clarabel", "scs"]
#: The prior's shape: the entropic divergence of the module doc, or the squared Euclidean distance
#: ``‖(p − p0) / u‖²`` of the scaled standard parameters to CAD (the tie-break's, at weight ``w``).
PriorShape = Literal["entropic", "euclidean"]


@dataclass(frozen=True)
class ConsistentSettings:
    """The options of the consistent program (``pcls``, ``nearest_consistent``), checked once.

    Attributes:
        prior_weight: ``w >= 0`` of the entropic divergence to the CAD model (``TIE_BREAK`` if 0), or
            ``"auto"`` (``pcls`` only: chosen by cross-validation on the training data).
        min_mass: lower bound ``>= 0`` on every link mass (kg); ``None`` = 1 % of the smallest CAD mass.
        solver: the choice as given.
        conic_solvers: the solver configurations (:data:`SOLVER_CONFIGS`) ``solver`` stands for.
        plausibility: bounds beyond consistency (:class:`~idkit.conic.plausible.Plausibility`).
        prior_shape: the prior's shape (:data:`PriorShape`).
    """

    prior_weight: float | Literal["auto"]
    min_mass: float | None
    solver: Solver
    conic_solvers: tuple[str, ...]
    plausibility: Plausibility = field(default_factory=Plausibility)
    prior_shape: PriorShape = "entropic"

    @classmethod
    def checked(
        cls,
        who: str,
        prior_weight: float | str = 0.0,
        min_mass: float | None = None,
        solver: Solver = "auto",
        auto: bool = False,
        plausibility: Plausibility | None = None,
        prior_shape: PriorShape = "entropic",
    ) -> ConsistentSettings:
        """The settings, or ``ValueError`` naming ``who`` and the option; ``auto``: whether
        ``prior_weight="auto"`` is accepted (a fit has the data to choose it, a projection has not)."""
        weight: float | Literal["auto"] = "auto"
        if not (auto and prior_weight == "auto"):
            if isinstance(prior_weight, (str, bool)) or not (
                math.isfinite(prior_weight) and prior_weight >= 0
            ):
                allowed = "a finite number >= 0" + (" or 'auto'" if auto else "")
                raise ValueError(f"{who}: prior_weight must be {allowed}, got {prior_weight!r}")
            weight = float(prior_weight)
        if min_mass is not None and not (math.isfinite(min_mass) and min_mass >= 0):
            raise ValueError(f"{who}: min_mass must be None or a finite number >= 0 (kg), got {min_mass!r}")
        choices = get_args(Solver)
        if solver not in choices:
            listed = ", ".join(map(repr, choices))
            raise ValueError(f"{who}: solver must be one of {listed}, got {solver!r}")
        shapes = get_args(PriorShape)
        if prior_shape not in shapes:
            raise ValueError(
                f"{who}: prior_shape must be one of {', '.join(map(repr, shapes))}, got {prior_shape!r}"
            )
        conic = {"auto": AUTO_SOLVERS, "clarabel": AUTO_SOLVERS[:2], "scs": ("SCS",)}[solver]
        return cls(weight, min_mass, solver, conic, plausibility or Plausibility(), prior_shape)


@dataclass(frozen=True)
class ConsistentSolution:
    """A solved physically consistent program.

    Attributes:
        params: standard parameters ``[P]`` (float64, CPU).
        min_eigenvalues: smallest pseudo-inertia eigenvalue per link ``[nb]`` (physical units, ``>= 0``).
        divergence: entropic divergence to the (well-posed) CAD pseudo-inertia per link ``[nb]`` (nats).
        data_term: ``‖R K p − b‖² / s²`` at the solution.
        status, solver: cvxpy's status and the solver configuration that produced it.
        solve_time_s: wall time of cvxpy (canonicalisation + solver), all configurations tried.
        repaired: links whose solution was a hair outside the cone and was moved onto it.
    """

    params: Tensor
    min_eigenvalues: Tensor
    divergence: Tensor
    data_term: float
    status: str
    solver: str
    solve_time_s: float
    repaired: tuple[str, ...] = ()


def divergence(j: np.ndarray, j0: np.ndarray) -> float:
    """Entropic divergence ``D(J ‖ J0)`` of two 4×4 pseudo-inertias (``inf`` if ``J`` is singular)."""
    sign, logdet = np.linalg.slogdet(j)
    if sign <= 0:
        return float("inf")
    return float(-logdet + np.linalg.slogdet(j0)[1] + np.trace(np.linalg.solve(j0, j)) - 4.0)


def pseudo_inertia_expression(pi: Any, cp: Any) -> Any:
    """``J(pi)`` as a symmetric 4×4 cvxpy expression."""
    return cp.bmat(pseudo_inertia_rows([pi[k] for k in range(10)]))


class ConsistentProgram:
    """The program of the module doc for one robot, built once and solved for any data and weight.

    The data ``(R, b) / s`` and the weight ``w`` are cvxpy parameters, so cvxpy canonicalises the
    program once (it is DPP) and a later solve only hands the conic solver new numbers: the
    cross-validation of ``prior_weight`` solves it tens of times.

    Args:
        robot: a ``urdf`` robot.
        settings: mass floor, conic solvers and plausibility bounds (the weight is given to :meth:`solve`).
        rows: the number of rows ``r`` of the compressed data ``R[r, B]``.
        prior: the entropic prior (solved with ``w > 0``), else the tie-break (``w = 0``).
        who: name used in error messages.
        reference: the CAD reference (:func:`~idkit.conic.prior.cad_reference`), if already made.
    """

    def __init__(
        self,
        robot: URDFRobot,
        settings: ConsistentSettings,
        rows: int,
        prior: bool,
        who: str = "pcls",
        reference: CadReference | None = None,
    ) -> None:
        import cvxpy as cp

        self.robot, self.settings, self.prior, self.who = robot, settings, prior, who
        nb = self.links = link_count(robot)
        self.reference = reference = reference or cad_reference(robot)
        self.unit = unit = reference.unit
        nominal = robot.nominal_params().double().numpy()
        cad_masses = nominal[0 : 10 * nb : 10]
        min_mass = settings.min_mass
        self.floor = floor = 0.01 * float(cad_masses.min()) if min_mass is None else float(min_mass)
        K = robot.base_map.double().numpy()
        self.z = z = cp.Variable(K.shape[1])
        self.R = cp.Parameter((rows, K.shape[0]))
        self.b = cp.Parameter(rows)
        self.weight = cp.Parameter(nonneg=True)
        data = cp.sum_squares(self.R @ (K * unit) @ z - self.b)
        pseudo = [pseudo_inertia_expression(z[10 * i : 10 * i + 10], cp) for i in range(nb)]
        constraints = [j >> CONE_MARGIN * np.eye(4) for j in pseudo]
        constraints.append(z[0 : 10 * nb : 10] >= floor / cad_masses)
        names = robot.param_names
        nonnegative = [k for k, name in enumerate(names) if name.endswith(NONNEGATIVE_SUFFIXES)]
        if nonnegative:
            constraints.append(z[nonnegative] >= 0)
        index = {name: k for k, name in enumerate(names)}
        held = [index[name] for name in getattr(robot, "a_priori_params", ())]  # merged armatures, shapes
        if held:
            constraints.append(z[held] == nominal[held] / unit[held])
        for joint in robot.joint_names:
            if f"{joint}.fs" in index:
                constraints.append(z[index[f"{joint}.fc"]] + z[index[f"{joint}.fs"]] >= 0)
        constraints += plausibility_constraints(robot, settings.plausibility, z, unit, who)
        euclidean = cp.sum_squares(z[: 10 * nb] - nominal[: 10 * nb] / unit[: 10 * nb])
        if prior and settings.prior_shape == "euclidean":
            objective = data + self.weight * euclidean
        elif prior:  # the entropic divergence in scaled units, without its constants
            inverses = np.linalg.inv(reference.pseudo)
            entropic = sum(-cp.log_det(j) + cp.trace(inverses[i] @ j) for i, j in enumerate(pseudo))
            objective = data + self.weight * entropic
        else:  # a barrier-free tie-break: the log-det barrier is ill-conditioned where the LMIs are active
            objective = data + TIE_BREAK * euclidean
        self.program = cp.Problem(cp.Minimize(objective), constraints)

    def solve(
        self, R: np.ndarray, b: np.ndarray, scale2: float, weight: float = 0.0, once: bool = False
    ) -> ConsistentSolution:
        """Solve for the data ``‖R alpha − b‖² / scale2`` and prior weight ``weight`` (``> 0`` exactly
        when the program was built with ``prior``); ``once``: skip the reusable canonicalisation.

        Raises:
            IdentificationError: infeasible constraints, or no solver configuration found a solution
                inside the physical cone (one line naming each).
        """
        if (weight > 0) != self.prior:
            raise ValueError(f"{self.who}: weight {weight:g} for a program built with prior={self.prior}")
        scale = np.sqrt(scale2)
        self.R.value, self.b.value = R / scale, b / scale
        self.weight.value = weight
        started = time.perf_counter()
        infeasible = (
            f"no link mass can be >= min_mass={self.floor:g} kg with a positive semidefinite "
            "pseudo-inertia, friction >= 0 and the plausibility bounds asked for — check min_mass and the "
            "bounds"
        )
        failures: list[str] = []
        for config in self.settings.conic_solvers:
            status = solve_program(self.program, (config,), self.who, infeasible, once, failures)
            if status is None:
                continue
            z = np.asarray(self.z.value, dtype=np.float64)
            z, repaired, worst = _into_cone(z, self.links, self.robot.link_names)
            if worst is not None:
                failures.append(f"{config}: status {status!r} but {worst} outside the cone")
                continue
            return self._solution(z, R, b, scale, config, status, time.perf_counter() - started, repaired)
        raise IdentificationError(f"{self.who}: the conic solver failed ({'; '.join(failures)})")

    def _solution(
        self,
        z: np.ndarray,
        R: np.ndarray,
        b: np.ndarray,
        scale: float,
        config: str,
        status: str,
        elapsed: float,
        repaired: tuple[str, ...],
    ) -> ConsistentSolution:
        nb = self.links
        params = torch.as_tensor(self.unit * z, dtype=torch.float64)
        physical = pseudo_inertia(params[: 10 * nb].reshape(nb, 10)).numpy()
        scaled = pseudo_inertia(torch.as_tensor(z[: 10 * nb]).reshape(nb, 10)).numpy()
        residual = (R @ self.robot.base_map.double().numpy() @ params.numpy() - b) / scale
        return ConsistentSolution(
            params=params,
            min_eigenvalues=torch.as_tensor(np.linalg.eigvalsh(physical)[:, 0]),
            divergence=torch.as_tensor([divergence(scaled[i], self.reference.pseudo[i]) for i in range(nb)]),
            data_term=float(residual @ residual),
            status=status,
            solver=config,
            solve_time_s=elapsed,
            repaired=repaired,
        )


def _into_cone(
    z: np.ndarray, links: int, names: Sequence[str]
) -> tuple[np.ndarray, tuple[str, ...], str | None]:
    """The scaled solution with each pseudo-inertia a hair outside the cone moved onto it (negative
    eigenvalues set to 0, then a rounding margin); the links moved; the worst link further outside
    (``"name (eigenvalue)"``) or ``None``."""
    z = z.copy()
    pseudo = pseudo_inertia(torch.as_tensor(z[: 10 * links]).reshape(links, 10)).numpy()
    repaired, worst = [], None
    for i, j in enumerate(pseudo):
        values, vectors = np.linalg.eigh(j)
        if values[0] >= 0:
            continue
        if values[0] < -REPAIR_LIMIT:
            worst = f"{names[i]} ({values[0]:.3g})"
            break
        fixed = vectors @ np.diag(np.maximum(values, 1e-12 * max(values[-1], 1.0))) @ vectors.T
        z[10 * i : 10 * i + 10] = _standard_from_pseudo(fixed)
        repaired.append(names[i])
    return z, tuple(repaired), worst


def _standard_from_pseudo(j: np.ndarray) -> np.ndarray:
    """The 10 standard parameters of a pseudo-inertia (the inverse of ``pseudo_inertia_rows``)."""
    second = (j[:3, :3] + j[:3, :3].T) / 2
    inertia = np.trace(second) * np.eye(3) - second
    (xx, xy, xz), (_, yy, yz), (_, _, zz) = inertia
    return np.array([j[3, 3], *j[:3, 3], xx, xy, xz, yy, yz, zz])


def cone_violations(names: Sequence[str], pseudo: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Smallest eigenvalue ``[nb]`` of each solved pseudo-inertia ``pseudo[nb, 4, 4]``, and the
    bodies (``"name (eigenvalue)"``) whose eigenvalue is below ``-PSD_TOLERANCE`` of their scale."""
    lowest = np.linalg.eigvalsh(pseudo)[:, 0]
    sizes = np.abs(pseudo).max((1, 2))
    outside = [
        f"{name} ({value:.3g})"
        for name, value, size in zip(names, lowest, sizes, strict=True)
        if value < -PSD_TOLERANCE * size
    ]
    return lowest, outside


def solve_program(
    program: Any,
    configs: tuple[str, ...],
    who: str,
    infeasible: str,
    once: bool = False,
    failures: list[str] | None = None,
) -> str | None:
    """Solve the cvxpy ``program`` with the first configuration of ``configs`` (:data:`SOLVER_CONFIGS`)
    that returns a solution; its status, or ``None`` with each failure appended to ``failures``.
    ``once``: the program is solved a single time, so its parameters are taken as constants.

    Raises:
        IdentificationError: infeasible (``infeasible`` says why that can be), or, when no
            ``failures`` list is given, every configuration failed (one line naming each cause).
    """
    import cvxpy as cp

    own = failures is None
    failures = [] if failures is None else failures
    for config in configs:
        name, options = SOLVER_CONFIGS[config]
        solver = _interruptible_scs() if name == "SCS" else name
        try:
            with warnings.catch_warnings():  # "may be inaccurate": the status says it, and is reported
                warnings.simplefilter("ignore", UserWarning)
                program.solve(solver=solver, ignore_dpp=once, **options)
        except cp.error.SolverError as exc:
            failures.append(f"{config}: {str(exc).splitlines()[0]}")
            continue
        if program.status in (cp.INFEASIBLE, cp.INFEASIBLE_INACCURATE):
            raise IdentificationError(
                f"{who}: the constraints are infeasible ({name} status {program.status!r}): {infeasible}"
            )
        if program.status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) and program.variables()[0].value is not None:
            return str(program.status)
        failures.append(f"{config}: status {program.status!r}")
    if own:
        raise IdentificationError(f"{who}: the conic solver failed ({'; '.join(failures)})")
    return None


@functools.cache
def _interruptible_scs() -> Any:
    """cvxpy's SCS interface, but Ctrl-C stops the run: SCS catches SIGINT itself and returns
    "interrupted", which cvxpy reports as a solver failure, so the next fold or weight would start."""
    from cvxpy.reductions.solvers.conic_solvers.scs_conif import SCS

    class InterruptibleSCS(SCS):
        def name(self) -> str:
            return "SCS_INTERRUPTIBLE"

        def invert(self, solution: dict[str, Any], inverse_data: Any) -> Any:
            if solution["info"].get("status_val") == SCS_INTERRUPTED:
                raise KeyboardInterrupt
            return super().invert(solution, inverse_data)

    return InterruptibleSCS()


#: SCS's status value when it stopped on SIGINT.
SCS_INTERRUPTED = -5


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


def solve_consistent(
    robot: URDFRobot,
    R: np.ndarray,
    b: np.ndarray,
    scale2: float,
    settings: ConsistentSettings,
    who: str = "pcls",
) -> ConsistentSolution:
    """Solve the program of the module doc once, at the fixed ``settings.prior_weight``."""
    weight = float(settings.prior_weight)
    program = ConsistentProgram(robot, settings, R.shape[0], prior=weight > 0, who=who)
    return program.solve(R, b, scale2, weight, once=True)


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
    in units of ``PROJECTION_UNIT`` under the constraints of the module doc. ``W`` is the base
    regressor on ``samples`` when given (e.g. the training data), otherwise on the robot's own random
    states (``robot.n_states`` states, seed ``robot.seed``). An estimate that is already consistent is
    returned (up to the ``TIE_BREAK`` pull), and its unidentifiable part is resolved towards CAD.

    Returns:
        The :class:`ConsistentSolution`; ``data_term`` is the squared relative torque change.
    """
    if (params is None) == (base_params is None):
        raise ValueError("nearest_consistent: give exactly one of params [P] or base_params [B]")
    settings = ConsistentSettings.checked("nearest_consistent", prior_weight, min_mass, solver)
    robot = linked(robot)
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
