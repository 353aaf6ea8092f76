"""A stalled driver: case ``c`` with three 40 ms stalls (the states repeat their last row while the
commands go on), fitted with the stalled rows left out (idkit's default, :mod:`idkit.data.artefacts`)
and kept as data, from the same starts.

Run: ``python bench/rollout_stalls.py [--starts 3] [--threads 2]``. Columns: unknowns within 5 % of the
truth (the delay within 5 % or 0.1 ms, as in ``bench/rollout.py``), the largest relative error, wall time.

Measured 2026-12-07 on the shared 2-core machine under load (``--starts 3 --threads 1``): stalled rows
left out 36/36 within 5 % from each start (largest error 1.3 %); kept as data 36/36 (largest 4.4–4.6 %).
"""

# ruff: noqa: E402
from __future__ import annotations

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import argparse
import time
import warnings
from dataclasses import replace

import numpy as np
from rollout import SUCCESS, relative_errors

from idkit.estimators.rollout import RolloutEstimator
from idkit.testing import rollout_cases as cases


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--starts", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    base = cases.case_b(corrupted=True)
    case = replace(base, fit=cases.stalled(base.fit))
    starts = [case.start, *case.starts(args.starts - 1, seed=1)]
    print(f"case c + 3 stalls of 40 ms: {len(case.truth)} unknowns, {case.fit.n_samples} samples")
    print(f"{'stalled rows':<14}{'start':>6}{'within 5 %':>12}{'worst':>9}{'wall':>8}  left out")
    for mode in ("left out", "kept"):
        for k, start in enumerate(starts):
            problem = cases.problem_of(case, start, threads=args.threads, leave_out_stalls=mode != "kept")
            began = time.perf_counter()
            estimate = RolloutEstimator().fit(problem)
            wall = time.perf_counter() - began
            errors = relative_errors(case, np.array(list(estimate.params.values())))
            within = int((errors < SUCCESS).sum())
            print(
                f"{mode:<14}{k:>6}{f'{within}/{errors.size}':>12}{errors.max():>8.1%}{wall:>7.1f}s  "
                f"{estimate.details['outliers']}",
                flush=True,
            )


if __name__ == "__main__":
    main()
