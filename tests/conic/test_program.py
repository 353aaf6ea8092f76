"""The consistent program's guarantees, independent of the conic solver's last digits.

The bundled cylindrical URDF is the hard case: its rods and disc are singular bodies, and a truth at
CAD puts the solution on the boundary of the cone. Before idkit solved in scaled units with thickened
references, the fits on it failed on some CPUs and not on others (Clarabel, then SCS outside the
cone). Here the same fits must succeed with every candidate prior weight solved, every link inside
the cone, and a result that moves by far less than the noise when the input moves by 1e-9.
"""

from __future__ import annotations

import warnings
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest
import torch

from idkit.conic.program import REPAIR_LIMIT, _into_cone, _standard_from_pseudo
from idkit.estimators.physical import PhysicallyConsistentLS, PriorWeightWarning
from idkit.problem import Problem, Samples
from idkit.robots.inertia import pseudo_inertia, pseudo_inertia_rows
from idkit.robots.urdf import URDFRobot

CYLINDRICAL = str(files("idkit") / "robots/assets/cylindrical.urdf")
NOISE = 0.01  # N·m, on torques of ~1-80 N·m


def smooth_samples(robot: URDFRobot, seed: int, n: int = 1200, rate: float = 200.0) -> Samples:
    """A smooth three-harmonic motion inside the limits, the CAD body with friction and offsets, and
    Gaussian torque noise ``NOISE`` — a recording's correlated samples, not random states."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    q, qd, qdd = (np.zeros((n, robot.n_joints)) for _ in range(3))
    for j, body in enumerate(robot.tree.bodies):
        lo, hi = body.limits
        q[:, j] = (lo + hi) / 2
        for k in (1, 2, 3):
            w, phase, a = 2 * np.pi * 0.15 * k * (1 + 0.2 * j), rng.uniform(0, 2 * np.pi), 0.2 * (hi - lo) / k
            q[:, j] += a * np.sin(w * t + phase)
            qd[:, j] += a * w * np.cos(w * t + phase)
            qdd[:, j] -= a * w**2 * np.sin(w * t + phase)
    params = robot.nominal_params().clone()
    for k, name in enumerate(robot.param_names):
        params[k] = {"fc": 0.5, "fv": 0.2, "offset": 0.1}.get(name.rsplit(".", 1)[1], float(params[k]))
    states = [torch.from_numpy(x) for x in (q, qd, qdd)]
    tau = robot.inverse_dynamics(params, *states)
    tau = tau + NOISE * torch.from_numpy(rng.standard_normal(tau.shape))
    return Samples(*states, tau)


def fit_quietly(robot: URDFRobot, samples: Samples):
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        fit = PhysicallyConsistentLS().fit(Problem(robot, samples))
    assert not [w for w in said if issubclass(w.category, PriorWeightWarning)], "a candidate failed"
    return fit


def check_inside_the_cone(robot: URDFRobot, params: dict[str, float]) -> None:
    nb = len(robot.link_names)
    values = torch.tensor([params[name] for name in robot.param_names[: 10 * nb]], dtype=torch.float64)
    lowest = torch.linalg.eigvalsh(pseudo_inertia(values.reshape(nb, 10)))[:, 0]
    assert (lowest >= 0).all(), lowest


@pytest.mark.parametrize("seed", [1, 5])
def test_pcls_on_degenerate_cad_solves_every_candidate_and_ignores_a_1e_9_nudge(seed):
    robot = URDFRobot(CYLINDRICAL, friction=True, offset=True)
    samples = smooth_samples(robot, seed)
    nudge = 1 + 1e-9 * torch.from_numpy(np.random.default_rng(seed + 50).standard_normal(samples.tau.shape))
    fits = [
        fit_quietly(robot, samples),
        fit_quietly(robot, Samples(samples.q, samples.qd, samples.qdd, samples.tau * nudge)),
    ]
    held_out = smooth_samples(robot, seed + 100)
    predicted = []
    for fit in fits:
        check_inside_the_cone(robot, fit.params)
        assert all(np.isfinite(s) for s in fit.details["prior_weight_cv"]["scores"])
        values = torch.tensor([fit.params[name] for name in robot.param_names], dtype=torch.float64)
        predicted.append(robot.inverse_dynamics(values, held_out.q, held_out.qd, held_out.qdd))
        # the fit explains the held-out motion to the noise: a right model, not only a solved program
        assert float((predicted[-1] - held_out.tau).square().mean().sqrt()) < 1.5 * NOISE
    # far below the noise: no result sits on a knife edge of the solver or the weight choice
    assert float((predicted[0] - predicted[1]).abs().max()) < 0.05 * NOISE


def test_a_solution_a_hair_outside_the_cone_is_moved_onto_it_and_a_far_one_refused():
    names = ("rod", "ball")
    ball = _standard_from_pseudo(np.diag([0.3, 0.3, 0.3, 1.0]))
    rod = np.diag([1e-3, 1.0, 1.0, 1.0])
    np.testing.assert_allclose(
        np.array(pseudo_inertia_rows(list(_standard_from_pseudo(rod))), dtype=float), rod, atol=1e-15
    )
    rod[0, 0] = -0.1 * REPAIR_LIMIT  # the thin moment just negative: an interior-point solver's hair
    z = np.concatenate([_standard_from_pseudo(rod), ball])
    moved, repaired, worst = _into_cone(z, 2, names)
    assert repaired == ("rod",) and worst is None
    lowest = np.linalg.eigvalsh(pseudo_inertia(torch.as_tensor(moved).reshape(2, 10)).numpy())[:, 0]
    assert (lowest >= 0).all()
    assert np.abs(moved - z).max() < 2 * REPAIR_LIMIT  # a change far below any torque noise
    np.testing.assert_array_equal(moved[10:], z[10:])  # the ball was inside: untouched
    rod[0, 0] = -0.01
    _, _, worst = _into_cone(np.concatenate([_standard_from_pseudo(rod), ball]), 2, names)
    assert worst == "rod (-0.01)"


def test_scs_stopped_by_ctrl_c_stops_the_run_instead_of_failing_one_candidate():
    """SCS catches SIGINT and returns "interrupted", which cvxpy calls a solver failure: the
    cross-validation would go on to the next fold. idkit's SCS interface turns it back into Ctrl-C."""
    from idkit.conic.program import SCS_INTERRUPTED, _interruptible_scs

    with pytest.raises(KeyboardInterrupt):
        _interruptible_scs().invert({"info": {"status_val": SCS_INTERRUPTED}}, None)


@pytest.mark.integration
def test_ctrl_c_during_an_scs_cross_validation_stops_within_a_second(tmp_path):
    import subprocess
    import sys
    import textwrap

    script = textwrap.dedent(
        f"""
        import os, signal, sys, threading, time
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from test_program import CYLINDRICAL, smooth_samples
        from idkit.estimators.physical import PhysicallyConsistentLS
        from idkit.problem import Problem
        from idkit.robots.urdf import URDFRobot
        robot = URDFRobot(CYLINDRICAL, friction=True, offset=True)
        problem = Problem(robot, smooth_samples(robot, 1))
        sent = []
        def interrupt():
            time.sleep(4.0)
            sent.append(time.perf_counter())
            os.kill(os.getpid(), signal.SIGINT)
        threading.Thread(target=interrupt, daemon=True).start()
        try:
            PhysicallyConsistentLS(solver="scs").fit(problem)
            print("finished")
        except KeyboardInterrupt:
            print(f"stopped {{time.perf_counter() - sent[0]:.3f}}")
        """
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600)
    last = out.stdout.strip().splitlines()[-1] if out.stdout.strip() else ""
    assert last.startswith("stopped"), repr(out.stdout) + out.stderr[-2000:]
    assert float(last.split()[1]) < 1.0


def test_the_euclidean_prior_pulls_to_cad_and_an_unknown_shape_is_refused():
    """``prior_shape="euclidean"`` (studied in bench/pcls_prior_rule.py): at a huge weight the fit is CAD's
    inertials; any other shape is refused in one line naming the choices."""
    from idkit.conic.program import ConsistentSettings, compress, solve_consistent

    robot = URDFRobot(CYLINDRICAL, friction=True, offset=True)
    problem = Problem(robot, smooth_samples(robot, seed=2, n=400))
    W, tau = problem.base_regressor(), problem.tensors().tau.reshape(-1)
    R, b, rest = compress(W, tau)
    scale2 = rest / (W.shape[0] - W.shape[1])
    nb = len(robot.link_names)
    cad = robot.nominal_params().double().numpy()[: 10 * nb]
    distances = []
    for weight in (1.0, 1e8):
        settings = ConsistentSettings.checked("test", weight, prior_shape="euclidean")
        fit = solve_consistent(robot, R, b, scale2, settings).params.numpy()[: 10 * nb]
        distances.append(np.abs(fit - cad).max())
    assert distances[1] < 0.1 * distances[0]  # pulled to CAD (its singular rods kept inside the cone)
    with pytest.raises(
        ValueError, match=r"^test: prior_shape must be one of 'entropic', 'euclidean', got 'l1'$"
    ):
        ConsistentSettings.checked("test", 1.0, prior_shape="l1")  # type: ignore[arg-type]
