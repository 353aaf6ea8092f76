"""robot=mjcf: a MuJoCo model read into the URDF robot's tree; torques equal mujoco.mj_inverse."""

from __future__ import annotations

import sys

import numpy as np
import pytest
import torch
from urdf_cases import TREE_URDF, random_states

from idkit.cli.errors import one_line
from idkit.registry import PluginLoadError
from idkit.robots.mjcf import MJCFRobot
from idkit.robots.urdf import URDFRobot
from idkit.robots.urdf_model import ASSETS
from idkit.studies.build import build

mujoco = pytest.importorskip("mujoco")

# ruff: noqa: E501  (the test MJCF below keeps one element per line)

# What a URDF cannot say and the tree must get right: hinge axes through a joint `pos` off the body
# origin, `ref` (qpos0 != 0) on a hinge and a slide joint, a `<frame>`, degrees (the MJCF default),
# euler and axisangle orientations, `fullinertia`, inertia from a geom (no <inertial>), a body
# welded to a moving one (merged) and one welded to the world (dropped), a branch, gravity 9.7.
ARM = """<mujoco model="arm">
  <option gravity="0 0 -9.7"/>
  <default><joint damping="0.3" frictionloss="0.2"/></default>
  <worldbody>
    <body name="pedestal" pos="0 0 0.2"><geom type="box" size="0.1 0.1 0.1"/></body>
    <frame pos="0.05 0 0.3" euler="0 0 20">
      <body name="upper" pos="0 0.1 0.2" euler="10 -20 30">
        <joint name="shoulder" pos="0.02 -0.03 0.05" axis="0 0.6 0.8" ref="15" range="-120 120" actuatorfrcrange="-50 40"/>
        <inertial pos="0.1 0.02 0.2" mass="2" fullinertia="0.05 0.04 0.03 0.001 -0.002 0.003"/>
        <body name="sleeve" pos="0.1 0 0.4" axisangle="1 0 0 30">
          <joint name="slide" type="slide" axis="1 0 1" ref="0.05" range="0 0.3" damping="1.1" frictionloss="0.4"/>
          <geom type="capsule" size="0.03 0.1" pos="0 0 0.1" density="900"/>
          <body name="tool" pos="0 0.05 0.2" quat="0.9 0.1 0.2 0.3">
            <inertial pos="0.01 0.02 0.03" quat="0.8 0.2 -0.1 0.3" mass="0.4" diaginertia="0.002 0.0015 0.001"/>
            <body name="wrist" pos="0.03 0 0.1">
              <joint name="twist" axis="1 0 0" pos="0 0.01 0"/>
              <inertial pos="0 0 0.05" mass="0.7" diaginertia="0.004 0.003 0.002"/>
            </body>
          </body>
        </body>
        <body name="side" pos="-0.1 0 0.3">
          <joint name="elbow" axis="0 1 0" range="-60 60"/>
          <inertial pos="0.05 0 0" mass="0.5" diaginertia="0.001 0.001 0.001"/>
        </body>
      </body>
    </frame>
  </worldbody>
</mujoco>
"""


def mj_torques(model, q: torch.Tensor, qd: torch.Tensor, qdd: torch.Tensor, joints) -> np.ndarray:
    """``mj_inverse``'s ``qfrc_inverse`` per sample ``[N, n]`` in idkit's joint order, contacts and
    joint-limit forces off (the tree models neither)."""
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT) | int(
        mujoco.mjtDisableBit.mjDSBL_LIMIT
    )
    data = mujoco.MjData(model)
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name) for name in joints]
    qpos = [model.jnt_qposadr[i] for i in ids]
    dofs = [model.jnt_dofadr[i] for i in ids]
    out = []
    for x, v, a in zip(q.numpy(), qd.numpy(), qdd.numpy(), strict=True):
        data.qpos[qpos] = x
        data.qvel[dofs], data.qacc[dofs] = v, a
        mujoco.mj_inverse(model, data)
        out.append(data.qfrc_inverse[dofs].copy())
    return np.stack(out)


def moving_states(robot: URDFRobot, n: int, seed: int) -> tuple[torch.Tensor, ...]:
    """Random states whose speeds are at least 1 (MuJoCo's ``frictionloss`` is a soft constraint that
    equals ``fc sign(qd)`` only once a joint moves: at 1e-2 rad/s it does not on the KUKA)."""
    q, qd, qdd = random_states(robot, n, seed)
    return q, torch.sign(qd) * (1.0 + qd.abs()), qdd


def with_mujoco_friction(robot: MJCFRobot) -> torch.Tensor:
    """Nominal parameters with ``fc`` = the model's ``frictionloss`` and ``fv`` = its ``damping``."""
    params, n = robot.nominal_params().clone(), robot.n_joints
    params[-2 * n : -n] = torch.as_tensor(robot.mujoco_model.frictionloss)
    params[-n:] = torch.as_tensor(robot.mujoco_model.damping)
    return params


def test_tree_of_the_test_arm():
    robot = MJCFRobot(ARM)
    assert robot.joint_names == ("shoulder", "slide", "twist", "elbow")
    assert robot.link_names == ("upper", "sleeve", "wrist", "side")
    assert robot.tree.parents == (-1, 0, 1, 0)
    assert [b.kind for b in robot.tree.bodies] == ["revolute", "prismatic", "revolute", "revolute"]
    assert robot.tree.bodies[1].welded == ("tool",)
    assert robot.gravity == pytest.approx(9.7)
    shoulder = robot.tree.bodies[0]
    np.testing.assert_allclose(shoulder.limits, np.radians([-120, 120]))
    assert shoulder.effort == 40.0 and robot.tree.bodies[2].limits is None
    assert robot.effort_limits is None  # twist and elbow declare none
    np.testing.assert_allclose(robot.mujoco_model.damping, [0.3, 1.1, 0.3, 0.3])


def test_ref_moves_the_pose_not_q():
    """idkit's ``q`` is MuJoCo's ``qpos``: at ``q = ref`` the bodies sit where the XML draws them."""
    robot = MJCFRobot(ARM)
    assert robot.tree.bodies[1].limits == (0.0, 0.3)
    model = mujoco.MjModel.from_xml_string(ARM)
    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0
    mujoco.mj_kinematics(model, data)
    upper = robot.tree.bodies[0]
    angle = np.radians(15)
    k = np.array(
        [
            [0, -upper.axis[2], upper.axis[1]],
            [upper.axis[2], 0, -upper.axis[0]],
            [-upper.axis[1], upper.axis[0], 0],
        ]
    )
    turned = upper.rotation @ (np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k)
    np.testing.assert_allclose(turned, data.xmat[model.body("upper").id].reshape(3, 3), atol=1e-12)


@pytest.mark.parametrize("friction", [False, True])
def test_torques_equal_mj_inverse_on_the_test_arm(friction):
    robot = MJCFRobot(ARM, friction=friction)
    model = mujoco.MjModel.from_xml_string(ARM)
    if not friction:
        model.dof_damping[:] = 0.0
        model.dof_frictionloss[:] = 0.0
    params = with_mujoco_friction(robot) if friction else robot.nominal_params()
    q, qd, qdd = moving_states(robot, 60, seed=3)
    expected = mj_torques(model, q, qd, qdd, robot.joint_names)
    np.testing.assert_allclose(
        robot.inverse_dynamics(params, q, qd, qdd).numpy(), expected, rtol=0, atol=1e-8
    )
    regressor = robot.standard_regressor(q, qd, qdd)
    np.testing.assert_allclose((regressor @ params).numpy(), expected, rtol=0, atol=1e-8)
    assert np.abs(expected).max() > 1.0  # not a vacuous comparison


def test_armature_and_drive_options_pass_through_and_equal_mj_inverse():
    """A model's joint ``armature`` is the a-priori ``<joint>.armature``; with it mj_inverse still agrees."""
    text = edit('<joint name="elbow"', '<joint name="elbow" armature="0.1"')
    text = text.replace('<joint name="shoulder"', '<joint name="shoulder" armature="0.25"', 1)
    robot = MJCFRobot(text, armature=True, effort_scale=[2.0, 3.0, 4.0, 5.0])
    prior = dict(zip(robot.param_names, robot.nominal_params().tolist(), strict=True))
    assert prior["elbow.armature"] == pytest.approx(0.1) and prior["shoulder.armature"] == pytest.approx(0.25)
    assert prior["twist.armature"] == 0.0
    model = mujoco.MjModel.from_xml_string(text)
    model.dof_damping[:] = 0.0
    model.dof_frictionloss[:] = 0.0
    q, qd, qdd = moving_states(robot, 40, seed=5)
    expected = mj_torques(model, q, qd, qdd, robot.joint_names)
    torques = robot.inverse_dynamics(robot.nominal_params(), q, qd, qdd).numpy()
    np.testing.assert_allclose(torques, expected, rtol=0, atol=1e-8)
    without = MJCFRobot(
        text.replace('armature="0.1"', 'armature="0"').replace('armature="0.25"', 'armature="0"')
    )
    assert (
        np.abs(expected - without.inverse_dynamics(without.nominal_params(), q, qd, qdd).numpy()).max() > 1e-3
    )
    np.testing.assert_allclose(robot.joint_torques(torch.ones(1, 4)).numpy(), [[2.0, 3.0, 4.0, 5.0]])


def test_the_tree_urdf_converted_by_mujoco():
    """MuJoCo's conversion of the shared URDF case: idkit's MJCF robot equals mj_inverse on it, and
    equals the URDF robot up to the 6 significant digits MuJoCo writes placements with."""
    from idkit.robots.mjcf_export import urdf_to_mjcf

    text = urdf_to_mjcf(TREE_URDF)
    robot, urdf = MJCFRobot(text), URDFRobot(TREE_URDF)
    assert robot.joint_names == urdf.joint_names and robot.link_names == urdf.link_names
    q, qd, qdd = moving_states(robot, 40, seed=4)
    model = mujoco.MjModel.from_xml_string(text)
    tau = robot.inverse_dynamics(robot.nominal_params(), q, qd, qdd).numpy()
    np.testing.assert_allclose(tau, mj_torques(model, q, qd, qdd, robot.joint_names), rtol=0, atol=1e-8)
    reference = urdf.inverse_dynamics(urdf.nominal_params(), q, qd, qdd).numpy()
    np.testing.assert_allclose(tau, reference, rtol=1e-4, atol=1e-4 * np.abs(reference).max())


def test_a_urdf_mujoco_refuses_is_refused_in_one_line():
    """The cylindrical robot's thin rods have a zero principal moment, which MuJoCo does not take."""
    from idkit.robots.mjcf_export import urdf_to_mjcf

    with pytest.raises(ValueError, match="MuJoCo cannot convert .*cylindrical.urdf: .*'link2'") as caught:
        urdf_to_mjcf(str(ASSETS / "cylindrical.urdf"))
    assert "\n" not in str(caught.value)


@pytest.mark.kuka
def test_kuka_converted_by_mujoco(kuka_dir):
    """The judged model: MuJoCo's own conversion of the KUKA URDF, with its damping and frictionloss."""
    from idkit.robots.mjcf_export import urdf_to_mjcf

    with pytest.warns(UserWarning, match="collision mesh"):
        text = urdf_to_mjcf(kuka_dir / "kuka_lwr4.urdf")
    robot = MJCFRobot(text, friction=True)
    urdf = URDFRobot(str(kuka_dir / "kuka_lwr4.urdf"))
    q, qd, qdd = moving_states(robot, 50, seed=5)
    tau = robot.inverse_dynamics(with_mujoco_friction(robot), q, qd, qdd).numpy()
    model = mujoco.MjModel.from_xml_string(text)
    np.testing.assert_allclose(tau, mj_torques(model, q, qd, qdd, robot.joint_names), rtol=0, atol=1e-8)
    np.testing.assert_allclose(robot.mujoco_model.frictionloss, [0.5, 0.8, 0.4, 0.3, 0.2, 0.1, 0.05])
    # The KUKA's numbers have at most 6 digits but for the 1/12 m l² inertias (MuJoCo rounds them).
    rigid = robot.nominal_params()[:70] - urdf.nominal_params()
    assert rigid.abs().max() < 1e-7


def edit(old: str, new: str) -> str:
    assert old in ARM
    return ARM.replace(old, new, 1)


REFUSED = {
    "ball joint": (
        edit('type="slide" axis="1 0 1"', 'type="ball"'),
        "joint 'slide' \\(body 'sleeve'\\) is a ball joint",
    ),
    "free joint": (
        edit(
            "<worldbody>", '<worldbody><body name="ball"><freejoint name="loose"/><geom size="0.1"/></body>'
        ),
        "joint 'loose' \\(body 'ball'\\) is a free joint",
    ),
    "two joints": (
        edit('<joint name="elbow"', '<joint name="extra" axis="1 0 0"/><joint name="elbow"'),
        "body 'side' has 2 joints \\(extra, elbow\\)",
    ),
    "equality": (
        ARM.replace(
            "</mujoco>", '<equality><joint name="couple" joint1="elbow" joint2="twist"/></equality></mujoco>'
        ),
        "equality constraints.*'couple' \\(joint\\)",
    ),
    "tendon": (
        ARM.replace(
            "</mujoco>",
            '<tendon><fixed name="belt" stiffness="3"><joint joint="elbow" coef="1"/><joint joint="twist" coef="-1"/></fixed></tendon></mujoco>',
        ),
        "tendon 'belt' \\(stiffness\\)",
    ),
    "stiffness": (
        edit('<joint name="elbow"', '<joint name="elbow" stiffness="2"'),
        "joint 'elbow' \\(body 'side'\\) has stiffness=2",
    ),
    "armature": (
        edit('<joint name="elbow"', '<joint name="elbow" armature="0.1"'),
        "joints with armature: elbow \\(0.1\\); identify it with robot.armature=true",
    ),
    "gravcomp": (edit('<body name="side"', '<body name="side" gravcomp="1"'), "body 'side' has gravcomp=1"),
    "fluid": (
        edit('<option gravity="0 0 -9.7"/>', '<option gravity="0 0 -9.7" density="1.2"/>'),
        "fluid forces",
    ),
    "gravity": (edit('gravity="0 0 -9.7"', 'gravity="0 9.7 0"'), "gravity=0 9.7 0"),
    "unnamed joint": (
        edit('<joint name="elbow" axis', "<joint axis"),
        "joint '#3' \\(body 'side'\\) has no name",
    ),
    "no joint": (
        "<mujoco><worldbody><body name='b'><geom size='1'/></body></worldbody></mujoco>",
        "no hinge or slide joint",
    ),
    "urdf": (TREE_URDF, "is a URDF.*use robot=urdf"),
    "not xml": ("<mujoco>", "not valid XML"),
    "mujoco refuses": (edit('mass="0.5"', 'mass="-1"'), "MuJoCo cannot load <MJCF text>: .*mass"),
}


@pytest.mark.parametrize("case", list(REFUSED))
def test_what_the_tree_cannot_model_is_refused_in_one_line(case):
    text, message = REFUSED[case]
    with pytest.raises(ValueError, match=message) as caught:
        build("robot", {"_name_": "mjcf", "mjcf": text})
    line = one_line(caught.value)
    assert line is not None and "\n" not in line and line.startswith("mjcf: ")


def test_missing_file_and_missing_mujoco(tmp_path, monkeypatch):
    with pytest.raises(FileNotFoundError, match="arm.xml"):
        MJCFRobot(str(tmp_path / "arm.xml"))
    (tmp_path / "arm.xml").write_text((ASSETS / "arm.xml").read_text())
    with pytest.raises(ValueError) as caught:  # before: "neither MJCF text, an existing file, ..."
        MJCFRobot(str(tmp_path))
    assert str(caught.value) == f"mjcf: {tmp_path} is a directory, not a MJCF file; .xml files in it: arm.xml"
    monkeypatch.setitem(sys.modules, "mujoco", None)  # `import mujoco` now raises ImportError
    with pytest.raises(PluginLoadError, match=r"pip install robot-idkit\[mjcf\]") as caught:
        MJCFRobot(ARM)
    assert (
        one_line(caught.value) == "mjcf: MuJoCo models need the mujoco package: pip install robot-idkit[mjcf]"
    )


def test_errors_name_the_format():
    robot = MJCFRobot(ARM)
    with pytest.raises(ValueError, match="^mjcf: params need 40 values"):
        robot.inverse_dynamics(torch.zeros(3), *random_states(robot, 2, seed=0))


def test_the_shipped_arm_is_the_default_and_equals_mj_inverse():
    robot = MJCFRobot(friction=True)
    assert robot.joint_names == ("j1", "j2", "j3") and robot.gravity == pytest.approx(9.81)
    model = mujoco.MjModel.from_xml_path(str(ASSETS / "arm.xml"))
    q, qd, qdd = moving_states(robot, 30, seed=6)
    tau = robot.inverse_dynamics(with_mujoco_friction(robot), q, qd, qdd).numpy()
    np.testing.assert_allclose(tau, mj_torques(model, q, qd, qdd, robot.joint_names), rtol=0, atol=1e-8)
    with pytest.raises(FileNotFoundError, match=r"shipped: arm\)"):
        MJCFRobot("no_such_robot")
