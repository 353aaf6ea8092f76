"""pcls and the projection onto physically consistent parameters, against LS and by construction."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import torch
from urdf_cases import TREE_URDF

from idkit import registry
from idkit.conic.program import nearest_consistent
from idkit.estimators.linear.observation import IdentificationError
from idkit.estimators.physical import PhysicallyConsistentLS
from idkit.problem import Problem, Samples
from idkit.robots.inertia import min_pseudo_inertia_eigenvalues
from idkit.robots.urdf import URDFRobot

#: Interior-point solutions may sit this far outside the PSD cone (kg·m² scale of the test robot).
EIGEN_TOL = 1e-9


@functools.cache
def tree_robot() -> URDFRobot:
    return URDFRobot(TREE_URDF, friction=True, offset=True)


def true_params(robot: URDFRobot) -> torch.Tensor:
    """CAD inertials (strictly physical) with friction and offsets filled in."""
    params = robot.nominal_params().clone()
    n, nb = robot.n_joints, len(robot.link_names)
    params[10 * nb : 10 * nb + 2 * n] = torch.linspace(0.1, 0.8, 2 * n, dtype=torch.float64)
    params[10 * nb + 2 * n :] = torch.linspace(-0.2, 0.2, n, dtype=torch.float64)
    return params


def simulated(robot: URDFRobot, params: torch.Tensor, noise: float, seed: int = 0, n: int = 300) -> Samples:
    """Torques of ``params`` on random states plus Gaussian noise of ``noise`` × each joint's RMS."""
    generator = torch.Generator().manual_seed(seed)
    q, qd, qdd = robot.random_states(n, generator)
    tau = robot.inverse_dynamics(params, q, qd, qdd)
    scale = tau.square().mean(0).sqrt()
    return Samples(
        q, qd, qdd, tau + noise * scale * torch.randn(tau.shape, generator=generator, dtype=tau.dtype)
    )


def vector(values: dict[str, float]) -> np.ndarray:
    return np.array(list(values.values()))


@pytest.mark.parametrize("noise", [0.0, 1e-3])
def test_pcls_equals_ls_when_ls_is_consistent(noise):
    """Simulated from physical parameters, LS is consistent: the LMIs are inactive, pcls = LS."""
    robot = tree_robot()
    problem = Problem(robot, simulated(robot, true_params(robot), noise))
    ls = registry.create("estimator", "ls").fit(problem)
    projected = nearest_consistent(
        robot, base_params=torch.as_tensor(vector(ls.base_params)), samples=problem.samples
    )
    assert projected.data_term < 1e-2  # LS is consistent: < (0.01 % torque change)^2 away
    pcls = registry.create("estimator", "pcls", prior_weight=0.0).fit(problem)
    a_ls, a_pcls = vector(ls.base_params), vector(pcls.base_params)
    if noise == 0.0:
        np.testing.assert_allclose(a_pcls, a_ls, rtol=0, atol=1e-6 * np.abs(a_ls).max())
    else:  # the tie-break moves the fit by a small fraction of the data's own uncertainty
        std = vector(pcls.details["uncertainty"]["std"])
        assert (np.abs(a_pcls - a_ls) <= 0.05 * std).all()
    assert min(pcls.details["min_eigenvalue"].values()) > 0


def test_pcls_is_consistent_where_ls_is_not():
    """Non-physical 'truth' (a negative mass): LS follows it, pcls stays physical and fits worse."""
    robot = tree_robot()
    params = true_params(robot)
    params[10] = -1.0  # link b: negative mass
    problem = Problem(robot, simulated(robot, params, noise=1e-2, seed=1))
    ls = registry.create("estimator", "ls").fit(problem)
    pcls = PhysicallyConsistentLS(prior_weight=0.0).fit(problem)
    p = torch.as_tensor(vector(pcls.params))
    eig = min_pseudo_inertia_eigenvalues(robot, p)
    assert (eig > -EIGEN_TOL).all()
    np.testing.assert_allclose(eig.numpy(), list(pcls.details["min_eigenvalue"].values()), atol=1e-12)
    assert p[10] >= 0.01 * 0.5 - 1e-9  # the default mass floor: 1 % of the smallest CAD mass (0.5 kg)
    assert pcls.details["criterion_value"] > ls.details["criterion_value"]
    friction = [k for k, name in enumerate(robot.param_names) if name.endswith((".fc", ".fv"))]
    assert (p[friction] >= -1e-9).all()


def test_prior_pulls_towards_cad():
    robot = tree_robot()
    problem = Problem(robot, simulated(robot, true_params(robot) * 1.3, noise=0.05, seed=2))
    free = PhysicallyConsistentLS(prior_weight=0.0).fit(problem)
    pulled = PhysicallyConsistentLS(prior_weight=1e4).fit(problem)
    # What the prior guarantees: it is a barrier (-log det), so every link stays strictly inside the
    # PSD cone (finite divergence), and by optimality of both programs the pulled fit trades data
    # fit for divergence: its summed divergence is no larger and its data criterion no smaller. The
    # free fit may legitimately sit on the PSD boundary, where its divergence is infinite.
    assert all(np.isfinite(v) for v in pulled.details["divergence"].values())
    assert sum(pulled.details["divergence"].values()) < sum(free.details["divergence"].values())
    assert pulled.details["criterion_value"] >= free.details["criterion_value"] * (1 - 1e-6)
    assert pulled.estimator == "PCLS-prior10000"


def test_projection_returns_consistent_parameters_and_keeps_consistent_ones():
    robot = tree_robot()
    bad = true_params(robot).clone()
    bad[0] = -0.5  # link a: negative mass
    bad[4:10] = -bad[4:10]  # and a negative inertia
    assert min_pseudo_inertia_eigenvalues(robot, bad).min() < 0
    projected = nearest_consistent(robot, bad)
    assert (projected.min_eigenvalues > -EIGEN_TOL).all()
    assert (min_pseudo_inertia_eigenvalues(robot, projected.params) > -EIGEN_TOL).all()
    good = true_params(robot)
    again = nearest_consistent(robot, good)
    np.testing.assert_allclose(
        robot.base_params(again.params).numpy(),
        robot.base_params(good).numpy(),
        atol=1e-5 * float(good.abs().max()),
    )


def test_inputs_are_checked():
    robot = tree_robot()
    with pytest.raises(ValueError, match="exactly one of params"):
        nearest_consistent(robot)
    with pytest.raises(ValueError, match=r"params must be \[" + str(robot.n_params)):
        nearest_consistent(robot, torch.zeros(3))
    with pytest.raises(ValueError, match="solver must be"):
        PhysicallyConsistentLS(solver="mosek-pro").fit(
            Problem(robot, simulated(robot, true_params(robot), 0.0))
        )
    with pytest.raises(ValueError, match="needs a 'urdf' robot"):
        nearest_consistent(registry.create("robot", "cylindrical"), torch.ones(4))


def test_urdf_without_inertials_is_refused():
    robot = URDFRobot(_strip_inertial(TREE_URDF, "c"))
    with pytest.raises(ValueError, match=r"link\(s\) 'c' have no <inertial>"):
        nearest_consistent(robot, robot.nominal_params())


def _strip_inertial(urdf: str, link: str) -> str:
    start = urdf.index(f'<link name="{link}">')
    end = urdf.index("</link>", start) + len("</link>")
    return urdf[:start] + f'<link name="{link}"/>' + urdf[end:]


def test_solver_failure_is_one_line(monkeypatch):
    import cvxpy as cp

    def broken(self, *args, **kwargs):
        raise cp.error.SolverError("numerical trouble")

    monkeypatch.setattr(cp.Problem, "solve", broken)
    robot = tree_robot()
    with pytest.raises(
        IdentificationError,
        match=r"^nearest_consistent: the conic solver failed "
        r"\(CLARABEL: numerical trouble; CLARABEL_RELAXED: numerical trouble; SCS: numerical trouble\)$",
    ):
        nearest_consistent(robot, true_params(robot))


def test_an_inaccurate_solution_outside_the_cone_is_refused(monkeypatch):
    """A solver that stops 'optimal_inaccurate' with a negative pseudo-inertia eigenvalue (SCS did so
    on the cylindrical URDF's near-singular CAD inertias with a prior) is an error, not a result."""
    import cvxpy as cp

    def inaccurate(self, *args, **kwargs):
        variable = self.variables()[0]
        variable.value = -np.ones(variable.shape)  # negative masses: every link outside the cone
        self._status = cp.OPTIMAL_INACCURATE

    monkeypatch.setattr(cp.Problem, "solve", inaccurate)
    robot = tree_robot()
    with pytest.raises(
        IdentificationError,
        match=r"^nearest_consistent: the conic solver failed \(CLARABEL: status 'optimal_inaccurate' but a "
        r"\(-1.89\) outside the cone; CLARABEL_RELAXED: .*; SCS: .* outside the cone\)$",
    ):
        nearest_consistent(robot, true_params(robot))


def test_scs_agrees_with_clarabel():
    """The LMI program alone (no prior): the default prior_weight=auto would solve one entropic
    program per fold and weight, which SCS, a first-order solver, takes minutes for."""
    robot = tree_robot()
    problem = Problem(robot, simulated(robot, true_params(robot), noise=1e-2, seed=3))
    clarabel = PhysicallyConsistentLS(solver="clarabel", prior_weight=0.0).fit(problem)
    scs = PhysicallyConsistentLS(solver="scs", prior_weight=0.0).fit(problem)
    assert scs.details["solver"] == "SCS"
    assert scs.details["criterion_value"] == pytest.approx(clarabel.details["criterion_value"], rel=1e-3)


def test_stribeck_friction_never_drives_the_joint():
    """fs may be negative (friction building up after a reversal) but not below -fc."""
    robot = URDFRobot(TREE_URDF, friction=True, stribeck_velocity=0.3)
    params = robot.nominal_params().clone()
    n, start = robot.n_joints, 10 * len(robot.link_names)
    params[start : start + n] = 0.5  # fc
    params[start + 2 * n :] = -1.5  # fs < -fc: friction that would push at low speed
    estimate = PhysicallyConsistentLS().fit(Problem(robot, simulated(robot, params, noise=1e-3, seed=4)))
    fit = torch.as_tensor(vector(estimate.params))
    assert (fit[start : start + n] + fit[start + 2 * n :] >= -1e-9).all()
    assert (fit[start + 2 * n :] < 0).any()


def test_prior_weight_auto_follows_cad_only_as_far_as_the_data_allow():
    """prior_weight=auto (the default): on data simulated from the CAD model itself the prior is right
    and cross-validation leans on it; with inertias 30 % off CAD and little noise the data win."""
    from idkit.estimators.physical import PriorWeightNote

    robot = tree_robot()
    nb = len(robot.link_names)
    off = true_params(robot).clone()
    off[: 10 * nb] *= 1.3
    cad_data = Problem(robot, simulated(robot, true_params(robot), 0.05, seed=3))
    with pytest.warns(PriorWeightNote) as said:
        right = PhysicallyConsistentLS().fit(cad_data)
    wrong = PhysicallyConsistentLS().fit(Problem(robot, simulated(robot, off, 1e-3, seed=3)))
    assert right.details["prior_weight"] >= 1000 and wrong.details["prior_weight"] <= 100
    reason = right.details["prior_weight_cv"]["reason"]
    notes = [str(note.message) for note in said if note.category is PriorWeightNote]
    assert len(notes) == 1 and reason in notes[0]  # the choice, said (beside the other variant's weight)
    for fit in (right, wrong):
        cv = fit.details["prior_weight_cv"]
        assert cv["candidates"] == [0, 1, 3, 10, 30, 100, 300, 1000, 3000, 10000]
        assert all(len(folds) == 5 for folds in cv["per_fold"])
        # the lowest cross-validated error, unless its fit is degenerate (then within one standard error)
        chosen = cv["candidates"].index(cv["chosen"])
        distances = cv["standard_errors_from_best"]
        assert min(distances) == 0 and cv["scores"][distances.index(0)] == min(cv["scores"])
        assert cv["scores"][chosen] == min(cv["scores"]) or (
            distances[chosen] <= 1 and "degenerate" in cv["reason"]
        )
    assert right.estimator == "PCLS"


def test_prior_weight_auto_on_too_few_samples_is_zero_and_says_why():
    """Said in result.json and in one warning (the command prints it as one ``warning:`` line)."""
    from idkit.estimators.physical import PriorWeightWarning

    robot = tree_robot()
    problem = Problem(robot, simulated(robot, true_params(robot), 0.01, n=20))
    with pytest.warns(PriorWeightWarning) as said:
        fit = PhysicallyConsistentLS().fit(problem)
    assert fit.details["prior_weight"] == 0.0
    assert fit.details["prior_weight_cv"]["reason"].startswith("20 samples are too few to cross-validate")
    (warning,) = [w for w in said if w.category is PriorWeightWarning]  # once, for both variants
    assert str(warning.message).startswith("pcls prior_weight=auto: 20 samples are too few to cross-validate")
    assert "prior weight 0 " in str(warning.message)


def test_prior_weight_auto_names_a_weight_whose_solve_failed(monkeypatch):
    """A candidate the solver fails on drops out of the choice (score inf): the reason says so, and a
    warning (not a note: the choice was made without it) names the weight and the solver's words."""
    from idkit.estimators import physical

    solve = physical.ConsistentProgram.solve

    def failing(self, R, b, scale2, weight=0.0, once=False):
        if weight == 3000.0:
            raise IdentificationError("pcls: the conic solver failed (CLARABEL: status 'numerical')")
        return solve(self, R, b, scale2, weight, once)

    monkeypatch.setattr(physical.ConsistentProgram, "solve", failing)
    robot = tree_robot()
    with pytest.warns(physical.PriorWeightWarning) as said:
        fit = PhysicallyConsistentLS().fit(Problem(robot, simulated(robot, true_params(robot), 0.05, seed=3)))
    cv = fit.details["prior_weight_cv"]
    assert cv["scores"][cv["candidates"].index(3000)] == float("inf") and cv["chosen"] != 3000
    assert cv["reason"].endswith("; 3000 left out (the solve failed)")
    assert [str(w.message) for w in said if w.category is physical.PriorWeightWarning] == [
        "pcls prior_weight=auto: the solve failed for weight 3000, left out of the choice (pcls: the conic "
        "solver failed (CLARABEL: status 'numerical')); set estimator.prior_weight to fix one"
    ]
