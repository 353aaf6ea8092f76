"""What a rollout fit knows and does not: standard deviations, 95 % intervals, flat directions, and
whether the noise or the model is what limits it.

**Why the textbook is not enough.** The polish's Jacobian ``J`` at the solution gives the textbook
covariance ``κ (JᵀJ)⁻¹`` (Huber's ``κ = mean ψ² / (mean ψ')²`` and ``M / (M − p)``; the fitted initial
states profiled out). It is right when the residual is white noise, and there it is kept (clean and
glitched logs: 35 of 36 intervals covered). When the model is wrong (links 10 % heavier than the
model), the estimate is *biased* towards what best absorbs the missing physics, and the residual is a
smooth misfit — far above the noise, or (the fitted start states and unknowns absorbing most of it)
hardly: 1.03–1.6× the noise on the pendulum below. The textbook intervals were ~400× too narrow on
the issue's case and covered no truth.

**What is done instead (when the fit is model-limited).** The segments are the natural clusters of a
rollout fit (each starts from its own state; the misfit is correlated within one). Contiguous groups of
segments (``GROUPS`` at most) are left out in turn, and the estimate each leave-one-out fit would give
is taken one Newton step from the solution on the polish's own Jacobian (no extra rollouts; exact for
a linear model): ``θ₋g = θ̂ + (A − A_g)⁻¹ s_g`` with ``A_g`` the group's (profiled) Hessian and ``s_g``
its score. The jackknife's pseudo-values ``θ̂ − (G − 1)(θ₋g − θ̂)`` are what each stretch of the log
alone says. Under noise alone their standard deviation is ``√G`` textbook σ; under a wrong model they
scatter by how much the answer depends on which motion the model is asked to explain — evidence of
the bias, which a standard error of a mean (the cluster sandwich, that spread over ``√G``) does not
measure and which does not shrink with a longer log. A wrong model's bias can also be the same in
every stretch for one unknown (an armature absorbing a heavier link's inertia everywhere) while the
others disagree: so the largest ratio of spread to textbook σ over the unknowns (``inflation``) is
applied to *every* unknown: the model error is one, measured where it shows. The intervals are then
``θ̂ ± 1.96 · inflation · σ_textbook`` in coordinates; never narrower than the textbook.

Measured on a 2-joint torque-driven pendulum whose log was made with links 10 % heavier or lighter
than the model (tests/sim/test_uncertainty_coverage.py, 50 draws, 200 intervals): 0.925 hold the
truth, 0.265 of the textbook's. On an exploratory 16 draws of it, the cluster sandwich held 0.50 and
each unknown's own spread 0.70 (the consistently biased armature never): hence the rule above. A
residual bootstrap was not chosen: it needs refits, and resampled residuals carry the model's bias
into every replicate. Limitation: with many unknowns a wrong model can be absorbed to the noise level
(a 7-joint servo arm, 35 unknowns, links 10 % heavier: misfit 1.0, no autocorrelation, stretches
agreeing as noise explains); no residual-based rule sees it, and the intervals then cover the fit's
own parameters, not the truth (4 draws: 0.06 held the truth). For that, ``heavier_links`` says how far
each estimate would move were every link of the model ``LINKS`` heavier (one extra rollout batch; the
Gauss–Newton move that absorbs the residual's change): on the pendulum above, applied to the fits of
logs made with 10 % heavier links, it brought errors of 0.2–2 % down to 0.02–0.2 %. It is reported,
not added to the intervals: with the right model it would widen them for an error that is not there.

**When.** ``misfit`` is the robust residual RMS in units of the log's noise level (each channel's
median absolute residual over its noise, :func:`idkit.sim.problem.noise_scale`; 1 ≈ noise-limited),
``autocorrelation`` the lag-one correlation of the (ψ-clipped) residual within segments (≈ 0 for white
noise, → 1 for a smooth misfit), ``disagreement`` how much more the groups' scores (their pull on
the estimate) disagree than noise explains (:func:`disagreement`: ≈ 1 under noise, whatever each
stretch's excitation — the spread of pseudo-values itself is not calibrated that way where the
excitation differs between stretches). The fit is *model-limited* when ``misfit > MISFIT``,
``autocorrelation > AUTOCORRELATION`` or ``disagreement`` above what noise alone gives in all but 1 %
of fits (:func:`disagreement_limit`: χ² quantile); then the wide intervals are used and ``reason`` says why.
Otherwise the textbook intervals stand. A log whose driver stalled (rows repeated for 40 ms) biased
the estimate as a wrong model does before the problem left stalls out (the textbook intervals held
0.62 of the truths on the coverage test's corrupted case) and was called model-limited the same way
(0.80 of the fits; 0.955 held the truth): the fit is limited by something other than the noise, and
the intervals say so. With stalls left out: 0.96 either way, 0.02 of the fits widened.

A *flat direction* is an eigenvector of the unknowns' information along which the data cannot tell a
change from noise: a standard deviation over ``FLAT`` in coordinates (a factor ``e^0.5 ≈ 1.65`` of a
log-scaled value), or an eigenvalue below ``1e-12`` of the largest. It is named by its largest
components (``j1.armature + 0.9·j1.damping``): those unknowns are not separately identifiable from this
log; a longer or richer motion, or fixing one of them, is what helps.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from idkit.optim.levenberg import BlockJacobian
from idkit.optim.robust import Loss, psi, psi_slope
from idkit.sim.quantities import Unknowns
from idkit.sim.shooting import Shooting

FLAT = 0.5
#: Components of a flat direction at least this fraction of its largest are named.
NAMED = 0.2
#: Robust residual RMS above this many noise levels: the model, not the noise, limits the fit.
MISFIT = 2.0
#: Lag-one autocorrelation of the residual above this: structured (not white) misfit.
AUTOCORRELATION = 0.5
#: The disagreement test's false alarms under noise alone: at most this share of fits (module docstring).
FALSE_ALARM = 0.01
#: At most this many groups of contiguous segments are left out in turn.
GROUPS = 10
#: The model error whose effect is reported: every link this much heavier (relative).
LINKS = 0.1
#: A coordinate within this of its bound is at the bound.
AT_BOUND = 1e-6


@dataclass(frozen=True)
class Uncertainty:
    """What the fit knows (module docstring).

    Attributes:
        std: per unknown its standard deviation (``inf``: not determined by the log).
        interval95: per unknown a 95 % interval (from the coordinate's, so asymmetric in log scale).
        flat: the flat directions, each ``{"direction": {name: weight}, "sigma": coordinate std}``.
        at_bound: the unknowns whose estimate is at a bound (their interval is the fit's, not the truth's).
        model_limited: the residual is far above the noise or structured (``reason`` says which).
        misfit: robust residual RMS / the log's noise level (1 ≈ noise-limited).
        method: ``"textbook"`` (white-noise Jacobian covariance) or ``"block spread"`` (module docstring).
        reason: one sentence: which method and why.
        autocorrelation: lag-one autocorrelation of the residual within segments.
        disagreement: how many times more the estimates of stretches of the log disagree than the noise
            explains (the largest over the unknowns; ≈ 1 when the model is right).
        textbook_std: the white-noise standard deviations, for comparison.
        heavier_links: per unknown the relative change of its estimate were every link of the model
            ``LINKS`` heavier (mass and inertia): what a model error the log may not show would do.
    """

    std: dict[str, float]
    interval95: dict[str, tuple[float, float]]
    flat: list[dict[str, Any]] = field(default_factory=list)
    at_bound: list[str] = field(default_factory=list)
    model_limited: bool = False
    misfit: float = float("nan")
    method: str = "textbook"
    reason: str = ""
    autocorrelation: float = float("nan")
    disagreement: float = float("nan")
    textbook_std: dict[str, float] = field(default_factory=dict)
    heavier_links: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """``result.json``'s record (the torque path's names: ``std``, ``interval95``)."""
        return {
            "std": self.std,
            "interval95": {k: list(v) for k, v in self.interval95.items()},
            "flat_directions": self.flat,
            "at_bound": list(self.at_bound),
            "model_limited": self.model_limited,
            "misfit": self.misfit,
            "method": self.method,
            "reason": self.reason,
            "autocorrelation": self.autocorrelation,
            "disagreement": self.disagreement,
            "textbook_std": self.textbook_std,
            "heavier_links": self.heavier_links,
        }


@dataclass(frozen=True)
class Pieces:
    """The profiled least-squares pieces per segment, in coordinates of the unknowns.

    Attributes:
        info: ``[S, P, P]`` each segment's information with unit weights (the textbook's).
        hessian: ``[S, P, P]`` each segment's Hessian of the loss (weights ``ψ'``).
        score: ``[S, P]`` each segment's gradient of the loss at the solution.
        kappa: the textbook's efficiency factor.
        power: ``mean ψ²``, the variance of a residual's score under noise alone.
    """

    info: np.ndarray
    hessian: np.ndarray
    score: np.ndarray
    kappa: float
    power: float = 1.0


def pieces(
    jac: BlockJacobian, residual: np.ndarray, threshold: float, loss: Loss, rows: Sequence[tuple[int, int]]
) -> Pieces:
    """Each segment's share of the information, Hessian and score, its initial state (the block of
    ``jac`` on its rows, if any) profiled out: a segment's start state only moves its own residuals.

    Args:
        jac: ``[M, P + …]`` the residual's Jacobian: the unknowns' columns dense, the initial states
            in blocks.
        residual: ``[M]`` standardised residual divided by ``√M``.
        threshold: the loss's threshold in the residual's units.
        loss: the polish's loss.
        rows: ``(start, stop)`` each segment's residual rows.
    """
    m = residual.size
    root = np.sqrt(m)
    u, k = residual * root, threshold * root
    slope = psi_slope(loss, u, k)
    scores = psi(loss, u, k)
    p = jac.dense.shape[1]
    kappa = float(np.mean(scores**2)) / max(float(np.mean(slope)), 1e-12) ** 2 * m / max(m - jac.shape[1], 1)
    blocks = {b[0]: b[3] * root for b in jac.blocks}
    info, hessian, score = (
        np.zeros((len(rows), p, p)),
        np.zeros((len(rows), p, p)),
        np.zeros((len(rows), p)),
    )
    for g, (a, b) in enumerate(rows):
        dense = jac.dense[a:b] * root
        states = blocks.get(a)
        for weights, out in ((np.ones(b - a), info), (np.maximum(slope[a:b], 0.0), hessian)):
            profiled = _profiled(dense, states, weights)
            out[g] = profiled.T @ (weights[:, None] * profiled)
            if out is hessian:
                score[g] = profiled.T @ scores[a:b]
    return Pieces(info, hessian, score, kappa, float(np.mean(scores**2)))


def _profiled(dense: np.ndarray, states: np.ndarray | None, weights: np.ndarray) -> np.ndarray:
    """The unknowns' columns less their weighted projection on the segment's initial-state columns."""
    if states is None:
        return dense
    gram = states.T @ (weights[:, None] * states)
    return dense - states @ (np.linalg.pinv(gram, hermitian=True) @ (states.T @ (weights[:, None] * dense)))


def group_edges(segments: int, groups: int = GROUPS) -> np.ndarray:
    """``[G + 1]`` segment indices bounding ``min(groups, segments)`` contiguous groups."""
    return np.round(np.linspace(0, segments, min(groups, segments) + 1)).astype(int)


def disagreement(parts: Pieces, groups: int = GROUPS) -> tuple[float, int]:
    """``(D, dof)``: how much more the groups' scores disagree than noise explains, and the degrees of
    freedom of ``D² · dof`` (χ² under Gaussian noise). Each group's score ``s_g`` has covariance
    ``mean ψ² · I_g`` under noise alone (``I_g`` its information), so ``Σ_g s_gᵀ (mean ψ² · I_g)⁻¹ s_g``
    is χ² with ``(G − 1) · P`` degrees of freedom (the scores sum to zero at the solution), whatever the
    excitation of each group: ``D`` is its ratio to the degrees of freedom, square-rooted."""
    edges = group_edges(parts.score.shape[0], groups)
    total, rank = 0.0, np.linalg.matrix_rank(parts.info.sum(axis=0), hermitian=True)
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        s = parts.score[a:b].sum(axis=0)
        total += float(s @ np.linalg.pinv(parts.power * parts.info[a:b].sum(axis=0), hermitian=True) @ s)
    dof = (len(edges) - 2) * int(rank)
    return (float(np.sqrt(total / dof)) if dof > 0 else float("nan")), dof


def block_spread(parts: Pieces, groups: int = GROUPS) -> np.ndarray:
    """``[P]`` the standard deviation over contiguous groups of segments of the jackknife's pseudo-values
    (module docstring), in coordinates; ``nan`` with fewer than 3 groups."""
    edges = group_edges(parts.score.shape[0], groups)
    count = len(edges) - 1
    if count < 3:
        return np.full(parts.score.shape[1], np.nan)
    total = parts.hessian.sum(axis=0)
    pseudo = []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        rest = total - parts.hessian[a:b].sum(axis=0)
        step = np.linalg.pinv(rest, hermitian=True) @ parts.score[a:b].sum(axis=0)
        pseudo.append(-(count - 1) * step)
    return np.asarray(np.std(np.array(pseudo), axis=0, ddof=1))


def cluster_sandwich(parts: Pieces) -> np.ndarray:
    """``[P, P]`` the cluster-robust (segments as clusters) covariance ``A⁻¹ (G/(G−1)) Σ s_g s_gᵀ A⁻¹``
    in coordinates: right for noise correlated within segments, not for a model's bias (kept for
    comparison and tests)."""
    g = parts.score.shape[0]
    bread = np.linalg.pinv(parts.hessian.sum(axis=0), hermitian=True)
    meat = parts.score.T @ parts.score * g / max(g - 1, 1)
    return bread @ meat @ bread


def disagreement_limit(dof: int) -> float:
    """The largest :func:`disagreement` noise alone gives in all but ``FALSE_ALARM`` of fits."""
    from scipy.special import gammaincinv  # chi2's quantile; scipy.stats costs ~2.5 s CPU to import

    if dof < 1:
        return float("inf")
    return float(np.sqrt(2 * gammaincinv(dof / 2, 1 - FALSE_ALARM) / dof))


def heavier_links_change(shooting: Shooting, x: np.ndarray, residual: np.ndarray) -> np.ndarray:
    """``[M]`` how the residual at variables ``x[size]`` moves were every body of the model ``LINKS``
    heavier (mass and rotational inertia; one rollout batch on the shooting's simulator, whose model
    copy is restored after)."""
    from idkit.robots.mjcf import import_mujoco

    mujoco = import_mujoco()
    simulator = shooting.simulator
    values, _ = shooting.split(x[:, None])
    (model,) = simulator.models(values)
    saved = model.body_mass.copy(), model.body_inertia.copy()
    scratch = mujoco.MjData(model)
    try:
        model.body_mass[1:] *= 1 + LINKS
        model.body_inertia[1:] *= 1 + LINKS
        mujoco.mj_setConst(model, scratch)
        return np.asarray(shooting.residual(x[:, None])[:, 0] - residual)
    finally:
        model.body_mass[:], model.body_inertia[:] = saved
        mujoco.mj_setConst(model, scratch)


def compensating_shift(
    parts_jac: BlockJacobian,
    change: np.ndarray,
    hessian: np.ndarray,
    rows: Sequence[tuple[int, int]],
    weights: np.ndarray,
) -> np.ndarray:
    """``[P]`` the Gauss–Newton move of the unknowns' coordinates that absorbs a residual change
    ``change[M]`` (each segment's initial state free to absorb it too)."""
    root = np.sqrt(change.size)
    blocks = {b[0]: b[3] * root for b in parts_jac.blocks}
    pull = np.zeros(parts_jac.dense.shape[1])
    for a, b in rows:
        profiled = _profiled(parts_jac.dense[a:b] * root, blocks.get(a), weights[a:b])
        pull += profiled.T @ (weights[a:b] * change[a:b] * root)
    return -np.linalg.pinv(hessian, hermitian=True) @ pull


def residual_structure(
    residual: np.ndarray, threshold: float, loss: Loss, rows: Sequence[tuple[int, int]], channels: int
) -> float:
    """The lag-one autocorrelation of the ψ-clipped residual within segments, pooled over channels."""
    root = np.sqrt(residual.size)
    clipped = psi(loss, residual * root, threshold * root) if loss != "linear" else residual * root
    products = squares = 0.0
    for a, b in rows:
        x = clipped[a:b].reshape(-1, channels)
        x = x - x.mean(axis=0)
        products += float(np.sum(x[1:] * x[:-1]))
        squares += float(np.sum(x * x))
    return products / squares if squares > 0 else 0.0


def uncertainty(
    jac: BlockJacobian,
    residual: np.ndarray,
    threshold: float,
    loss: Loss,
    unknowns: Unknowns,
    z: np.ndarray,
    rows: Sequence[tuple[int, int]] | None = None,
    noise_units: np.ndarray | None = None,
    change: np.ndarray | None = None,
) -> Uncertainty:
    """The uncertainty of the unknowns at coordinates ``z[P]`` (module docstring).

    Args:
        jac: the Jacobian of the residual vector, the unknowns' columns dense, each segment's initial
            state (if fitted) a block on that segment's rows.
        residual: ``[M]`` the residual vector at the solution (standardised, divided by ``√M``), sample
            by sample, the ``C`` channels of a sample together.
        threshold: the loss's threshold in the residual's units.
        loss: the loss the polish minimised.
        unknowns: what the first ``P`` variables are.
        z: ``[P]`` their coordinates.
        rows: ``(start, stop)`` each segment's residual rows (``None``: one segment).
        noise_units: ``[C]`` each channel's robust residual scale in units of its noise level (``None``:
            the misfit is not known and only the residual's structure decides).
        change: ``[M]`` the residual's change were every link ``LINKS`` heavier
            (:func:`heavier_links_change`), or ``None``.
    """
    rows = [(0, residual.size)] if rows is None else list(rows)
    channels = len(noise_units) if noise_units is not None else 1
    parts = pieces(jac, residual, threshold, loss, rows)
    n = len(unknowns)
    info = parts.info.sum(axis=0)
    eigenvalues, vectors = np.linalg.eigh(0.5 * (info + info.T))
    top = max(float(eigenvalues[-1]), 1e-300)
    flat_mask = eigenvalues <= 1e-12 * top
    safe = np.where(flat_mask, np.inf, eigenvalues)
    kappa = parts.kappa
    textbook = np.sqrt(np.maximum(np.diag((vectors / safe) @ vectors.T * kappa), 0.0))
    undetermined = (np.abs(vectors[:, flat_mask]) > 1e-6).any(axis=1)
    misfit = float(np.sqrt(np.mean(np.square(noise_units)))) if noise_units is not None else float("nan")
    structure = residual_structure(residual, threshold, loss, rows, channels)
    groups = min(GROUPS, len(rows))
    spread = block_spread(parts)
    usable = np.isfinite(spread) & np.isfinite(textbook) & (textbook > 0)
    inflation = float(np.max(spread[usable] / textbook[usable])) if usable.any() else float("nan")
    disagrees, dof = disagreement(parts)
    reasons = []
    if misfit > MISFIT:
        reasons.append(f"residual {misfit:.3g}× the noise level")
    if structure > AUTOCORRELATION:
        reasons.append(f"residual time-correlated (lag-1 autocorrelation {structure:.2f})")
    if disagrees > disagreement_limit(dof):
        reasons.append(
            f"estimates over {groups} stretches of the log disagree {disagrees:.3g}× more than the noise "
            "explains"
        )
    limited = bool(reasons)
    sigma_z, method = textbook, "textbook"
    reason = (
        f"noise-limited fit: textbook (white-noise) intervals (residual {misfit:.3g}× the noise level, "
        f"lag-1 autocorrelation {structure:.2f}, stretches of the log agree within "
        f"{disagrees:.3g}× noise)"
    )
    if limited and np.isfinite(inflation):
        sigma_z, method = textbook * max(1.0, inflation), "block spread"
        reason = (
            f"model-limited fit ({'; '.join(reasons)}): every interval widened {max(1.0, inflation):.3g}× "
            "(the spread of what single stretches of the log say, at the unknown where it is largest): "
            "something other than the noise (the model, or a log the noise level does not describe) sets them"
        )
    elif limited:
        reason = (
            f"model-limited fit ({'; '.join(reasons)}), but too few segments ({len(rows)}) to measure the "
            "spread over stretches of the log: the textbook intervals shown are too narrow"
        )
    sigma_z = np.where(undetermined, np.inf, sigma_z)
    textbook = np.where(undetermined, np.inf, textbook)
    values = unknowns.from_coordinates(z)
    names = unknowns.names
    heavier = _heavier(jac, residual, threshold, loss, unknowns, z, rows, parts, change)
    lower, upper = unknowns.coordinate_bounds()
    at_bound = [
        name
        for name, zi, lo, hi in zip(names, z, lower, upper, strict=True)
        if min(zi - lo, hi - zi) <= AT_BOUND * max(hi - lo, 1e-12)
    ]
    flat = []
    for i in range(n):
        along = np.inf if flat_mask[i] else float(np.sqrt(kappa / eigenvalues[i]))
        if along > FLAT:
            v = vectors[:, i] / np.abs(vectors[:, i]).max()
            order = np.argsort(-np.abs(v))
            named = {names[j]: round(float(v[j]), 3) for j in order if abs(v[j]) >= NAMED}
            flat.append({"direction": named, "sigma": along})
    return Uncertainty(
        _values_std(unknowns, values, sigma_z),
        _intervals(unknowns, z, sigma_z),
        flat,
        at_bound,
        limited,
        misfit,
        method,
        reason,
        structure,
        disagrees,
        _values_std(unknowns, values, textbook),
        heavier,
    )


def _heavier(
    jac: BlockJacobian,
    residual: np.ndarray,
    threshold: float,
    loss: Loss,
    unknowns: Unknowns,
    z: np.ndarray,
    rows: Sequence[tuple[int, int]],
    parts: Pieces,
    change: np.ndarray | None,
) -> dict[str, float]:
    """Per unknown the relative change of its value that absorbs ``change`` (``{}`` without one)."""
    if change is None or not np.all(np.abs(change) < 1e100):  # a diverged rollout says nothing
        return {}
    root = np.sqrt(residual.size)
    weights = np.maximum(psi_slope(loss, residual * root, threshold * root), 0.0)
    shift = compensating_shift(jac, change, parts.hessian.sum(axis=0), rows, weights)
    values, moved = unknowns.from_coordinates(z), unknowns.from_coordinates(z + shift)
    return {
        name: float(m / v - 1) if v else float(m - v)
        for name, m, v in zip(unknowns.names, moved, values, strict=True)
    }


def _values_std(unknowns: Unknowns, values: np.ndarray, sigma_z: np.ndarray) -> dict[str, float]:
    """Coordinate standard deviations as the values' (a log coordinate's σ times the value)."""
    log = np.array([u.logarithmic for u in unknowns.items])
    width = unknowns.vector("upper") - unknowns.vector("lower")
    sigma = np.where(log, values * sigma_z, width * sigma_z)
    return {name: float(s) for name, s in zip(unknowns.names, sigma, strict=True)}


def _intervals(unknowns: Unknowns, z: np.ndarray, sigma_z: np.ndarray) -> dict[str, tuple[float, float]]:
    """95 % intervals of the values from the coordinates' (``±inf`` where σ is)."""
    finite = np.isfinite(sigma_z)
    low = unknowns.from_coordinates(z - 1.96 * np.where(finite, sigma_z, 0.0))
    high = unknowns.from_coordinates(z + 1.96 * np.where(finite, sigma_z, 0.0))
    return {
        name: ((float(lo), float(hi)) if ok else (-np.inf, np.inf))
        for name, lo, hi, ok in zip(unknowns.names, low, high, finite, strict=True)
    }
