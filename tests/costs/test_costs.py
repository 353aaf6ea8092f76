"""The 16 costs against independent numpy formulations, batch invariance and the relative policy."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from idkit import registry
from idkit.relative import RelativeFloorWarning, relative_denominator


def numpy_costs(e: np.ndarray) -> list[float]:
    """f1..f8 on one n × N matrix, written with np.linalg.norm where an ord exists."""
    n1, n2, ninf = (np.linalg.norm(e, ord=o) for o in (1, 2, np.inf))
    return [
        np.linalg.norm(e, ord="fro"),
        n2,
        n1,
        ninf,
        n1 * ninf,
        n1 * n2 * ninf,
        max(sum(x * x for x in row) for row in e),
        np.abs(e).max(),
    ]


def expected(error: np.ndarray, measured: np.ndarray, index: int) -> float:
    if index > 8:
        return numpy_costs(error / measured)[index - 9]
    return numpy_costs(error)[index - 1]


finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
away_from_zero = st.one_of(st.floats(0.5, 100.0), st.floats(-100.0, -0.5))


@settings(max_examples=25, deadline=None)
@given(
    data=st.data(),
    shape=st.tuples(st.integers(1, 4), st.integers(1, 12)),
    batch=st.sampled_from([(), (2,), (2, 3)]),
)
def test_costs_match_numpy(data, shape, batch):
    error = data.draw(arrays(np.float64, batch + shape, elements=finite))
    measured = data.draw(arrays(np.float64, shape, elements=away_from_zero))
    e, t = torch.from_numpy(error), torch.from_numpy(measured)
    flat = error.reshape(-1, *shape)
    for index in range(1, 17):
        value = registry.create("cost", f"f{index}")(e, t)
        assert value.shape == batch
        reference = np.array([expected(m, measured, index) for m in flat]).reshape(batch)
        np.testing.assert_allclose(value.numpy(), reference, rtol=1e-10, atol=1e-12, err_msg=f"f{index}")


def test_f8_is_max_absolute_not_signed_max():
    error = -torch.ones(1, 3, 2, dtype=torch.float64)  # over-prediction everywhere
    assert registry.create("cost", "f8")(error, torch.ones(3, 2)).item() == 1.0


@settings(max_examples=20, deadline=None)
@given(scale=st.floats(0.01, 100.0), seed=st.integers(0, 2**16))
def test_induced_norms_are_absolutely_homogeneous(scale, seed):
    e = torch.randn(3, 10, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    t = torch.ones(3, 10, dtype=torch.float64)
    for index in (1, 2, 3, 4):
        cost = registry.create("cost", f"f{index}")
        torch.testing.assert_close(cost(-scale * e, t), scale * cost(e, t), rtol=1e-12, atol=0)


def test_batched_equals_one_by_one(rng):
    e = torch.randn(2, 3, 3, 10, generator=rng, dtype=torch.float64)
    t = torch.randn(3, 10, generator=rng, dtype=torch.float64).sign() * 5
    for index in range(1, 17):
        cost = registry.create("cost", f"f{index}")
        stacked = torch.stack([torch.stack([cost(m, t) for m in row]) for row in e])
        torch.testing.assert_close(cost(e, t), stacked, rtol=1e-14, atol=0)


def test_float32_stays_float32(rng):
    e = torch.randn(5, 3, 10, generator=rng)
    for index in range(1, 17):
        assert registry.create("cost", f"f{index}")(e, torch.ones(3, 10)).dtype == torch.float32


def test_relative_floor_replaces_tiny_torques_and_warns():
    measured = torch.tensor([[10.0, -10.0, 1e-9, 0.0, -1e-9]], dtype=torch.float64)
    rms = measured.square().mean().sqrt().item()
    with pytest.warns(RelativeFloorWarning, match="3 measured torque"):
        denominator = relative_denominator(measured, floor=1e-3)
    limit = 1e-3 * rms
    torch.testing.assert_close(
        denominator, torch.tensor([[10.0, -10.0, limit, limit, -limit]], dtype=torch.float64)
    )
    with pytest.warns(RelativeFloorWarning):
        value = registry.create("cost", "f9")(torch.ones(1, 1, 5, dtype=torch.float64), measured)
    assert torch.isfinite(value).all()


def test_relative_no_warning_when_nothing_is_small():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        relative_denominator(torch.tensor([[1.0, -2.0, 3.0]]))


def test_relative_errors_on_undefined_cases():
    with pytest.raises(ValueError, match=r"joint\(s\) \[1\] are all zero"):
        relative_denominator(torch.tensor([[1.0, 2.0], [0.0, 0.0]]))
    with pytest.raises(ValueError, match="exactly zero and floor=0"):
        relative_denominator(torch.tensor([[1.0, 0.0]]), floor=0.0)
    with pytest.raises(ValueError, match="floor must be >= 0"):
        relative_denominator(torch.tensor([[1.0]]), floor=-1.0)
