"""Self-collision with pinocchio + coal: pairs tested, contacts against a closed form, and every
way of saying "not checked"."""

from __future__ import annotations

import numpy as np
import pytest

from idkit.excitation import collision as module
from idkit.excitation.collision import NotChecked, SelfCollision, self_collision
from idkit.robots.urdf import URDFRobot
from tests.excitation.arm_cases import ARM_URDF, TOUCH, touches_table

pytest.importorskip("pinocchio")


@pytest.fixture(scope="module")
def arm() -> URDFRobot:
    return URDFRobot(ARM_URDF)


def test_adjacent_bodies_and_bodies_joined_by_a_link_without_geometry_are_not_tested(arm):
    test = self_collision(arm)
    assert isinstance(test, SelfCollision)
    assert test.pairs == [("arm", "table"), ("hand", "shoulder"), ("hand", "table")]
    assert test.status() == "checked with pinocchio + coal (3 body pairs)"
    assert test.incomplete == []


def test_contacts_equal_the_closed_form(arm):
    test = self_collision(arm)
    rng = np.random.default_rng(0)
    q = rng.uniform([-2, -1.5, -2, -2], [2, 1.5, 2, 2], size=(400, 4))
    q[:5, 1] = [TOUCH - 1e-6, TOUCH + 1e-6, 0.0, 1.4, -1.4]  # either side of the touching angle
    contacts = test.contacts(q)
    found = {c.index for c in contacts if (c.first, c.second) == ("arm", "table")}
    expected = {i for i, pose in enumerate(q) if touches_table(pose[1])}
    assert found == expected and 0 < len(expected) < 400
    # The hand's smaller sphere at the arm's tip touches only where the arm does (sin q2 > 0.7).
    assert {(c.first, c.second) for c in contacts} == {("arm", "table"), ("hand", "table")}
    assert {c.index for c in contacts} == expected
    first = test.contacts(q, first_only=True)
    assert len(first) == 1 and first[0].index == min(expected)


def test_missing_meshes_are_left_out_and_named(arm, tmp_path):
    text = ARM_URDF.replace(
        '<collision><geometry><sphere radius="0.1"/></geometry></collision>',
        '<collision><geometry><mesh filename="package://nowhere/shoulder.stl"/></geometry></collision>',
    )
    test = self_collision(URDFRobot(text))
    assert isinstance(test, SelfCollision) and test.incomplete == ["shoulder"]
    assert test.status().endswith("; without shoulder (mesh not found))")
    assert all("shoulder" not in pair for pair in test.pairs)


@pytest.mark.parametrize(
    ("robot", "reason"),
    [
        ("cylindrical-class", "CylindricalRobot is not a URDF robot"),
        ("cylindrical", "no collision geometry"),
    ],
)
def test_robots_without_geometry_are_not_checked(robot, reason, cylindrical):
    subject = cylindrical if robot == "cylindrical-class" else URDFRobot(robot)
    result = self_collision(subject)
    assert isinstance(result, NotChecked) and result.status() == f"not checked ({reason})"


def test_without_pinocchio_it_says_so(arm, monkeypatch):
    monkeypatch.setattr(module, "_import_pinocchio", lambda: None)
    result = self_collision(arm)
    assert isinstance(result, NotChecked)
    assert result.status() == "not checked (pinocchio+coal not installed: pip install robot-idkit[collision])"
