"""Excitation optimisation: hard limits on a dense grid (box, effort, self-collision), the criterion it
reports, seeds, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit.excitation.collision import self_collision
from idkit.excitation.effort import nominal_torques
from idkit.excitation.feasible import fit_into_limits, largest_feasible_scale, scale_motion
from idkit.excitation.fourier import FourierExcitation
from idkit.excitation.optimize import _adam_search, optimize_excitation
from idkit.interfaces import Robot
from idkit.robots.cylindrical import CylindricalRobot
from idkit.robots.urdf import URDFRobot
from tests.excitation.arm_cases import arm_urdf

SMALL = {"swarms": 2, "particles": 16, "iterations": 15, "adam_steps": 10}

#: Eq. (38) typed from the paper: rows theta1, d2, d3; columns q, qd, qdd as (lower, upper).
EQ38 = np.array(
    [
        [(-math.pi, math.pi), (-4, 4), (-3, 3)],
        [(0, 1), (-2, 2), (-2, 2)],
        [(0, 1), (-1.5, 1.5), (-1, 1)],
    ]
)


def fourier_numpy(options: dict, t: np.ndarray) -> tuple[np.ndarray, ...]:
    """Swevers' series from the options alone: ``(q, qd, qdd)`` ``[T, n]`` and the per-term radii."""
    a, b, offset = np.array(options["a"]), np.array(options["b"]), np.array(options["offset"])
    w = 2 * math.pi / options["period"] * np.arange(1, a.shape[1] + 1)
    s, c = np.sin(t[:, None, None] * w), np.cos(t[:, None, None] * w)  # [T, 1, K]
    q = offset + (a / w * s - b / w * c).sum(-1)
    qd = (a * c + b * s).sum(-1)
    qdd = (-a * w * s + b * w * c).sum(-1)
    return q, qd, qdd, np.hypot(a, b), w


@pytest.fixture(scope="module")
def result():
    return optimize_excitation(CylindricalRobot(), seed=3, **SMALL)


def test_optimised_motion_stays_within_eq38_between_grid_points(result):
    """On a grid 10× finer than the check grid, no sample leaves eq. (38) by more than the
    interpolation bound ``h²/8 · max|x''|`` of the check grid (h = 1 ms: below 1e-5 here)."""
    assert torch.count_nonzero(result.excess_after) == 0
    t = np.linspace(0.0, 10.0, 100_001)
    q, qd, qdd, radius, w = fourier_numpy(result.excitation.options(), t)
    h = 10.0 / (len(result.grid) - 1)
    for v, x in enumerate((q, qd, qdd)):
        curvature = (radius * w ** (v + 1)).sum(-1)  # bound on |x''| per joint
        slack = h**2 / 8 * curvature
        assert (x >= EQ38[:, v, 0] - slack).all() and (x <= EQ38[:, v, 1] + slack).all()
        assert slack.max() < 1e-5


def test_reported_criterion_equals_numpy_and_beats_eq39(result):
    t = np.arange(1, 11, dtype=np.float64)
    q, qd, qdd, _, _ = fourier_numpy(result.excitation.options(), t)
    rows = []
    for (_, _, d3), (th_d, _, d3_d), (th_dd, d2_dd, d3_dd) in zip(q, qd, qdd, strict=True):
        rows += [
            [th_dd, 0.0, 2 * d3 * d3_d * th_d + d3**2 * th_dd, 2 * d3_d * th_d + 2 * d3 * th_dd],
            [0.0, d2_dd + 9.81, d2_dd + 9.81, 0.0],
            [0.0, 0.0, d3_dd - d3 * th_d**2, -(th_d**2)],
        ]
    w = np.array(rows)
    assert result.after == pytest.approx(np.linalg.cond(w / np.linalg.norm(w, axis=0)), rel=1e-9)
    assert result.before == pytest.approx(36.11, abs=0.01)
    assert result.after < result.before / 2
    # Eq. (39) itself leaves eq. (38): d2 < 0 (by 0.089 m at worst), reported, not hidden.
    assert result.excess_before[0, 1] == pytest.approx(0.0893, abs=1e-4)
    assert torch.count_nonzero(result.excess_before) == 1


def test_samples_are_the_optimised_motion_at_the_sample_times(result):
    t, q, qd, qdd = result.samples()
    assert torch.equal(t, torch.arange(1, 11, dtype=torch.float64))
    for a, b in zip((q, qd, qdd), result.excitation(t), strict=True):
        assert torch.equal(a, b)


@given(seed=st.integers(0, 2**31 - 1))
@settings(max_examples=3, deadline=None)
def test_same_seed_same_excitation(seed):
    cylindrical = CylindricalRobot()
    budget = {**SMALL, "iterations": 5, "adam_steps": 3}
    first = optimize_excitation(cylindrical, seed=seed, **budget)
    again = optimize_excitation(cylindrical, seed=seed, **budget)
    assert torch.equal(first.excitation.to_vector(), again.excitation.to_vector())
    other = optimize_excitation(cylindrical, seed=seed + 1, **budget)
    assert not torch.equal(first.excitation.to_vector(), other.excitation.to_vector())


def test_d_optimality_improves_on_eq39(cylindrical):
    result = optimize_excitation(cylindrical, criterion="logdet", seed=0, **SMALL)
    assert result.after > result.before
    assert torch.count_nonzero(result.excess_after) == 0


@given(seed=st.integers(0, 2**31 - 1), spread=st.floats(0.1, 3.0))
@settings(max_examples=25, deadline=None)
def test_fit_into_limits_makes_any_candidate_feasible_and_keeps_feasible_ones(seed, spread):
    family, limits = FourierExcitation(3), CylindricalRobot().motion_limits()
    lower, upper = family.coefficient_box(limits)
    g = torch.Generator().manual_seed(seed)
    middle, half = (upper + lower) / 2, (upper - lower) / 2
    candidates = middle + spread * half * (
        2 * torch.rand(8, lower.numel(), generator=g, dtype=torch.float64) - 1
    )
    candidates[:, :3] = candidates[:, :3].clamp(lower[:3], upper[:3])  # offsets inside the position range
    grid = torch.linspace(0.0, 10.0, 501, dtype=torch.float64)
    fitted = fit_into_limits(family, candidates, limits, grid)
    assert torch.count_nonzero(limits.excess(*family.evaluate(fitted, grid))) == 0
    torch.testing.assert_close(fitted[:, :3], candidates[:, :3], rtol=0, atol=0)  # offsets untouched
    ratio = fitted[:, 3:] / candidates[:, 3:]
    assert (ratio <= 1).all() and (ratio >= 0).all()
    inside = (limits.excess(*family.evaluate(candidates, grid)) == 0).flatten(1).all(1)
    torch.testing.assert_close(fitted[inside], candidates[inside], rtol=1e-11, atol=0)


def test_urdf_limits_need_accelerations_then_are_respected():
    robot = URDFRobot("cylindrical")
    limits = robot.motion_limits()
    assert torch.isinf(limits.upper[2]).all()
    with pytest.raises(ValueError, match="no finite position, velocity or acceleration limit"):
        free = limits.replace("position", -math.inf, math.inf).replace("velocity", -math.inf, math.inf)
        optimize_excitation(robot, limits=free, **SMALL)
    bounded = limits.replace("acceleration", -2.0, 2.0)
    result = optimize_excitation(robot, limits=bounded, seed=1, **SMALL)
    assert torch.count_nonzero(result.excess_after) == 0
    assert result.after < float("inf")


class NoLimits(Robot):
    joint_names = ("a",)
    param_names = ("m",)

    def bounds(self):
        return torch.zeros(1), torch.ones(1)

    def inverse_dynamics(self, params, q, qd, qdd):
        return params[..., 0, None, None] * qdd


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"method": "bfgs"}, "unknown method 'bfgs'; use one of pso, adam, pso\\+adam"),
        ({"criterion": "aopt"}, "unknown excitation criterion"),
        ({"particles": 0}, "particles must be an integer >= 1"),
        ({"t_end": 0.0}, r"^optimize_excitation: t_end must be a finite number > 0, got 0\.0$"),
        (
            {"learning_rate": 0.0},
            r"^optimize_excitation: learning_rate must be a finite number > 0, got 0\.0$",
        ),
        ({"learning_rate": math.inf}, r"learning_rate must be a finite number > 0, got inf$"),
        ({"excitation": "nope"}, "unknown excitation 'nope'"),
        (
            {
                "excitation": "paper",
                "options": {"amplitude": [[1.0]] * 2, "omega": [[1.0]] * 2, "offset": [0.0] * 2},
            },
            "moves 2 joints, but robot CylindricalRobot has 3",
        ),
    ],
)
def test_bad_options_are_named(cylindrical, options, match):
    with pytest.raises((ValueError, LookupError), match=match):
        optimize_excitation(cylindrical, **{**SMALL, **options})


def test_a_robot_without_limits_says_so():
    with pytest.raises(NotImplementedError, match="NoLimits declares no joint motion limits"):
        optimize_excitation(NoLimits(), **SMALL)


def test_largest_feasible_scale_finds_the_closed_form_scale_and_only_returns_tested_ones():
    family = FourierExcitation(
        2, 3, 4.0, offset=[0.1, -0.2], a=[[1.0, 0.5, -0.2]] * 2, b=[[0.3, 0.0, 0.4]] * 2
    )
    grid = torch.linspace(0.0, 4.0, 401, dtype=torch.float64)
    deviation = float((family(grid)[0] - torch.tensor([0.1, -0.2], dtype=torch.float64)).abs().max())
    tested = []

    def small(coefficients):
        ok = bool((family.evaluate(coefficients, grid)[0] - torch.tensor([0.1, -0.2])).abs().max() <= 0.25)
        tested.append((coefficients, ok))
        return ok

    scale = largest_feasible_scale(family, family.to_vector(), small)
    assert scale == pytest.approx(0.25 / deviation, abs=2**-20) and scale <= 0.25 / deviation
    assert any(
        ok
        and torch.equal(
            c, scale_motion(family, family.to_vector(), torch.full((2,), scale, dtype=torch.float64))
        )
        for c, ok in tested
    )
    assert largest_feasible_scale(family, family.to_vector(), lambda c: True) == 1.0
    with pytest.raises(ValueError, match="its rest pose \\(the offsets\\) already fails"):
        largest_feasible_scale(family, family.to_vector(), lambda c: False)


@pytest.fixture(scope="module")
def arm_result():
    """The table arm (``arm_cases``) with its table raised to 0.35 m (the arm touches it for
    q2 > 0.0834), a tight effort limit on j2 (its static load is up to 8.6 N·m) and the
    self-collision test: the search knows effort and offset poses, the final stage both."""
    pytest.importorskip("pinocchio")
    robot = URDFRobot(arm_urdf(0.35).replace('upper="1.5" effort="40"', 'upper="1.5" effort="10"'))
    limits = robot.motion_limits().replace("acceleration", -3.0, 3.0)
    test = self_collision(robot)
    found = optimize_excitation(
        robot, options={"rest": True, "period": 5.0}, n_samples=25, t_end=5.0, limits=limits,
        check_points=2501, collision=test, seed=0, **SMALL,
    )  # fmt: skip
    return robot, test, found


def test_the_optimised_arm_motion_rests_keeps_effort_and_touches_nothing(arm_result):
    robot, test, result = arm_result
    q, qd, qdd = result.excitation(result.grid)
    assert torch.count_nonzero(result.excess_after) == 0
    tau = nominal_torques(robot, q, qd, qdd)
    assert (tau.abs() <= torch.as_tensor(robot.effort_limits)).all()
    assert float(tau[:, 1].abs().max()) > 8.0  # the j2 limit (10 N·m) is close
    assert float(q[:, 1].max()) <= 0.0834 + 1e-3  # below the table's edge of contact
    assert test.contacts(q.numpy()) == []
    for end in (0, -1):
        assert qd[end].abs().max() < 1e-12 and qdd[end].abs().max() < 1e-12
    assert result.effort.tolist() == [40.0, 10.0, 10.0, 10.0]


def test_a_shrunk_motion_says_why_and_what_it_cost(arm_result):
    _, _, result = arm_result
    details = result.details
    assert 0 < details["shrunk_by"] < 1 and "self-collision" in details["shrunk_for"]
    # Shrinking cost conditioning (here a lot: the table leaves little room); the reported value is
    # the shrunk motion's.
    assert details["criterion_before_shrink"] < result.after


def test_the_written_out_adam_is_torch_adam():
    """Same points as ``torch.optim.Adam`` (projected on the cube) on a function with a known gradient."""
    target = torch.tensor([[0.2, 0.9, 0.5], [1.3, -0.4, 0.7]], dtype=torch.float64)

    def objective(unit):
        return ((unit - target) ** 2 * torch.tensor([1.0, 10.0, 0.1])).sum(-1) + unit[..., 0] ** 4

    starts = torch.tensor([[0.5, 0.5, 0.5], [0.1, 0.8, 0.3]], dtype=torch.float64)
    found = _adam_search(objective, starts, 40, 0.05)
    unit = starts.clone().requires_grad_(True)
    reference = torch.optim.Adam([unit], lr=0.05)
    best, best_loss = starts.clone(), torch.full((2,), math.inf, dtype=torch.float64)
    for step in range(41):
        value = objective(unit)
        improved = value.detach() < best_loss
        best = torch.where(improved[:, None], unit.detach(), best)
        best_loss = torch.where(improved, value.detach(), best_loss)
        if step == 40:
            break
        reference.zero_grad()
        value.sum().backward()
        reference.step()
        with torch.no_grad():
            unit.clamp_(0.0, 1.0)
    torch.testing.assert_close(found, best, rtol=0, atol=1e-14)
    assert found[1, 1] == 0.0  # its target is outside the cube: the wall binds
