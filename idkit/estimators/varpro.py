"""``varpro``: variable projection for a robot whose friction has nonlinear shape parameters.

With the sigmoid friction of Gaz et al. (``robot.friction=sigmoid``, :mod:`idkit.robots.drives`) the
torques are linear in every parameter but the shapes ``θ = (φ2, φ3)`` of each joint::

    τ = W_fixed α_fixed + S(θ) φ1,        S(θ)_j = σ(φ2_j (q̇_j + φ3_j)) − σ(φ2_j φ3_j)  (joint j's rows)

``W_fixed`` holds the base columns that do not depend on ``θ`` (rigid body, armature, viscous,
offsets). Variable projection (Golub & Pereyra 1973) eliminates the linear part: for a given ``θ``
the best ``(α_fixed, φ1)`` is a least-squares solve, so the search runs over ``2n`` numbers only::

    r(θ) = min_α ‖τ − [W_fixed | S(θ)] α‖² = ‖τ⊥‖² − bᵀ A⁻¹ b,
    A = diag(‖S_j‖²) − Gᵀ G,   G = Q₀ᵀ S,   b = Sᵀ τ⊥

with ``W_fixed = Q₀ R₀`` factored once and ``τ⊥ = τ − Q₀ Q₀ᵀ τ``. ``S``'s columns live on disjoint
rows (one joint each), so a whole swarm of candidates costs one batched product ``G`` (``K × N × n ×
L``) and ``K`` solves of ``n × n`` systems: no factorisation per particle. The batched particle swarm
(:mod:`idkit.optim.swarm`) searches ``θ`` in the robot's box, ``polish`` refines the best point
by Levenberg–Marquardt with Kaufman's Jacobian of the projected residual, and the linear parameters
at the final ``θ`` come from one least-squares solve, or from ``pcls`` (``refine="pcls"``:
physically consistent, on the robot rebuilt with ``θ`` as its reference shape).
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import numpy as np
import torch
from torch import Tensor

from idkit.estimate import Estimate, to_python
from idkit.estimators.bounds import at_bounds, warn_at_bounds
from idkit.estimators.linear.observation import IdentificationError
from idkit.estimators.linear.uncertainty import base_uncertainties
from idkit.interfaces import Estimator, Robot
from idkit.model import IdentifiedModel
from idkit.optim import sizes, swarm
from idkit.problem import Problem
from idkit.robots.drives import sigmoid_friction
from idkit.robots.urdf import URDFRobot
from idkit.runtime import resolve_threads, torch_threads

#: Relative ridge on ``A`` (scale of its trace): a shape whose sigmoid is nearly linear in ``q̇``
#: (collinear with viscous friction) gets a finite, slightly pessimistic cost instead of round-off.
RIDGE = 1e-12
#: The polish stops when a step lowers the residual sum of squares by less than this fraction,
CONVERGED = 1e-10
#: or when the next step moves no shape by more than this fraction of its box width. On the search's
#: subsampled data it stops at a looser fraction: the steps on every sample finish the descent.
STEP_TOLERANCE = 1e-12
COARSE_CONVERGED = 1e-2
#: Nanoseconds of one core per residual (sample × joint) of one shape's evaluation: about the fewest
#: measured (16–85 ns on the README's drive recording, 213–3,401 samples, 16–256 shapes at once), so
#: the long-search notice's estimate is a lower bound.
VARPRO_RESIDUAL_NS = 15.0


@dataclass(frozen=True)
class Projection:
    """The data of the projected problem, built once per fit.

    Rows are joint-major (joint ``j``'s ``N`` samples, then joint ``j + 1``'s): every column of
    ``S(θ)`` and of its derivatives lives on one joint's block of rows, so its products with ``Q₀``
    are ``n`` matrix products over ``N`` contiguous rows, with no reordering.

    Attributes:
        fixed: base-parameter columns that do not depend on ``θ`` ``[L]`` (indices into the base).
        scaled: base-parameter columns of ``φ1`` ``[n]`` (one per joint, in joint order).
        w_fixed: ``W_fixed`` ``[n, N, L]`` (joint ``j``'s rows in ``w_fixed[j]``).
        q0: ``Q₀`` of ``W_fixed = Q₀ R₀`` ``[n, N, L]`` (rows as ``w_fixed``).
        r0: ``R₀`` ``[L, L]``.
        q0_tau: ``Q₀ᵀτ`` ``[L]``.
        tau: measured torques ``[n, N]``; ``tau_perp`` the part orthogonal to ``W_fixed`` ``[n, N]``.
        qd: joint velocities ``[n, N]``.
    """

    fixed: list[int]
    scaled: list[int]
    w_fixed: Tensor
    q0: Tensor
    r0: Tensor
    q0_tau: Tensor
    tau: Tensor
    tau_perp: Tensor
    qd: Tensor

    def sigmoids(self, theta: Tensor) -> Tensor:
        """``S(θ)`` of shapes ``theta[K, 2n]`` (all ``φ2``, then all ``φ3``) as ``[n, N, K]``: joint
        ``j``'s sigmoids on its own rows, in the layout of ``q0``'s per-joint products."""
        n = self.qd.shape[0]
        return sigmoid_friction(self.qd[..., None], theta[:, :n].T[:, None], theta[:, n:].T[:, None])

    def columns(self, theta: Tensor) -> Tensor:
        """``S(θ)`` of one shape ``theta[2n]`` as ``[n, N]``."""
        return self.sigmoids(theta[None])[..., 0]

    def matrix(self, theta: Tensor) -> Tensor:
        """``[W_fixed | S(θ)]`` ``[n·N, L + n]`` of one shape ``theta[2n]`` (rows joint-major)."""
        n, samples, width = self.w_fixed.shape
        s = self.w_fixed.new_zeros(n, samples, n)
        s.diagonal(dim1=0, dim2=2).copy_(self.columns(theta).T)  # joint j's column on its rows
        return torch.cat([self.w_fixed, s], 2).reshape(-1, width + n)

    def residual(self, theta: Tensor) -> Tensor:
        """``r(θ)`` ``[...]`` for shapes ``theta[..., 2n]`` (module doc), ``≥ 0``."""
        n = self.qd.shape[0]
        s = self.sigmoids(theta.reshape(-1, 2 * n))  # [n, N, K]
        g = torch.bmm(self.q0.mT, s).permute(2, 0, 1)  # Gᵀ = (Q₀ᵀS)ᵀ per shape [K, n, L]
        a = _ridged(torch.diag_embed(s.square().sum(1).T) - g @ g.mT)  # [K, n, n]
        b = (s * self.tau_perp[..., None]).sum(1).T  # Sᵀτ⊥ [K, n]
        gain = (b * torch.linalg.solve(a, b[..., None])[..., 0]).sum(-1)
        return (self.tau_perp.square().sum() - gain).clamp_min(0.0).reshape(theta.shape[:-1])

    def shape_derivatives(self, theta: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """``S(θ)``, ``∂S/∂φ2`` and ``∂S/∂φ3`` of one shape ``theta[2n]``, each ``[n, N]`` (joint ``j``'s
        column on its own rows; not yet times ``φ1``)."""
        n = self.qd.shape[0]
        steepness, shift = theta[:n, None], theta[n:, None]  # [n, 1]
        moved = self.qd + shift
        sigma, rest = torch.sigmoid(steepness * moved), torch.sigmoid(steepness * shift)
        slope, slope_rest = sigma * (1 - sigma), rest * (1 - rest)
        return sigma - rest, slope * moved - slope_rest * shift, (slope - slope_rest) * steepness

    def linearised(self, theta: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """What a Gauss–Newton step at one shape ``theta[2n]`` needs: ``JᵀJ`` ``[2n, 2n]``, ``Jᵀr``
        ``[2n]`` and ``‖r‖²``, with ``r`` the projected residual and ``J`` Kaufman's Jacobian
        ``−P⊥ ∂S/∂θ φ1`` (columns: every ``φ2``, then every ``φ3``).

        Every product is per joint or with ``Q₀`` (the columns of ``S`` and ``∂S/∂θ`` live on one
        joint's rows each), so a step costs ``O(N n L)``, never a product with the whole ``W``:
        ``JᵀJ = DᵀD − G_DᵀG_D − CᵀA⁻¹C`` with ``D = ∂S/∂θ φ1``, ``G_D = Q₀ᵀD``, ``C = S⊥ᵀD``, and
        ``Jᵀr = −Dᵀr``; ``r = τ⊥ − S⊥φ1`` is formed explicitly (matrix–vector products), so
        ``‖r‖²`` has no cancellation.
        """
        n, width = self.qd.shape[0], self.q0.shape[-1]
        # per joint: S and ∂S/∂φ2, ∂S/∂φ3 (not yet times φ1), and τ⊥ beside them for the Gram matrix
        columns = torch.stack([*self.shape_derivatives(theta), self.tau_perp], -1)  # [n, N, 4]
        gram = columns.mT @ columns  # [n, 4, 4]: every product of two columns of one joint
        products = torch.bmm(self.q0.mT, columns[..., :3])  # Q₀ᵀ[S, ∂S] [n, L, 3] (Q₀ᵀτ⊥ = 0)
        g = products[..., 0]  # Gᵀ [n, L]
        a = _ridged(torch.diag(gram[:, 0, 0]) - g @ g.T)
        amplitude = torch.linalg.solve(a, gram[:, 0, 3])  # φ1 [n]
        # r = τ⊥ − S⊥φ1 = τ⊥ − Sφ1 + Q₀(Gφ1), by matrix–vector products
        r = self.tau_perp - columns[..., 0] * amplitude[:, None] + self.q0 @ (amplitude @ g)  # [n, N]
        scale = amplitude[:, None]  # D = ∂S/∂θ · φ1: joint j's columns times its φ1
        g_d = (products[..., 1:] * scale[..., None]).permute(1, 2, 0).reshape(width, 2 * n)  # Q₀ᵀD
        # DᵀD and SᵀD are per joint: on the diagonals of their n × n blocks
        dd = torch.diag_embed((gram[:, 1:3, 1:3] * (scale * scale)[..., None]).permute(1, 2, 0))
        sd = torch.diag_embed((gram[:, 0, 1:3] * scale).T)
        c = sd.transpose(0, 1).reshape(n, 2 * n) - g @ g_d  # S⊥ᵀD
        normal = dd.transpose(1, 2).reshape(2 * n, 2 * n) - g_d.T @ g_d - c.T @ torch.linalg.solve(a, c)
        gradient = -((columns[..., 1:3] * r[..., None]).sum(1) * scale).T.reshape(-1)  # −Dᵀr
        return normal, gradient, r.square().sum()


def _ridged(a: Tensor) -> Tensor:
    """``A`` ``[..., n, n]`` plus ``RIDGE`` times its trace on the diagonal."""
    ridge = RIDGE * a.diagonal(dim1=-2, dim2=-1).sum(-1).clamp_min(torch.finfo(a.dtype).tiny)
    return a + ridge[..., None, None] * torch.eye(a.shape[-1], dtype=a.dtype, device=a.device)


def projection(robot: Any, q: Tensor, qd: Tensor, qdd: Tensor, tau: Tensor) -> Projection:
    """The projected problem of ``robot`` (a ``urdf`` robot with ``friction="sigmoid"``) on samples."""
    return _projection(robot, robot.regressor(q, qd, qdd), qd, tau)


def _projection(robot: Any, regressor: Tensor, qd: Tensor, tau: Tensor) -> Projection:
    """``projection`` given the regressor ``[N, n, B]`` of the samples (``qd``, ``tau`` ``[N, n]``)."""
    names = list(robot.param_names)
    base = list(robot.base.indices)
    scaled_names = [f"{j}.phi1" for j in robot.joint_names]
    try:
        scaled = [base.index(names.index(name)) for name in scaled_names]
    except ValueError:
        raise IdentificationError(
            "varpro: a sigmoid amplitude phi1 is not a base parameter of this robot (a joint that never "
            "moves?); the shapes cannot be identified"
        ) from None
    shared = [robot.base_param_names[k] for k in scaled if np.count_nonzero(robot.base.matrix[k]) > 1]
    if shared:
        raise IdentificationError(f"varpro: other parameters regroup into the sigmoid amplitude {shared[0]}")
    fixed = [k for k in range(len(base)) if k not in scaled]
    w_fixed = regressor[..., fixed].transpose(0, 1).contiguous()  # [n, N, L]
    q0, r0 = torch.linalg.qr(w_fixed.reshape(-1, len(fixed)))  # rows joint-major: Q₀ is too
    q0 = q0.reshape(w_fixed.shape)
    tau = tau.T.contiguous()
    q0_tau = q0.reshape(-1, q0.shape[-1]).T @ tau.reshape(-1)
    return Projection(fixed, scaled, w_fixed, q0, r0, q0_tau, tau, tau - q0 @ q0_tau, qd.T.contiguous())


class VariableProjection(Estimator):
    """``varpro``: swarm over the sigmoid friction shapes, least squares for everything else.

    Args:
        particles: particles of the swarm searching the ``2n`` shapes.
        iterations: evaluations per particle (the first is the random start).
        polish: at most this many Levenberg–Marquardt steps from the swarm's best shape (0 = none).
        search_samples: the swarm sees at most this many samples (every ``k``-th): it only has to
            find the basin, which the polish and the final solve, on every sample, then descend.
        refine: ``"none"``: least squares for the linear parameters at the final shape;
            ``"pcls"``: physically consistent least squares there (pseudo-inertia LMIs, armature and
            friction ≥ 0), on the robot rebuilt with the found shape as its reference.
        prior_weight: ``pcls``'s prior weight when ``refine="pcls"``: ``"auto"`` (the default, as
            ``pcls``'s) cross-validates the pull towards the URDF's inertials; a number fixes it.
        plausible: with ``refine="pcls"``, keep every link mass within ``pcls``'s plausible range of
            its CAD mass (``pcls``'s ``plausible``).
        threads: torch intra-op threads; ``None`` = ``idkit.runtime``'s size rule.

    ``details``: ``shape`` (``φ2``, ``φ3`` per joint), ``criterion_value`` (‖τ − Wα‖), ``history``
    (the swarm's best residual per kept iteration), ``evaluations``, ``rel_error_train``,
    ``search_time_s``, ``at_bound`` (the shapes the box stopped, said in a ``warning:`` line) and the
    ``uncertainty`` of the base parameters and the shapes not at a bound (``_uncertainty``).
    """

    #: The conformance suite's problem: a robot with sigmoid friction (the cylindrical one from its URDF).
    conformance_robot: ClassVar[tuple[str, dict[str, Any]]] = (
        "urdf",
        {"urdf": "cylindrical", "friction": "sigmoid"},
    )
    conformance_options: ClassVar[dict[str, Any]] = {"particles": 8, "iterations": 5, "polish": 2}

    def __init__(
        self,
        particles: int = 16,
        iterations: int = 15,
        polish: int = 50,
        search_samples: int = 250,
        refine: Literal["none", "pcls"] = "none",
        prior_weight: float | Literal["auto"] = "auto",
        plausible: bool = False,
        threads: int | None = None,
    ) -> None:
        self.particles = particles
        self.iterations = iterations
        self.polish = polish
        self.search_samples = search_samples
        self.refine = refine
        self.prior_weight = prior_weight
        self.plausible = plausible
        self.threads = threads
        self.resolve()  # a bad option is refused now, not after the search; every fit resolves again

    def resolve(self) -> None:
        """Check the options (``ValueError`` naming the one at fault); a fit reads them as they are."""
        from idkit.conic.program import ConsistentSettings  # cvxpy stays unimported until a fit

        for option, value, least in (
            ("particles", self.particles, 1),
            ("iterations", self.iterations, 1),
            ("polish", self.polish, 0),
            ("search_samples", self.search_samples, 1),
        ):
            if isinstance(value, bool) or not isinstance(value, int) or value < least:
                raise ValueError(f"varpro option {option} must be an integer >= {least}, got {value!r}")
        # before a search whose time or history would have no bound
        budget = {"particles": self.particles, "iterations": self.iterations}
        sizes.check_evaluations("varpro", budget, "iterations", sizes.PSO_STEP_EVALUATIONS)
        if self.refine not in ("none", "pcls"):
            raise ValueError(f"varpro: refine must be 'none' or 'pcls', got {self.refine!r}")
        if self.threads is not None and (isinstance(self.threads, bool) or self.threads < 1):
            raise ValueError(f"varpro: threads must be None or an integer >= 1, got {self.threads!r}")
        ConsistentSettings.checked("varpro", self.prior_weight, auto=True)

    @property
    def name(self) -> str:
        return "VarPro" + ("-pcls" if self.refine == "pcls" else "")

    def fit(self, problem: Problem) -> Estimate:
        start = time.perf_counter()
        self.resolve()
        problem.check_identifiable()
        robot = problem.robot
        if not isinstance(robot, URDFRobot) or robot.friction != "sigmoid":
            raise IdentificationError(
                f"varpro: robot {type(robot).__name__} has no nonlinear friction shapes; use a 'urdf' robot "
                "with friction=sigmoid (a model linear in its parameters needs estimator=ls)"
            )
        s = problem.tensors()
        n = robot.n_joints
        searched = min(s.tau.shape[0], self.search_samples) * n  # the swarm's error-tensor size per particle
        sizes.announce_long_search(
            "varpro", self.particles * self.iterations, 1, [searched], VARPRO_RESIDUAL_NS
        )
        width = len(robot.base_param_names)
        sizes.check_memory(
            f"varpro: particles={self.particles} shapes evaluated at once on {searched} residuals of "
            f"{width} columns",
            sizes.FLOAT * self.particles * searched * (width + 4),
            "lower estimator.particles or estimator.search_samples",
        )
        threads = resolve_threads(self.threads, self.particles * searched)
        with torch_threads(threads), torch.no_grad():
            regressor = robot.regressor(s.q, s.qd, s.qdd)
            data = _projection(robot, regressor, s.qd, s.tau)
            stride = -(-s.q.shape[0] // self.search_samples)  # the swarm's every stride-th sample
            coarse = (
                data
                if stride == 1
                else _projection(robot, regressor[::stride], s.qd[::stride], s.tau[::stride])
            )
            lower, upper = robot.bounds()
            box = [
                robot.param_names.index(f"{j}.{key}") for key in ("phi2", "phi3") for j in robot.joint_names
            ]
            lower, upper = lower[box].to(s.tau), upper[box].to(s.tau)
            draws = swarm.Draws([swarm.Uniform(problem.generator(), s.tau)])
            reference = robot.nominal_params()[box].to(s.tau)  # one particle starts at the robot's shape
            kept = sizes.history_stride(self.iterations)  # at most HISTORY_ROWS + 1 rows of history
            state, history = swarm.run(
                coarse.residual, lower, upper, (), self.particles, self.iterations, swarm.SwarmRules(), draws,
                kept, start=reference[None],
            )  # fmt: skip
            theta = state.global_position
            if coarse is not data:  # most steps where they are cheap; the last ones on every sample
                theta = _polish(coarse, theta, lower, upper, self.polish, COARSE_CONVERGED)
                theta = _polish(data, theta, lower, upper, self.polish, damping=1e-6)
            else:
                theta = _polish(data, theta, lower, upper, self.polish)
        search_time = time.perf_counter() - start
        steepness, shift = theta[:n], theta[n:]
        shape_names = [robot.param_names[k] for k in box]
        ended = at_bounds(shape_names, theta, lower, upper)
        warn_at_bounds(
            self.name, ended, shape_names, lower, upper, "robot.steepness_range or robot.max_shift"
        )
        with torch_threads(threads), torch.no_grad():
            if self.refine == "pcls":
                refined, details = self._pcls(robot, problem, steepness, shift)
                params = refined.vector.to(s.tau)
                alpha = robot.base_params(params)
                predicted = refined.predict(s.q, s.qd, s.qdd)
            else:
                solved = _solve(data, theta)
                params = _standard(robot, data, theta, solved.alpha)
                alpha = robot.base_params(params)
                predicted = (solved.w @ solved.alpha).reshape(n, -1).T  # rows joint-major
                free = [k for k, name in enumerate(shape_names) if name not in ended]
                details = _uncertainty(robot, data, solved, theta, free, shape_names)
        residual = float(torch.linalg.vector_norm(s.tau - predicted))
        cost = residual if problem.cost is None else float(problem.evaluate(params))
        details = {
            "criterion": "||tau_s - W(theta) alpha||_2, theta = sigmoid shapes searched by PSO",
            "criterion_value": residual,
            "rel_error_train": residual / float(torch.linalg.vector_norm(s.tau)),
            "shape": {
                joint: {"phi2": float(steepness[j]), "phi3": float(shift[j])}
                for j, joint in enumerate(robot.joint_names)
            },
            "history": [float(h) for h in history.sqrt().tolist()],
            "at_bound": ended,
            "search_stride": stride,
            "history_stride": kept,
            "evaluations": self.particles * self.iterations,
            "search_time_s": search_time,
            "threads": threads,
            **details,
        }
        return Estimate(
            estimator=self.name,
            params=dict(zip(robot.param_names, params.tolist(), strict=True)),
            cost=cost,
            wall_time_s=time.perf_counter() - start,
            base_params=dict(zip(robot.base_param_names, alpha.tolist(), strict=True)),
            details=to_python(details),
        )

    def _pcls(
        self, robot: URDFRobot, problem: Problem, steepness: Tensor, shift: Tensor
    ) -> tuple[IdentifiedModel, dict[str, Any]]:
        """pcls on the robot whose reference sigmoid shape is the one found: the model on ``robot``
        (whose parameters include the shape) and the details kept of the fit."""
        from dataclasses import replace

        from idkit.estimators.physical import PhysicallyConsistentLS

        with warnings.catch_warnings():  # the merged-armature statement was made by the robot already
            warnings.simplefilter("ignore", UserWarning)
            shaped = robot.with_options(sigmoid_steepness=steepness.tolist(), sigmoid_shift=shift.tolist())
        refine = PhysicallyConsistentLS(prior_weight=self.prior_weight, plausible=self.plausible)
        fitted = refine.fit(replace(problem, robot=shaped))
        keep = (
            "min_eigenvalue",
            "divergence",
            "solver",
            "status",
            "solve_time_s",
            "uncertainty",
            "prior_weight",
            "plausibility",
        )
        return IdentifiedModel(robot, fitted), {k: fitted.details[k] for k in keep}


def _polish(
    data: Projection,
    theta: Tensor,
    lower: Tensor,
    upper: Tensor,
    steps: int,
    converged: float = CONVERGED,
    damping: float = 1e-3,
) -> Tensor:
    """Levenberg–Marquardt on the projected residual from ``theta``, kept in the box.

    Kaufman's Jacobian of ``r(θ) = P⊥(θ) τ``: ``J = −P⊥ ∂S/∂θ · φ1`` (``P⊥`` the projector off
    ``[W_fixed | S(θ)]``, ``φ1`` the amplitudes solved at ``θ``), through the small products of
    ``Projection.linearised``. Steps are scaled by the box widths; one that does not lower ``r``
    raises the damping instead (starting at ``damping``: small from a point that is already near
    the minimum); it stops when a step lowers ``‖r‖²`` by less than the fraction ``converged``, or
    when the linear model predicts that the next one will (that step is taken without evaluating it).
    """
    width = upper - lower
    normal, gradient, current = data.linearised(theta)
    for _ in range(steps):
        scaled = normal * width[:, None] * width  # 2n columns: small and well scaled
        scaled = scaled + damping * torch.diag(scaled.diagonal().clamp_min(torch.finfo(theta.dtype).tiny))
        step = torch.linalg.solve(scaled, gradient * width) * width
        if not bool((step.abs() > STEP_TOLERANCE * width).any()):
            break  # at an exact fit ‖r‖² is round-off, and steps this small would be tried until
            # the damping ran out
        candidate = torch.minimum(torch.maximum(theta - step, lower), upper)
        if float(2 * step @ gradient - step @ normal @ step) <= converged * float(current):
            return candidate  # the linear model's decrease ‖r‖² − ‖r − J·step‖² is below the
            # tolerance: a step this small is where the model is exact; evaluating it would only
            # confirm that the descent is over
        candidate_normal, candidate_gradient, value = data.linearised(candidate)
        if value < current:
            done = current - value <= converged * current
            theta, normal, gradient, current = candidate, candidate_normal, candidate_gradient, value
            damping = max(damping / 10, 1e-12)
            if done:
                break
        else:
            damping *= 10
            if damping > 1e8:
                break
    return theta


@dataclass(frozen=True)
class Solved:
    """The least-squares linear parameters at one shape, from a QR of ``W = [W_fixed | S(θ)]``
    assembled from ``W_fixed``'s (``Q₀ R₀``, factored once) and an ``n``-column QR of ``S``'s part
    off it — no factorisation of the whole ``W``.

    Attributes:
        w: ``W`` ``[n·N, L + n]`` (rows joint-major, as ``Projection``).
        alpha: its least-squares solution ``[L + n]`` (``fixed`` then ``scaled`` columns).
    """

    w: Tensor
    alpha: Tensor


def _solve(data: Projection, theta: Tensor) -> Solved:
    """``Solved`` at shape ``theta[2n]``. The solution is taken through the SVD of the equilibrated
    ``R`` with singular values below ``max(M, B) · eps · σ_max`` dropped (the rank rule of the
    uncertainty report), so a shape that leaves a combination undetermined gives the minimum-norm
    answer there instead of an overflow."""
    n, samples, width = data.q0.shape
    q0 = data.q0.reshape(-1, width)
    columns = data.columns(theta)  # [n, N]
    g = (data.q0.mT @ columns[..., None])[..., 0].T  # Q₀ᵀS [L, n], per joint
    s = columns.new_zeros(n, samples, n)
    s.diagonal(dim1=0, dim2=2).copy_(columns.T)
    s = s.reshape(-1, n)  # S [n·N, n]: joint j's column on its rows
    s_perp = s - q0 @ g
    again = q0.T @ s_perp  # re-orthogonalised once: S may lie close to span(W_fixed)
    s_perp, g = s_perp - q0 @ again, g + again
    qs, rs = torch.linalg.qr(s_perp)
    r = torch.cat([torch.cat([data.r0, g], 1), torch.cat([g.new_zeros((n, width)), rs], 1)])
    tau = data.tau.reshape(-1)
    rhs = torch.cat([data.q0_tau, qs.T @ tau])
    scale = torch.linalg.vector_norm(r, dim=0)  # the column norms of W (Q has orthonormal columns)
    scale = torch.where(scale > 0, scale, torch.ones_like(scale))
    u, sigma, vh = torch.linalg.svd(r / scale, full_matrices=False)
    tol = max(tau.shape[0], len(scale)) * torch.finfo(sigma.dtype).eps * sigma[:1]
    kept = sigma > tol
    inverse = torch.where(kept, 1 / sigma, torch.zeros_like(sigma))
    alpha = (vh.T @ (inverse * (u.T @ rhs))) / scale
    return Solved(torch.cat([data.w_fixed.reshape(-1, width), s], 1), alpha)


def _uncertainty(
    robot: Robot, data: Projection, solved: Solved, theta: Tensor, free: list[int], shape_names: list[str]
) -> dict[str, Any]:
    """``{"uncertainty": …}`` of the linear parameters and of the shapes ``theta[free]`` (those not at a
    bound): the sandwich of :mod:`idkit.estimators.linear.uncertainty` on the model linearised at
    ``θ``, ``τ ≈ W α + D (θ' − θ)`` with ``D = ∂(S φ1)/∂θ``, so that the shapes' scatter widens the
    linear parameters' (at a fixed shape their std would be optimistic). A shape at a bound is held
    there (the box set it, and the fit says so)."""
    n, samples = data.qd.shape
    amplitude = solved.alpha[len(data.fixed) :]  # φ1, joint order
    _, steepness, shift = data.shape_derivatives(theta)
    d = theta.new_zeros(n, samples, 2 * n)
    d[..., :n].diagonal(dim1=0, dim2=2).copy_((steepness * amplitude[:, None]).T)
    d[..., n:].diagonal(dim1=0, dim2=2).copy_((shift * amplitude[:, None]).T)
    d = d.reshape(-1, 2 * n)[:, free]
    jacobian = torch.cat([solved.w, d], 1)
    target = data.tau.reshape(-1) + d @ theta[free]  # J [α; θ] = τ + D θ: the residual stays τ − Wα
    # rows sample-major: a sample's joints share a score
    jacobian = jacobian.reshape(n, samples, -1).transpose(0, 1).reshape(jacobian.shape)
    target = target.reshape(n, samples).T.reshape(-1)
    names = [robot.base_param_names[k] for k in data.fixed + data.scaled] + [shape_names[k] for k in free]
    estimate = torch.cat([solved.alpha, theta[free]])
    uncertainty = base_uncertainties(
        jacobian[None], target[None], estimate[None], names, structural=robot.unidentifiable, joints=n
    )
    values = dict(zip(names, estimate.tolist(), strict=True))
    return _shapes_without_amplitude(uncertainty[0].to_details(), values, robot.joint_names)


def _shapes_without_amplitude(
    details: dict[str, Any], values: dict[str, float], joints: Sequence[str]
) -> dict[str, Any]:
    """A joint whose sigmoid amplitude ``φ1`` is within two standard deviations of 0 has no friction
    step the data can see, so its shape (``φ2``, ``φ3``) is not identified whatever the linearised
    std says: its std becomes infinite and the combination is named as unidentifiable."""
    found = details["uncertainty"]
    std = found["std"]
    for joint in joints:
        amplitude, spread = values.get(f"{joint}.phi1"), std.get(f"{joint}.phi1")
        if amplitude is None or spread is None or not abs(amplitude) < 2 * spread:
            continue
        for key in ("phi2", "phi3"):
            name = f"{joint}.{key}"
            if name in std:
                std[name] = math.inf
                found.get("std_rel_pct", {})[name] = math.inf
        found.setdefault("unidentifiable", []).append(
            f"{joint}.phi2, {joint}.phi3 (the friction step {joint}.phi1 is within 2 std of 0)"
        )
    return details


def _standard(robot: Robot, data: Projection, theta: Tensor, solution: Tensor) -> Tensor:
    """Standard parameters ``[P]`` of the linear parameters ``solution`` (``fixed`` then ``scaled``
    columns) and the shape ``theta``."""
    alpha = torch.empty(len(robot.base_param_names), dtype=solution.dtype, device=solution.device)
    alpha[data.fixed + data.scaled] = solution
    params = robot.params_from_base(alpha).clone()
    shapes = [robot.param_names.index(f"{j}.{key}") for key in ("phi2", "phi3") for j in robot.joint_names]
    params[shapes] = theta
    return params
