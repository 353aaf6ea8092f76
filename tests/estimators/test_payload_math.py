"""The payload fit's rigid-body pieces against independent references: the frame change against the
parallel-axis theorem, the delta-method Jacobian against finite differences and its standard
deviations against Monte Carlo, and the SDK argument orders."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit.estimators.payload import centroidal_jacobian, payload_block, sdk_conventions
from idkit.robots.inertia import centroidal, frame_change, standard_parameters
from idkit.robots.urdf_model import rpy_matrix

angles = st.tuples(*[st.floats(-np.pi, np.pi)] * 3)
vectors = st.tuples(*[st.floats(-0.5, 0.5)] * 3)


def body(mass: float, com, moments, rpy) -> tuple[float, np.ndarray, np.ndarray]:
    """A physical body: principal moments (made to obey the triangle inequality) turned by ``rpy``."""
    a, b, c = sorted(moments)
    moments = np.array([a, b, min(c, a + b)])
    axes = rpy_matrix(np.array(rpy))
    return mass, np.array(com), axes @ np.diag(moments) @ axes.T


@settings(max_examples=50, deadline=None)
@given(
    mass=st.floats(0.1, 10),
    com=vectors,
    moments=st.tuples(*[st.floats(1e-4, 1e-1)] * 3),
    rpy=angles,
    frame_rpy=angles,
    translation=vectors,
)
def test_frame_change_is_the_parallel_axis_theorem_in_the_new_frame(
    mass, com, moments, rpy, frame_rpy, translation
):
    m, c, inertia = body(mass, com, moments, rpy)
    rotation, p = rpy_matrix(np.array(frame_rpy)), np.array(translation)
    moved = frame_change(rotation, p) @ standard_parameters(m, c, inertia)
    expected = standard_parameters(m, rotation @ c + p, rotation @ inertia @ rotation.T)
    np.testing.assert_allclose(moved, expected, rtol=0, atol=1e-12 * (1 + np.abs(expected).max()))


def test_frame_changes_compose():
    r1, r2 = rpy_matrix(np.array([0.3, -1.0, 2.0])), rpy_matrix(np.array([-0.7, 0.2, 0.4]))
    p1, p2 = np.array([0.1, -0.2, 0.3]), np.array([-0.05, 0.4, 0.0])
    np.testing.assert_allclose(
        frame_change(r1, p1) @ frame_change(r2, p2), frame_change(r1 @ r2, r1 @ p2 + p1), atol=1e-14
    )


def _flat(phi: np.ndarray) -> np.ndarray:
    m, c, inertia = centroidal(phi)
    return np.array([m, *c, *inertia[np.triu_indices(3)]])


def test_the_delta_method_jacobian_equals_finite_differences():
    phi = standard_parameters(*body(2.3, [0.02, -0.015, 0.08], [0.012, 0.015, 0.008], [0.1, 0.2, 0.3]))
    step = 1e-6 * np.maximum(np.abs(phi), 1e-3)
    numeric = np.stack(
        [
            (_flat(phi + step[k] * e) - _flat(phi - step[k] * e)) / (2 * step[k])
            for k, e in enumerate(np.eye(10))
        ],
        1,
    )
    np.testing.assert_allclose(centroidal_jacobian(phi), numeric, rtol=1e-6, atol=1e-8)


def test_delta_method_standard_deviations_match_monte_carlo():
    phi = standard_parameters(*body(2.3, [0.02, -0.015, 0.08], [0.012, 0.015, 0.008], [0.1, 0.2, 0.3]))
    rng = np.random.default_rng(0)
    spread = 1e-3 * np.abs(phi).max() * rng.uniform(0.2, 1.0, 10)  # small: the linearisation holds
    mixing = np.linalg.qr(rng.normal(size=(10, 10)))[0]
    covariance = mixing @ np.diag(spread**2) @ mixing.T  # correlated, as a fit's covariance is
    block = payload_block(phi, covariance, "tool", "tool", 0.0)
    draws = np.array([_flat(x) for x in rng.multivariate_normal(phi, covariance, 20000)])
    expected = np.array(
        [block["mass_std"], *block["com_std"], *np.array(block["inertia_std"])[np.triu_indices(3)]]
    )
    np.testing.assert_allclose(draws.std(0), expected, rtol=0.03)


def test_an_unidentified_parameter_makes_the_quantities_it_touches_unknown():
    phi = standard_parameters(*body(1.0, [0.0, 0.0, 0.1], [0.01, 0.01, 0.01], [0, 0, 0]))
    covariance = 1e-8 * np.eye(10)
    covariance[7, :] = covariance[:, 7] = np.inf  # Iyy about the origin: free
    block = payload_block(phi, covariance, "tool", "tool", 0.0)
    assert np.isfinite(block["mass_std"]) and np.isfinite(block["com_std"]).all()
    assert np.isinf(np.array(block["inertia_std"])[1, 1]) and np.isfinite(
        np.array(block["inertia_std"])[0, 1]
    )


def test_a_massless_payload_has_no_centre_of_mass_to_hand_over():
    block = payload_block(np.zeros(10), np.eye(10), "tool", "tool", 0.0)
    assert block["mass"] == 0 and block["com"] is None and block["sdk"] is None


def test_sdk_argument_orders():
    inertia = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]])  # unsymmetric: shows the order
    sdk = sdk_conventions(2.5, np.array([0.1, 0.2, 0.3]), inertia)
    assert sdk["libfranka"]["load_inertia"] == [1.0, 4.0, 7.0, 2.0, 5.0, 8.0, 3.0, 6.0, 9.0]  # column-major
    assert sdk["libfranka"]["F_x_Cload"] == [0.1, 0.2, 0.3] and sdk["libfranka"]["load_mass"] == 2.5
    assert sdk["ur"]["inertia"] == [1.0, 5.0, 9.0, 2.0, 3.0, 6.0]  # [Ixx, Iyy, Izz, Ixy, Ixz, Iyz]


@pytest.mark.parametrize("mass", [0.5, 3.0])
def test_centroidal_of_the_block_inverts_the_parallel_axis_theorem(mass):
    m, c, inertia = body(mass, [0.01, 0.02, -0.03], [0.002, 0.003, 0.004], [0.5, 0.1, -0.2])
    block = payload_block(standard_parameters(m, c, inertia), np.zeros((10, 10)), "tool", "tool", 0.0)
    np.testing.assert_allclose(block["com"], c, atol=1e-15)
    np.testing.assert_allclose(block["inertia"], inertia, atol=1e-15)
