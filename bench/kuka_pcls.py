"""Physically consistent fits of the KUKA LWR4+: trained on measurements_1, scored on 2 and 3.

Run: ``python bench/kuka_pcls.py [--adam]``. Prints one Markdown table: ‖E‖/‖T‖ on the training
recording and the two held-out ones, NRMS/limit, the smallest pseudo-inertia eigenvalue over the
links (and how many links are negative), and the wall time of the fit (of the projection for the
"projected" rows). Rows: unconstrained LS, LS projected onto the consistent set (in the training
data's torque metric and in the robot's random-state metric), pcls without prior and with
``prior_weight`` 100 / 300 / 1000, each with Coulomb + viscous friction and again with a Stribeck
term (``v_s = 0.05 rad/s``); ``--adam`` adds box-constrained Adam (4 starts, f1) and its projections.
The recordings' own velocities and accelerations are used, as in ``idkit +experiment=kuka``. Needs
the KUKA files in ``../shared/data/kuka-lwr4`` (not part of the repo).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch

from idkit import registry
from idkit.conic.program import nearest_consistent
from idkit.data.load import load_data_file
from idkit.estimators.physical import PhysicallyConsistentLS
from idkit.model import IdentifiedModel
from idkit.problem import Problem, Samples
from idkit.robots.inertia import min_pseudo_inertia_eigenvalues
from idkit.robots.urdf import URDFRobot
from idkit.studies.validation import validate

KUKA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "kuka-lwr4"
PRIORS = (0.0, 100.0, 300.0, 1000.0)


def row(label: str, robot: URDFRobot, params: torch.Tensor, seconds: float, data: dict[int, Samples]) -> str:
    scores = {k: validate(robot, s, params) for k, s in data.items()}
    eig = min_pseudo_inertia_eigenvalues(robot, params)
    cells = [
        label,
        *(f"{100 * scores[k].rel_all:.2f} %" for k in (1, 2)),
        f"{100 * scores[2].nrms_limit:.3f} %",
        f"{100 * scores[3].rel_all:.2f} %",
        f"{100 * scores[3].nrms_limit:.3f} %",
        f"{float(eig.min()):.1e} ({int((eig < 0).sum())} < 0)",
        f"{seconds:.2f} s",
    ]
    return "| " + " | ".join(cells) + " |"


def vector(robot: URDFRobot, values: dict[str, float]) -> torch.Tensor:
    return IdentifiedModel.from_params(robot, values).vector


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--adam", action="store_true", help="add Adam (4 starts) and its projections")
    args = parser.parse_args()
    torch.set_num_threads(1)
    data = {k: load_data_file(KUKA / f"measurements_{k}.npz").samples for k in (1, 2, 3)}
    print(
        "| model | meas. 1 (train) | meas. 2 | meas. 2 NRMS/limit | meas. 3 | meas. 3 NRMS/limit "
        "| min eig (links < 0) | time |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for stribeck in (None, 0.05):
        options = {} if stribeck is None else {"stribeck_velocity": stribeck}
        robot = URDFRobot(str(KUKA / "kuka_lwr4.urdf"), friction=True, offset=True, **options)
        suffix = "" if stribeck is None else f", Stribeck {stribeck} rad/s"
        problem = Problem(robot, data[1], cost=registry.create("cost", "f1"))
        fits = [("LS", registry.create("estimator", "ls"))]
        if args.adam:
            fits.append(("Adam-f1", registry.create("estimator", "adam", starts=4, history=False)))
        for name, estimator in fits:
            estimate = estimator.fit(problem)
            params = vector(robot, estimate.params)
            print(row(name + suffix, robot, params, estimate.wall_time_s, data), flush=True)
            for metric, samples in (("training data", data[1]), ("random states", None)):
                started = time.perf_counter()
                projected = nearest_consistent(robot, params, samples=samples)
                seconds = time.perf_counter() - started
                print(row(f"{name} projected ({metric}){suffix}", robot, projected.params, seconds, data))
        for weight in PRIORS:
            estimate = PhysicallyConsistentLS(prior_weight=weight, plausible=False).fit(problem)
            label = f"pcls, prior_weight {weight:g}{suffix}"
            print(row(label, robot, vector(robot, estimate.params), estimate.wall_time_s, data), flush=True)


if __name__ == "__main__":
    main()
