"""Where the time of one command goes: ``idkit +scenario=outliers estimator=pso cost=f13``.

Runs the command in fresh processes (each pays every import, as a user does) and prints the CPU
seconds of its phases: the whole process, the imports by package (``python -X importtime``, which
reports wall time), and, with the phase's function wrapped in a CPU timer, Hydra's config
composition, the study (of which the fit), the report (of which the plots). CPU time where
possible, because the benchmark machine is shared.

    python bench/latency.py [--repeat 3] [extra overrides ...]
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

COMMAND = ["+scenario=outliers", "estimator=pso", "cost=f13"]
#: Top-level packages whose cumulative import time is reported .
PACKAGES = (
    "torch",
    "hydra",
    "omegaconf",
    "matplotlib",
    "numpy",
    "numba",
    "scipy",
    "cvxpy",
    "pytorch_kinematics",
    "idkit",
)
#: Timed phases: label -> (module, attribute path) of the function whose CPU time is the phase.
PHASES = {
    "Hydra: compose the config": (
        "hydra._internal.config_loader_impl",
        "ConfigLoaderImpl.load_configuration",
    ),
    "study (simulate, fit, metrics)": ("idkit.studies.single", "run"),
    "  of which the PSO fit": ("idkit.estimators.pso", "ParticleSwarm.fit"),
    "  of which the fast engine's load (numba)": ("idkit.optim.fast", "kernel"),
    "report (text, files, plots)": ("idkit.reports.single", "write"),
    "  of which the plots (matplotlib import included)": ("idkit.reports.plots", "convergence"),
    "  of which the plots, 2nd figure": ("idkit.reports.plots", "estimates_vs_truth"),
}
#: Runs the command with each phase's function wrapped in a CPU timer (no profiler overhead).
DRIVER = """
import functools, importlib, json, os, sys, time
sys.argv = ["idkit", *sys.argv[1:]]
phases, spent = json.loads(os.environ["LATENCY_PHASES"]), {}
def timed(label, function):
    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        started = time.process_time()
        try:
            return function(*args, **kwargs)
        finally:
            spent[label] = spent.get(label, 0.0) + time.process_time() - started
    return wrapper
for label, (module, path) in phases.items():
    owner = importlib.import_module(module)
    *parents, name = path.split(".")
    for parent in parents:
        owner = getattr(owner, parent)
    setattr(owner, name, timed(label, getattr(owner, name)))
from idkit.cli import main
try:
    main()
except SystemExit:
    pass
print("LATENCY " + json.dumps(spent))
"""


def child_cpu(args: list[str], env: dict[str, str]) -> float:
    """User + system CPU seconds of one child process running ``args``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(args, env=env, check=True, capture_output=True, text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def import_times(args: list[str], env: dict[str, str]) -> dict[str, float]:
    """Cumulative import seconds of ``PACKAGES`` in one run (``-X importtime``, top-level rows)."""
    out = subprocess.run(args[:1] + ["-X", "importtime"] + args[1:], env=env, capture_output=True, text=True)
    found: dict[str, float] = {}
    for line in out.stderr.splitlines():
        match = re.match(r"import time:\s+\d+ \|\s+(\d+) \|( *)(\S+)$", line)
        if match and match.group(3).split(".")[0] in PACKAGES and match.group(3) in PACKAGES:
            found[match.group(3)] = found.get(match.group(3), 0.0) + int(match.group(1)) / 1e6
    return found


def phases(args: list[str], env: dict[str, str], work: Path) -> dict[str, float]:
    """CPU seconds of ``PHASES`` in one run (their modules are imported before the clock starts)."""
    import json

    driver = work / "driver.py"
    driver.write_text(DRIVER)
    out = subprocess.run([args[0], str(driver), *args[3:]], env={**env, "LATENCY_PHASES": json.dumps(PHASES)},
                         check=True, capture_output=True, text=True)  # fmt: skip
    spent = json.loads(out.stdout.rsplit("LATENCY ", 1)[1])
    return {label: spent.get(label, 0.0) for label in PHASES}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per measurement (median)")
    parser.add_argument("overrides", nargs="*", help="extra overrides, e.g. plots=false")
    options = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        env = {**os.environ, "OMP_NUM_THREADS": "1"}
        args = [sys.executable, "-c", "from idkit.cli import main; main()", *COMMAND, *options.overrides,
                f"hydra.run.dir={work}/run"]  # fmt: skip
        print(f"load average before: {os.getloadavg()[0]:.1f}")
        started = time.perf_counter()
        whole = [child_cpu(args[:-1] + [f"hydra.run.dir={work}/run{i}"], env) for i in range(options.repeat)]
        wall = (time.perf_counter() - started) / options.repeat
        bare = [child_cpu([sys.executable, "-c", "import torch"], env) for _ in range(options.repeat)]
        imports = [
            import_times(args[:-1] + [f"hydra.run.dir={work}/imp{i}"], env) for i in range(options.repeat)
        ]
        timed = [
            phases(args[:-1] + [f"hydra.run.dir={work}/prof{i}"], env, work) for i in range(options.repeat)
        ]
        print(f"load average after: {os.getloadavg()[0]:.1f}")
    rows = [
        ("whole command (process CPU)", statistics.median(whole)),
        ("  wall (mean, machine shared)", wall),
        ("python -c 'import torch' alone (process CPU)", statistics.median(bare)),
    ]
    rows += [
        (f"import {p} (cumulative, wall)", statistics.median(i.get(p, 0.0) for i in imports))
        for p in PACKAGES
    ]
    rows += [(label, statistics.median(p[label] for p in timed)) for label in PHASES]
    print(f"\n`idkit {' '.join(COMMAND + options.overrides)}`, median of {options.repeat} fresh processes\n")
    print("| phase | seconds |\n| --- | ---: |")
    for label, value in rows:
        print(f"| {label} | {value:.3f} |")


if __name__ == "__main__":
    main()
