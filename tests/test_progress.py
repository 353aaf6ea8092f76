"""Progress lines: quiet unless a study listens, one line per new stage, else at most one per interval;
a rollout fit says its search and its polish."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from idkit import progress


def test_nothing_is_printed_unless_a_study_listens(capsys):
    progress.report("search", 1, 10, 3.0)
    with progress.reporting("fit", enabled=False) as reporter:
        progress.report("search", 1, 10, 3.0)
    assert reporter is None and capsys.readouterr() == ("", "")


def test_a_new_stage_prints_at_once_and_a_stage_at_most_once_per_interval():
    lines: list[str] = []
    now = [0.0]
    with progress.reporting("fit", write=lines.append, interval=3.0) as reporter:
        assert reporter is not None
        reporter.clock, reporter.started = (lambda: now[0]), 0.0
        progress.count_rollouts(lambda: 1234)
        for step in range(10):  # one call a second
            now[0] = float(step)
            progress.report("search", step + 1, 10, 10.0 - step)
        progress.report("polish", best=2.0, what="error / noise")  # numbered by the reporter
        progress.report("polish", best=1.5, what="error / noise")  # within the interval: not printed
    progress.report("search", 99)  # after the block: nobody listens
    assert lines == [
        "fit: search · iteration 1/10 · best cost 10 · 1,234 rollouts · 0.0 s",
        "fit: search · iteration 4/10 · best cost 7 · 1,234 rollouts · 3.0 s",
        "fit: search · iteration 7/10 · best cost 4 · 1,234 rollouts · 6.0 s",
        "fit: search · iteration 10/10 · best cost 1 · 1,234 rollouts · 9.0 s",
        "fit: polish · iteration 1 · error / noise 2 · 1,234 rollouts · 9.0 s",
    ]


@settings(deadline=None)  # a shared machine's load is not this test's subject
@given(
    st.lists(st.tuples(st.floats(0, 5, allow_nan=False), st.sampled_from(["search", "polish"])), max_size=60)
)
def test_lines_of_one_stage_are_an_interval_apart_and_every_stage_change_is_said(calls):
    lines: list[tuple[float, str]] = []
    now = [0.0]
    with progress.reporting("fit", write=lambda line: lines.append((now[0], line)), interval=3.0) as reporter:
        assert reporter is not None
        reporter.clock = lambda: now[0]
        previous = None
        changes = 0
        for step, (gap, stage) in enumerate(calls):
            now[0] += gap
            progress.report(stage, step)
            changes += stage != previous
            previous = stage
    said = [(t, line.split(" · ")[0]) for t, line in lines]
    assert sum(1 for k, (_, s) in enumerate(said) if k == 0 or s != said[k - 1][1]) == changes
    for (t0, s0), (t1, s1) in zip(said, said[1:], strict=False):
        assert s0 != s1 or t1 - t0 >= 3.0


def test_a_rollout_fit_reports_its_search_and_its_polish():
    from idkit import registry
    from idkit.testing.rollout_cases import conformance_problem

    lines: list[str] = []
    estimator = registry.create("estimator", "rollout", particles=4, iterations=3, polish_iterations=5)
    with progress.reporting("rollout", write=lines.append, interval=0.0):
        estimate = estimator.fit(conformance_problem())
    stages = [line.split(" · ")[0] for line in lines]
    assert stages[0] == "rollout: search" and "rollout: polish" in stages
    assert all(" · iteration " in line and " rollouts · " in line for line in lines)
    last = int(lines[-1].split(" · ")[-2].split()[0].replace(",", ""))
    assert 0 < last <= estimate.details["rollouts"]
