"""The payload's one verdict per quantity: the rule, the SDK calls it allows, every printed line
agreeing with it, and recordings that cannot show the payload (or the arm) recognised as such."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit.estimators.payload import PayloadIdentification, payload_block
from idkit.estimators.payload_verdict import sdk_calls, verdict
from idkit.problem import Problem, Recorded, Samples
from idkit.reports import payload as payload_report
from idkit.robots.inertia import standard_parameters
from idkit.robots.urdf import URDFRobot

INERTIA = np.diag([0.004, 0.005, 0.003])
COM = np.array([0.05, 0.0, -0.1])  # 0.112 m from the origin
SDK = {
    "libfranka": {"load_mass": 2.0, "F_x_Cload": [0.05, 0.0, -0.1], "load_inertia": [0.0] * 9},
    "ur": {"mass": 2.0, "cog": [0.05, 0.0, -0.1], "inertia": [0.0] * 6},
}


def judged(mass_std=0.01, com_std=(1e-3,) * 3, inertia_std=1e-4, unusable=None) -> dict:
    stds = np.full((3, 3), inertia_std)
    return verdict(2.0, mass_std, COM, com_std, INERTIA, stds, unusable)


def test_identified_means_a_standard_deviation_within_a_tenth_of_the_quantitys_scale():
    assert judged()["mass"] and judged()["com"] and judged()["inertia"]
    assert judged(mass_std=0.19)["mass"] and not judged(mass_std=0.21)["mass"]  # 10 % of 2 kg
    # centre of mass: 10 % of its distance from the origin (0.112 m), per coordinate, all three needed
    assert judged(com_std=(0.011, 0, 0))["com"] and not judged(com_std=(0.0, 0.0, 0.012))["com"]
    assert not judged(com_std=(0.0, np.inf, 0.0))["com"]
    assert judged(com_std=(0.0, np.inf, 0.0))["identified"]["cx"]
    # inertia: 10 % of the largest principal moment (0.005)
    assert judged(inertia_std=4.9e-4)["inertia"] and not judged(inertia_std=5.1e-4)["inertia"]
    nothing = judged(unusable="the reference cannot show the arm")
    assert not (nothing["mass"] or nothing["com"] or nothing["inertia"])


def test_a_centre_of_mass_at_the_origin_is_judged_on_a_centimetre():
    found = verdict(1.0, 0.0, [0.0, 0.0, 0.0], [0.0009, 0.0, 0.0011], INERTIA, np.zeros((3, 3)))
    assert not found["com"] and found["identified"]["cx"] and not found["identified"]["cz"]


def test_an_sdk_call_is_offered_only_when_everything_it_takes_is_identified():
    everything = sdk_calls(SDK, judged())
    assert set(everything) == {"libfranka", "ur", "withheld"} and everything["withheld"] == []
    no_inertia = sdk_calls(SDK, judged(inertia_std=np.inf))
    assert "libfranka" not in no_inertia and no_inertia["ur"] == {"mass": 2.0, "cog": [0.05, 0.0, -0.1]}
    assert no_inertia["withheld"] == [
        "libfranka setLoad and URScript set_target_payload (they take the inertia): inertia not identified"
    ]
    mass_only = sdk_calls(SDK, judged(com_std=(0.0, np.inf, 0.0), inertia_std=np.inf))
    assert (
        set(mass_only) == {"withheld"}
        and "centre of mass and inertia not identified" in mass_only["withheld"][1]
    )


def block_with(com_std: list[float], inertia_std: float, mass_std: float) -> dict:
    """A payload block whose covariance gives these standard deviations (diagonal, in the block's own
    parameters, so the delta method passes them through to the printed quantities)."""
    phi = standard_parameters(2.0, COM, INERTIA)
    block = payload_block(phi, np.eye(10) * 1e-12, "tool", "tool", 0.0)
    judged_ = verdict(2.0, mass_std, COM, com_std, INERTIA, np.full((3, 3), inertia_std))
    block.update(
        mass_std=mass_std,
        com_std=com_std,
        inertia_std=np.full((3, 3), inertia_std).tolist(),
        verdict=judged_,
        sdk=sdk_calls(SDK, judged_),
        equations=100,
        rank=10,
        unknowns=10,
        cond=3.0,
        rel_error=0.01,
        rel_error_arm_only=0.2,
    )
    return block


SPREADS = st.sampled_from([0.0, 1e-4, 0.05, np.inf])


@given(com=st.lists(SPREADS, min_size=3, max_size=3), inertia=SPREADS, mass=SPREADS)
@settings(max_examples=40, deadline=None)
def test_every_printed_line_follows_the_one_verdict(com, inertia, mass):
    block = block_with(com, inertia, mass)
    found = block["verdict"]
    lines = payload_report.lines({"payload": block})
    text = "\n".join(lines)
    for label, key in (("mass", "mass"), ("centre of mass", "com"), ("inertia", "inertia")):
        state = "identified      " if found[key] else "not identified  "
        assert f"  {label:<16}{state}" in text, (label, text)
    everything = found["mass"] and found["com"] and found["inertia"]
    assert ("setLoad(" in text) == everything and ("set_target_payload(" in text) == everything
    assert ("set_payload(" in text) == (found["mass"] and found["com"])
    assert "inf" not in text.replace("infinite", "")  # never a ±inf handed over or printed
    assert ("not identified, free" in text) == any(np.isinf([*com, inertia, mass]))


def test_a_reference_held_still_is_no_reference_and_nothing_is_identified(tmp_path):
    """``correction=model`` with a reference that never moves: it cannot fix the arm's correction,
    which then trades against the payload; the report says so specifically."""
    robot = URDFRobot("cylindrical")
    t = torch.linspace(0.5, 10, 200, dtype=torch.float64)
    q, qd, qdd = robot.excitation(t)
    truth = robot.nominal_params().clone()
    truth[20:30] += torch.as_tensor(standard_parameters(2.0, COM, INERTIA))
    data = Samples(q, qd, qdd, robot.inverse_dynamics(truth, q, qd, qdd))
    pose = q[60].expand_as(q).clone()
    still = torch.zeros_like(q)
    weight = robot.inverse_dynamics(robot.nominal_params(), pose, still, still)  # the arm alone, held still
    rest = str(tmp_path / "rest.npz")  # read by the study, handed over as samples
    problem = Problem(robot, data, recordings={rest: Recorded(Samples(pose, still, still, weight))})
    estimate = PayloadIdentification(reference=rest).fit(problem)
    block = estimate.details["payload"]
    assert block["recordings"]["reference_motion_share"] == 0.0
    assert block["verdict"]["unusable"].startswith(f"the reference {tmp_path / 'rest.npz'} cannot show")
    assert not (block["verdict"]["mass"] or block["verdict"]["com"] or block["verdict"]["inertia"])
    text = "\n".join(payload_report.lines(estimate.details))
    assert "is no reference: it hardly moves (0 % of the arm's torque comes from motion)" in text
    assert "no SDK call" in text and "setLoad(" not in text and "set_payload(" not in text


def test_data_held_still_say_the_inertia_cannot_show():
    robot = URDFRobot("cylindrical")
    poses = robot.excitation(torch.linspace(0.5, 10, 40, dtype=torch.float64))[0].repeat_interleave(5, 0)
    still = torch.zeros_like(poses)
    truth = robot.nominal_params().clone()
    truth[20:30] += torch.as_tensor(standard_parameters(2.0, COM, INERTIA))
    data = Samples(poses, still, still, robot.inverse_dynamics(truth, poses, still, still))
    estimate = PayloadIdentification().fit(Problem(robot, data))
    block = estimate.details["payload"]
    assert block["recordings"]["data_motion_share"] == 0.0 and not block["verdict"]["inertia"]
    assert block["mass"] == pytest.approx(2.0, rel=1e-6) and block["verdict"]["mass"]
    text = "\n".join(payload_report.lines(estimate.details))
    assert "the data hardly move: 0 % of the payload's torque comes from motion" in text
