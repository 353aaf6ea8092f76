"""Inertias in log-Cholesky coordinates (idkit.sim.inertia): physical by construction, MuJoCo's bodies."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from idkit.robots.inertia import centroidal
from idkit.sim.export import identified_xml
from idkit.sim.inertia import coordinates, from_mujoco, mujoco_inertial, standard
from idkit.sim.model import load_model
from idkit.sim.problem import RolloutProblem, SimRobot
from idkit.sim.quantities import select_unknowns
from idkit.testing import rollout_cases as cases


@settings(max_examples=50, deadline=None)
@given(arrays(np.float64, 10, elements=st.floats(-2.0, 2.0)))
def test_every_coordinate_vector_is_a_physical_body_and_comes_back(theta):
    mass, com, about_com = centroidal(standard(theta))
    moments = np.linalg.eigvalsh(about_com)
    assert mass > 0 and moments.min() > -1e-12 * moments.max()
    assert moments[2] <= moments[0] + moments[1] + 1e-9 * moments.max()  # the triangle inequality
    np.testing.assert_allclose(coordinates(standard(theta)), theta, atol=1e-7)


def test_a_mujoco_body_round_trips():
    model = mujoco.MjModel.from_xml_string(cases.ARM7)
    for body in range(1, model.nbody):
        theta = from_mujoco(
            model.body_mass[body], model.body_ipos[body], model.body_inertia[body], model.body_iquat[body]
        )
        mass, ipos, moments, _ = mujoco_inertial(theta)
        assert mass == pytest.approx(model.body_mass[body], rel=1e-12)
        np.testing.assert_allclose(ipos, model.body_ipos[body], atol=1e-12)
        np.testing.assert_allclose(np.sort(moments), np.sort(model.body_inertia[body]), rtol=1e-9)


def test_fitting_an_inertia_starts_at_zero_error_and_writes_the_body():
    case = cases.case_b()
    sim = load_model(case.model)
    unknowns = select_unknowns(sim, case.fit.joint_names, ["l5.inertia", "damping"])
    assert unknowns.names[:2] == ("l5.inertia.alpha", "l5.inertia.d1") and len(unknowns) == 17
    problem = RolloutProblem(SimRobot(sim, unknowns, case.fit.joint_names), case.fit, threads=1)
    values = unknowns.vector("start")
    simulator = problem.simulator()
    try:
        assert np.abs(problem.error(values[None], simulator)).max() < 1e-6
        values[0] += 0.1  # e^0.2: a fifth more mass
        assert np.abs(problem.error(values[None], simulator)).max() > 1.0
    finally:
        simulator.close()
    written = load_model(identified_xml(sim, unknowns, values)).model
    body = sim.model.body("l5").id
    assert written.body_mass[body] == pytest.approx(1.5 * np.exp(0.2), rel=1e-5)
    assert unknowns.bodies(sim, values)["l5"]["mass"] == pytest.approx(1.5 * np.exp(0.2))
