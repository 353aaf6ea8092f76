"""Rigid-body inertia helpers: pseudo-inertia against point masses, parallel axis both ways."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from idkit.robots.cylindrical import CylindricalRobot
from idkit.robots.inertia import centroidal, link_count, pseudo_inertia, standard_parameters


def point_mass_body(masses: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Standard parameters ``[10]`` (about the origin) and the reference ``J = Σ m [x; 1][x; 1]ᵀ``."""
    inertia = sum(m * (x @ x * np.eye(3) - np.outer(x, x)) for m, x in zip(masses, points, strict=True))
    (xx, xy, xz), (_, yy, yz), (_, _, zz) = inertia
    standard = np.array([masses.sum(), *(masses @ points), xx, xy, xz, yy, yz, zz])
    lifted = np.c_[points, np.ones(len(masses))]
    return standard, (masses[:, None] * lifted).T @ lifted


def test_pseudo_inertia_is_the_second_moment_of_point_masses():
    """Independent reference: J = sum_k m_k [x_k; 1][x_k; 1]^T for a body made of point masses."""
    rng = np.random.default_rng(0)
    for _ in range(5):
        standard, expected = point_mass_body(rng.uniform(0.1, 2.0, 5), rng.normal(size=(5, 3)))
        np.testing.assert_allclose(pseudo_inertia(torch.as_tensor(standard)).numpy(), expected, atol=1e-12)


def test_pseudo_inertia_is_batched_over_leading_dimensions():
    rng = np.random.default_rng(1)
    bodies = [point_mass_body(rng.uniform(0.1, 2.0, 4), rng.normal(size=(4, 3))) for _ in range(6)]
    standard = torch.as_tensor(np.stack([s for s, _ in bodies])).reshape(2, 3, 10)
    expected = np.stack([j for _, j in bodies]).reshape(2, 3, 4, 4)
    np.testing.assert_allclose(pseudo_inertia(standard).numpy(), expected, atol=1e-12)


@settings(max_examples=50, deadline=None)
@given(
    mass=st.floats(0.05, 50.0),
    com=arrays(np.float64, 3, elements=st.floats(-2.0, 2.0)),
    spread=arrays(np.float64, (3, 3), elements=st.floats(-1.0, 1.0)),
)
def test_parallel_axis_round_trip(mass, com, spread):
    """``centroidal`` undoes ``standard_parameters`` for any body with positive mass."""
    inertia_c = spread @ spread.T  # symmetric (a real body's is also PSD; the algebra does not need it)
    m, c, back = centroidal(standard_parameters(mass, com, inertia_c))
    assert m == mass
    np.testing.assert_allclose(c, com, atol=1e-12)
    np.testing.assert_allclose(back, inertia_c, atol=1e-9 * (1 + mass * (1 + com @ com)))


def test_parallel_axis_matches_point_masses_about_their_centre():
    """Independent reference: the point masses' inertia about the origin, from their own centroid."""
    rng = np.random.default_rng(2)
    masses, points = rng.uniform(0.1, 2.0, 5), rng.normal(size=(5, 3))
    standard, _ = point_mass_body(masses, points)
    com = masses @ points / masses.sum()
    relative = points - com
    inertia_c = sum(m * (x @ x * np.eye(3) - np.outer(x, x)) for m, x in zip(masses, relative, strict=True))
    np.testing.assert_allclose(standard_parameters(masses.sum(), com, inertia_c), standard, atol=1e-12)


def test_link_count_refuses_a_robot_without_links():
    with pytest.raises(ValueError, match="needs a 'urdf' robot .* got CylindricalRobot"):
        link_count(CylindricalRobot())
