"""Logs the model cannot have produced and bounds the log cannot support: one line before the fit;
a driver's stalls left out of the error; unsupported estimates said one line each."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

from idkit.data.commands import RobotLog
from idkit.sim.log_check import RolloutWarning, check_delay_bound, warn_unsupported
from idkit.sim.quantities import select_unknowns
from idkit.sim.segments import split
from idkit.testing import rollout_cases as cases


@pytest.fixture(scope="module")
def problem():
    return cases.conformance_problem()


def _with(log: RobotLog, **arrays) -> RobotLog:
    fields = {k: getattr(log, k) for k in ("t", "q", "qd", "command_t", "commands")} | arrays
    return RobotLog(**fields, joint_names=log.joint_names, command_names=log.command_names, source="run.csv")


def test_a_log_in_degrees_is_refused_naming_the_file_the_joint_and_the_cause():
    """Case b's arm (joints of ±3 rad, up to 0.5 rad sines) logged in degrees: 270 "rad/s"."""
    case = cases.case_b()
    problem = cases.problem_of(case)
    log = case.fit
    degrees = _with(log, q=np.degrees(log.q), qd=np.degrees(log.qd))
    with pytest.raises(ValueError, match=r"^run.csv: joint j1 moves at 27\d.* rad/s .*degrees") as raised:
        replace(problem, samples=degrees)
    assert "\n" not in str(raised.value)


def test_velocities_in_other_units_than_positions_are_refused(problem):
    log = problem.samples
    with pytest.raises(ValueError, match=r"^run.csv: joint joint1's logged velocities are 57.3× the rate"):
        replace(problem, samples=_with(log, qd=log.qd * np.array([np.degrees(1.0), 1.0])))
    with pytest.raises(ValueError, match=r"joint joint2's logged velocities are 0.1× the rate"):
        replace(problem, samples=_with(log, qd=log.qd * np.array([1.0, 0.1])))
    replace(problem, samples=_with(log, qd=log.qd * 1.5))  # a filter's lag or gain: not refused
    with pytest.raises(
        ValueError, match=r"joint joint1's logged velocities are zero while its positions move"
    ):
        replace(problem, samples=_with(log, qd=np.zeros_like(log.qd)))


def test_positions_far_outside_a_limited_joints_range_are_refused():
    case = cases.case_b()
    problem = cases.problem_of(case)
    sim = problem.robot.sim
    low, high = sim.model.jnt_range[sim.joint_id("j1")]
    assert sim.model.jnt_limited[sim.joint_id("j1")]
    q = case.fit.q.copy()
    q[:, 0] += 3 * (high - low)
    with pytest.raises(ValueError, match=r"joint j1 reaches .* far outside its range"):
        replace(problem, samples=_with(case.fit, q=q))


def test_a_delay_bound_over_a_tenth_of_the_log_is_refused():
    case = cases.case_b()
    problem = cases.problem_of(case)
    duration = case.fit.t[-1] - case.fit.t[0]
    sim = problem.robot.sim
    ok = select_unknowns(
        sim, case.fit.joint_names, ("command_delay",), bounds={"command_delay": [0, 0.1 * duration]}
    )
    check_delay_bound(ok, case.fit.t, "run.csv")
    long = select_unknowns(
        sim, case.fit.joint_names, ("command_delay",), bounds={"command_delay": [0, 100.0]}
    )
    with pytest.raises(
        ValueError, match=r"^run.csv: the bound of command_delay reaches 100 s, more than a tenth"
    ):
        check_delay_bound(long, case.fit.t, "run.csv")
    with pytest.raises(ValueError, match="more than a tenth of the log"):
        cases.problem_of(replace(case, bounds={**case.bounds, "command_delay": [0.0, 100.0]}))


def test_stalled_rows_are_in_no_segment_and_so_in_no_error(problem):
    log = problem.samples
    stalled = cases.stalled(log, stretches=2, seconds=0.02)
    other = replace(problem, samples=stalled, _cache={})
    assert other.outliers() == {"stalled": 20, "stalls": 2, "dropped": 0}
    rows = set(np.flatnonzero(other.artefacts().stalled))
    predicted = {i for a, b in other.segments() for i in range(a, b)}
    assert rows and not rows & predicted
    assert split(log.t, None, other.artefacts().stalled) == [
        (a, b) for a, b in _runs_between(log.n_samples, sorted(rows))
    ]
    simulator = other.simulator()
    try:
        assert not rows & set(simulator.samples.tolist())
    finally:
        simulator.close()


def _runs_between(n: int, excluded: list[int]) -> list[tuple[int, int]]:
    out, first = [], 0
    for i in [*excluded, n]:
        if i > first:
            out.append((first, i))
        first = i + 1
    return out


def test_an_estimate_on_a_bound_or_with_an_infinite_sigma_is_said_in_one_line_each(problem):
    unknowns = problem.robot.unknowns
    lower, upper = unknowns.vector("lower"), unknowns.vector("upper")
    values = (lower + upper) / 2
    values[0] = lower[0]
    std = dict.fromkeys(unknowns.names, 0.1)
    std[unknowns.names[-1]] = np.inf
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        lines = warn_unsupported(unknowns, values, std)
    assert [str(w.message) for w in caught if w.category is RolloutWarning] == lines
    assert len(lines) == 2 and all("\n" not in line for line in lines)
    assert f"{unknowns.names[0]} = " in lines[0] and "ended on its lower bound" in lines[0]
    assert "infinite σ" in lines[1]
    assert unknowns.at_bound(values) == [unknowns.names[0]]


def test_stalls_can_be_fitted_as_data_to_measure_what_they_do(problem):
    stalled = replace(problem, samples=cases.stalled(problem.samples, stretches=2, seconds=0.02), _cache={})
    kept = replace(stalled, leave_out_stalls=False, _cache={})
    assert kept.outliers()["stalled"] == 0 and stalled.outliers()["stalled"] == 20
    assert kept.segments() == problem.segments()
