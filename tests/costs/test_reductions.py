"""The entrywise reductions against plain numpy formulations, at their thresholds and on ties."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from idkit.costs.reductions import PARAMETRIC, huber_mean, kept_entries, trimmed_mean_square


def numpy_huber(e: np.ndarray, delta: float) -> np.ndarray:
    """The textbook two-branch Huber loss, averaged over the last two axes."""
    a = np.abs(e)
    return np.where(a <= delta, 0.5 * a**2, delta * (a - 0.5 * delta)).mean(axis=(-2, -1))


def numpy_trimmed(e: np.ndarray, trim: float) -> np.ndarray:
    """Sort the squares, drop the largest floor(trim m) of them, average the rest."""
    flat = np.sort((e**2).reshape(*e.shape[:-2], -1), axis=-1)
    drop = int(np.floor(trim * flat.shape[-1] + 1e-9))
    return flat[..., : flat.shape[-1] - drop].mean(axis=-1)


#: Multiples of the threshold: exactly at ±delta, inside and beyond it, and repeated values (ties).
ON_GRID = st.sampled_from([-2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 2.0])
#: (Away from zero: below ~1e-154 squares underflow to subnormals, where rounding is coarser.)
ENTRIES = st.one_of(ON_GRID, st.floats(0.01, 5.0), st.floats(-5.0, -0.01))


@settings(max_examples=60, deadline=None)
@given(
    data=st.data(),
    shape=st.tuples(st.integers(1, 4), st.integers(1, 12)),
    batch=st.sampled_from([(), (3,), (2, 3)]),
    delta=st.floats(1e-3, 1e3),
)
def test_huber_matches_the_two_branch_formula(data, shape, batch, delta):
    multiples = data.draw(arrays(np.float64, batch + shape, elements=ENTRIES))
    e = multiples * delta  # grid entries land exactly on ±delta, ±delta/2, ±2 delta
    got = huber_mean(torch.from_numpy(e), delta)
    assert got.shape == batch
    np.testing.assert_allclose(got.numpy(), numpy_huber(e, delta), rtol=1e-13, atol=0)


@settings(max_examples=60, deadline=None)
@given(
    data=st.data(),
    shape=st.tuples(st.integers(1, 4), st.integers(1, 12)),
    batch=st.sampled_from([(), (3,), (2, 3)]),
    trim=st.one_of(st.sampled_from([0.0, 0.1, 0.5, 0.9]), st.floats(0.0, 0.95)),
)
def test_trimmed_matches_sorting_even_with_ties(data, shape, batch, trim):
    e = data.draw(arrays(np.float64, batch + shape, elements=ENTRIES))  # grid values repeat: ties
    got = trimmed_mean_square(torch.from_numpy(e), trim)
    assert got.shape == batch
    np.testing.assert_allclose(got.numpy(), numpy_trimmed(e, trim), rtol=1e-13, atol=0)


def test_huber_is_continuous_with_its_slope_at_the_threshold():
    delta = 0.7
    at, below, above = (
        torch.full((1, 1), v, dtype=torch.float64) for v in (delta, delta - 1e-9, delta + 1e-9)
    )
    assert huber_mean(at, delta).item() == pytest.approx(0.5 * delta**2, rel=1e-15)
    assert (huber_mean(above, delta) - huber_mean(below, delta)).item() == pytest.approx(
        2e-9 * delta, rel=1e-5
    )


def test_trim_zero_is_the_mean_square_and_the_slack_rounds_as_decimal():
    e = torch.arange(1.0, 101.0, dtype=torch.float64).view(4, 25)
    torch.testing.assert_close(trimmed_mean_square(e, 0.0), e.square().mean(), rtol=1e-15, atol=0)
    assert kept_entries(100, 0.29) == 71  # 0.29 * 100 = 28.999999999999996 in binary
    assert kept_entries(30, 0.1) == 27 and kept_entries(1, 0.5) == 1


def test_a_trim_that_leaves_nothing_is_an_error():
    assert kept_entries(10, 1 - 1e-12) == 0
    with pytest.raises(ValueError, match="leaves none of the 10 entries"):
        trimmed_mean_square(torch.ones(2, 5, dtype=torch.float64), 1 - 1e-12)


@pytest.mark.parametrize(
    ("name", "value", "message"),
    [
        ("huber", 0.0, r"huber: delta must be > 0, got 0.0"),
        ("huber", -1.0, r"huber: delta must be > 0"),
        ("huber", math.inf, r"huber: delta must be > 0, got inf"),
        ("huber", "wide", r"huber: delta must be > 0, got 'wide'"),
        ("trimmed", 1.0, r"trimmed: trim must be in \[0, 1\), got 1.0"),
        ("trimmed", -0.1, r"trimmed: trim must be in \[0, 1\)"),
        ("trimmed", math.nan, r"trimmed: trim must be in \[0, 1\), got nan"),
    ],
)
def test_parameters_outside_the_domain_are_named(name, value, message):
    with pytest.raises(ValueError, match=message):
        PARAMETRIC[name].check(name, value)


def test_valid_parameters_come_back_as_floats():
    assert PARAMETRIC["huber"].check("huber", 2) == 2.0 and PARAMETRIC["trimmed"].check("trimmed", 0) == 0.0
