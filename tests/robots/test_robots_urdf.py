"""The generic URDF robot: Newton–Euler torques and regressor vs pinocchio, base parameters, inputs."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from urdf_cases import TREE_URDF, pin_maps, pin_model, pin_torques_and_regressor, random_states

from idkit.robots.urdf import URDFRobot
from idkit.robots.urdf_model import ASSETS, parse_urdf


@pytest.fixture(params=["cylindrical", "tree", "kuka"])
def urdf(request) -> str:
    """URDF text or path: the shipped cylindrical robot, the branched test robot, the KUKA arm."""
    if request.param == "kuka":
        return str(request.getfixturevalue("kuka_dir") / "kuka_lwr4.urdf")
    return {"cylindrical": str(ASSETS / "cylindrical.urdf"), "tree": TREE_URDF}[request.param]


@functools.cache
def robot_for(urdf: str, **options: bool) -> URDFRobot:
    """One robot per URDF and options for the whole module (the base-parameter search takes time)."""
    return URDFRobot(urdf, **options)


@pytest.fixture
def kuka(kuka_dir) -> URDFRobot:
    return robot_for(str(kuka_dir / "kuka_lwr4.urdf"), friction=True, offset=True)


def test_matches_pinocchio_torques_regressor_and_parameters(urdf):
    """Torques, standard regressor and CAD parameters equal pinocchio's to 1e-9 (joints mapped by name)."""
    robot = robot_for(urdf)
    model = pin_model(urdf)
    rows, cols = pin_maps(robot, model)
    nominal = robot.nominal_params()
    pin_params = np.concatenate([model.inertias[i].toDynamicParameters() for i in range(1, model.njoints)])
    np.testing.assert_allclose(nominal.numpy(), pin_params[cols], rtol=0, atol=1e-12)
    q, qd, qdd = random_states(robot, 200, seed=7)
    tau_pin, y_pin = pin_torques_and_regressor(robot, model, q, qd, qdd)
    tau = robot.inverse_dynamics(nominal, q, qd, qdd).numpy()
    np.testing.assert_allclose(tau, tau_pin[:, rows], rtol=0, atol=1e-9 * max(1.0, np.abs(tau_pin).max()))
    y = robot.standard_regressor(q, qd, qdd).numpy()
    np.testing.assert_allclose(
        y, y_pin[:, rows][:, :, cols], rtol=0, atol=1e-9 * max(1.0, np.abs(y_pin).max())
    )


def test_joint_order_and_welded_links_follow_the_urdf():
    """Depth-first body order; fixed links merged into their moving parent, root-welded ones dropped."""
    tree = parse_urdf(TREE_URDF)
    assert tree.joint_names == ("j1", "j2", "j3", "j4")
    assert tree.parents == (-1, 0, 1, 0)
    assert tree.link_names == ("a", "b", "c", "d")
    # The welded tool (0.4 kg) rides on body "b"; the pedestal (3 kg) is welded to the root: dropped.
    masses = [body.inertial[0] for body in tree.bodies]
    assert masses == pytest.approx([2.0, 1.5 + 0.4, 0.8, 0.5], abs=1e-15)


def test_friction_and_offset_terms(kuka):
    """``fc sign(qd) + fv qd + offset`` per joint on top of the rigid body, and their regressor columns."""
    q, qd, qdd = random_states(kuka, 20, seed=3)
    n = kuka.n_joints
    params = kuka.nominal_params().clone()
    fc, fv, off = (torch.linspace(0.5, 2.0, n, dtype=torch.float64) * s for s in (1.0, 3.0, -0.7))
    params[-3 * n :] = torch.cat([fc, fv, off])
    rigid = kuka.inverse_dynamics(kuka.nominal_params(), q, qd, qdd)
    expected = rigid + fc * torch.sign(qd) + fv * qd + off
    torch.testing.assert_close(kuka.inverse_dynamics(params, q, qd, qdd), expected, rtol=0, atol=1e-12)
    torch.testing.assert_close(kuka.standard_regressor(q, qd, qdd) @ params, expected, rtol=0, atol=1e-10)
    assert kuka.param_names[-3 * n :: n] == ("lwr_0_joint.fc", "lwr_0_joint.fv", "lwr_0_joint.offset")


def test_base_regressor_reproduces_the_dynamics(kuka):
    """``Y @ base_params(p) == inverse_dynamics(p)`` for parameters far from the CAD values."""
    q, qd, qdd = random_states(kuka, 100, seed=11)
    lower, upper = kuka.bounds()
    params = lower + (upper - lower) * torch.rand(
        4, kuka.n_params, generator=torch.Generator().manual_seed(0), dtype=torch.float64
    )
    tau = kuka.inverse_dynamics(params, q, qd, qdd)
    linear = torch.einsum("snb,kb->ksn", kuka.regressor(q, qd, qdd), kuka.base_params(params))
    torch.testing.assert_close(linear, tau, rtol=0, atol=1e-10 * tau.abs().max().item())


def test_base_map_structure_and_inverse(kuka):
    """``K[:, base] = I``; ``base_params ∘ params_from_base = id``; ``params_from_base(K p0) = p0``."""
    k = kuka.base_map
    torch.testing.assert_close(
        k[:, list(kuka.base.indices)], torch.eye(len(kuka.base_param_names), dtype=torch.float64)
    )
    alpha = kuka.base_params(kuka.nominal_params()) + torch.randn(
        5, k.shape[0], generator=torch.Generator().manual_seed(1), dtype=torch.float64
    )
    torch.testing.assert_close(kuka.base_params(kuka.params_from_base(alpha)), alpha, rtol=0, atol=1e-12)
    nominal = kuka.nominal_params()
    torch.testing.assert_close(kuka.params_from_base(kuka.base_params(nominal)), nominal, rtol=0, atol=1e-12)
    # Friction and offset are identifiable on their own (base columns, not regrouped).
    for name in kuka.param_names[-3 * kuka.n_joints :]:
        assert name in kuka.base_param_names


def test_base_rank_is_stable_and_matches_pinocchio_regressor_rank(urdf):
    """The rank is seed-independent and equals the SVD rank of pinocchio's stacked regressor."""
    robot = robot_for(urdf)
    ranks = {len(robot.base_param_names)} | {len(URDFRobot(urdf, seed=s).base_param_names) for s in (1, 2)}
    assert len(ranks) == 1
    model = pin_model(urdf)
    _, y_pin = pin_torques_and_regressor(robot, model, *random_states(robot, 100, seed=5))
    stacked = y_pin.reshape(-1, y_pin.shape[-1])
    assert np.linalg.matrix_rank(stacked, tol=1e-9 * np.abs(stacked).max()) == ranks.pop()


def test_kuka_groups_read_like_the_textbook(kuka):
    """Distal masses regroup onto proximal first moments with the link offsets as coefficients."""
    groups = dict(zip(kuka.base_param_names, kuka.base_param_groups, strict=True))
    # Joint 1 (vertical axis) sees only Izz of link 1 plus Izz of link 2 (whose axis is horizontal).
    assert groups["lwr_1_link.IzzR"] == "lwr_1_link.Izz +1*lwr_2_link.Izz"
    # Link 3's origin is 0.2 m up link 2's z axis, links 4..7 hang 0.4 m up it.
    assert groups["lwr_2_link.mczR"].startswith(
        "lwr_2_link.mcz +0.2*lwr_3_link.m +1*lwr_3_link.mcz +0.4*lwr_4_link.m"
    )
    assert "lwr_1_link.m" not in kuka.base_param_names  # the first link's mass never acts


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_null_space_of_base_map_does_not_move_the_torques(seed):
    """Parameters differing by a null vector of ``K`` give the same torques (they are unidentifiable)."""
    robot = robot_for(TREE_URDF, friction=True, offset=True)
    gen = torch.Generator().manual_seed(seed)
    _, _, vh = torch.linalg.svd(robot.base_map)
    null = vh[len(robot.base_param_names) :].T @ torch.randn(
        vh.shape[0] - len(robot.base_param_names), generator=gen, dtype=torch.float64
    )
    q, qd, qdd = robot.random_states(10, gen)
    p = robot.nominal_params()
    torch.testing.assert_close(
        robot.inverse_dynamics(p + null, q, qd, qdd),
        robot.inverse_dynamics(p, q, qd, qdd),
        rtol=0,
        atol=1e-10,
    )


def test_batched_regressor_path_equals_newton_euler_and_sees_in_place_changes(kuka_dir):
    """Parameter batches go through the kept regressor; single sets on new states through the RNEA."""
    kuka = URDFRobot(str(kuka_dir / "kuka_lwr4.urdf"), friction=True, offset=True)  # nothing kept yet
    q, qd, qdd = random_states(kuka, 30, seed=2)
    gen = torch.Generator().manual_seed(3)
    params = kuka.nominal_params() + 0.1 * torch.randn(3, kuka.n_params, generator=gen, dtype=torch.float64)
    direct = torch.stack([kuka.inverse_dynamics(p, q, qd, qdd) for p in params])  # cache still empty
    assert kuka._regressor_cache is None
    batched = kuka.inverse_dynamics(params, q, qd, qdd)
    assert kuka._regressor_cache is not None
    torch.testing.assert_close(batched, direct, rtol=0, atol=1e-11 * direct.abs().max().item())
    q.add_(0.3)  # in place: the kept regressor must not be reused
    moved = torch.stack([kuka.inverse_dynamics(p, q, qd, qdd) for p in params])
    torch.testing.assert_close(kuka.inverse_dynamics(params, q, qd, qdd), moved, rtol=0, atol=1e-9)
    assert not torch.allclose(moved, direct)
