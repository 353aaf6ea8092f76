"""Iteratively reweighted least squares (IRLS) on the robot's regressor: robust M-estimation.

The standard robust-regression baseline in robot identification. Stack the regressor into
``W[N n, B]`` and the torques into ``t[N n]`` (divided row by row by the measured torques for the
relative variant, the paper's eqs. 36-37), start from least squares and repeat:

1. residuals ``r = t - W alpha``; robust scale ``s = median(|r|) / 0.6745`` (the MAD about 0,
   consistent for Gaussian noise);
2. weights ``w_i = psi(r_i / s) / (r_i / s)``:
   Huber ``min(1, c / |u|)``, Tukey's bisquare ``(1 - (u / c)²)²`` for ``|u| < c``, else 0;
3. ``alpha = argmin sum w_i (t_i - W_i alpha)²`` (a least-squares solve, not an inverse);

until ``||alpha_new - alpha|| <= tol ||alpha||``. The fixed point solves the M-estimation
equations ``sum psi(r_i / s) W_i = 0``. The default tuning constants (Huber 1.345, Tukey 4.685)
give 95 % efficiency under Gaussian noise. Tukey's weights redescend to zero, so its iteration
has several fixed points; it starts from the converged Huber fit, as is customary.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable

import torch
from idkit.estimate import Estimate, jsonable
from idkit.estimators.observation import linear_system
from idkit.interfaces import Estimator
from idkit.problem import Problem
from idkit.relative import DEFAULT_FLOOR
from idkit.runtime import resolve_threads, torch_threads
from torch import Tensor

#: ``Phi^{-1}(3/4)``: the MAD of a standard normal variable.
MAD_TO_SIGMA = 0.6744897501960817
TUNING = {"huber": 1.345, "tukey": 4.685}


def huber_weights(u: Tensor, c: float) -> Tensor:
    """``psi(u) / u`` of Huber's loss: 1 inside ``±c``, ``c / |u|`` outside."""
    return torch.clamp(c / u.abs(), max=1.0)


def tukey_weights(u: Tensor, c: float) -> Tensor:
    """``psi(u) / u`` of Tukey's bisquare: ``(1 - (u / c)²)²`` inside ``±c``, 0 outside."""
    return torch.where(u.abs() < c, (1 - (u / c).square()).square(), torch.zeros_like(u))


WEIGHTS: dict[str, Callable[[Tensor, float], Tensor]] = {"huber": huber_weights, "tukey": tukey_weights}


def mad_scale(r: Tensor) -> Tensor:
    """Robust scale ``median(|r|) / 0.6745`` of residuals ``r[M]`` (the median of an even count
    averages the two middle values, as numpy's does)."""
    v = r.abs().sort().values
    m = v.shape[0]
    return (v[(m - 1) // 2] + v[m // 2]) / (2 * MAD_TO_SIGMA)


def _solve(w: Tensor, t: Tensor) -> Tensor:
    """Least-squares ``alpha[B]`` of ``w[M, B] alpha = t[M]``.

    QR-based ``gels`` (the caller checks that ``w`` has full column rank): torch's CPU default,
    ``gelsy``, is not bitwise reproducible from call to call with MKL (differences of ~1e-15
    measured), which would break "same seed → same estimate"; ``gels`` is, and CUDA has it too.
    """
    return torch.linalg.lstsq(w, t[:, None], driver="gels").solution[:, 0]


class IRLS(Estimator):
    """Robust M-estimate of the base parameters by iteratively reweighted least squares.

    Needs a robot with a regressor; the physical parameters reported are
    ``robot.params_from_base(alpha)``.

    Args:
        weight: ``"huber"`` or ``"tukey"`` (bisquare; rejects gross outliers completely).
        tuning: the constant ``c`` in units of the robust scale; ``None`` = 1.345 (Huber) or
            4.685 (Tukey). Smaller is more robust and less efficient.
        max_iter: most reweighting steps per stage (the convergence is linear; with the MAD
            scale re-estimated every step a rate of ~0.8 per step is typical).
        tol: stop when the relative change of ``alpha`` is at most ``tol`` (at least 100 machine
            epsilons of the problem's dtype: IRLS converges linearly, round-off sets the floor).
        relative: fit the relative error (eq. 27 via eqs. 36-37) instead of the absolute one.
        floor: near-zero policy of the relative error (``idkit.relative``).
        threads: torch intra-op threads during the fit (restored afterwards); ``None`` keeps
            torch's setting. 1 by default: these are small solves, and on a busy 2-core machine
            two threads made a fit ~5x slower (measured, noisy).
    """

    def __init__(
        self,
        weight: str = "huber",
        tuning: float | None = None,
        max_iter: int = 200,
        tol: float = 1e-8,
        relative: bool = False,
        floor: float = DEFAULT_FLOOR,
        threads: int | None = 1,
    ) -> None:
        if weight not in WEIGHTS:
            raise ValueError(f"irls: weight must be one of {sorted(WEIGHTS)}, got {weight!r}")
        if tuning is not None and not tuning > 0:
            raise ValueError(f"irls: tuning must be > 0 (or None for the default), got {tuning}")
        if max_iter < 1 or not tol > 0:
            raise ValueError(f"irls: need max_iter >= 1 and tol > 0, got {max_iter}, {tol}")
        self.weight = weight
        self.tuning = tuning
        self.max_iter = max_iter
        self.tol = tol
        self.relative = relative
        self.floor = floor
        self.threads = threads

    @property
    def label(self) -> str:
        return f"IRLS-{self.weight.capitalize()}" + ("-rel" if self.relative else "")

    def _stage(self, w: Tensor, t: Tensor, alpha: Tensor, name: str, c: float) -> tuple[Tensor, dict]:
        """Reweight until converged; returns ``alpha`` and this stage's record."""
        weights_of = WEIGHTS[name]
        eps = torch.finfo(t.dtype).eps
        exact, tol = 64 * eps * t.abs().max(), max(self.tol, 100 * eps)
        for iteration in range(1, self.max_iter + 1):
            r = t - w @ alpha
            scale = mad_scale(r)
            if scale <= exact:  # (nearly) exact fit: nothing to reweight
                return alpha, {
                    "weight": name,
                    "iterations": iteration - 1,
                    "converged": True,
                    "exact_fit": True,
                }
            weights = weights_of(r / scale, c)
            if int((weights > 0).sum()) < w.shape[1]:
                raise ValueError(
                    f"irls: only {int((weights > 0).sum())} residuals keep a non-zero {name} weight, "
                    f"fewer than the {w.shape[1]} base parameters; increase tuning (now {c})"
                )
            root = weights.sqrt()
            new = _solve(w * root[:, None], t * root)
            change = torch.linalg.vector_norm(new - alpha)
            alpha = new
            if change <= tol * torch.linalg.vector_norm(alpha):
                return alpha, {"weight": name, "iterations": iteration, "converged": True, "exact_fit": False}
        warnings.warn(
            f"irls: {name} stage did not converge in {self.max_iter} iterations (tol {self.tol:g})",
            RuntimeWarning,
            stacklevel=3,
        )
        return alpha, {"weight": name, "iterations": self.max_iter, "converged": False, "exact_fit": False}

    def fit(self, problem: Problem) -> Estimate:
        """Estimate base and physical parameters; ``[N, n]`` samples become ``N n`` equations."""
        if self.threads is None:
            return self._fit(problem)
        with torch_threads(resolve_threads(self.threads, 0)):
            return self._fit(problem)

    def _fit(self, problem: Problem) -> Estimate:
        robot = problem.robot
        if not robot.has_regressor:
            raise ValueError(
                f"irls needs a robot with a linear regressor; {type(robot).__name__} has none "
                "(use a search-based estimator such as pso instead)"
            )
        start = time.perf_counter()
        s = problem.tensors()
        system = linear_system(problem, self.relative, self.floor)  # rows ordered (sample, joint)
        w, t = system.W, system.tau
        b = w.shape[-1]
        rank = int(torch.linalg.matrix_rank(w))
        if rank < b:
            raise ValueError(
                f"irls: the stacked regressor has rank {rank} < {b} base parameters: these "
                f"{s.n_samples} samples do not excite every base parameter"
            )
        c = self.tuning if self.tuning is not None else TUNING[self.weight]
        alpha = _solve(w, t)
        stages = []
        if self.weight == "tukey":  # the redescending stage starts from the Huber fit
            alpha, record = self._stage(w, t, alpha, "huber", TUNING["huber"])
            stages.append(record)
        alpha, record = self._stage(w, t, alpha, self.weight, c)
        stages.append(record)

        r = t - w @ alpha
        scale = mad_scale(r)
        weights = WEIGHTS[self.weight](r / scale, c) if scale > 0 else torch.ones_like(r)
        params = robot.params_from_base(alpha)
        criterion = float((r.square() * weights).sum())
        cost = float(problem.evaluate(params)) if problem.cost is not None else criterion
        return Estimate(
            estimator=self.label,
            params=dict(zip(robot.param_names, params.tolist(), strict=True)),
            cost=cost,
            wall_time_s=time.perf_counter() - start,
            base_params=dict(zip(robot.base_param_names, alpha.tolist(), strict=True)),
            details=jsonable(
                {
                    "criterion": "weighted sum of squared residuals at the final weights",
                    "criterion_value": criterion,
                    "weight": self.weight,
                    "tuning": c,
                    "relative": self.relative,
                    "scale": float(scale),
                    "stages": stages,
                    "weights": weights.reshape(s.n_samples, robot.n_joints),
                    "downweighted": int((weights < 1).sum()),
                    "rejected": int((weights == 0).sum()),
                    "equations": int(t.shape[0]),
                    "dtype": str(s.tau.dtype).removeprefix("torch."),
                    "device": str(s.tau.device),
                    "threads": torch.get_num_threads(),
                }
            ),
        )
