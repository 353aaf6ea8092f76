"""Levenberg–Marquardt with eliminated blocks (idkit.optim.levenberg), robust losses and scales
(idkit.optim.robust), and the cooperative swarm (idkit.optim.blocks), against scipy and closed forms."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.optimize import least_squares as scipy_least_squares

from idkit.optim.blocks import cooperative_search
from idkit.optim.levenberg import BlockJacobian, least_squares
from idkit.optim.robust import TUNING, channel_log_scales, mad_scale, psi, psi_slope, rho, weights

SEGMENTS, PER = 4, 30


def _data(outliers: bool):
    """y = a·exp(b·t) + c_s on four segments: (a, b) shared, one offset per segment."""
    rng = np.random.default_rng(0)
    t = np.tile(np.linspace(0, 1, PER), SEGMENTS)
    segment = np.repeat(np.arange(SEGMENTS), PER)
    offsets = np.array([0.5, -0.2, 0.1, 0.3])
    y = 2.0 * np.exp(0.7 * t) + offsets[segment] + 0.01 * rng.standard_normal(t.size)
    if outliers:
        y[rng.choice(t.size, 6, replace=False)] += 5.0
    return t, segment, y


def _model(x, t, segment):
    return x[0] * np.exp(x[1] * t) + x[2 + segment]


def _residual(t, segment, y):
    def residual(points: np.ndarray) -> np.ndarray:
        return np.stack([y - _model(x, t, segment) for x in points.T], axis=1)

    return residual


def _jacobian(t, segment):
    def jacobian(x: np.ndarray, r: np.ndarray) -> BlockJacobian:
        x = x[:, 0]
        dense = -np.column_stack([np.exp(x[1] * t), x[0] * t * np.exp(x[1] * t)])
        blocks = tuple((s * PER, (s + 1) * PER, 2 + s, -np.ones((PER, 1))) for s in range(SEGMENTS))
        return BlockJacobian(dense, blocks)

    return jacobian


@pytest.mark.parametrize(("loss", "outliers"), [("linear", False), ("huber", True)])
def test_matches_scipy_with_the_blocks_eliminated(loss, outliers):
    t, segment, y = _data(outliers)
    x0 = np.array([1.0, 0.2, 0.0, 0.0, 0.0, 0.0])
    k = 0.05
    lower, upper = np.array([0.1, -3.0]), np.array([10.0, 3.0])
    residual, jacobian = _residual(t, segment, y), _jacobian(t, segment)
    # from far the IRLS Hessian (Huber's own is zero where every residual is an outlier), then Huber's
    near, _ = least_squares(x0, residual, jacobian, lower, upper, loss, k, hessian="irls", ftol=1e-6)
    found, trace = least_squares(near, residual, jacobian, lower, upper, loss, k, ftol=1e-14, xtol=1e-14)
    reference = scipy_least_squares(
        lambda x: y - _model(x, t, segment),
        x0,
        loss=loss,
        f_scale=k,
        xtol=1e-14,
        ftol=1e-14,
        gtol=1e-14,
    )
    np.testing.assert_allclose(found, reference.x, atol=1e-7)
    assert trace.losses == sorted(trace.losses, reverse=True)  # every accepted step lowers the loss


def test_keeps_the_dense_variables_in_their_box():
    t, segment, y = _data(False)
    x0 = np.array([1.0, 0.2, 0.0, 0.0, 0.0, 0.0])
    upper = np.array([10.0, 0.5])  # the optimum's b (0.7) lies beyond
    found, _ = least_squares(
        x0, _residual(t, segment, y), _jacobian(t, segment), np.array([0.1, -3.0]), upper, "linear", 1.0
    )
    reference = scipy_least_squares(
        lambda x: y - _model(x, t, segment),
        x0,
        bounds=([0.1, -3.0, *[-np.inf] * 4], [10.0, 0.5, *[np.inf] * 4]),
        xtol=1e-14,
        ftol=1e-14,
        gtol=1e-14,
    )
    assert found[1] == pytest.approx(0.5)
    np.testing.assert_allclose(found, reference.x, atol=1e-6)


def test_block_jacobian_products_equal_the_dense_ones():
    t, segment, _ = _data(False)
    jac = _jacobian(t, segment)(np.array([[1.5], [0.3], [0], [0], [0], [0]]), None)
    full = np.zeros(jac.shape)
    full[:, :2] = jac.dense
    for row_start, row_stop, column, values in jac.blocks:
        full[row_start:row_stop, column : column + values.shape[1]] = values
    w = np.random.default_rng(1).uniform(0, 2, t.size)
    v = np.random.default_rng(2).standard_normal(t.size)
    np.testing.assert_allclose(jac.gram(w), full.T @ (w[:, None] * full), atol=1e-12)
    np.testing.assert_allclose(jac.t_dot(v), full.T @ v, atol=1e-12)


@pytest.mark.parametrize("loss", ["huber", "cauchy", "linear"])
def test_losses_derivatives_and_weights(loss):
    r = np.linspace(-4, 4, 81)
    k = 1.3
    step = 1e-6
    np.testing.assert_allclose(
        psi(loss, r, k), (rho(loss, r + step, k) - rho(loss, r - step, k)) / (2 * step), atol=1e-6
    )
    inside = np.abs(np.abs(r) - k) > 1e-3  # Huber's ρ'' jumps at ±k
    slope = (psi(loss, r + step, k) - psi(loss, r - step, k)) / (2 * step)
    np.testing.assert_allclose(psi_slope(loss, r, k)[inside], slope[inside], atol=1e-5)
    nonzero = r != 0
    np.testing.assert_allclose(weights(loss, r, k)[nonzero], psi(loss, r, k)[nonzero] / r[nonzero])
    assert TUNING["huber"] == 1.345


def test_mad_scale_is_the_noise_level_whatever_the_glitches():
    """400 draws of N(0, 1) with 2 % glitches of 50: the scale within 10 % of 1 (its sampling error at
    N = 400 is about 6 %), where the standard deviation is over 7."""
    rng = np.random.default_rng(3)
    e = rng.standard_normal(400)
    e[:8] += 50
    assert mad_scale(e) == pytest.approx(1.0, rel=0.1)
    assert e.std() > 7
    scales = channel_log_scales(np.stack([e, 3 * e])[None], trim=0.1)[0]
    assert scales[1] - scales[0] == pytest.approx(np.log(3))


def test_cooperative_search_finds_a_separable_minimum_and_repeats_under_a_seed():
    """Three blocks of two coordinates, each part a shifted quadratic of its own block plus a weak
    coupling: the swarms find the minimum; the same seed gives the same answer."""
    target = np.array([0.3, -0.5, 1.2, 0.8, -1.0, 0.1])
    blocks = [np.array([0, 1]), np.array([2, 3]), np.array([4, 5])]

    def objective(x):
        parts = np.stack([((x[:, b] - target[b]) ** 2).sum(axis=1) for b in blocks], axis=1)
        parts += 0.01 * (x.sum(axis=1, keepdims=True) - target.sum()) ** 2
        return parts, parts.sum(axis=1)

    lower, upper, start = -2 * np.ones(6), 2 * np.ones(6), np.zeros(6)
    runs = [
        cooperative_search(objective, lower, upper, start, blocks, 12, 60, torch.Generator().manual_seed(7))
        for _ in range(2)
    ]
    np.testing.assert_allclose(runs[0].x, target, atol=0.05)
    np.testing.assert_array_equal(runs[0].x, runs[1].x)
    assert runs[0].history == sorted(runs[0].history, reverse=True)
    with pytest.raises(ValueError, match="partition"):
        cooperative_search(objective, lower, upper, start, blocks[:2], 4, 2, torch.Generator())


def test_broyden_update_meets_the_secant_equation_within_the_sparsity():
    t, segment, y = _data(False)
    jac = _jacobian(t, segment)(np.array([[1.0], [0.2], [0], [0], [0], [0]]), None)
    rng = np.random.default_rng(1)
    dx, dr = rng.normal(size=6), rng.normal(size=t.size)
    updated = jac.broyden(dx, dr)
    full = np.zeros((t.size, 6))
    full[:, :2] = updated.dense
    for a, b, c, v in updated.blocks:
        full[a:b, c : c + v.shape[1]] = v
    np.testing.assert_allclose(full @ dx, dr, atol=1e-12)  # J dx = dr, row by row
    for (*_, v), (*_, old) in zip(updated.blocks, jac.blocks, strict=True):
        assert v.shape == old.shape  # no fill-in outside a segment's own rows


@pytest.mark.parametrize(("loss", "outliers"), [("linear", False), ("huber", True)])
def test_updated_jacobians_reach_the_same_optimum_with_fewer_evaluated(loss, outliers):
    t, segment, y = _data(outliers)
    x0 = np.array([1.0, 0.2, 0.0, 0.0, 0.0, 0.0])
    lower, upper = np.array([0.1, -3.0]), np.array([10.0, 3.0])
    residual, jacobian = _residual(t, segment, y), _jacobian(t, segment)
    options = {"hessian": "irls", "ftol": 1e-12, "xtol": 1e-12, "max_iter": 200}
    every, traced = least_squares(x0, residual, jacobian, lower, upper, loss, 0.05, **options)
    updated, trace = least_squares(x0, residual, jacobian, lower, upper, loss, 0.05, refresh=4, **options)
    np.testing.assert_allclose(updated, every, atol=1e-6)
    assert trace.jacobians < traced.jacobians
    assert trace.losses == sorted(trace.losses, reverse=True)
