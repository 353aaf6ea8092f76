"""The fast engine on a machine without a C compiler: fresh processes, fresh caches, same numbers.

Run: ``python bench/no_compiler.py [--repeats 7]``. Each row is a new Python process that fits the
benchmark's 10-run estimate (paper preset, f13, ``torque_noise``, seed 0, one thread) ``repeats + 1``
times and reports: the first fit's wall time from the call to the result (the one-time kernel load
or build included), the build it recorded apart (``details["engine_build_s"]``), the median of the
later fits, and a hash of the estimate's numbers. Environments:

- *normal*: this process's ``PATH`` (a C compiler on it here) and a warm cache;
- *no compiler, fresh cache*: ``PATH`` holds no ``cc``/``gcc``/``clang`` (an empty folder; the
  interpreter is called by its full path), ``CC`` is unset, and ``IDKIT_CACHE_DIR`` is a new empty
  folder — a new user's first run on a slim machine. The child checks that no compiler is found.

The ratio column is the median fit against the normal environment's, measured in the same run.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = """
import hashlib, json, shutil, statistics, sys, time
import torch
torch.set_num_threads(1)
started = time.perf_counter()
from idkit.costs import paper
from idkit.data.scenarios import simulate
from idkit.estimators.pso import ParticleSwarm
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot
robot = CylindricalRobot()
problem = Problem(robot, simulate(robot, "torque_noise", seed=0), paper.f13(), seed=0)
pso = ParticleSwarm(preset="paper", runs=10, threads=1, history=False, engine=sys.argv[1])
call = time.perf_counter()
first = pso.fit(problem)
first_s = time.perf_counter() - call
times = []
for _ in range(int(sys.argv[2])):
    call = time.perf_counter()
    pso.fit(problem)
    times.append(time.perf_counter() - call)
assert all(again.params == first.params for again in [pso.fit(problem)])
print(json.dumps({
    "compiler": [shutil.which(c) for c in ("cc", "gcc", "clang")],
    "first_s": first_s,
    "build_s": first.details.get("engine_build_s"),
    "engine": first.details["engine"],
    "how": first.details.get("engine_build"),
    "median_s": statistics.median(times or [first_s]),
    "numbers": hashlib.sha256(json.dumps(first.params, sort_keys=True).encode()).hexdigest()[:12],
}))
"""


def child(engine: str, repeats: int, environment: dict[str, str]) -> dict:
    done = subprocess.run(
        [sys.executable, "-c", CHILD, engine, str(repeats)],
        env=environment,
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode:
        raise RuntimeError(f"child failed: {done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def rows(repeats: int, candidates: dict[str, dict[str, str]] | None = None) -> list[str]:
    """Markdown rows: per candidate (extra environment variables), normal and no-compiler processes."""
    candidates = candidates or {"fast kernel": {}}
    lines = []
    with tempfile.TemporaryDirectory() as empty, tempfile.TemporaryDirectory() as caches:
        for name, extra in candidates.items():
            normal = {**os.environ, **extra}
            child("native", 0, normal)  # warm the normal cache
            base = child("native", repeats, normal)
            bare = {k: v for k, v in normal.items() if k != "CC"}
            bare.update(
                PATH=empty, IDKIT_CACHE_DIR=str(Path(caches) / hashlib.md5(name.encode()).hexdigest())
            )
            fresh = child("native", repeats, bare)
            if any(fresh["compiler"]):
                raise RuntimeError(f"the no-compiler child still finds a compiler: {fresh['compiler']}")
            for label, result in (("normal PATH, warm cache", base), ("no compiler, fresh cache", fresh)):
                lines.append(
                    f"| {name}: {label} | {result['engine']} | {result['first_s']:.2f} s "
                    f"| {result['build_s'] or 0:.2f} s | {result['median_s'] * 1e3:.2f} ms "
                    f"| {result['median_s'] / base['median_s']:.2f}× | {result['numbers']} |"
                )
    return lines


HEADER = (
    "| 10-run estimate in a new process | engine | first fit, call to result | of which build "
    "(recorded apart) | later fits (median) | vs normal | numbers (hash) |\n"
    "| --- | --- | --- | --- | --- | --- | --- |"
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    print(HEADER)
    print("\n".join(rows(args.repeats)))


if __name__ == "__main__":
    main()
