"""Drives as parts of the URDF robot: armature, effort scale, friction models.

References: pinocchio's ``rnea`` with ``model.armature`` (rigid body + ``Ia q̈``), MuJoCo's
``mj_inverse`` with ``dof_armature`` and ``dof_damping``, and the friction formulas written out in
numpy (Gaz et al.'s sigmoid literally as printed in the paper).
"""

from __future__ import annotations

import sys
import warnings

import numpy as np
import pytest
import torch
from hydra.core.global_hydra import GlobalHydra

from idkit.cli import app
from idkit.data.io import save_samples
from idkit.data.scenarios import simulate
from idkit.estimators.physical import PhysicallyConsistentLS
from idkit.problem import Problem
from idkit.registry import create
from idkit.robots.drives import read_armatures, with_drive_values
from idkit.robots.urdf import URDFRobot
from idkit.robots.urdf_export import identified_urdf
from idkit.studies.single import run
from tests.urdf_cases import TREE_URDF, pin_model, pin_torques_and_regressor, random_states

#: (mechanicalReduction, rotor_inertia) of the test robot's joints: armature = I N².
ROTORS = {"j1": (50.0, 2e-5), "j2": (20.0, 1e-3), "j3": (100.0, 1e-5), "j4": (80.0, 3e-5)}


def with_transmissions(urdf: str, rotors: dict[str, tuple[float, float]]) -> str:
    """``urdf`` with one ROS SimpleTransmission per joint carrying idkit's armature convention."""
    parts = [
        f'<transmission name="{joint}_trans"><type>transmission_interface/SimpleTransmission</type>'
        f'<joint name="{joint}"><hardwareInterface>EffortJointInterface</hardwareInterface></joint>'
        f'<actuator name="{joint}_motor"><mechanicalReduction>{ratio}</mechanicalReduction>'
        f"<rotor_inertia>{inertia}</rotor_inertia></actuator></transmission>"
        for joint, (ratio, inertia) in rotors.items()
    ]
    return urdf.replace("</robot>", "\n".join(parts) + "\n</robot>")


TREE_DRIVES = with_transmissions(TREE_URDF, ROTORS)


def quiet_robot(urdf: str, **options) -> URDFRobot:
    """A robot built without the merged-armature warning (tested on its own)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return URDFRobot(urdf, **options)


def drive_values(robot: URDFRobot, seed: int) -> torch.Tensor:
    """Random drive parameters inside the robot's box; the URDF's inertials."""
    lower, upper = robot.bounds()
    u = torch.rand(robot.n_params, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    params = robot.nominal_params().clone()
    nb = 10 * len(robot.link_names)
    params[nb:] = lower[nb:] + (upper[nb:] - lower[nb:]) * u[nb:] * 0.3 + 0.1 * (upper[nb:] - lower[nb:])
    return params


def friction_by_hand(robot: URDFRobot, params: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Friction torque ``[N, n]`` of each model written out in numpy, independent of drives.py."""
    value = {
        s: params[[robot.param_names.index(f"{j}.{s}") for j in robot.joint_names]]
        for s in robot.drives.suffixes
    }
    viscous = value["fv"] * qd
    if robot.friction is True:
        return value["fc"] * np.sign(qd) + viscous
    if robot.friction == "asymmetric":
        return np.where(qd > 0, value["fc_pos"], np.where(qd < 0, -value["fc_neg"], 0.0)) + viscous
    phi1, phi2, phi3 = value["phi1"], value["phi2"], value["phi3"]
    return phi1 / (1 + np.exp(-phi2 * (qd + phi3))) - phi1 / (1 + np.exp(-phi2 * phi3)) + viscous


@pytest.mark.parametrize("friction", [True, "asymmetric", "sigmoid"])
def test_drive_torques_equal_pinocchio_with_armature_plus_friction_by_hand(friction):
    robot = quiet_robot(TREE_DRIVES, friction=friction, armature=True, offset=True)
    params = drive_values(robot, seed=3)
    q, qd, qdd = random_states(robot, 40, seed=1)
    model = pin_model(TREE_URDF)
    rows = [model.joints[model.getJointId(name)].idx_v for name in robot.joint_names]
    armature = params[[robot.param_names.index(f"{j}.armature") for j in robot.joint_names]].numpy()
    model.armature[rows] = armature
    rigid = URDFRobot(TREE_URDF)
    torques, _ = pin_torques_and_regressor(rigid, model, q, qd, qdd)
    offset = params[[robot.param_names.index(f"{j}.offset") for j in robot.joint_names]].numpy()
    expected = torques[:, rows] + friction_by_hand(robot, params.numpy(), qd.numpy()) + offset
    np.testing.assert_allclose(
        robot.inverse_dynamics(params, q, qd, qdd).numpy(), expected, rtol=0, atol=1e-10
    )
    batch = torch.stack([params, drive_values(robot, seed=4)])  # the cached-regressor path, two shapes
    both = robot.inverse_dynamics(batch, q, qd, qdd)
    np.testing.assert_allclose(both[0].numpy(), expected, rtol=0, atol=1e-10)
    torch.testing.assert_close(both[1], robot.inverse_dynamics(batch[1], q.clone(), qd.clone(), qdd.clone()))
    reference = params.clone()  # the regressor is exact at the reference sigmoid shape
    shapes = [robot.param_names.index(name) for name in robot.drives.names_where(lambda t: t.shape)]
    reference[shapes] = robot.nominal_params()[shapes]
    torch.testing.assert_close(
        robot.standard_regressor(q, qd, qdd) @ reference, robot.inverse_dynamics(reference, q, qd, qdd)
    )


def test_armature_and_viscous_friction_equal_mujoco_mj_inverse():
    mujoco = pytest.importorskip("mujoco")
    robot = quiet_robot(TREE_DRIVES, friction=True, armature=True)
    params = drive_values(robot, seed=5)
    params[[robot.param_names.index(f"{j}.fc") for j in robot.joint_names]] = (
        0.0  # frictionloss is a constraint
    )
    model = mujoco.MjModel.from_xml_string(
        TREE_URDF.replace("</robot>", '<mujoco><compiler discardvisual="true"/></mujoco></robot>')
    )
    data = mujoco.MjData(model)
    for j in robot.joint_names:
        dof = model.joint(j).dofadr[0]
        model.dof_armature[dof] = float(params[robot.param_names.index(f"{j}.armature")])
        model.dof_damping[dof] = float(params[robot.param_names.index(f"{j}.fv")])
        model.dof_frictionloss[dof] = 0.0
    q, qd, qdd = random_states(robot, 20, seed=2)
    expected = robot.inverse_dynamics(params, q, qd, qdd).numpy()
    for i in range(q.shape[0]):
        for k, j in enumerate(robot.joint_names):
            joint = model.joint(j)
            data.qpos[joint.qposadr[0]] = q[i, k]
            data.qvel[joint.dofadr[0]] = qd[i, k]
            data.qacc[joint.dofadr[0]] = qdd[i, k]
        mujoco.mj_inverse(model, data)
        got = [data.qfrc_inverse[model.joint(j).dofadr[0]] for j in robot.joint_names]
        np.testing.assert_allclose(got, expected[i], rtol=0, atol=1e-6)


def test_a_priori_armature_is_read_from_the_transmissions():
    robot = quiet_robot(TREE_DRIVES, armature=True)
    got = robot.nominal_params()[-robot.n_joints :].numpy()
    np.testing.assert_allclose(got, [ROTORS[j][1] * ROTORS[j][0] ** 2 for j in robot.joint_names], rtol=1e-15)
    assert quiet_robot(TREE_URDF, armature=True).nominal_params()[-4:].tolist() == [0.0] * 4


@pytest.mark.parametrize(
    ("element", "message"),
    [
        ("<rotor_inertia>-1e-5</rotor_inertia>", "transmission 'j1_trans' has <rotor_inertia>-1e-5"),
        ("<rotor_inertia>abc</rotor_inertia>", "transmission 'j1_trans' has <rotor_inertia>abc"),
    ],
)
def test_a_bad_rotor_inertia_is_named(element, message):
    bad = TREE_DRIVES.replace("<rotor_inertia>2e-05</rotor_inertia>", element)
    with pytest.raises(ValueError, match=message):
        read_armatures(bad)


def test_two_transmissions_of_one_joint_are_refused():
    """The second used to replace the first without a word: which rotor is the joint's?"""
    twice = with_transmissions(TREE_DRIVES, {"j1": (10.0, 1e-4)})
    with pytest.raises(ValueError, match=r"transmission 'j1_trans' gives joint 'j1' a <rotor_inertia>, and"):
        read_armatures(twice)


def test_merged_armature_is_named_and_kept_at_its_a_priori_value():
    with pytest.warns(UserWarning, match=r"j1\.armature merges with the link inertia \(a\.IzzR\)"):
        robot = URDFRobot(TREE_DRIVES, friction=True, armature=True)
    assert robot.a_priori_params == ("j1.armature", "j4.armature")  # j4 rotates d about a: like j1
    assert robot.unidentifiable == (
        "j1.armature merges with the link inertia (a.IzzR): not identifiable, kept at its a-priori "
        "value 0.05",
        "j4.armature merges with the link inertia (d.IyyR): not identifiable, kept at its a-priori "
        "value 0.192",
    )
    truth = robot.nominal_params()
    truth[robot.param_names.index("j1.armature")] = 0.3  # the data see only a.Izz + j1.armature
    back = robot.params_from_base(robot.base_params(truth))
    assert (
        back[robot.param_names.index("j1.armature")]
        == robot.nominal_params()[robot.param_names.index("j1.armature")]
    )
    torch.testing.assert_close(robot.base_params(back), robot.base_params(truth), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize(
    ("scale", "message"),
    [
        ([1.0, 2.0], r"effort_scale has 2 value\(s\) but the robot has 3 joints \(theta1, d2, d3\)"),
        ([1.0, 0.0, 2.0], r"effort_scale\[1\] = 0 for joint d2 must be a finite factor > 0"),
        ([1.0, 2.0, -3.0], r"effort_scale\[2\] = -3 for joint d3 must be a finite factor > 0"),
    ],
)
def test_a_bad_effort_scale_is_refused_in_one_line(scale, message):
    with pytest.raises(ValueError, match=message):
        create("robot", "urdf", effort_scale=scale)


def test_the_command_refuses_a_bad_effort_scale_in_one_line(monkeypatch, capsys, tmp_path):
    monkeypatch.chdir(tmp_path)  # the run directory Hydra makes
    monkeypatch.setattr(sys, "argv", ["idkit", "robot=urdf", "robot.effort_scale=[1,2]", "estimator=ls"])
    GlobalHydra.instance().clear()
    with pytest.raises(SystemExit) as exit_:
        app.main()
    GlobalHydra.instance().clear()
    said = capsys.readouterr().err.strip().splitlines()
    assert exit_.value.code != 0
    assert len(said) == 1 and "effort_scale has 2 value(s) but the robot has 3 joints" in said[0], said


def test_other_friction_options_are_refused():
    with pytest.raises(ValueError, match="friction='viscous' is not a friction model"):
        URDFRobot("cylindrical", friction="viscous")
    with pytest.raises(ValueError, match="needs friction=true"):
        URDFRobot("cylindrical", friction="asymmetric", stribeck_velocity=0.1)
    with pytest.raises(ValueError, match=r"sigmoid_steepness=\[1.0, 2.0\] needs one finite value or 3"):
        URDFRobot("cylindrical", friction="sigmoid", sigmoid_steepness=[1.0, 2.0])
    # a reference shape outside its box names the option given and the box's own option
    with pytest.raises(
        ValueError,
        match=r"^urdf: sigmoid_steepness=0 \(the reference sigmoid phi2\) leaves its search box \[1, 100\] "
        r"\(steepness_range\); give sigmoid_steepness inside it, or widen steepness_range$",
    ):
        URDFRobot("cylindrical", friction="sigmoid", sigmoid_steepness=0)
    with pytest.raises(ValueError, match=r"sigmoid_shift=\[0, 0.5, 0\] .* \(max_shift\); give sigmoid_shift"):
        URDFRobot("cylindrical", friction="sigmoid", sigmoid_shift=[0, 0.5, 0])


def simulated_current_recording(robot: URDFRobot, truth: torch.Tensor, scale: np.ndarray, path, n: int):
    """Noise-free samples of ``truth`` whose efforts are recorded as ``joint torque / k``."""
    samples = simulate(robot, "clean", seed=0, n_samples=n, params=truth)
    current = samples.tau / torch.as_tensor(scale)
    save_samples(type(samples)(samples.q, samples.qd, samples.qdd, current), path)
    return samples


def check_ls_recovers_armature(urdf: str, truth_of, tmp_path, n_samples: int) -> None:
    """``friction=true armature=true effort_scale=[…] estimator=ls`` on a current recording."""
    options = {"friction": True, "armature": True}
    robot = quiet_robot(urdf, **options)
    truth = truth_of(robot)
    scale = np.linspace(2.0, 9.0, robot.n_joints)  # gear ratio × torque constant, N·m/A
    path, held_out = tmp_path / "current.npz", tmp_path / "held_out.npz"
    simulated_current_recording(robot, truth, scale, path, n_samples)
    # the clean scenario samples one fixed motion: the held-out file samples it at other times
    samples = simulated_current_recording(robot, truth, scale, held_out, n_samples + 37)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        result = run(
            {"_name_": "urdf", "urdf": urdf, **options, "effort_scale": scale.tolist()},
            estimator="ls",
            cost=None,
            data=str(path),
            validate=[str(held_out)],
            identified_urdf=False,
        )
    estimate = result.estimate.params
    separable = [j for j in robot.joint_names if f"{j}.armature" not in robot.a_priori_params]
    assert separable, "no separable armature: the test would check nothing"
    for joint in separable:
        name = f"{joint}.armature"
        assert abs(estimate[name] - float(truth[robot.param_names.index(name)])) <= 1e-3 * abs(
            float(truth[robot.param_names.index(name)])
        ), (name, estimate[name])
    for name in robot.a_priori_params:  # named, and not given a value from the data
        assert estimate[name] == float(robot.nominal_params()[robot.param_names.index(name)])
    unidentifiable = result.estimate.details["uncertainty"]["unidentifiable"]
    assert unidentifiable[: len(robot.unidentifiable)] == list(robot.unidentifiable)
    # The held-out error is in joint torque (N·m): the recording's currents were scaled back.
    rms = result.validation[0].scores.rms
    assert np.max(rms) < 1e-6 * float(samples.tau.abs().max()), rms


def tree_truth(robot: URDFRobot) -> torch.Tensor:
    """The URDF's inertials and armature, Coulomb and viscous friction."""
    n = robot.n_joints
    values = {"fc": [0.2 + 0.1 * k for k in range(n)], "fv": [0.05 + 0.02 * k for k in range(n)]}
    return with_drive_values(robot.param_names, robot.joint_names, robot.nominal_params(), values)


def test_ls_recovers_every_separable_armature_of_the_test_robot_from_currents(tmp_path):
    check_ls_recovers_armature(TREE_DRIVES, tree_truth, tmp_path, n_samples=300)


@pytest.mark.kuka
def test_ls_recovers_the_kuka_armatures_of_joints_3_to_7_from_currents(tmp_path, kuka_dir):
    urdf = str(kuka_dir / "kuka_lwr4.urdf")  # its transmissions give the armature (0.128-0.896 kg m²)
    robot = quiet_robot(urdf, friction=True, armature=True)
    assert robot.a_priori_params == ("lwr_0_joint.armature", "lwr_1_joint.armature")
    check_ls_recovers_armature(urdf, tree_truth, tmp_path, n_samples=600)


def test_identified_urdf_round_trips_the_armature(tmp_path):
    robot = quiet_robot(TREE_DRIVES, friction="asymmetric", armature=True, offset=True)
    params = drive_values(robot, seed=7)
    merged = [robot.param_names.index(name) for name in robot.a_priori_params]
    params[merged] = robot.nominal_params()[merged]  # what every estimator returns for them
    text = identified_urdf(robot, params)
    assert "the armature of j1 merges with the link inertia (not identifiable)" in text
    back = quiet_robot(text, friction="asymmetric", armature=True, offset=True)
    armatures = [robot.param_names.index(f"{j}.armature") for j in robot.joint_names]
    np.testing.assert_allclose(back.nominal_params()[armatures], params[armatures], rtol=1e-14)
    plain = quiet_robot(TREE_URDF, armature=True)  # no transmissions: armature 0 a priori
    params = plain.nominal_params()
    params[-4:] = torch.tensor([0.01, 0.02, 0.03, 0.04])
    bare = identified_urdf(plain, params)
    assert set(read_armatures(bare)) == {"j1", "j2", "j3", "j4"}  # new transmissions where none were
    pin_model(bare)  # pinocchio still loads it


def test_pcls_keeps_armature_nonnegative_and_merged_armature_at_its_prior():
    robot = quiet_robot(TREE_DRIVES, friction=True, armature=True)
    truth = tree_truth(robot)
    for joint in ("j2", "j3"):
        truth[robot.param_names.index(f"{joint}.armature")] = -0.05  # not physical
    samples = simulate(robot, "clean", seed=0, n_samples=200, params=truth)
    estimate = PhysicallyConsistentLS().fit(Problem(robot, samples)).params
    for joint in robot.joint_names:
        assert estimate[f"{joint}.armature"] >= -1e-9
    assert estimate["j1.armature"] == pytest.approx(
        float(robot.nominal_params()[robot.param_names.index("j1.armature")]), rel=1e-6
    )


@pytest.mark.parametrize("friction", [True, "asymmetric"])
def test_a_coulomb_velocity_scale_makes_the_coulomb_term_a_tanh(friction):
    """``coulomb_velocity=v``: the friction by hand with ``tanh(q̇ / v)`` for ``sign(q̇)`` (per joint),
    exactly; 0 and ``auto`` keep the sign; the regressor stays exact (one linear coefficient)."""
    scales = [0.01, 0.02, 0.05, 0.1]
    robot = quiet_robot(TREE_DRIVES, friction=friction, offset=True, coulomb_velocity=scales)
    plain = quiet_robot(TREE_DRIVES, friction=friction, offset=True)
    params = drive_values(robot, seed=5)
    q, qd, qdd = random_states(robot, 40, seed=2)
    qd = qd * torch.logspace(-3, 0, 40, dtype=torch.float64)[:, None]  # slow samples too
    smooth = np.tanh(qd.numpy() / np.array(scales))
    value = {s: params[[robot.param_names.index(f"{j}.{s}") for j in robot.joint_names]].numpy()
             for s in robot.drives.suffixes}  # fmt: skip
    if friction is True:
        coulomb = value["fc"] * smooth
    else:
        coulomb = value["fc_pos"] * (1 + smooth) / 2 - value["fc_neg"] * (1 - smooth) / 2
    sign = friction_by_hand(plain, params.numpy(), qd.numpy()) - value["fv"] * qd.numpy()
    expected = plain.inverse_dynamics(params, q, qd, qdd).numpy() - sign + coulomb
    np.testing.assert_allclose(
        robot.inverse_dynamics(params, q, qd, qdd).numpy(), expected, rtol=0, atol=1e-10
    )
    torch.testing.assert_close(
        robot.standard_regressor(q, qd, qdd) @ params, robot.inverse_dynamics(params, q, qd, qdd)
    )
    for keep in (0, "auto", None):
        same = quiet_robot(TREE_DRIVES, friction=friction, offset=True, coulomb_velocity=keep)
        torch.testing.assert_close(
            same.inverse_dynamics(params, q, qd, qdd), plain.inverse_dynamics(params, q, qd, qdd)
        )


def test_tanh_coulomb_equals_the_sigmoid_model_at_zero_shift():
    """``fc tanh(q̇ / v)`` is Gaz et al.'s sigmoid with ``φ1 = 2 fc``, ``φ2 = 2 / v``, ``φ3 = 0``: two
    code paths, one law."""
    v, fc = 0.04, 0.7
    tanh = URDFRobot("cylindrical", friction=True, coulomb_velocity=v)
    sigmoid = URDFRobot("cylindrical", friction="sigmoid", sigmoid_steepness=2 / v)
    qd = torch.linspace(-0.3, 0.3, 61, dtype=torch.float64)[:, None].expand(-1, 3).contiguous()
    q, qdd = torch.zeros_like(qd), torch.zeros_like(qd)
    a = with_drive_values(tanh.param_names, tanh.joint_names, tanh.nominal_params(), {"fc": [fc] * 3})
    b = with_drive_values(
        sigmoid.param_names, sigmoid.joint_names, sigmoid.nominal_params(), {"phi1": [2 * fc] * 3}
    )
    torch.testing.assert_close(tanh.inverse_dynamics(a, q, qd, qdd), sigmoid.inverse_dynamics(b, q, qd, qdd))


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"friction": True, "coulomb_velocity": -0.1}, r"coulomb_velocity=-0.1 needs 'auto', 0 \(the sign\)"),
        ({"friction": True, "coulomb_velocity": "fast"}, r"coulomb_velocity='fast' needs 'auto'"),
        ({"friction": True, "coulomb_velocity": [0.1, 0.2]}, r"or 3 of them \(joints: theta1, d2, d3\)"),
        ({"friction": True, "coulomb_velocity": [0.1, 0.0, 0.2]}, "mixes 0 .the sign. with scales > 0"),
        ({"friction": "sigmoid", "coulomb_velocity": 0.1}, "needs friction=true or 'asymmetric'"),
        ({"coulomb_velocity": 0.1}, "needs friction=true or 'asymmetric', got False"),
    ],
)
def test_a_bad_coulomb_velocity_is_refused_in_one_line(options, message):
    with pytest.raises(ValueError, match=message):
        URDFRobot("cylindrical", **options)
