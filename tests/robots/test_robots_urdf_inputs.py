"""The URDF robot's inputs, search boxes and plugin contract (no pinocchio needed)."""

from __future__ import annotations

import pytest
import torch

from idkit import registry
from idkit.robots.cylindrical import CylindricalRobot
from idkit.robots.urdf import URDFRobot
from idkit.robots.urdf_model import parse_urdf
from idkit.testing import check_robot

CHAIN = """<robot name="rrp">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0.1 0 0"/><mass value="1"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.03"/></inertial></link>
  <link name="l2"><inertial><origin xyz="0.2 0.05 0"/><mass value="2"/>
    <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.03" iyz="0" izz="0.04"/></inertial></link>
  <link name="l3"><inertial><origin xyz="0 0 0.1"/><mass value="0.5"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.002"/></inertial></link>
  <joint name="r1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="r2" type="{r2_type}"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.3 0 0" rpy="1.5707963267948966 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/>{mimic}</joint>
  <joint name="p3" type="prismatic"><parent link="l2"/><child link="l3"/><origin xyz="0.4 0 0"/>
    <axis xyz="1 0 0"/><limit lower="0" upper="0.3" effort="1" velocity="1"/></joint>
</robot>
"""


def chain(r2_type: str = "revolute", mimic: str = "") -> str:
    return CHAIN.format(r2_type=r2_type, mimic=mimic)


@pytest.mark.parametrize("kind", ["floating", "planar", "ball", "spherical"])
def test_unsupported_joint_type_names_the_joint(kind):
    with pytest.raises(ValueError, match=rf"joint 'r2' has (unknown )?type '{kind}'"):
        URDFRobot(chain(kind))


def test_mimic_joint_is_refused():
    with pytest.raises(ValueError, match="joint 'r2' has <mimic>"):
        URDFRobot(chain(mimic='<mimic joint="r1" multiplier="1"/>'))


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("<robot name='x'><link name='a'/></robot>", "no revolute, continuous or prismatic joint"),
        ("<robot><link name='a'/><link name='b'/></robot>", "expected one root link"),
        ("<robot name='x'><link", "not valid XML"),
        ("<model/>", "expected <robot>"),
        (
            chain().replace('<parent link="l1"/>', '<parent link="nowhere"/>'),
            "parent link 'nowhere' is not defined",
        ),
        (chain().replace('<axis xyz="1 0 0"/>', '<axis xyz="0 0 0"/>'), "joint 'p3' has a zero axis"),
        (chain().replace('xyz="0.4 0 0"', 'xyz="0.4 0"'), "joint 'p3' <origin>: xyz needs 3 numbers"),
        (chain().replace('<joint name="r2"', "<joint"), "a <joint> has no name attribute"),
        (chain().replace('<link name="l3">', "<link>"), "a <link> has no name attribute"),
        (chain().replace('<child link="l2"/>', ""), "joint 'r2': child link None is not defined"),
    ],
)
def test_malformed_urdf_is_explained(text, message):
    with pytest.raises(ValueError, match=message):
        parse_urdf(text)


def test_missing_file_lists_shipped_assets(tmp_path):
    with pytest.raises(FileNotFoundError, match="shipped: .*cylindrical"):
        URDFRobot(str(tmp_path / "absent.urdf"))


def test_a_directory_is_named_as_one(tmp_path):
    """Before: "is neither URDF text, an existing file, nor a shipped asset" — but it exists."""
    (tmp_path / "arm.urdf").write_text(CHAIN.format(r2_type="revolute", mimic=""))
    with pytest.raises(ValueError) as info:
        URDFRobot(str(tmp_path))
    assert str(info.value) == f"urdf: {tmp_path} is a directory, not a URDF file; .urdf files in it: arm.urdf"


@pytest.mark.parametrize("encoding", ["utf-8", "ISO-8859-1", "UTF-16"])
def test_text_with_an_xml_encoding_declaration(encoding, tmp_path):
    """URDF text carrying any ``encoding=`` line parses (as text and as a file in that encoding)."""
    text = f'<?xml version="1.0" encoding="{encoding}"?>\n<!-- café -->\n' + chain()
    from_text = URDFRobot(text)
    path = tmp_path / "rrp.urdf"
    path.write_bytes(text.encode(encoding))
    from_file = URDFRobot(str(path))
    assert from_text.joint_names == from_file.joint_names == ("r1", "r2", "p3")
    torch.testing.assert_close(from_text.nominal_params(), from_file.nominal_params(), rtol=0, atol=0)


def test_continuous_joint_is_revolute_without_limits():
    robot = URDFRobot(chain("continuous"))
    body = robot.tree.bodies[1]
    assert (body.kind, body.limits) == ("revolute", None)


def test_cylindrical_urdf_equals_the_closed_form_model():
    """The shipped cylindrical URDF through the generic RNEA gives eqs. (19)-(21) at the paper's values."""
    robot, closed = URDFRobot("cylindrical"), CylindricalRobot()
    q, qd, qdd = robot.random_states(300, torch.Generator().manual_seed(4))
    expected = closed.inverse_dynamics(closed.nominal_params(), q, qd, qdd)
    torch.testing.assert_close(
        robot.inverse_dynamics(robot.nominal_params(), q, qd, qdd), expected, rtol=0, atol=1e-9
    )


def test_bounds_hold_the_cad_values_and_base_bounds_hold_the_box_image():
    robot = URDFRobot(chain(), friction=True, offset=True)
    lower, upper = robot.bounds()
    nominal = robot.nominal_params()
    assert bool(((lower <= nominal) & (nominal <= upper)).all())
    base_lower, base_upper = robot.base_bounds()
    corners = lower + (upper - lower) * torch.randint(0, 2, (500, robot.n_params), dtype=torch.float64)
    alpha = robot.base_params(torch.cat([corners, nominal[None]]))
    tol = 1e-12 * (1 + alpha.abs())
    assert bool(((base_lower - tol <= alpha) & (alpha <= base_upper + tol)).all())
    # The box is tight: each face is reached by the corner that maximises/minimises that row.
    k = robot.base_map
    best = torch.where(k > 0, upper, lower)
    torch.testing.assert_close((k * best).sum(-1), base_upper, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("options", [{}, {"urdf": chain(), "friction": True, "offset": True}])
def test_conformance_suite(options):
    check_robot(URDFRobot(**options))


def test_registered_as_urdf_plugin():
    robot = registry.create("robot", "urdf", urdf=chain(), friction=True)
    assert isinstance(robot, URDFRobot)
    assert robot.param_names[-6:] == ("r1.fc", "r2.fc", "p3.fc", "r1.fv", "r2.fv", "p3.fv")


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_runs_on_cuda():
    robot = URDFRobot(chain(), friction=True)
    q, qd, qdd = (x.cuda() for x in robot.random_states(50, torch.Generator().manual_seed(0)))
    params = robot.nominal_params()
    tau = robot.inverse_dynamics(params.cuda(), q, qd, qdd)
    expected = robot.inverse_dynamics(params, q.cpu(), qd.cpu(), qdd.cpu())
    torch.testing.assert_close(tau.cpu(), expected, rtol=0, atol=1e-10)
    torch.testing.assert_close(
        robot.regressor(q, qd, qdd) @ robot.base_params(params.cuda()), tau, rtol=0, atol=1e-10
    )


def test_too_few_states_for_the_base_parameter_search():
    with pytest.raises(ValueError, match="n_states=2 gives 6 regressor rows for 30 parameters"):
        URDFRobot(chain(), n_states=2)
