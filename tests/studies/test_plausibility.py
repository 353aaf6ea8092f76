"""Plausible, not only consistent: the bound pcls enforces on request, the flag every fit carries, and
the held-out cost the study prints when a fit leaves a link implausible."""

from __future__ import annotations

import re

import pytest
import torch
from urdf_cases import TREE_URDF

from idkit.conic.plausible import plausibility_report
from idkit.estimators.physical import PhysicallyConsistentLS, PlausibleNote
from idkit.problem import Problem, Samples
from idkit.reports.single import text
from idkit.robots.urdf import URDFRobot
from idkit.studies import single


def recording(robot: URDFRobot, params: torch.Tensor, seed: int, n: int = 400) -> Samples:
    generator = torch.Generator().manual_seed(seed)
    q, qd, qdd = robot.random_states(n, generator)
    tau = robot.inverse_dynamics(params, q, qd, qdd)
    noise = 0.01 * tau.square().mean(0).sqrt() * torch.randn(tau.shape, generator=generator, dtype=tau.dtype)
    return Samples(q, qd, qdd, tau + noise)


def heavy_link_b() -> tuple[URDFRobot, torch.Tensor]:
    """The tree robot whose link 'b' really weighs three times its CAD mass (a consistent body)."""
    robot = URDFRobot(TREE_URDF, friction=True, offset=True)
    params = robot.nominal_params().clone()
    b = robot.link_names.index("b")
    params[10 * b : 10 * b + 10] *= 3.0
    return robot, params


def test_the_flag_and_the_bound():
    robot, truth = heavy_link_b()
    problem = Problem(robot, recording(robot, truth, seed=1))
    free = PhysicallyConsistentLS(prior_weight=1.0).fit(problem)
    found = free.details["plausibility"]
    assert found["enforced"] == "none" and found["implausible"] == ["b"]
    assert found["mass"]["b"] / found["cad_mass"]["b"] > 2.5  # the data say 3x: the fit follows them
    bounded = PhysicallyConsistentLS(prior_weight=1.0, plausible=True, mass_ratio=(0.5, 2.0)).fit(problem)
    kept = bounded.details["plausibility"]
    assert kept["implausible"] == [] and "b" in kept["at_bound"]  # (c may go to its bound too)
    for link, mass in kept["mass"].items():
        assert 0.5 - 1e-6 <= mass / kept["cad_mass"][link] <= 2.0 + 1e-6
    # the price: the bounded model explains the training data worse
    assert bounded.details["rel_error_train"] > 1.5 * free.details["rel_error_train"]


def test_the_study_prints_what_plausibility_costs_on_the_held_out_file():
    """Link b really weighs 3x CAD: plausible=auto finds the bounds cost accuracy and leaves them off,
    and the other choice printed is the option's own fit (same fixed weight), scored held out."""
    robot, truth = heavy_link_b()
    result = single.run(
        robot=robot,
        estimator={"_name_": "pcls", "prior_weight": 1.0},
        cost=None,
        data=recording(robot, truth, seed=2),
        validate=[recording(robot, truth, seed=3)],
    )
    choice = result.estimate.details["plausible_choice"]
    assert choice["plausible"] is False and choice["reason"].startswith("not kept plausible: 5-fold")
    assert result.plausible is not None and result.plausible.implausible == ("b",)
    assert result.plausible.option == "estimator.plausible=true" and result.plausible.differs == ""
    (reported,), (bounded,) = [h.scores for h in result.validation], result.plausible.scores
    assert bounded.rel_all > reported.rel_all  # the truth is implausible: bounding it costs accuracy
    own = PhysicallyConsistentLS(prior_weight=1.0, plausible=True).fit(
        Problem(robot, recording(robot, truth, 2))
    )
    for name, value in own.params.items():  # the option's own fit, not a variant of it
        assert result.plausible.estimate.params[name] == pytest.approx(value, rel=1e-4, abs=1e-7)
    shown = text(result)
    said = "with estimator.plausible=true (enforced: link masses within [0.5, 2] x CAD; mass inside"
    assert said in shown and f"{100 * bounded.rel_all:.2f} %" in shown
    assert f"plausible=auto: {choice['reason']}" in shown
    bounded_by = "; ".join(f"{link}: nothing: no usable geometry" for link in ("a", "b", "c", "d"))
    assert f"bounded by: {bounded_by}" in shown  # which bodies are bounded by what, by name
    record = result.estimate.details["plausibility"]["links"]
    for link, verdict in record.items():  # the table reads the one record, reasons included
        row = next(line for line in shown.splitlines() if line.startswith(f"{link} "))
        assert (
            row.endswith(" !" + (f" ({'; '.join(verdict['reasons'])})" if verdict["reasons"] else ""))
            != (verdict["plausible"])
        )
    payload = result.payload()["plausible_alternative"]
    assert payload["option"] == "estimator.plausible=true" and "b" in payload["at_bound"]


def test_plausible_auto_keeps_the_bounds_where_they_cost_nothing():
    """Data of the CAD model itself: the bounds cost nothing in cross-validation, so they are kept; the
    note gives the figure both ways; the record holds the other choice, plausible=false's own fit."""
    robot = URDFRobot(TREE_URDF, friction=True, offset=True)
    problem = Problem(robot, recording(robot, robot.nominal_params(), seed=4))
    with pytest.warns(PlausibleNote) as said:
        fit = PhysicallyConsistentLS(prior_weight=10.0).fit(problem)
    choice = fit.details["plausible_choice"]
    assert choice["plausible"] is True and fit.details["plausibility"]["enforced"] != "none"
    assert re.search(
        r"torque error [\d.]+ % with the bounds \(prior weight 10\), [\d.]+ % without", choice["reason"]
    )
    assert [str(w.message) for w in said if w.category is PlausibleNote] == [
        f"pcls plausible=auto: {choice['reason']}"
    ]
    other = choice["alternative"]
    assert other["option"] == "estimator.plausible=false" and other["plausibility"]["enforced"] == "none"
    free = PhysicallyConsistentLS(prior_weight=10.0, plausible=False).fit(problem)
    for name, value in free.params.items():  # the same program, solved with and without DPP: 1e-5
        assert other["params"][name] == pytest.approx(value, rel=1e-3, abs=1e-5)


def test_a_given_band_is_honoured_and_a_band_without_plausibility_refused():
    robot, truth = heavy_link_b()
    problem = Problem(robot, recording(robot, truth, seed=1))
    fit = PhysicallyConsistentLS(prior_weight=1.0, mass_ratio=(0.8, 1.25)).fit(problem)
    assert "plausible_choice" not in fit.details  # given: enforced, not cross-validated away
    record = fit.details["plausibility"]
    assert record["enforced"].startswith("link masses within [0.8, 1.25] x CAD") and "b" in record["at_bound"]
    heavy = PhysicallyConsistentLS(prior_weight=1.0, total_mass=40.0)  # the CAD total is about 5 kg
    with pytest.warns(PlausibleNote, match=r"total_mass=40 kg is outside \[0.5, 2\] x the CAD total"):
        fit = heavy.fit(problem)
    assert "plausible_choice" not in fit.details and sum(fit.details["plausibility"]["mass"].values()) == (
        pytest.approx(40.0, rel=1e-6)
    )
    with pytest.raises(ValueError, match=r"^pcls: mass_ratio is the band plausible=true enforces"):
        PhysicallyConsistentLS(plausible=False, mass_ratio=(0.5, 2.0))
    with pytest.raises(ValueError, match=r"^pcls: plausible must be true, false or auto, got 'yes'$"):
        PhysicallyConsistentLS(plausible="yes")  # type: ignore[arg-type]


def test_a_point_mass_and_a_rod_are_degenerate_with_their_reason():
    """The one rule's verdicts: a link made a point mass, one made a rod, one that no body has."""
    robot = URDFRobot(TREE_URDF)
    params = robot.nominal_params().clone().double().numpy()
    names = robot.link_names
    a, b, c = (names.index(k) for k in ("a", "b", "c"))
    m = params[10 * a]
    params[10 * a + 1 : 10 * a + 4] = 0.0
    params[10 * a + 4 : 10 * a + 10] = [1e-9 * m, 0, 0, 1e-9 * m, 0, 1e-9 * m]  # a point at the origin
    mb = params[10 * b]
    params[10 * b + 1 : 10 * b + 4] = 0.0
    params[10 * b + 4 : 10 * b + 10] = [0.01 * mb, 0, 0, 0.01 * mb, 0, 1e-7 * mb]  # a rod along z
    params[10 * c + 4] = 10 * (params[10 * c + 7] + params[10 * c + 9])  # triangle inequality broken
    record = plausibility_report(robot, None, params)
    links = record["links"]
    assert links["a"]["reasons"][0].startswith("degenerate: a point mass: radius of gyration")
    assert (
        links["b"]["reasons"] == [links["b"]["reasons"][0]] and "a rod or plate" in links["b"]["reasons"][0]
    )
    assert links["c"]["reasons"][0].startswith("no body has this inertia")
    assert set(record["implausible"]) >= {"a", "b", "c"} and record["degenerate"] == ["a", "b"]
    assert record["not_a_body"] == ["c"] and links["d"]["plausible"]


def test_the_weight_moves_off_a_degenerate_fit_only_as_far_as_the_data_allow():
    """cross_validated_weight: the lowest error, unless its fit is degenerate; then the smallest larger
    weight whose fit is not (here: stand-ins that call every weight below 30, or every weight,
    degenerate)."""
    from idkit.conic.program import ConsistentProgram, ConsistentSettings, compress
    from idkit.estimators.physical import cross_validated_weight

    robot = URDFRobot(TREE_URDF, friction=True, offset=True)
    problem = Problem(robot, recording(robot, robot.nominal_params(), seed=5, n=300))
    W, tau = problem.base_regressor(), problem.tensors().tau.reshape(-1)
    R, _, rest = compress(W, tau)
    settings = ConsistentSettings.checked("test", "auto", auto=True)
    built = {p: ConsistentProgram(robot, settings, R.shape[0], p) for p in (False, True)}
    scale2 = rest / (W.shape[0] - W.shape[1])
    plain = cross_validated_weight(built.__getitem__, robot, W, tau, scale2)
    best = min(plain.scores, key=plain.scores.__getitem__)
    assert plain.weight == best and plain.reason.startswith("the lowest 5-fold cross-validated")
    moved = cross_validated_weight(
        built.__getitem__, robot, W, tau, scale2, degenerate=lambda w: ["a"] if w < 30 else []
    )
    if best >= 30:
        assert moved.weight == best and moved.reason == plain.reason
    else:  # the first weight that leaves none: 30, said with its cost in standard errors
        assert (
            moved.weight == 30 and "there a is degenerate (a rod, plate or point mass), so 30" in moved.reason
        )
        assert ("within one standard error" in moved.reason) == (plain.standard_errors[30] <= 1)
    never = cross_validated_weight(built.__getitem__, robot, W, tau, scale2, degenerate=lambda w: ["a"])
    assert never.weight == best and never.reason.endswith("and stay so at every weight")
