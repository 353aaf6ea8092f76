"""Can a physically consistent fit of the KUKA LWR4+ predict measurements_2 to <= 2.3 % ‖E‖/‖T‖?

Run: ``python bench/kuka_meas2.py``. pcls (Coulomb + viscous + offset, with and without the
low-speed friction term) trained on measurements_1, scored on measurements_2 and _3, over small
prior weights and over the training data's derivatives: the files' own, or idkit's filter
(``preprocess`` with ``apply: on``) at several cut-offs. Scores always use the files' own
derivatives of the held-out recordings (as in ``idkit +experiment=kuka``), and, for the filtered
rows, also the same filter applied to the held-out recordings. Needs ../shared/data/kuka-lwr4.
"""

from __future__ import annotations

from pathlib import Path

import torch

from idkit.data.options import DataOptions
from idkit.data.pipeline import read_training
from idkit.estimators.physical import PhysicallyConsistentLS
from idkit.model import IdentifiedModel
from idkit.problem import Problem
from idkit.robots.inertia import min_pseudo_inertia_eigenvalues
from idkit.robots.urdf import URDFRobot
from idkit.studies.validation import validate

KUKA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "kuka-lwr4"
FILES = [KUKA / f"measurements_{k}.npz" for k in (1, 2, 3)]


def main() -> None:
    torch.set_num_threads(1)
    rigid = URDFRobot(str(KUKA / "kuka_lwr4.urdf"))
    own = [f.samples for f in read_training(rigid, FILES, DataOptions.of()).files]
    columns = "meas. 1 | meas. 2 | meas. 3 | meas. 2 / 3 (same filter) | min eig"
    print(f"| training derivatives | low-speed term | prior | {columns} |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for cutoff in (None, 2.0, 4.0, 10.0):
        if cutoff is None:
            train, filtered, source = own[0], None, "files' own"
        else:
            loaded = read_training(rigid, FILES, DataOptions.of({"apply": "on", "cutoff": cutoff})).files
            train, filtered, source = (
                loaded[0].samples,
                [f.samples for f in loaded],
                f"idkit filter {cutoff:g} Hz",
            )
        for stribeck in (None, 0.05):
            robot = URDFRobot(
                str(KUKA / "kuka_lwr4.urdf"), friction=True, offset=True, stribeck_velocity=stribeck
            )
            problem = Problem(robot, train)
            for weight in (0.0, 10.0, 30.0, 100.0, 300.0):
                estimate = PhysicallyConsistentLS(prior_weight=weight, plausible=False).fit(problem)
                params = IdentifiedModel(robot, estimate).vector
                scores = [100 * validate(robot, s, params).rel_all for s in own]
                same = (
                    "–"
                    if filtered is None
                    else " / ".join(f"{100 * validate(robot, s, params).rel_all:.2f} %" for s in filtered[1:])
                )
                eig = float(min_pseudo_inertia_eigenvalues(robot, params).min())
                cells = [
                    source,
                    "0.05 rad/s" if stribeck else "no",
                    f"{weight:g}",
                    *(f"{v:.2f} %" for v in scores),
                    same,
                    f"{eig:.1e}",
                ]
                print("| " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
