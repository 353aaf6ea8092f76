"""The model's named quantities and the unknowns chosen from them (idkit.sim.quantities)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit.sim.model import load_model
from idkit.sim.quantities import select_unknowns, servo_kind
from idkit.testing import rollout_cases as cases

SERVO = """<mujoco><worldbody><body><joint name="a" axis="0 1 0" damping="0.5"/><geom size="0.1" mass="1"/>
<body pos="0 0 -0.3"><joint name="b" axis="0 1 0"/><geom size="0.1" mass="1"/></body></body></worldbody>
<actuator><position name="pa" joint="a" kp="50" kv="3"/><velocity name="va" joint="a" kv="7"/>
<motor name="mb" joint="b" gear="2"/></actuator></mujoco>"""


@pytest.fixture(scope="module")
def servo():
    return load_model(SERVO)


def test_kinds_expand_per_element_and_names_pick_one(servo):
    bounds = {"mb.bias": [-1, 1], "b.damping": [0, 1]}
    unknowns = select_unknowns(servo, ("a", "b"), ["damping", "kp", "kv", "gear", "mb.bias"], bounds=bounds)
    names = ("a.damping", "b.damping", "pa.kp", "pa.kv", "va.kv", "pa.gear", "va.gear", "mb.gear", "mb.bias")
    assert unknowns.names == names
    assert [servo_kind(servo.model, a) for a in range(3)] == ["position", "velocity", "other"]


def test_starts_are_the_models_values_and_bounds_a_box_around_them(servo):
    unknowns = select_unknowns(servo, ("a",), ["damping", "kp", "kv"], box=(0.5, 4.0))
    np.testing.assert_allclose(unknowns.vector("start"), [0.5, 50, 3, 7])
    np.testing.assert_allclose(unknowns.vector("lower"), [0.25, 25, 1.5, 3.5])
    np.testing.assert_allclose(unknowns.vector("upper"), [2.0, 200, 12, 28])


def test_shared_kind_is_one_unknown(servo):
    unknowns = select_unknowns(
        servo, ("a", "b"), ["damping"], shared=["damping"], bounds={"damping": [0.0, 5]}
    )
    assert unknowns.names == ("damping",)
    assert len(unknowns.items[0].targets) == 2
    assert unknowns.vector("start")[0] == pytest.approx(0.25)  # the mean of 0.5 and 0


@pytest.mark.parametrize(
    ("params", "options", "message"),
    [
        (["stiffness"], {}, "a.stiffness starts at 0"),
        (["damping"], {"start": {"a.damping": 9.0}, "bounds": {"damping": [0.1, 1]}}, "outside its bounds"),
        (["damping"], {"bounds": {"a.damping": [1.0, 0.5]}}, "lower < upper"),
        (["damping"], {"bounds": {"kp": [1.0, 2.0]}}, "bounds: kp name"),
        (["torque"], {}, "neither a kind"),
        (["x.damping"], {}, "no damping named"),
        (["damping", "a.damping"], {}, "repeats"),
        (["kp"], {"joints": ("b",)}, "no element of kind 'kp'"),
    ],
)
def test_bad_choices_are_refused_naming_them(servo, params, options, message):
    options = dict(options)
    joints = options.pop("joints", ("a",))
    with pytest.raises(ValueError, match=message):
        select_unknowns(servo, joints, params, **options)


@settings(max_examples=15, deadline=None)
@given(st.lists(st.floats(0.2, 5.0), min_size=10, max_size=10))
def test_written_model_compiles_to_the_values_set_in_place(factors):
    """What the estimator sets in a compiled model (and mj_setConst) is what identified.xml compiles to."""
    sim = load_model(cases.ARM7)
    joints = sim.joint_names()
    unknowns = select_unknowns(sim, joints[:2], ["armature", "damping", "frictionloss", "kp", "kv"])
    values = unknowns.vector("start") * np.array(factors)
    model = mujoco.MjModel.from_xml_string(cases.ARM7)
    unknowns.apply(model, values)
    mujoco.mj_setConst(model, mujoco.MjData(model))
    spec = sim.copy_spec()
    unknowns.write(spec, sim, values)
    compiled = spec.compile()
    for field in (
        "dof_armature",
        "dof_damping",
        "dof_frictionloss",
        "dof_invweight0",
        "actuator_gainprm",
        "actuator_biasprm",
    ):
        np.testing.assert_allclose(getattr(model, field), getattr(compiled, field), rtol=1e-12, err_msg=field)


def test_coordinates_are_logarithmic_above_zero_and_linear_from_it(servo):
    unknowns = select_unknowns(servo, ("a",), ["damping", "pa.bias"], bounds={"pa.bias": [-2.0, 2.0]})
    z = unknowns.to_coordinates(np.array([0.5, 1.0]))
    np.testing.assert_allclose(z, [np.log(0.5), 0.25])
    np.testing.assert_allclose(unknowns.from_coordinates(z), [0.5, 1.0])


def test_an_actuator_quantity_answers_to_its_joints_name(servo):
    """``a.kp`` is ``pa.kp`` (the only position servo on joint a); ``a.kv`` is ambiguous (two actuators
    give joint a a velocity gain) and ``b.gear`` is ``mb.gear``."""
    unknowns = select_unknowns(
        servo, ("a", "b"), ["a.kp", "mb.gear"], start={"b.gear": 3.0}, bounds={"a.kp": [1, 99]}
    )
    assert unknowns.names == ("a.kp", "mb.gear")
    assert unknowns.items[0].targets == (0,) and unknowns.items[0].upper == 99
    assert unknowns.vector("start")[1] == 3.0
    named = select_unknowns(servo, ("a",), ["kp"], start={"a.kp": 60.0})
    assert named.names == ("pa.kp",) and named.vector("start")[0] == 60.0
    with pytest.raises(ValueError, match="no kv named 'a.kv'"):
        select_unknowns(servo, ("a",), ["a.kv"])


def test_the_old_name_delay_reads_as_command_delay_and_says_it_is_deprecated():
    sim = load_model(cases.ARM7)
    with pytest.warns(FutureWarning, match="'delay' is now called 'command_delay'"):
        old = select_unknowns(
            sim, ("j1",), ("damping", "delay"), bounds={"delay": [0, 0.01]}, start={"delay": 0.002}
        )
    new = select_unknowns(
        sim,
        ("j1",),
        ("damping", "command_delay"),
        bounds={"command_delay": [0, 0.01]},
        start={"command_delay": 0.002},
    )
    assert old == new and old.names[-1] == "command_delay"
    with pytest.warns(FutureWarning), pytest.raises(ValueError, match="give command_delay once"):
        select_unknowns(sim, ("j1",), ("delay",), start={"delay": 0.0, "command_delay": 0.0})
