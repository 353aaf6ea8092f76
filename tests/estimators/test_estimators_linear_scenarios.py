"""The LS family on the paper's four noise scenarios behaves as the paper describes (Tables II–V).

One noise draw per table in the paper is one sample; here every claim is checked over 20 seeds
(medians and fractions), with thresholds far from the measured values (quoted per test) yet tight
enough that a wrong W, a wrong relative transform or a wrong TLS would fail them.
"""

from __future__ import annotations

import functools
import warnings

import numpy as np
import pytest

from idkit.data.scenarios import simulate
from idkit.estimators.linear.least_squares import LeastSquares, TotalLeastSquares
from idkit.estimators.linear.robust_ls import RobustLeastSquares
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot

SEEDS = range(20)
TRUE = np.array([5.0, 3.0, -0.5, 3.0])
ESTIMATORS = {
    "LS": LeastSquares(),
    "LS-rel": LeastSquares(relative=True),
    "TLS": TotalLeastSquares(),
    "TLS-rel": TotalLeastSquares(relative=True),
    "RLS": RobustLeastSquares(),
    "RLS-rel": RobustLeastSquares(relative=True),
}


@functools.cache
def estimates(scenario: str) -> dict[str, np.ndarray]:
    """Physical estimates ``[seeds, 4]`` per estimator label."""
    robot = CylindricalRobot()
    out: dict[str, list] = {name: [] for name in ESTIMATORS}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # near-degenerate TLS draws warn; that is the point here
        for seed in SEEDS:
            problem = Problem(robot, simulate(robot, scenario, seed=seed))
            for name, estimator in ESTIMATORS.items():
                out[name].append(estimator.fit(problem).vector())
    return {name: np.array(values) for name, values in out.items()}


def errors(scenario: str, name: str) -> np.ndarray:
    """Relative parameter error ``‖θ̂ − θ‖ / ‖θ‖`` per seed."""
    return np.linalg.norm(estimates(scenario)[name] - TRUE, axis=1) / np.linalg.norm(TRUE)


@pytest.mark.parametrize("scenario", ["all_noise", "outliers"])
def test_tls_degrades_badly_with_noise_on_everything_and_outliers(scenario):
    """Tables IV/V: TLS gives m3 < 0 and worse. Measured medians 256 (all_noise), 31 (outliers)."""
    tls, ls = errors(scenario, "TLS"), errors(scenario, "LS")
    assert np.median(tls) > 1.0
    assert np.mean(tls > 3 * ls) >= 0.8  # measured 1.0 and 0.95


def test_tls_is_as_good_as_ls_with_state_noise_only():
    """Table II: TLS ≈ LS. Measured medians 0.039 and 0.039."""
    tls, ls = errors("state_noise", "TLS"), errors("state_noise", "LS")
    assert np.median(tls) < 0.1
    assert np.median(tls) < 1.5 * np.median(ls)


@pytest.mark.parametrize("scenario", ["state_noise", "torque_noise", "all_noise", "outliers"])
def test_least_squares_and_relative_transform_stay_accurate(scenario):
    """LS and LS-rel within 10 % (median; measured ≤ 0.08); TLS-rel never collapses like TLS
    (median ≤ 0.2 measured, where TLS reaches 31–256)."""
    assert np.median(errors(scenario, "LS")) < 0.1
    assert np.median(errors(scenario, "LS-rel")) < 0.12
    assert np.median(errors(scenario, "TLS-rel")) < 0.3
    assert np.max(errors(scenario, "RLS")) < 1.0  # robust: never a TLS-like blow-up (max 0.37)


@pytest.mark.parametrize("scenario", ["torque_noise", "all_noise", "outliers"])
def test_rls_shrinks_the_centre_of_mass(scenario):
    """Tables III–V: RLS moves −s3z from ≈ 0.5 (LS) towards 0 (0.35, 0.30, 0.32 in the paper) —
    the ρ of the TLS problem is large there. Measured medians of −s3z: LS 0.48–0.52, RLS −0.05–0.07
    (more shrinkage than the paper's draw: our TLS problems are closer to degenerate, see TLS)."""
    ls, rls = -estimates(scenario)["LS"][:, 2], -estimates(scenario)["RLS"][:, 2]
    assert abs(np.median(ls) - 0.5) < 0.05
    assert np.median(rls) < np.median(ls) - 0.1
    assert np.mean(rls < ls) >= 0.9
