"""The rollout fit's uncertainty (idkit.sim.uncertainty) against closed forms on a linear model."""

from __future__ import annotations

import numpy as np
import pytest

from idkit.optim.levenberg import BlockJacobian
from idkit.sim.quantities import Unknown, Unknowns
from idkit.sim.uncertainty import GROUPS, block_spread, cluster_sandwich, pieces, uncertainty

#: ``bias`` unknowns of width 1 in [-0.5, 0.5]: their coordinate is their value.
UNKNOWNS = Unknowns(tuple(Unknown(f"b{i}", "bias", (0,), 0.0, -0.5, 0.5) for i in range(3)))


def _linear(m: int, rng: np.random.Generator, noise: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Regressors ``X[m, 3]``, the least-squares estimate and its residual for ``y = X β + noise``."""
    x = np.column_stack([np.ones(m), np.sin(np.linspace(0, 9, m)), rng.standard_normal(m)])
    y = x @ np.array([0.1, -0.2, 0.05]) + noise
    beta, *_ = np.linalg.lstsq(x, y, rcond=None)
    return x, beta, y - x @ beta


def _call(x: np.ndarray, beta: np.ndarray, r: np.ndarray, segments: int, **options):
    """``uncertainty`` as the polish calls it: residual r / √M, Jacobian ∂r/∂β / √M (= −X / √M)."""
    m = r.size
    edges = np.linspace(0, m, segments + 1).astype(int)
    rows = list(zip(edges[:-1].tolist(), edges[1:].tolist(), strict=True))
    jac = BlockJacobian(-x / np.sqrt(m))
    return uncertainty(jac, r / np.sqrt(m), np.inf, "linear", UNKNOWNS, beta, rows, **options), jac, rows


def test_textbook_sigma_is_ordinary_least_squares_with_white_residuals():
    rng = np.random.default_rng(0)
    x, beta, r = _linear(2000, rng, 0.01 * rng.standard_normal(2000))
    found, _, _ = _call(x, beta, r, 20, noise_units=np.array([1.0]))
    s2 = r @ r / (r.size - 3)
    ols = np.sqrt(np.diag(s2 * np.linalg.inv(x.T @ x)))
    np.testing.assert_allclose(list(found.std.values()), ols, rtol=1e-10)
    np.testing.assert_allclose(list(found.textbook_std.values()), ols, rtol=1e-10)
    low, high = found.interval95["b1"]
    assert (low, high) == pytest.approx((beta[1] - 1.96 * ols[1], beta[1] + 1.96 * ols[1]), rel=1e-10)
    assert not found.model_limited and found.method == "textbook" and "noise-limited" in found.reason


def test_the_cluster_sandwich_is_its_closed_form_and_near_ols_when_residuals_are_white():
    rng = np.random.default_rng(1)
    x, beta, r = _linear(4000, rng, 0.01 * rng.standard_normal(4000))
    _, jac, rows = _call(x, beta, r, 40)
    parts = pieces(jac, r / np.sqrt(r.size), np.inf, "linear", rows)
    bread = np.linalg.inv(x.T @ x)
    meat = sum(x[a:b].T @ np.outer(r[a:b], r[a:b]) @ x[a:b] for a, b in rows) * 40 / 39
    np.testing.assert_allclose(cluster_sandwich(parts), bread @ meat @ bread, rtol=1e-8)
    ols = np.diag(r @ r / (r.size - 3) * bread)
    ratio = np.sqrt(np.diag(cluster_sandwich(parts)) / ols)
    assert np.all((ratio > 0.6) & (ratio < 1.4))  # 40 clusters: the sandwich's own scatter ~ 1/√(2·40)


def test_the_block_spread_is_the_exact_delete_a_group_jackknife_of_a_linear_fit():
    """For a linear model one Newton step is the refit: the pseudo-values' spread equals the one of
    leave-one-group-out least-squares refits."""
    rng = np.random.default_rng(2)
    x, beta, r = _linear(600, rng, 0.01 * rng.standard_normal(600))
    _, jac, rows = _call(x, beta, r, 30)
    parts = pieces(jac, r / np.sqrt(r.size), np.inf, "linear", rows)
    edges = np.round(np.linspace(0, len(rows), GROUPS + 1)).astype(int)
    y = x @ beta + r
    pseudo = []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        keep = np.ones(r.size, dtype=bool)
        keep[rows[a][0] : rows[b - 1][1]] = False
        refit, *_ = np.linalg.lstsq(x[keep], y[keep], rcond=None)
        pseudo.append(GROUPS * beta - (GROUPS - 1) * refit)
    np.testing.assert_allclose(block_spread(parts), np.std(pseudo, axis=0, ddof=1), rtol=1e-8)


def test_a_structured_misfit_is_called_model_limited_and_widens_the_intervals():
    """A slow drift the regressors cannot fit (a model error), 5× the noise: model-limited, the
    intervals widened (never narrower than the textbook), the reason says why; the same fit with
    white noise of that size is not."""
    rng = np.random.default_rng(3)
    m = 3000
    drift = 0.05 * np.sin(np.linspace(0, 40, m) ** 1.3)
    x, beta, r = _linear(m, rng, drift + 0.01 * rng.standard_normal(m))
    found, _, _ = _call(x, beta, r, 30, noise_units=np.array([5.0]))
    assert found.model_limited and found.method == "block spread"
    assert "model-limited" in found.reason and "5× the noise" in found.reason
    assert found.autocorrelation > 0.8
    widened = np.array(list(found.std.values())) / np.array(list(found.textbook_std.values()))
    assert np.all(widened >= 1.0) and widened.max() > 2
    x, beta, r = _linear(m, rng, 0.05 * rng.standard_normal(m))
    white, _, _ = _call(x, beta, r, 30, noise_units=np.array([1.0]))
    assert not white.model_limited and white.std == white.textbook_std
    assert abs(white.autocorrelation) < 0.1 and white.misfit == 1.0


def test_an_estimate_at_its_bound_is_named():
    rng = np.random.default_rng(4)
    x, beta, r = _linear(500, rng, 0.01 * rng.standard_normal(500))
    found, _, _ = _call(x, np.array([0.5, beta[1], beta[2]]), r, 5)
    assert found.at_bound == ["b0"]


@pytest.mark.statistical
def test_the_disagreement_test_raises_few_false_alarms_under_white_noise():
    """400 linear fits with white noise, 30 segments in 10 groups of very different excitation (a slow
    sine regressor): the disagreement is ≈ 1 (measured mean 0.98) and the fit is called model-limited in
    at most 3 % (measured 0.25 %; FALSE_ALARM is 1 %)."""
    rng = np.random.default_rng(5)
    flagged, values = [], []
    for _ in range(400):
        x, beta, r = _linear(1500, rng, 0.05 * rng.standard_normal(1500))
        found, _, _ = _call(x, beta, r, 30, noise_units=np.array([1.0]))
        flagged.append(found.model_limited)
        values.append(found.disagreement)
    assert 0.9 < float(np.mean(values)) < 1.1
    assert float(np.mean(flagged)) <= 0.03
