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

import time
import warnings
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import numpy as np
import torch
from torch import Tensor

from idkit.estimate import Estimate, to_python
from idkit.estimators.linear.observation import IdentificationError
from idkit.estimators.linear.uncertainty import base_uncertainty
from idkit.interfaces import Estimator, Robot
from idkit.optim import swarm
from idkit.problem import Problem
from idkit.robots.drives import sigmoid_friction
from idkit.runtime import resolve_threads, torch_threads

#: Relative ridge on ``A`` (scale of its trace): a shape whose sigmoid is nearly linear in ``q̇``
#: (collinear with viscous friction) gets a finite, slightly pessimistic cost instead of round-off.
RIDGE = 1e-12
#: The polish stops when a step lowers the residual sum of squares by less than this fraction.
CONVERGED = 1e-10


@dataclass(frozen=True)
class Projection:
    """The data of the projected problem, built once per fit.

    Attributes:
        fixed: base-parameter columns that do not depend on ``θ`` ``[L]`` (indices into the base).
        scaled: base-parameter columns of ``φ1`` ``[n]`` (one per joint, in joint order).
        w_fixed: ``W_fixed`` ``[N·n, L]`` (rows sample-major).
        q0: ``Q₀`` of ``W_fixed = Q₀ R₀`` as ``[N, n, L]`` (rows by sample and joint).
        tau: measured torques ``[N, n]``; ``tau_perp`` the part orthogonal to ``W_fixed`` ``[N, n]``.
        qd: joint velocities ``[N, n]``.
    """

    fixed: list[int]
    scaled: list[int]
    w_fixed: Tensor
    q0: Tensor
    tau: Tensor
    tau_perp: Tensor
    qd: Tensor

    def split(self, theta: Tensor) -> tuple[Tensor, Tensor]:
        """``(φ2, φ3)`` each ``[..., 1, n]`` of shapes ``theta[..., 2n]`` (all ``φ2``, then all ``φ3``)."""
        n = self.qd.shape[1]
        return theta[..., None, :n], theta[..., None, n:]

    def columns(self, theta: Tensor) -> Tensor:
        """``S(θ)`` as ``[..., N, n]``: joint ``j``'s sigmoid on its own rows."""
        steepness, shift = self.split(theta)
        return sigmoid_friction(self.qd, steepness, shift)

    def matrix(self, theta: Tensor) -> Tensor:
        """``[W_fixed | S(θ)]`` ``[N·n, L + n]`` of one shape ``theta[2n]`` (regressor rows sample-major)."""
        n = self.qd.shape[1]
        return torch.cat([self.w_fixed, torch.diag_embed(self.columns(theta)).reshape(-1, n)], dim=1)

    def jacobian(self, theta: Tensor) -> tuple[Tensor, Tensor]:
        """Kaufman's Jacobian ``[N·n, 2n]`` of the projected residual and the residual ``[N·n]`` at one
        shape ``theta[2n]`` (columns: every ``φ2``, then every ``φ3``)."""
        n = self.qd.shape[1]
        q0 = self.q0.reshape(-1, self.q0.shape[-1])
        steepness, shift = self.split(theta)
        inner = steepness * (self.qd + shift)
        slope, rest = _sigmoid_slope(inner), _sigmoid_slope(steepness * shift)
        s = torch.sigmoid(inner) - torch.sigmoid(steepness * shift)  # [N, n]
        s_block = torch.diag_embed(s).reshape(-1, n)
        s_perp = s_block - q0 @ (q0.T @ s_block)
        qs, rs = torch.linalg.qr(s_perp)
        tau_perp = self.tau_perp.reshape(-1)
        amplitude = torch.linalg.solve_triangular(rs, (qs.T @ tau_perp)[:, None], upper=True)[:, 0]
        residual = tau_perp - qs @ (qs.T @ tau_perp)
        d_steepness = (slope * (self.qd + shift) - rest * shift) * amplitude
        d_shift = (slope - rest) * steepness * amplitude
        d = torch.cat([torch.diag_embed(d_steepness), torch.diag_embed(d_shift)], -1).reshape(-1, 2 * n)
        d = d - q0 @ (q0.T @ d)
        return -(d - qs @ (qs.T @ d)), residual

    def residual(self, theta: Tensor) -> Tensor:
        """``r(θ)`` ``[...]`` for shapes ``theta[..., 2n]`` (module doc), ``≥ 0``."""
        s = self.columns(theta)  # [..., N, n]
        g = torch.einsum("inl,...in->...ln", self.q0, s)  # [..., L, n]
        a = torch.diag_embed(s.square().sum(-2)) - g.mT @ g  # [..., n, n]
        b = (s * self.tau_perp).sum(-2)  # [..., n]
        ridge = RIDGE * a.diagonal(dim1=-2, dim2=-1).sum(-1).clamp_min(torch.finfo(a.dtype).tiny)
        a = a + ridge[..., None, None] * torch.eye(a.shape[-1], dtype=a.dtype, device=a.device)
        gain = (b * torch.linalg.solve(a, b[..., None])[..., 0]).sum(-1)
        return (self.tau_perp.square().sum() - gain).clamp_min(0.0)


def _sigmoid_slope(x: Tensor) -> Tensor:
    """``σ'(x) = σ(x) (1 − σ(x))``."""
    sigma = torch.sigmoid(x)
    return sigma * (1 - sigma)


def projection(robot: Any, q: Tensor, qd: Tensor, qdd: Tensor, tau: Tensor) -> Projection:
    """The projected problem of ``robot`` (a ``urdf`` robot with ``friction="sigmoid"``) on samples."""
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
    regressor = robot.regressor(q, qd, qdd)  # [N, n, B]
    w_fixed = regressor[..., fixed].reshape(-1, len(fixed))
    q0 = torch.linalg.qr(w_fixed).Q
    tau_perp = tau.reshape(-1) - q0 @ (q0.T @ tau.reshape(-1))
    n = robot.n_joints
    return Projection(fixed, scaled, w_fixed, q0.reshape(-1, n, len(fixed)), tau, tau_perp.reshape(-1, n), qd)


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
        prior_weight: ``pcls``'s prior weight when ``refine="pcls"``.
        threads: torch intra-op threads; ``None`` = ``idkit.runtime``'s size rule.

    ``details``: ``shape`` (``φ2``, ``φ3`` per joint), ``criterion_value`` (‖τ − Wα‖), ``history``
    (the swarm's best residual per iteration), ``evaluations``, ``rel_error_train``,
    ``search_time_s`` and the base-parameter ``uncertainty`` at the final shape (the shapes taken as
    known, so it is optimistic).
    """

    #: The conformance suite's problem: a robot with sigmoid friction (the cylindrical one from its URDF).
    conformance_robot: ClassVar[tuple[str, dict[str, Any]]] = (
        "urdf",
        {"urdf": "cylindrical", "friction": "sigmoid"},
    )
    conformance_options: ClassVar[dict[str, Any]] = {"particles": 8, "iterations": 5, "polish": 2}

    def __init__(
        self,
        particles: int = 32,
        iterations: int = 30,
        polish: int = 50,
        search_samples: int = 500,
        refine: Literal["none", "pcls"] = "none",
        prior_weight: float = 0.0,
        threads: int | None = None,
    ) -> None:
        self.particles = particles
        self.iterations = iterations
        self.polish = polish
        self.search_samples = search_samples
        self.refine = refine
        self.prior_weight = prior_weight
        self.threads = threads

    @property
    def name(self) -> str:
        return "VarPro" + ("-pcls" if self.refine == "pcls" else "")

    def fit(self, problem: Problem) -> Estimate:
        start = time.perf_counter()
        problem.check_identifiable()
        robot = problem.robot
        if getattr(robot, "friction", None) != "sigmoid":
            raise IdentificationError(
                f"varpro: robot {type(robot).__name__} has no nonlinear friction shapes; use a 'urdf' robot "
                "with friction=sigmoid (a model linear in its parameters needs estimator=ls)"
            )
        if self.particles < 1 or self.iterations < 1 or self.polish < 0 or self.search_samples < 1:
            raise ValueError(
                f"varpro: need particles >= 1, iterations >= 1, polish >= 0 and search_samples >= 1, got "
                f"{self.particles}, {self.iterations}, {self.polish}, {self.search_samples}"
            )
        s = problem.tensors()
        n = robot.n_joints
        searched = min(s.tau.shape[0], self.search_samples) * n  # the swarm's error-tensor size per particle
        threads = resolve_threads(self.threads, self.particles * searched)
        with torch_threads(threads), torch.no_grad():
            data = projection(robot, s.q, s.qd, s.qdd, s.tau)
            stride = -(-s.q.shape[0] // self.search_samples)  # the swarm's every stride-th sample
            coarse = (
                data if stride == 1 else projection(robot, *(x[::stride] for x in (s.q, s.qd, s.qdd, s.tau)))
            )
            lower, upper = robot.bounds()
            box = [
                robot.param_names.index(f"{j}.{key}") for key in ("phi2", "phi3") for j in robot.joint_names
            ]
            lower, upper = lower[box].to(s.tau), upper[box].to(s.tau)
            draws = swarm.Draws([swarm.Uniform(problem.generator(), s.tau)])
            state, history = swarm.run(
                coarse.residual, lower, upper, (), self.particles, self.iterations, swarm.SwarmRules(), draws
            )
            theta = _polish(data, state.global_position, lower, upper, self.polish)
        search_time = time.perf_counter() - start
        steepness, shift = theta[:n], theta[n:]
        with torch_threads(threads):
            if self.refine == "pcls":
                params, details = self._pcls(robot, problem, steepness, shift)
            else:
                params, details = _least_squares(robot, data, theta)
            alpha = robot.base_params(params)
            predicted = robot.inverse_dynamics(params, s.q, s.qd, s.qdd)
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
            "search_stride": stride,
            "evaluations": self.particles * self.iterations,
            "search_time_s": search_time,
            "threads": threads,
            **details,
        }
        if "uncertainty" not in details:
            order = data.fixed + data.scaled
            names = [robot.base_param_names[k] for k in order]
            w = data.matrix(theta).double()
            details.update(
                base_uncertainty(
                    w, s.tau.reshape(-1).double(), alpha[order].double(), names, robot.unidentifiable
                ).to_details()
            )
        return Estimate(
            estimator=self.name,
            params=dict(zip(robot.param_names, params.tolist(), strict=True)),
            cost=cost,
            wall_time_s=time.perf_counter() - start,
            base_params=dict(zip(robot.base_param_names, alpha.tolist(), strict=True)),
            details=to_python(details),
        )

    def _pcls(
        self, robot: Robot, problem: Problem, steepness: Tensor, shift: Tensor
    ) -> tuple[Tensor, dict[str, Any]]:
        """pcls on the robot whose reference sigmoid shape is the one found."""
        from dataclasses import replace

        from idkit.estimators.physical import PhysicallyConsistentLS

        with warnings.catch_warnings():  # the merged-armature statement was made by the robot already
            warnings.simplefilter("ignore", UserWarning)
            shaped = robot.with_options(sigmoid_steepness=steepness.tolist(), sigmoid_shift=shift.tolist())
        fitted = PhysicallyConsistentLS(prior_weight=self.prior_weight).fit(replace(problem, robot=shaped))
        params = torch.tensor([fitted.params[name] for name in robot.param_names], dtype=torch.float64)
        keep = ("min_eigenvalue", "divergence", "solver", "status", "solve_time_s", "uncertainty")
        return params.to(problem.tensors().tau), {k: fitted.details[k] for k in keep}


def _polish(data: Projection, theta: Tensor, lower: Tensor, upper: Tensor, steps: int) -> Tensor:
    """Levenberg–Marquardt on the projected residual from ``theta``, kept in the box.

    Kaufman's Jacobian of ``r(θ) = P⊥(θ) τ``: ``J = −P⊥ ∂S/∂θ · φ1`` (``P⊥`` the projector off
    ``[W_fixed | S(θ)]``, ``φ1`` the amplitudes solved at ``θ``); ``∂S_j/∂θ_j`` lives on joint ``j``'s
    rows, so a step costs products with ``Q₀`` and a QR of ``n`` columns, never of the whole ``W``.
    Steps are scaled by the box widths; one that does not lower ``r`` raises the damping instead.
    """
    width = upper - lower
    damping = 1e-3
    jacobian, r = data.jacobian(theta)
    current = r @ r
    for _ in range(steps):
        scaled = jacobian * width  # 2n columns: the normal equations are small and well scaled
        normal = scaled.T @ scaled
        normal = normal + damping * torch.diag(normal.diagonal().clamp_min(torch.finfo(r.dtype).tiny))
        step = torch.linalg.solve(normal, scaled.T @ r) * width
        candidate = torch.minimum(torch.maximum(theta - step, lower), upper)
        candidate_jacobian, candidate_r = data.jacobian(candidate)
        value = candidate_r @ candidate_r
        if value < current:
            converged = current - value <= CONVERGED * current
            theta, jacobian, r, current = candidate, candidate_jacobian, candidate_r, value
            damping = max(damping / 10, 1e-12)
            if converged:
                break
        else:
            damping *= 10
            if damping > 1e8:
                break
    return theta


def _least_squares(robot: Robot, data: Projection, theta: Tensor) -> tuple[Tensor, dict[str, Any]]:
    """Standard parameters ``[P]`` of the least-squares linear parameters at shape ``theta``."""
    w = data.matrix(theta)
    driver = "gelsd" if w.device.type == "cpu" else None  # the CPU default (gelsy) varies in round-off
    solution = torch.linalg.lstsq(w, data.tau.reshape(-1, 1), driver=driver).solution[:, 0]
    alpha = torch.empty(len(robot.base_param_names), dtype=w.dtype, device=w.device)
    alpha[data.fixed + data.scaled] = solution
    params = robot.params_from_base(alpha).clone()
    shapes = [robot.param_names.index(f"{j}.{key}") for key in ("phi2", "phi3") for j in robot.joint_names]
    params[shapes] = theta
    return params, {}
