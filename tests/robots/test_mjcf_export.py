"""identified.xml: MuJoCo loads it, mj_inverse on it equals idkit's torques with the identified
parameters, and reading it back returns them (URDF -> idkit -> MJCF -> idkit too)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from test_mjcf import ARM, mj_torques, moving_states
from test_urdf_export import perturbed
from urdf_cases import TREE_URDF

from idkit.model import IdentifiedModel
from idkit.reports import single as single_report
from idkit.robots.mjcf import MJCFRobot
from idkit.robots.mjcf_export import identified_mjcf, urdf_to_mjcf, write_identified_mjcf
from idkit.robots.urdf import URDFRobot
from idkit.studies import single

mujoco = pytest.importorskip("mujoco")


def kuka_urdf(kuka_dir) -> str:
    return str(kuka_dir / "kuka_lwr4.urdf")


def kuka_mjcf(kuka_dir) -> str:
    with pytest.warns(UserWarning, match="collision mesh"):
        return urdf_to_mjcf(kuka_urdf(kuka_dir))


@pytest.fixture(params=["arm", "kuka"])
def mjcf_robot(request) -> MJCFRobot:
    if request.param == "kuka":
        return MJCFRobot(kuka_mjcf(request.getfixturevalue("kuka_dir")), friction=True, offset=True)
    return MJCFRobot(ARM, friction=True, offset=True)


def test_mj_inverse_on_the_identified_xml_equals_idkit(mjcf_robot, tmp_path):
    params = perturbed(mjcf_robot, seed=0)
    path = write_identified_mjcf(mjcf_robot, params, tmp_path / "identified.xml")
    model = mujoco.MjModel.from_xml_path(str(path))
    q, qd, qdd = moving_states(mjcf_robot, 50, seed=1)
    n = mjcf_robot.n_joints
    offsets = params[-n:]
    expected = (mjcf_robot.inverse_dynamics(params, q, qd, qdd) - offsets).numpy()
    np.testing.assert_allclose(
        mj_torques(model, q, qd, qdd, mjcf_robot.joint_names), expected, atol=1e-8, rtol=0
    )
    # The offsets (a sensor bias, no MJCF field) travel as MuJoCo user data.
    stored = [model.numeric(f"idkit:{joint}.offset").data[0] for joint in mjcf_robot.joint_names]
    np.testing.assert_array_equal(stored, offsets.numpy())
    back = MJCFRobot(str(path), friction=True)
    np.testing.assert_allclose(back.nominal_params()[: 10 * n].numpy(), params[: 10 * n].numpy(), atol=1e-12)
    np.testing.assert_array_equal(back.mujoco_model.frictionloss, params[-3 * n : -2 * n].numpy())
    np.testing.assert_array_equal(back.mujoco_model.damping, params[-2 * n : -n].numpy())


@pytest.fixture(params=["tree", "kuka"])
def urdf_source(request) -> str:
    if request.param == "kuka":
        return kuka_urdf(request.getfixturevalue("kuka_dir"))
    return TREE_URDF


def test_round_trip_urdf_idkit_mjcf_idkit(urdf_source):
    """The URDF robot's parameters, written as MJCF and read back, are the same parameters."""
    robot = URDFRobot(urdf_source, friction=True)
    params = perturbed(robot, seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the KUKA's mesh note
        text = identified_mjcf(robot, params)
    back = MJCFRobot(text, friction=True)
    assert back.joint_names == robot.joint_names and back.link_names == robot.link_names
    n = robot.n_joints
    np.testing.assert_allclose(back.nominal_params()[: 10 * n].numpy(), params[: 10 * n].numpy(), atol=1e-12)
    np.testing.assert_array_equal(back.mujoco_model.frictionloss, params[-2 * n : -n].numpy())
    np.testing.assert_array_equal(back.mujoco_model.damping, params[-n:].numpy())
    # Placements pass through MuJoCo's 6-digit writer: the torques agree to that precision.
    q, qd, qdd = moving_states(robot, 30, seed=3)
    tau = robot.inverse_dynamics(params, q, qd, qdd)
    np.testing.assert_allclose(
        back.inverse_dynamics(params, q, qd, qdd), tau, atol=1e-4 * tau.abs().max(), rtol=0
    )


def test_welded_bodies_and_inertia_compiler_options():
    """A welded body's inertial is merged into its moving body (so written as zero), compiler options
    that would rescale the written inertials are dropped, and a fit without friction writes none."""
    source = ARM.replace(
        '<option gravity="0 0 -9.7"/>', '<option gravity="0 0 -9.7"/><compiler boundmass="0.01"/>'
    )
    robot = MJCFRobot(source)
    params = perturbed(robot, seed=4)
    text = identified_mjcf(robot, params)
    assert "boundmass" not in text
    assert '<body name="tool" pos="0 0.05 0.2" quat="0.9 0.1 0.2 0.3">' in text
    model = mujoco.MjModel.from_xml_string(text)
    assert model.body("tool").mass[0] == 0.0
    # Fitted without friction: MuJoCo must not add the source's damping and frictionloss on top.
    assert not model.dof_damping.any() and not model.dof_frictionloss.any()
    np.testing.assert_allclose(MJCFRobot(text).nominal_params().numpy(), params.numpy(), atol=1e-12)


def test_includes_and_meshes_load_from_another_folder(tmp_path):
    """identified.xml is written elsewhere than its source: includes are inlined, mesh paths absolute."""
    folder = tmp_path / "model"
    (folder / "meshes").mkdir(parents=True)
    (folder / "meshes" / "tet.obj").write_text(
        "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
    )
    (folder / "side.xml").write_text(
        '<mujoco><body name="side" pos="0.2 0 0"><joint name="elbow" axis="0 1 0"/>'
        '<geom type="mesh" mesh="tet"/><inertial pos="0.05 0 0" mass="0.5" diaginertia="0.001 0.001 0.001"/>'
        "</body></mujoco>"
    )
    (folder / "arm.xml").write_text(
        '<mujoco model="m"><compiler meshdir="meshes"/><asset><mesh name="tet" file="tet.obj"/></asset>'
        '<worldbody><body name="upper"><joint name="shoulder" axis="0 0 1"/>'
        '<inertial pos="0.1 0 0" mass="2" diaginertia="0.01 0.02 0.03"/><include file="side.xml"/>'
        "</body></worldbody></mujoco>"
    )
    robot = MJCFRobot(str(folder / "arm.xml"))
    params = perturbed(robot, seed=5)
    path = write_identified_mjcf(robot, params, tmp_path / "identified.xml")
    assert "<include" not in path.read_text()
    np.testing.assert_allclose(MJCFRobot(str(path)).nominal_params().numpy(), params.numpy(), atol=1e-12)


def test_identifying_an_identified_xml_again_replaces_its_numbers():
    robot = MJCFRobot(ARM, offset=True)
    first = identified_mjcf(robot, perturbed(robot, seed=6))
    again = MJCFRobot(first, offset=True)
    second = identified_mjcf(again, perturbed(again, seed=7))
    assert second.count('name="idkit:elbow.offset"') == 1
    assert second.count("<inertial") == first.count("<inertial")


def test_non_physical_inertials_are_refused_in_one_line():
    robot = MJCFRobot(ARM)
    params = robot.nominal_params().clone()
    params[10] = -1.0  # sleeve mass
    with pytest.raises(ValueError, match=r"sleeve \(mass -1\)") as caught:
        identified_mjcf(robot, params)
    assert "estimator=pcls" in str(caught.value) and "\n" not in str(caught.value)
    params = robot.nominal_params().clone()
    params[4 + 30] += 0.05  # side: Ixx grows past Iyy + Izz (the triangle inequality)
    with pytest.raises(ValueError, match=r"MuJoCo refuses non-physical inertials: side \(principal moments"):
        identified_mjcf(robot, params)


def test_a_fit_writes_identified_xml_or_says_why_not(tmp_path):
    """single.run: an mjcf robot's fit writes identified.xml; a non-physical one warns in one line and
    the other outputs are still written; a urdf robot writes it only when asked."""
    result = single.run(robot=MJCFRobot(ARM, friction=True), estimator="ls", cost=None, n_samples=60)
    written = single_report.write(result, tmp_path / "a", plots=False)
    assert MJCFRobot(written["identified_mjcf"]).link_names == ("upper", "sleeve", "wrist", "side")
    assert result.urdf is None  # an mjcf robot has no identified.urdf
    bad = dict(result.estimate.params)
    bad["side.m"] = -1.0
    unphysical = IdentifiedModel.from_params(MJCFRobot(ARM, friction=True), bad)
    with pytest.warns(UserWarning, match=r"identified.xml not written: mjcf export: .*side \(mass -1\)"):
        assert single._identified_mjcf(unphysical, None) is None
    urdf = URDFRobot(TREE_URDF)
    nominal = IdentifiedModel.from_params(urdf, urdf.nominal_params())
    assert single._identified_mjcf(nominal, None) is None
    assert MJCFRobot(single._identified_mjcf(nominal, True)).joint_names == urdf.joint_names
    assert single._identified_mjcf(unphysical, False) is None
