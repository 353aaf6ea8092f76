"""Every public function of idkit.sim, checked against MuJoCo itself or a closed form (the issue: "sim/
has 27 tests for 2,000 lines")."""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np
import pytest
import torch

from idkit.optim.levenberg import BlockJacobian
from idkit.sim.drive import match_commands
from idkit.sim.initial import robust_states
from idkit.sim.model import load_model, logged_state
from idkit.sim.problem import channel_scales, channel_spread, noise_scale
from idkit.sim.quantities import select_unknowns, set_quantity, write_quantity
from idkit.sim.segments import stretches
from idkit.sim.shooting import Shooting
from idkit.sim.timing import interpolate, readout
from idkit.sim.uncertainty import uncertainty
from idkit.testing import rollout_cases as cases


@pytest.fixture(scope="module")
def problem():
    return cases.conformance_problem()


def test_noise_scale_is_the_white_noises_sigma_on_a_smooth_signal():
    rng = np.random.default_rng(0)
    t = np.linspace(0, 10, 20000)
    smooth = np.column_stack([np.sin(t), 3 * np.cos(0.5 * t)])
    sigma = np.array([1e-3, 2e-2])
    found = noise_scale(smooth + sigma * rng.standard_normal(smooth.shape))
    np.testing.assert_allclose(found, sigma, rtol=0.05)  # 20,000 draws: the MAD's error is ~1 %
    assert np.all(noise_scale(smooth) < 1e-3 * sigma)  # a smooth signal has next to no 4th difference


def test_channel_spread_and_scales(problem):
    log = problem.samples
    x = np.hstack([log.q, log.qd])
    iqr = np.percentile(x, 75, axis=0) - np.percentile(x, 25, axis=0)
    np.testing.assert_allclose(channel_spread(log), iqr)
    still = replace(log, q=np.zeros_like(log.q) + [0.0, 2.0], qd=np.zeros_like(log.qd))
    np.testing.assert_array_equal(channel_spread(still), [1.0, 2.0, 1.0, 1.0])  # 0 → 1; constant → |x|
    scales = channel_scales(log)  # a noiseless log: the floor, a millionth of the spread
    np.testing.assert_allclose(scales, np.maximum(noise_scale(x), 1e-6 * iqr))
    np.testing.assert_allclose(problem.scales(), scales)
    np.testing.assert_allclose(problem.spreads(), iqr / scales)


def test_robust_states_replace_a_glitched_start_and_keep_a_clean_one():
    t = np.arange(100) * 0.01
    q = np.column_stack([np.sin(t), t**2])
    qd = np.column_stack([np.cos(t), 2 * t])
    glitched = q.copy()
    glitched[50, 0] += 0.3
    noise = np.full(4, 1e-4)
    q0, qd0 = robust_states(t, glitched, qd, np.array([20, 50]), noise)
    np.testing.assert_allclose(q0[1, 0], np.sin(0.5), atol=1e-6)  # the cubic's value, not the spike
    np.testing.assert_array_equal(q0[0], q[20])  # a clean sample is kept exactly
    np.testing.assert_array_equal(qd0, qd[[20, 50]])


def test_the_model_its_joints_actuators_and_state():
    sim = load_model(cases.ARM7)
    model = sim.model
    assert sim.joint_names() == tuple(f"j{i}" for i in range(1, 8)) and sim.timestep == model.opt.timestep
    assert len(sim.actuator_names()) == model.nu == 14
    driven = [sim.actuated_joint(a) for a in range(model.nu)]
    assert driven == model.actuator_trnid[:, 0].tolist() and sorted(set(driven)) == list(range(7))
    assert sim.state_size() == mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    with pytest.raises(ValueError, match="nope"):
        sim.joint_id("nope")
    spec = sim.copy_spec()
    spec.option.timestep = 0.01
    assert spec.compile().opt.timestep == 0.01 and sim.timestep == 0.002  # a copy: the model unchanged
    q, qd = np.linspace(0.1, 0.7, 7), np.linspace(-1, 1, 7)
    state = logged_state(sim, sim.joint_names(), q, qd)
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, state, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    np.testing.assert_array_equal(data.qpos, q)
    np.testing.assert_array_equal(data.qvel, qd)


def test_commands_drive_actuators_and_describe_says_which():
    case = cases.case_b()
    sim = load_model(case.model)
    drive = match_commands(sim, case.fit)
    shown = drive.describe(sim, case.fit)
    assert len(shown) == sim.model.nu and set(shown.values()) == set(case.fit.command_names)


def test_setting_a_quantity_in_place_equals_writing_it_into_the_spec():
    sim = load_model(cases.ARM7)
    unknowns = select_unknowns(sim, ("j2",), ("damping", "kp"))
    model = sim.model.__copy__() if hasattr(sim.model, "__copy__") else load_model(cases.ARM7).model
    spec = sim.copy_spec()
    for unknown, value in zip(unknowns.items, (3.5, 77.0), strict=True):
        for target in unknown.targets:
            set_quantity(model, unknown.kind, target, value)
            write_quantity(spec, sim, unknown.kind, target, value)
    compiled = spec.compile()
    for field in ("dof_damping", "actuator_gainprm", "actuator_biasprm"):
        np.testing.assert_allclose(getattr(model, field), getattr(compiled, field))
    assert model.dof_damping[1] == 3.5


def test_unknowns_joints_apply_and_set_const():
    sim = load_model(cases.ARM7)
    unknowns = select_unknowns(sim, ("j1", "j3"), ("armature", "kv", "command_delay"))
    assert unknowns.joints(sim) == [0, 2, 0, 2, None]
    assert unknowns.delay_index == 4 and unknowns.needs_set_const  # armature: mj_setConst after it
    model = load_model(cases.ARM7).model
    unknowns.apply(model, np.array([0.2, 0.3, 5.0, 6.0, 0.01]))
    assert model.dof_armature[[0, 2]].tolist() == [0.2, 0.3]


def test_stretches_between_gaps_and_excluded_rows():
    t = np.r_[np.arange(10), np.arange(20, 30)] * 0.01  # a gap after sample 9
    excluded = np.zeros(20, dtype=bool)
    excluded[[3, 4, 15]] = True
    assert stretches(t) == [(0, 10), (10, 20)]
    assert stretches(t, excluded) == [(0, 3), (5, 10), (10, 15), (16, 20)]


def test_interpolation_is_exact_for_a_cubic_between_the_rows():
    """Hermite interpolation with the velocities as slopes reproduces a cubic trajectory exactly."""
    dt = 0.01
    position = lambda s: 1 + 2 * s - 3 * s**2 + 4 * s**3  # noqa: E731
    velocity = lambda s: 2 - 6 * s + 12 * s**2  # noqa: E731
    grid = np.arange(1, 6) * dt  # the state rows after steps 0..4
    times = np.array([0.0, 0.013, 0.025, 0.037])  # logged samples off the grid
    view = readout(times, 0, times.size, dt)
    q, qd = interpolate(
        np.array([[position(0.0)]]), np.array([[velocity(0.0)]]),
        position(grid)[None, :, None], velocity(grid)[None, :, None], view, dt,
    )  # fmt: skip
    np.testing.assert_allclose(q[0, :, 0], position(times[view.samples]), atol=1e-12)


def test_the_batch_simulator_predicts_each_candidate_as_alone(problem):
    unknowns = problem.robot.unknowns
    start = unknowns.vector("start")
    values = np.stack([start, 1.5 * start])
    simulator = problem.simulator()
    try:
        q, qd = simulator.predict(values)
        q0, _ = simulator.predict(values[:1])
        q1, _ = simulator.predict(values[1:])
        assert simulator.counter.rollouts > 0 and len(simulator.models(values)) == 2
    finally:
        simulator.close()
    np.testing.assert_array_equal(q[0], q0[0])
    np.testing.assert_array_equal(q[1], q1[0])
    assert not np.allclose(q[0], q[1])


def test_the_problem_cost_is_the_cost_of_its_error_and_head_keeps_the_first_samples(problem):
    values = problem.robot.nominal_params()
    cost = problem.evaluate(values)
    simulator = problem.simulator()
    try:
        error = torch.from_numpy(problem.error(values.numpy()[None], simulator))
        expected = problem.cost(error, torch.from_numpy(problem.measured(simulator)))
    finally:
        simulator.close()
    assert float(cost) == pytest.approx(float(expected[0]), rel=1e-12)
    assert problem.head(50).samples.n_samples == 50
    lower, upper = problem.robot.bounds()
    assert torch.all(lower < values) and torch.all(values < upper)
    a, b = problem.generator(), problem.generator()
    assert torch.equal(torch.rand(3, generator=a), torch.rand(3, generator=b))
    problem.head(50).check_identifiable()
    many = replace(problem, segment=0.004)  # 2-sample segments: 1 predicted sample each
    predicted = sum(b - a - 1 for a, b in many.segments())
    assert 4 * predicted < 4 * problem.samples.n_samples


def test_the_shooting_jacobian_is_the_residuals_derivative(problem):
    simulator = problem.simulator()
    try:
        shooting = Shooting(problem, simulator, free_initial=True)
        z = problem.robot.unknowns.to_coordinates(problem.robot.unknowns.vector("start"))
        x = shooting.start(z)
        r = shooting.residual(x[:, None])
        jac = shooting.jacobian(x[:, None], r)
        for column in (0, 1, len(z)):  # two unknowns and an initial-state offset
            h = 1e-5 if column < len(z) else 1e-1
            up, down = x.copy(), x.copy()
            up[column] += h
            down[column] -= h
            central = (shooting.residual(up[:, None]) - shooting.residual(down[:, None]))[:, 0] / (2 * h)
            unit = np.zeros(jac.shape[1])
            unit[column] = 1.0
            got = _times(jac, unit)
            assert np.linalg.norm(got - central) <= 1e-3 * np.linalg.norm(central)
    finally:
        simulator.close()


def _times(jac: BlockJacobian, v: np.ndarray) -> np.ndarray:
    out = jac.dense @ v[: jac.dense.shape[1]]
    for row_start, row_stop, col_start, values in jac.blocks:
        out[row_start:row_stop] += values @ v[col_start : col_start + values.shape[1]]
    return out


def test_uncertainty_of_a_linear_least_squares_fit_is_the_textbook_covariance():
    """Residuals r = y − A z: covariance s² (AᵀA)⁻¹ with s² = RSS / (M − p) (linear loss, κ = mean u² ·
    M/(M − p)); a lower bound of 0 makes the coordinate linear, value / width, so σ is the coordinate's
    times the box's width."""
    sim = load_model(cases.ARM7)
    unknowns = select_unknowns(sim, ("j1", "j2"), ("damping",), bounds={"damping": [0.0, 20.0]})
    rng = np.random.default_rng(3)
    m = 400
    a = rng.standard_normal((m, 2))
    residual = 0.1 * rng.standard_normal(m)
    scale = np.sqrt(m)
    found = uncertainty(BlockJacobian(a / scale), residual / scale, 1.0, "linear", unknowns, np.full(2, 0.5))
    s2 = residual @ residual / (m - 2)
    expected = np.sqrt(np.diag(s2 * np.linalg.inv(a.T @ a))) * 20.0  # the width of [0, 20]
    np.testing.assert_allclose([found.std[n] for n in unknowns.names], expected, rtol=1e-9)
    assert not found.flat and found.at_bound == []
