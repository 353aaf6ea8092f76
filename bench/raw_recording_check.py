"""Does idkit's reported held-out figure on a raw recording match an independent re-score of its model?

Run: ``python bench/raw_recording_check.py [--variants clean,noisy] [--json out.json]``.

From the KUKA LWR4+ files (``../shared/data/kuka-lwr4``, not part of the repo) it writes raw CSV
recordings as a robot's logger would: ``t, q1..q7, tau1..tau7`` — no velocities, no accelerations —
with every timestamp jittered by up to ±0.5 ms (the samples stay where they were taken; only their
stamps are off). ``noisy`` and ``noisier`` also add white torque noise of 2 % and 10 % of each joint's
RMS torque (a current-based torque estimate is that noisy) and round the positions to an 18-bit
encoder (2π / 2¹⁸ rad). Then it runs the real-robot command with its
defaults (``preprocess.cutoff=auto``, ``pcls`` with ``prior_weight=auto``)::

    idkit robot=urdf robot.urdf=kuka_lwr4.urdf robot.friction=true robot.offset=true \\
          data=m1.csv 'validate=[m3.csv,m2.csv]' estimator=pcls

and re-scores the ``identified.urdf`` it wrote with :mod:`idkit.verify.rescore` (pinocchio, and
filters written out with scipy): once under idkit's documented metric (states at the cut-off the run
chose, torques compared below the scoring band) and once under a classic expert pipeline (positions
and torques low-passed at 5 Hz or 8 Hz, central differences). Prints one Markdown table.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from idkit.robots.urdf import URDFRobot
from idkit.verify.rescore import (
    documented_score,
    expert_score,
    filtered_states,
    predicted_torques,
    read_identified,
)

KUKA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "kuka-lwr4"
TRAIN, HELD_OUT = "measurements_1", ("measurements_3", "measurements_2")
#: Cut-offs (Hz) of the expert pipelines the reported figure is compared with.
EXPERTS = (5.0, 8.0)
JITTER_S = 5e-4
#: White torque noise per variant, as a fraction of each joint's RMS torque (``None``: as recorded).
TORQUE_NOISE = {"clean": None, "noisy": 0.02, "noisier": 0.10}
ENCODER_STEP = 2 * np.pi / 2**18


def write_raw(name: str, target: Path, noise: float | None, seed: int) -> Path:
    """``target/<name>.csv``: the recording's positions and torques at jittered stamps (module doc)."""
    data = np.load(KUKA / f"{name}.npz")
    rng = np.random.default_rng(seed)
    t = data["times"] - data["times"][0] + rng.uniform(-JITTER_S, JITTER_S, data["times"].size)
    q, tau = data["positions"].copy(), data["torques"].copy()
    if noise is not None:
        tau += noise * np.sqrt((tau**2).mean(0)) * rng.standard_normal(tau.shape)
        q = np.round(q / ENCODER_STEP) * ENCODER_STEP
    header = ["t", *(f"q{j + 1}" for j in range(7)), *(f"tau{j + 1}" for j in range(7))]
    path = target / f"{name}.csv"
    np.savetxt(
        path, np.column_stack([t, q, tau]), delimiter=",", header=",".join(header), comments="", fmt="%.17g"
    )
    return path


def check(variant: str, folder: Path) -> list[dict[str, object]]:
    """Write the raw files, run the command, re-score; one row per held-out file."""
    folder.mkdir(parents=True, exist_ok=True)
    files = {
        name: write_raw(name, folder, TORQUE_NOISE[variant], seed)
        for seed, name in enumerate((TRAIN, *HELD_OUT))
    }
    run = folder / "run"
    command = [
        str(Path(sys.executable).with_name("idkit")),
        "robot=urdf",
        f"robot.urdf={KUKA / 'kuka_lwr4.urdf'}",
        "robot.friction=true",
        "robot.offset=true",
        f"data={files[TRAIN]}",
        f"validate=[{','.join(str(files[n]) for n in HELD_OUT)}]",
        "estimator=pcls",
        f"hydra.run.dir={run}",
    ]
    started = time.perf_counter()
    subprocess.run(command, check=True, capture_output=True, text=True)
    elapsed = time.perf_counter() - started
    result = json.loads((run / "result.json").read_text())
    cutoff = float(result["data"]["preprocess"]["cutoff"])
    identified = read_identified(run / "identified.urdf")
    joints = URDFRobot(str(KUKA / "kuka_lwr4.urdf")).joint_names
    rows = []
    for name in HELD_OUT:
        table = np.loadtxt(files[name], delimiter=",", skiprows=1)
        t, q, tau = table[:, 0], table[:, 1:8], table[:, 8:15]
        reported = result["payload"]["validation"][str(files[name])]
        times, qf, qd, qdd, raw, _ = filtered_states(t, q, tau, cutoff)
        predicted = predicted_torques(identified, joints, qf, qd, qdd)
        independent = documented_score(times, raw, predicted, float(reported["band_hz"]))
        experts = {f: expert_score(identified, joints, t, q, tau, f) for f in EXPERTS}
        rows.append(
            {
                "variant": variant,
                "file": name,
                "cutoff_hz": cutoff,
                "prior_weight": result["payload"]["estimate"]["details"]["prior_weight"],
                "reported": reported["rel_all"],
                "reported_raw": reported["rel_all_raw"],
                "independent": independent,
                **{f"expert_{f:g}hz": v for f, v in experts.items()},
                "command_s": elapsed,
            }
        )
    return rows


def markdown(rows: list[dict[str, object]]) -> str:
    head = (
        "| recording | file | cut-off (auto) | prior (auto) | reported | independent re-score | ratio | "
        + " | ".join(f"expert {f:g} Hz | ratio" for f in EXPERTS)
        + " | unfiltered | command |"
    )
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        reported = float(r["reported"])  # type: ignore[arg-type]
        experts = " | ".join(
            f"{100 * float(r[f'expert_{f:g}hz']):.2f} % | {reported / float(r[f'expert_{f:g}hz']):.3f}"  # type: ignore[arg-type]
            for f in EXPERTS
        )
        lines.append(
            f"| {r['variant']} | {r['file']} | {float(r['cutoff_hz']):g} Hz | {float(r['prior_weight']):g} | "  # type: ignore[arg-type]
            f"{100 * reported:.2f} % | {100 * float(r['independent']):.2f} % | "  # type: ignore[arg-type]
            f"{reported / float(r['independent']):.3f} | {experts} | "  # type: ignore[arg-type]
            f"{100 * float(r['reported_raw']):.2f} % | "  # type: ignore[arg-type]
            f"{float(r['command_s']):.0f} s |"  # type: ignore[arg-type]
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", default="clean,noisy,noisier", help="of " + ", ".join(TORQUE_NOISE))
    parser.add_argument("--json", type=Path, default=None, help="also write the rows as JSON")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        for variant in args.variants.split(","):
            rows += check(variant, Path(scratch) / variant)
    print(markdown(rows))
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
