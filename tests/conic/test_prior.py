"""The CAD reference bodies: degenerate ones thickened, impossible ones replaced, the rest untouched."""

from __future__ import annotations

import warnings
from importlib.resources import files

import numpy as np
import pytest
import torch
from urdf_cases import TREE_URDF

from idkit.conic.prior import MIN_SIZE, MIN_THICKNESS, ReferenceNote, ReferenceWarning, cad_reference
from idkit.robots.inertia import pseudo_inertia
from idkit.robots.urdf import URDFRobot

CYLINDRICAL = str(files("idkit") / "robots/assets/cylindrical.urdf")


def scaled_cad(robot: URDFRobot) -> np.ndarray:
    reference = cad_reference(robot)
    nb = len(robot.link_names)
    z = robot.nominal_params()[: 10 * nb].numpy() / reference.unit[: 10 * nb]
    return pseudo_inertia(torch.as_tensor(z).reshape(nb, 10)).numpy()


def central_moments(j: np.ndarray) -> np.ndarray:
    """Eigenvalues of the second moment about the centre of mass of a pseudo-inertia."""
    c = j[:3, 3] / j[3, 3]
    return np.linalg.eigvalsh(j[:3, :3] - j[3, 3] * np.outer(c, c))


def test_a_physical_cad_body_is_its_own_reference():
    robot = URDFRobot(TREE_URDF)
    reference = cad_reference(robot)
    assert reference.thickened == () and reference.replaced == ()
    np.testing.assert_allclose(reference.pseudo, scaled_cad(robot), rtol=1e-12, atol=1e-14)


def test_rods_and_discs_are_thickened_to_a_tenth_of_their_length_and_said_once():
    """The paper's cylindrical URDF: link1 a flat disc, link2 and link3 rods (no axial inertia)."""
    robot = URDFRobot(CYLINDRICAL)
    reference = cad_reference(robot)
    assert reference.thickened == ("link1", "link2", "link3") and reference.replaced == ()
    for j0, cad in zip(reference.pseudo, scaled_cad(robot), strict=True):
        before, after = central_moments(cad), central_moments(j0)
        assert before[0] == pytest.approx(0.0, abs=1e-12)
        assert after[0] == pytest.approx(max(MIN_THICKNESS**2 * before[-1], MIN_SIZE**2), rel=1e-9)
        assert after[-1] == pytest.approx(before[-1], rel=1e-12)  # the long direction is the CAD's
        np.testing.assert_allclose(j0[:, 3], cad[:, 3], rtol=1e-12, atol=1e-15)  # mass and centre kept
        # well-conditioned: what keeps the entropic prior's gradient J0^-1 within a solver's reach
        assert np.linalg.cond(j0) < 1e5
    with pytest.warns(ReferenceNote, match=r"^pcls: the CAD body of link1, link2, link3 is degenerate"):
        reference.announce("pcls")


def test_an_impossible_cad_inertia_is_replaced_by_a_physical_body_with_a_warning():
    """A triangle inequality broken (izz > ixx + iyy): no rigid body has it; the prior uses the
    nearest physical one, said as a warning (the user's file is wrong)."""
    broken = TREE_URDF.replace(
        'ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"',
        'ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.005"',
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the robot's own model check warns too
        robot = URDFRobot(broken)
    reference = cad_reference(robot)
    assert reference.replaced == ("d",)
    assert np.linalg.eigvalsh(reference.pseudo)[:, 0].min() > 0
    with pytest.warns(ReferenceWarning, match=r"^pcls: the CAD inertia of d is no rigid body's"):
        reference.announce("pcls")


def test_a_link_without_inertial_is_refused_in_one_line():
    bare = TREE_URDF.replace('<mass value="0.5"/>', '<mass value="0"/>')
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = URDFRobot(bare)
    with pytest.raises(ValueError, match=r"^urdf: link\(s\) 'd' have no <inertial> \(CAD mass 0\)"):
        cad_reference(robot)
