"""Noise scenarios: bounds of the multiplicative errors, outlier counts, seeds, overrides, errors."""

from __future__ import annotations

import pytest
import torch

from idkit.data.scenarios import (
    SCENARIOS,
    Scenario,
    UnknownScenarioError,
    clean_samples,
    get_scenario,
    simulate,
    simulate_batch,
)
from idkit.data.trajectory import sample_times
from idkit.excitation.fourier import FourierExcitation
from idkit.excitation.paper import PaperExcitation
from idkit.interfaces import Robot
from idkit.problem import SAMPLE_ARRAYS

TRIALS = 300


def noisy_stack(batch) -> torch.Tensor:
    """Noisy arrays as ``[T, 4, N, n]`` (SAMPLE_ARRAYS order)."""
    return torch.stack([batch.q, batch.qd, batch.qdd, batch.tau], dim=1)


def clean_stack(batch) -> torch.Tensor:
    return torch.stack([getattr(batch.clean, k) for k in SAMPLE_ARRAYS])


def test_presets_match_the_paper():
    expected = {
        "clean": (10, 0.0, 0.0, 0, 0.0),
        "state_noise": (10, 0.2, 0.0, 0, 0.0),
        "torque_noise": (10, 0.0, 0.2, 0, 0.0),
        "all_noise": (20, 0.2, 0.2, 0, 0.0),
        "outliers": (10, 0.05, 0.05, 10, 0.7),
    }
    got = {
        name: (s.n_samples, s.state_noise, s.torque_noise, s.n_outliers, s.outlier_noise)
        for name, s in SCENARIOS.items()
    }
    assert got == expected
    assert all(s.name == name for name, s in SCENARIOS.items())


def test_clean_samples_follow_eq39_and_the_dynamics(cylindrical):
    t, clean = clean_samples(cylindrical, 10)
    assert torch.equal(t, sample_times(10))
    q, qd, qdd = PaperExcitation()(t)
    assert torch.equal(clean.q, q) and torch.equal(clean.qd, qd) and torch.equal(clean.qdd, qdd)
    # Independent reference: the regressor form (eq. 23) times the base parameters (eq. 24).
    p = cylindrical.nominal_params()
    tau_ref = cylindrical.regressor(q, qd, qdd) @ cylindrical.base_params(p)
    torch.testing.assert_close(clean.tau, tau_ref, rtol=1e-13, atol=1e-12)
    assert torch.equal(simulate(cylindrical, "clean", seed=5).tau, clean.tau)


def test_an_excitation_replaces_the_robots_motion(cylindrical):
    excitation = FourierExcitation(3, offset=[0.0, 0.5, 0.5])
    batch = simulate_batch(cylindrical, "torque_noise", trials=2, seed=4, excitation=excitation)
    states = excitation(batch.t)
    for got, expected in zip((batch.clean.q, batch.clean.qd, batch.clean.qdd), states, strict=True):
        assert torch.equal(got, expected)
    tau = cylindrical.inverse_dynamics(cylindrical.nominal_params(), *states)
    torch.testing.assert_close(batch.clean.tau, tau)
    # The same seed draws the same relative errors, whatever the motion.
    default = simulate_batch(cylindrical, "torque_noise", trials=2, seed=4)
    assert torch.equal(batch.relative_error, default.relative_error)
    assert torch.equal(simulate(cylindrical, "torque_noise", seed=4, excitation=excitation).tau, batch.tau[0])
    with pytest.raises(ValueError, match="moves 2 joints, but robot CylindricalRobot has 3"):
        simulate(cylindrical, excitation=FourierExcitation(2))


@pytest.mark.parametrize("name", ["clean", "state_noise", "torque_noise", "all_noise"])
def test_noise_stays_within_its_level_and_uses_it(cylindrical, name):
    sc = SCENARIOS[name]
    batch = simulate_batch(cylindrical, name, trials=TRIALS, seed=1)
    noisy, clean = noisy_stack(batch), clean_stack(batch)
    assert noisy.shape == (TRIALS, 4, sc.n_samples, 3)
    level = torch.tensor([sc.state_noise] * 3 + [sc.torque_noise], dtype=torch.float64)[:, None, None]
    deviation = (noisy - clean).abs()
    assert (deviation <= level * clean.abs() * (1 + 1e-12)).all()
    for a, x in enumerate(level.flatten().tolist()):
        ratio = deviation[:, a] / clean[a].abs()
        if x == 0:
            assert torch.equal(noisy[:, a], clean[a].expand_as(noisy[:, a]))
        else:  # uniform on (-x, x): with 300 x 30 draws the extremes come close to x, the mean to 0
            assert ratio.max() > 0.99 * x
            u = batch.relative_error[:, a]
            assert u.mean().abs() < 0.02 * x and (u > 0).float().mean().sub(0.5).abs() < 0.02
    torch.testing.assert_close(noisy, clean * (1 + batch.relative_error), rtol=0, atol=0)
    assert not batch.outliers.any()


def test_state_noise_does_not_leak_into_torques(cylindrical):
    batch = simulate_batch(cylindrical, "state_noise", trials=20, seed=2)
    assert torch.equal(batch.tau, batch.clean.tau.expand(20, -1, -1))
    assert not torch.equal(batch.q, batch.clean.q.expand(20, -1, -1))


def test_outliers_exact_count_and_bounds(cylindrical):
    batch = simulate_batch(cylindrical, "outliers", trials=TRIALS, seed=3)
    noisy, clean = noisy_stack(batch), clean_stack(batch)
    mask = batch.outliers
    assert mask.shape == (TRIALS, 4, 10, 3)
    assert (mask.sum(dim=(1, 2, 3)) == 10).all()
    ratio = (noisy - clean).abs() / clean.abs()
    assert (ratio[mask] <= 0.7 * (1 + 1e-12)).all() and (ratio[~mask] <= 0.05 * (1 + 1e-12)).all()
    # Components beyond 5 % are exactly the outliers that drew |u| > 5 % — at most 10 per trial.
    beyond = ratio > 0.05 * (1 + 1e-12)
    assert not (beyond & ~mask).any() and (beyond.sum(dim=(1, 2, 3)) <= 10).all()
    assert ratio[mask].max() > 0.69 and beyond.sum() > 0.9 * mask.sum()  # U(-0.7, 0.7): 93 % beyond 5 %
    # Outliers land on every array (states and torques) and every sample.
    assert (mask.sum(dim=(0, 2, 3)) > 0).all() and (mask.sum(dim=(0, 1, 3)) > 0).all()


def test_same_seed_same_samples_different_seed_different(cylindrical):
    for name in SCENARIOS:
        a, b = simulate(cylindrical, name, seed=7), simulate(cylindrical, name, seed=7)
        assert all(torch.equal(getattr(a, k), getattr(b, k)) for k in SAMPLE_ARRAYS)
        if name != "clean":
            c = simulate(cylindrical, name, seed=8)
            assert any(not torch.equal(getattr(a, k), getattr(c, k)) for k in SAMPLE_ARRAYS)
    x = simulate_batch(cylindrical, "outliers", trials=4, seed=7)
    y = simulate_batch(cylindrical, "outliers", trials=4, seed=8)
    assert not torch.equal(x.outliers, y.outliers)
    assert len({tuple(s.tau.flatten().tolist()) for s in x}) == 4  # trials differ from each other


def test_trial_i_does_not_depend_on_the_number_of_trials(cylindrical):
    small = simulate_batch(cylindrical, "outliers", trials=3, seed=11)
    large = simulate_batch(cylindrical, "outliers", trials=50, seed=11)
    assert torch.equal(small.relative_error, large.relative_error[:3])
    assert torch.equal(small.outliers, large.outliers[:3])
    one = simulate(cylindrical, "outliers", seed=11)
    assert torch.equal(one.qdd, large[0].qdd) and torch.equal(one.tau, large[0].tau)


def test_overrides_and_config_mapping(cylindrical):
    s = simulate(cylindrical, "all_noise", n_samples=7, torque_noise=0.0)
    assert s.q.shape == (7, 3)
    _, clean = clean_samples(cylindrical, 7)
    assert torch.equal(s.tau, clean.tau)
    cfg = {"name": "outliers", "n_samples": 20}
    sc = get_scenario(cfg)
    assert (sc.n_samples, sc.n_outliers, sc.outlier_noise) == (20, 10, 0.7)
    custom = Scenario(name="mine", n_samples=4, torque_noise=0.1)
    assert get_scenario(custom.as_dict()) == custom and Scenario(**custom.as_dict()) == custom
    assert get_scenario("clean", n_samples=None) == SCENARIOS["clean"]
    batch = simulate_batch(cylindrical, custom, trials=5, seed=0)
    assert batch.scenario == custom and batch.q.shape == (5, 4, 3)


def test_params_override_changes_the_true_torques(cylindrical):
    p = torch.tensor([1.0, 2.0, 0.3, 0.5], dtype=torch.float64)
    s = simulate(cylindrical, "clean", params=p)
    torch.testing.assert_close(s.tau, cylindrical.inverse_dynamics(p, s.q, s.qd, s.qdd), rtol=0, atol=0)
    with pytest.raises(ValueError, match=r"shape \(4,\)"):
        simulate(cylindrical, params=torch.ones(3))


def test_any_robot_can_be_simulated():
    class Mass(Robot):
        joint_names = ("x", "y")
        param_names = ("m",)

        def bounds(self):
            return torch.zeros(1), torch.ones(1)

        def inverse_dynamics(self, params, q, qd, qdd):
            return params[..., 0, None, None] * qdd

    s = simulate(Mass(), "torque_noise", params=torch.tensor([2.0]))
    assert s.tau.shape == (10, 2)
    with pytest.raises(ValueError, match="no nominal parameters"):
        simulate(Mass())


def test_errors_name_the_problem(cylindrical):
    with pytest.raises(UnknownScenarioError) as info:
        simulate(cylindrical, "outlier")
    for name in SCENARIOS:
        assert name in str(info.value)
    with pytest.raises(TypeError, match="valid fields"):
        simulate(cylindrical, "clean", noise=0.1)
    with pytest.raises(ValueError, match="state_noise"):
        Scenario(state_noise=-0.1)
    with pytest.raises(ValueError, match="n_samples"):
        Scenario(n_samples=0)
    with pytest.raises(ValueError, match="exceeds the 12 sample components"):
        simulate(cylindrical, "outliers", n_samples=1, n_outliers=13)
    with pytest.raises(ValueError, match="trials"):
        simulate_batch(cylindrical, "clean", trials=0)


def test_a_robot_whose_torques_have_the_wrong_shape_is_named():
    """A plugin returning ``[n, N]`` (or one number) was blamed on "samples: array 'tau'" before."""

    class Transposed(Robot):
        joint_names = ("x", "y")
        param_names = ("m",)

        def bounds(self):
            return torch.zeros(1), torch.ones(1)

        def inverse_dynamics(self, params, q, qd, qdd):
            return (params[..., 0, None, None] * qdd).transpose(-1, -2)

    with pytest.raises(ValueError) as info:
        simulate(Transposed(), "clean", n_samples=5, params=torch.tensor([2.0]))
    assert str(info.value) == (
        "robot Transposed: inverse_dynamics(params[1], q, qd, qdd [5, 2]) returned (2, 5), not tau [5, 2] "
        "(samples x joints; see the plugin contract)"
    )


def test_n_samples_beyond_the_memory_is_refused_before_anything_is_drawn(cylindrical, monkeypatch):
    import idkit.memory
    from idkit.data import scenarios
    from idkit.memory import SizeError

    # 4 arrays x 1000 samples x 3 joints: 12,000 components, 6 float64 per component and trial
    assert scenarios.simulation_bytes(1000, 3, 2) == 8 * (1000 + 12_000 + 2 * 12_000 * 6)
    monkeypatch.setattr(idkit.memory, "available_memory", lambda: 1_000_000)
    monkeypatch.setattr(scenarios, "clean_samples", lambda *a, **k: pytest.fail("allocated first"))
    with pytest.raises(SizeError) as info:
        simulate(cylindrical, "clean", n_samples=100_000)
    assert str(info.value) == (
        "scenario 'clean': n_samples=100000 (3 joints, 1 trial(s)) needs about 68 MB of memory; this "
        "machine has 1 MB available; fewer n_samples need less"
    )
