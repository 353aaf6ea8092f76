"""Models that cannot lie: a malformed URDF is refused at load in one line naming the element and file."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from test_robots_urdf_inputs import chain

from idkit import registry
from idkit.cli import errors
from idkit.data.scenarios import simulate
from idkit.problem import Problem
from idkit.robots.inertia import pseudo_inertia
from idkit.robots.model_checks import ModelError, ModelWarning, check_model, inertia_problem
from idkit.robots.urdf import URDFRobot
from idkit.robots.urdf_model import ASSETS, parse_urdf

L2_INERTIA = 'ixx="0.02" ixy="0" ixz="0" iyy="0.03" iyz="0" izz="0.04"'
#: Link l2 with principal moments 0.01, 0.01, 0.04: 0.01 + 0.01 < 0.04.
THIN = chain().replace(L2_INERTIA, 'ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.04"')


UNIQUE = "joint names must be unique (parameters are named after them)"


def write(tmp_path, text: str) -> str:
    path = tmp_path / "robot.urdf"
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (('<mass value="2"/>', '<mass value="-2"/>'), r"link 'l2' \(.*robot.urdf\): mass -2 kg is negative"),
        (('<mass value="2"/>', '<mass value="inf"/>'), r"robot.urdf: link 'l2' <mass>: value='inf' is not a"),
        (('<mass value="2"/>', '<mass value="nan"/>'), r"robot.urdf: link 'l2' <mass>: value='nan' is not a"),
        (('iyy="0.03"', 'iyy="-inf"'), r"link 'l2' <inertia>: iyy='-inf' is not a finite number"),
        (
            ('lower="-2" upper="2"', 'lower="2" upper="-2"'),
            r"joint 'r2' \(.*\): lower limit 2 > upper limit -2",
        ),
        (('joint name="p3"', 'joint name="r2"'), r"joint 'r2' \(.*robot.urdf\) is defined 2 times"),
        (('xyz="0.4 0 0"', 'xyz="0.4 inf 0"'), r"joint 'p3' <origin>: xyz='0.4 inf 0' is not a finite"),
        (
            ('<axis xyz="1 0 0"/>', '<axis xyz="1 nan 0"/>'),
            r"joint 'p3' <axis>: xyz='1 nan 0' is not a finite",
        ),
    ],
    ids=[
        "negative-mass",
        "inf-mass",
        "nan-mass",
        "inf-inertia",
        "limits",
        "joint-twice",
        "inf-origin",
        "nan-axis",
    ],
)
def test_malformed_model_is_refused_naming_element_and_file(tmp_path, edit, message):
    text = chain().replace(*edit)
    assert text != chain()
    with pytest.raises(ValueError, match=message) as error:
        URDFRobot(write(tmp_path, text), friction=True)
    assert "\n" not in str(error.value)


def _with(items: tuple, index: int, **change) -> tuple:
    return (*items[:index], replace(items[index], **change), *items[index + 1 :])


@pytest.mark.parametrize(
    ("part", "index", "change", "message"),
    [
        ("links", 2, {"mass": np.inf}, r"link 'l2' \(<URDF text>\): mass inf is not finite"),
        ("links", 2, {"com": np.array([0, np.nan, 0])}, r"link 'l2' .*: centre of mass \[0.0, nan, 0.0\]"),
        ("bodies", 0, {"axis": np.array([0, 0, np.inf])}, r"joint 'r1' .*: its placement, axis or limits"),
        ("bodies", 1, {"limits": (0.0, np.nan)}, r"joint 'r2' .*: its placement, axis or limits"),
    ],
)
def test_check_model_refuses_numbers_another_reader_could_give(part, index, change, message):
    """Non-finite numbers in the tree itself (a reader other than URDF's could produce them)."""
    tree = parse_urdf(chain())
    with pytest.raises(ModelError, match=message):
        check_model(replace(tree, **{part: _with(getattr(tree, part), index, **change)}))


def test_repeated_link_and_fixed_joint_names_are_refused():
    tool = '<link name="l3"/><joint name="p3" type="fixed"><parent link="l3"/><child link="tool"/></joint>'
    welded = chain().replace(
        "</robot>", tool.replace('<link name="l3"/>', '<link name="tool"/>') + "</robot>"
    )
    with pytest.raises(ModelError, match=r"joint 'p3' \(<URDF text>\) is defined 2 times"):
        parse_urdf(welded)
    twice = chain().replace("</robot>", '<link name="l1"/></robot>')
    with pytest.raises(ModelError, match=r"link 'l1' \(<URDF text>\) is defined 2 times"):
        parse_urdf(twice)


def test_a_link_welded_to_the_root_is_checked_too():
    """Links on the root are dropped from the dynamics, but a negative mass there is still a broken file."""
    pedestal = (
        '<link name="pedestal"><inertial><mass value="-1"/>'
        '<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>'
        '<joint name="weld" type="fixed"><parent link="pedestal"/><child link="base"/></joint>'
    )
    with pytest.raises(ModelError, match="link 'pedestal' .* mass -1 kg is negative"):
        parse_urdf(chain().replace("</robot>", pedestal + "</robot>"))


def test_lower_equal_upper_means_no_limit():
    """URDF's default ``lower = upper = 0`` (no lower/upper given) is no position limit, as before."""
    robot = URDFRobot(chain().replace('lower="-2" upper="2"', ""))
    assert robot.tree.bodies[1].limits is None


def test_non_physical_inertia_is_warned_and_fitted_by_ls_and_by_pcls_with_a_physical_prior():
    """Shipped URDFs with impossible inertias are common: pcls does not refuse them but takes the
    nearest physical body as the prior, and says so in a warning naming the link."""
    from idkit.conic.prior import ReferenceWarning
    from idkit.robots.inertia import min_pseudo_inertia_eigenvalues

    with pytest.warns(
        ModelWarning, match=r"link 'l2' \(<URDF text>\): .* triangle inequality \(0.01 \+ 0.01 < 0.04\)"
    ):
        robot = URDFRobot(THIN)
    problem = Problem(robot, simulate(robot, "clean", n_samples=60))
    estimate = registry.create("estimator", "ls").fit(problem)
    assert all(np.isfinite(list(estimate.params.values())))
    with pytest.warns(ReferenceWarning, match=r"^pcls: the CAD inertia of l2 is no rigid body's"):
        fit = registry.create("estimator", "pcls", prior_weight=10.0).fit(problem)
    params = torch.tensor([fit.params[name] for name in robot.param_names], dtype=torch.float64)
    assert (min_pseudo_inertia_eigenvalues(robot, params) >= 0).all()
    assert fit.details["cad_reference"]["replaced"] == ["l2"]


@pytest.mark.parametrize("source", ["cylindrical", "tree", "kuka"])
def test_shipped_and_test_models_pass_without_a_warning(source, kuka_dir):
    from urdf_cases import TREE_URDF

    urdf = {"cylindrical": str(ASSETS / "cylindrical.urdf"), "tree": TREE_URDF}.get(source)
    if source == "kuka":
        if not (kuka_dir / "kuka_lwr4.urdf").is_file():
            pytest.skip("KUKA URDF not present")
        urdf = str(kuka_dir / "kuka_lwr4.urdf")
    with warnings.catch_warnings():
        warnings.simplefilter("error", ModelWarning)
        parse_urdf(urdf)


def _inertia(moments: np.ndarray, angles: np.ndarray) -> np.ndarray:
    rotation = torch.linalg.matrix_exp(
        torch.tensor([[0, -angles[2], angles[1]], [angles[2], 0, -angles[0]], [-angles[1], angles[0], 0]])
    ).numpy()
    return rotation @ np.diag(moments) @ rotation.T


@settings(max_examples=200, deadline=None)
@given(
    moments=st.lists(st.floats(-1.0, 3.0), min_size=3, max_size=3),
    angles=st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3),
    mass=st.floats(0.1, 10.0),
    com=st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3),
)
def test_inertia_check_agrees_with_the_pseudo_inertia(moments, angles, mass, com):
    """Independent reference: the smallest eigenvalue of the 4×4 pseudo-inertia (about the link origin)."""
    inertia_c = _inertia(np.array(moments), np.array(angles))
    c = np.array(com)
    inertia_o = inertia_c + mass * (c @ c * np.eye(3) - np.outer(c, c))
    (xx, xy, xz), (_, yy, yz), (_, _, zz) = inertia_o
    j = pseudo_inertia(torch.tensor([mass, *(mass * c), xx, xy, xz, yy, yz, zz], dtype=torch.float64))
    smallest = float(torch.linalg.eigvalsh(j)[0])
    a, b, top = sorted(moments)
    margin = (a + b - top) / 2  # the smallest eigenvalue of the second moment about the centre of mass
    if abs(margin) < 1e-3:
        return  # the boundary: round-off decides
    assert (inertia_problem(inertia_c) is None) == (margin > 0) == (smallest > 0)


def test_the_command_line_refuses_in_one_line(tmp_path, run_idkit):
    """The reported case: two joints named r2 with friction (6 friction parameters became 4)."""
    path = write(tmp_path, chain().replace('joint name="p3"', 'joint name="r2"'))
    argv = ["robot=urdf", f"robot.urdf={path}", "robot.friction=true", "estimator=ls"]
    status, said = run_idkit(*argv, f"hydra.run.dir={tmp_path / 'run'}")
    assert status == errors.USAGE
    assert said == [f"idkit: joint 'r2' ({path}) is defined 2 times; {UNIQUE}"]
