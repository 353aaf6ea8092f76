"""The robustness study's non-search estimators over stacked trials: the measurement behind
docs/estimators.md ("Many trials at once").

Run: ``python bench/linear_trials.py [TRIALS] [CHUNK]`` (default ``1000 50``, the study's default
``trials=1000`` and ``robustness.chunk=50``). The robustness study's default estimators (ls,
ls-rel, rls, rls-rel, irls of idkit-robust if installed) are fitted to the study's four scenarios
as the study calls them: one ``fit_trials`` call per chunk of ``CHUNK`` trials and scenario. Each
is also fitted trial by trial (``fit`` per problem, what ``fit_trials`` did before these
estimators stacked trials) on the first chunk of every scenario, in the same run, so the ratio
depends less on the machine's load. One torch thread, one warm-up call, best of 3 for the
trial-by-trial column.
"""

from __future__ import annotations

import sys
import time
import warnings

import torch

from idkit import registry
from idkit.data.presets import PAPER_SCENARIOS
from idkit.data.scenarios import simulate_batch
from idkit.estimators.trials import fit_trials
from idkit.problem import Problem

ESTIMATORS = [("ls", {}), ("ls", {"relative": True}), ("rls", {}), ("rls", {"relative": True}), ("irls", {})]


def main() -> None:
    trials = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    chunk = int(sys.argv[2]) if len(sys.argv) > 2 else 50
    torch.set_num_threads(1)
    warnings.simplefilter("ignore")  # IRLS trials that reach max_iter warn; counted in the plugin's docs
    robot = registry.create("robot", "cylindrical")
    chosen = [(n, o) for n, o in ESTIMATORS if n in registry.available("estimator")]
    estimators = {f"{n}{'-rel' if o else ''}": registry.create("estimator", n, **o) for n, o in chosen}
    draws = {s: simulate_batch(robot, s, trials=trials, seed=0) for s in PAPER_SCENARIOS}
    chunks = [
        [Problem(robot, draws[s][t], seed=t) for t in range(first, min(first + chunk, trials))]
        for first in range(0, trials, chunk)
        for s in PAPER_SCENARIOS
    ]
    print(f"{trials} trials x {len(PAPER_SCENARIOS)} scenarios, {len(chunks)} fit_trials calls per estimator")
    print("estimator   whole study, stacked   per trial, stacked   per trial, alone   ratio")
    total = 0.0
    first = [p for problems in chunks[: len(PAPER_SCENARIOS)] for p in problems]
    for label, estimator in estimators.items():
        fit_trials(estimator, chunks[0])  # warm-up: first calls into torch and LAPACK
        stacked = _timed(lambda e=estimator: [fit_trials(e, problems) for problems in chunks])
        total += stacked
        alone = min(_timed(lambda e=estimator: [e.fit(p) for p in first]) for _ in range(3)) / len(first)
        per_trial = stacked / (trials * len(PAPER_SCENARIOS))
        print(
            f"{label:10s} {stacked:20.2f} s {per_trial * 1e3:17.3f} ms {alone * 1e3:15.3f} ms"
            f" {alone / per_trial:6.1f}x"
        )
    print(f"{'all':10s} {total:20.2f} s")


def _timed(work) -> float:
    start = time.perf_counter()
    work()
    return time.perf_counter() - start


if __name__ == "__main__":
    main()
