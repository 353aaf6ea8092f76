"""How well a motion excites a robot's base parameters, for a whole batch of motions at once.

``W[..., N·n, B]`` stacks the robot's base regressor over the ``N`` sample times (sample-major,
as the least-squares family builds it, eq. 8). Two classic measures of ``W``:

* ``"cond"`` — the condition number of ``W`` with unit-norm columns (Gautier & Khalil 1992):
  the column scaling makes it independent of the base parameters' units, and it bounds how much a
  relative error in the torques can grow in the estimate. Smaller is better, 1 is ideal.
* ``"logdet"`` — D-optimality, ``log det(Wᵀ W)`` of the unscaled ``W``: the log volume of the
  information matrix (inverse of the confidence ellipsoid's volume under white torque noise).
  Larger is better; it depends on units and grows with the amplitude and the number of samples.

Both see torque errors only. Errors in the measured states enter ``W`` itself (errors in
variables), and a motion that is well conditioned can amplify them (docs/excitation.md measured it).
A third criterion models both:

* ``"ls_error"`` — the expected parameter error of least squares under the scenarios' noise model
  (:class:`NoiseModel`): ``K`` draws of multiplicative uniform errors on ``q, qd, qdd`` and on the
  true torques ``W α`` (``α`` the robot's nominal base parameters), an LS fit per draw, and the mean
  over the draws of the mean ``|α̂_i - α_i| / |α_i|`` (the robustness study's parameter error, on
  base parameters, over those with ``α_i != 0``). The draws are fixed once (common random numbers,
  from the model's seed), so the criterion is a deterministic, smooth function of the motion that
  an optimiser can compare candidates on and differentiate. Smaller is better.

:func:`make_criterion` builds one as a :class:`Criterion`: ``value`` is the number reported (the
cond and logdet through an SVD of ``W``), ``loss`` the number an optimiser minimises (the same
quantity: for cond and logdet through the ``B × B`` Gram matrix, several times cheaper than the
SVD of a tall ``W`` and agreeing with it to rounding for any ``W`` worth keeping, ``cond < 1e6``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import torch
from torch import Tensor

from idkit.interfaces import Robot
from idkit.seeds import check_seed, torch_generator

CRITERIA = ("cond", "logdet", "ls_error")

#: Which way each criterion improves.
BETTER: dict[str, Literal["smaller", "larger"]] = {
    "cond": "smaller",
    "logdet": "larger",
    "ls_error": "smaller",
}


def check_criterion(criterion: str) -> str:
    """``criterion`` if it is one of ``CRITERIA``, else a ``ValueError`` listing them."""
    if criterion not in CRITERIA:
        raise ValueError(f"unknown excitation criterion {criterion!r}; use one of {', '.join(CRITERIA)}")
    return criterion


def observation_matrix(robot: Robot, q: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
    """Base regressor stacked over samples, ``W[..., N·n, B]``, for states ``[..., N, n]``.

    A regressor row depends on its own sample only, so a batch of trajectories is one call on
    ``[... · N, n]`` states.
    """
    if not robot.has_regressor:
        raise ValueError(f"robot {type(robot).__name__} has no base regressor; excitation design needs one")
    n_samples, n_joints = q.shape[-2:]
    batch = q.shape[:-2]
    y = robot.regressor(q.reshape(-1, n_joints), qd.reshape(-1, n_joints), qdd.reshape(-1, n_joints))
    return y.reshape(*batch, n_samples * n_joints, y.shape[-1])


def _unit_columns(w: Tensor) -> Tensor:
    """``w[..., M, B]`` with every nonzero column scaled to unit norm (a zero column stays zero)."""
    norm = torch.linalg.vector_norm(w, dim=-2, keepdim=True)
    return w / torch.where(norm > 0, norm, torch.ones_like(norm))


def scaled_condition_number(w: Tensor) -> Tensor:
    """Condition number ``[...]`` of ``w[..., M, B]`` after scaling its columns to unit norm.

    A zero column (an unexcited parameter) gives ``inf``.
    """
    sigma = torch.linalg.svdvals(_unit_columns(w))
    return sigma[..., 0] / sigma[..., -1]


def log_det_information(w: Tensor) -> Tensor:
    """``log det(wᵀ w)`` ``[...]`` of ``w[..., M, B]`` as ``2 Σ log σ`` (no squaring of ``w``'s condition)."""
    return 2.0 * torch.log(torch.linalg.svdvals(w)).sum(-1)


def _finite_gram(w: Tensor) -> tuple[Tensor, Tensor]:
    """``(wᵀ w [..., B, B], finite [...])``; a non-finite Gram matrix is replaced by the identity so
    that no decomposition sees NaN (LAPACK refuses it), and ``finite`` says which were."""
    gram = w.mT @ w
    finite = gram.isfinite().all(-1).all(-1)
    eye = torch.eye(gram.shape[-1], dtype=gram.dtype, device=gram.device)
    return torch.where(finite[..., None, None], gram, eye), finite


def gram_condition_number(w: Tensor) -> Tensor:
    """``scaled_condition_number(w)`` ``[...]`` from the eigenvalues of the column-scaled ``wᵀ w``.

    ``sqrt(λ_max / λ_min)`` of a ``B × B`` matrix instead of an SVD of ``M × B``: the search's
    version (several times cheaper for the tall ``W`` of a real arm). Squaring loses accuracy only
    when ``cond`` nears ``1/sqrt(eps)`` (``1e8``); a non-positive ``λ_min`` or a non-finite ``w``
    gives ``inf``.
    """
    gram, finite = _finite_gram(w)
    diagonal = gram.diagonal(dim1=-2, dim2=-1)
    scale = torch.where(diagonal > 0, diagonal, torch.ones_like(diagonal)).rsqrt()
    eigenvalues = torch.linalg.eigvalsh(gram * scale[..., :, None] * scale[..., None, :])
    smallest = eigenvalues[..., 0]
    unexcited = (diagonal <= 0).any(-1) | (smallest <= 0) | ~finite
    ratio = eigenvalues[..., -1] / torch.where(unexcited, torch.ones_like(smallest), smallest)
    return torch.where(unexcited, torch.full_like(ratio, math.inf), ratio.sqrt())


def gram_log_det(w: Tensor) -> Tensor:
    """``log_det_information(w)`` ``[...]`` from a Cholesky factor of ``wᵀ w`` (``-inf`` if singular
    or non-finite)."""
    gram, finite = _finite_gram(w)
    factor, info = torch.linalg.cholesky_ex(gram)
    value = 2.0 * torch.log(factor.diagonal(dim1=-2, dim2=-1)).sum(-1)
    return torch.where((info == 0) & finite, value, torch.full_like(value, -math.inf))


@dataclass(frozen=True)
class NoiseModel:
    """The measurement errors ``ls_error`` expects: the scenarios' model (``idkit.data.scenarios``).

    Attributes:
        state: level ``X`` of the multiplicative error ``U(-X, X)`` on ``q``, ``qd``, ``qdd``.
        torque: level of the multiplicative error on the torques.
        draws: number ``K`` of noise draws the expectation is estimated from.
        seed: seed of the draws (fixed for a whole optimisation: common random numbers).
    """

    state: float = 0.2
    torque: float = 0.2
    draws: int = 32
    seed: int = 0

    def __post_init__(self) -> None:
        for key in ("state", "torque"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value < 1:
                raise ValueError(f"excitation noise: {key} must be a level in [0, 1), got {value!r}")
        if isinstance(self.draws, bool) or not isinstance(self.draws, int) or self.draws < 1:
            raise ValueError(f"excitation noise: draws must be an integer >= 1, got {self.draws!r}")
        check_seed(self.seed, "excitation noise: seed")

    def errors(self, n_samples: int, n_joints: int) -> Tensor:
        """The drawn relative errors ``u[K, 4, N, n]`` (rows ``q, qd, qdd, tau``), float64 CPU."""
        generator = torch_generator(self.seed)
        unit = (
            2.0 * torch.rand(self.draws, 4, n_samples, n_joints, generator=generator, dtype=torch.float64) - 1
        )
        level = torch.tensor([self.state] * 3 + [self.torque], dtype=torch.float64)
        return unit * level[:, None, None]


#: Sampled states ``(q, qd, qdd)``, each ``[..., N, n]``.
States = tuple[Tensor, Tensor, Tensor]


class Criterion:
    """One criterion of a batch of sampled motions: ``value`` as reported, ``loss`` to minimise.

    Both take the clean regressor ``w[..., N·n, B]`` of the states ``(q, qd, qdd)`` (each
    ``[..., N, n]``; ``cond`` and ``logdet`` need ``w`` only) and return ``[...]``.
    """

    #: Regressor evaluations per sampled state (``ls_error``: the clean one and one per noise draw).
    states_per_sample = 1

    def __init__(self, name: str) -> None:
        self.name = check_criterion(name)
        self.better = BETTER[name]

    def value(self, w: Tensor, states: States | None = None) -> Tensor:
        if self.name == "cond":
            return scaled_condition_number(w)
        return log_det_information(w)

    def loss(self, w: Tensor, states: States | None = None) -> Tensor:
        if self.name == "cond":
            return gram_condition_number(w)
        return -gram_log_det(w)


class LSErrorCriterion(Criterion):
    """``ls_error`` (module docstring) for ``robot`` sampled at ``N`` times.

    Args:
        robot: a robot with a base regressor and nominal parameters (the truth of the simulation).
        noise: the errors to expect.
        n_samples: ``N``, the number of sample times (the draws are ``[K, 4, N, n]``).
    """

    def __init__(self, robot: Robot, noise: NoiseModel, n_samples: int) -> None:
        super().__init__("ls_error")
        nominal = robot.nominal_params()
        if nominal is None:
            raise ValueError(
                f"excitation criterion ls_error needs the robot's nominal parameters; {type(robot).__name__} "
                "has none"
            )
        self.robot = robot
        self.noise = noise
        self.truth = robot.base_params(torch.as_tensor(nominal, dtype=torch.float64))  # [B]
        self.errors = noise.errors(n_samples, robot.n_joints)  # [K, 4, N, n]
        self.states_per_sample = 1 + noise.draws

    def value(self, w: Tensor, states: States | None = None) -> Tensor:
        return self.loss(w, states)

    def loss(self, w: Tensor, states: States | None = None) -> Tensor:
        if states is None:
            raise ValueError("excitation criterion ls_error needs the sampled states, not only W")
        u = self.errors.to(w)
        stacked = torch.stack(states, -3)[..., None, :, :, :]  # [..., 1, 3, N, n]
        noisy_q, noisy_qd, noisy_qdd = (stacked * (1.0 + u[:, :3])).unbind(-3)  # each [..., K, N, n]
        noisy_w = observation_matrix(self.robot, noisy_q, noisy_qd, noisy_qdd)  # [..., K, N·n, B]
        truth = self.truth.to(w)
        tau = (w @ truth)[..., None, :] * (1.0 + u[:, 3].flatten(-2))  # [..., K, N·n]
        estimate = least_squares(noisy_w, tau)  # [..., K, B]
        known = truth != 0
        relative = (estimate[..., known] - truth[known]).abs() / truth[known].abs()
        return relative.mean(-1).mean(-1)


def least_squares(w: Tensor, tau: Tensor) -> Tensor:
    """``argmin ‖w α - tau‖`` ``[..., B]`` for ``w[..., M, B]``, ``tau[..., M]``, differentiable.

    Householder QR of the column-scaled ``w`` (the LS estimator's equilibration; no normal
    equations): ``α = D⁻¹ R⁻¹ Qᵀ tau``. A rank-deficient ``w`` gives non-finite entries.
    """
    norm = torch.linalg.vector_norm(w, dim=-2)
    scale = torch.where(norm > 0, norm, torch.ones_like(norm))
    q, r = torch.linalg.qr(w / scale[..., None, :])
    solution = torch.linalg.solve_triangular(r, (q.mT @ tau[..., None]), upper=True)[..., 0]
    return solution / scale


def make_criterion(
    criterion: str, robot: Robot, n_samples: int, noise: NoiseModel | None = None
) -> Criterion:
    """The criterion ``criterion`` for ``robot`` at ``n_samples`` sample times (``noise``: ``ls_error``'s
    noise model, default :class:`NoiseModel`)."""
    if check_criterion(criterion) == "ls_error":
        return LSErrorCriterion(robot, noise or NoiseModel(), n_samples)
    return Criterion(criterion)


def criterion_value(criterion: str, w: Tensor) -> Tensor:
    """The value ``[...]`` of ``cond`` or ``logdet`` for ``w[..., M, B]``, as reported."""
    return Criterion(criterion).value(w)


def excitation_criterion(
    robot: Robot, criterion: str, q: Tensor, qd: Tensor, qdd: Tensor, noise: NoiseModel | None = None
) -> Tensor:
    """``criterion`` ``[...]`` of sampled states ``[..., N, n]`` (e.g. a recording) on ``robot``."""
    chosen = make_criterion(criterion, robot, q.shape[-2], noise)
    return chosen.value(observation_matrix(robot, q, qd, qdd), (q, qd, qdd))
