"""A real arm's simulator by the documented flow: torque fit → ``identified.xml`` → rollout refine.

Run: ``python bench/rollout_real_arm.py [--data /work/shared/data/kuka-lwr4] [--out /tmp/real_arm]
[--torque-options ...] [--rollout-options ...]``

The two commands of ``docs/rollout.md`` run as a user runs them (subprocesses of the ``idkit``
command, their CPU seconds measured as the children's user + system time): the torque fit on the
training log (``measurements_1``), then ``+experiment=rollout rollout.model=<its run folder>`` on the
same log. Each model — the torque fit's ``identified.xml`` (rebuilt from its ``result.json`` when the
fit did not write it) and the refined one — is then scored here with MuJoCo alone, independently of
idkit's simulator: every held-out log cut into 0.5 s segments, each started from the logged
positions and velocities and driven by the logged torques (× the fit's effort scale − its offsets,
held from sample to sample), its positions compared with the log's at every later sample of the
segment. The table: RMS position error per joint and over all joints (mrad), per held-out log and
model, and the refine's CPU seconds and rollouts. Say the machine's load beside the numbers.
"""

# ruff: noqa: E402
from __future__ import annotations

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import argparse
import json
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import mujoco
import numpy as np

SEGMENT = 0.5


def run(command: list[str]) -> tuple[float, float, str]:
    """Run ``command``; its (CPU seconds of the children, wall seconds, output)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if done.returncode:
        sys.exit(
            f"failed ({done.returncode}): {' '.join(command)}\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
        )
    return cpu, wall, done.stdout + done.stderr


def motor_model(xml: str) -> tuple[mujoco.MjModel, list[str]]:
    """The model, with one motor (gear 1) per hinge joint when it has no actuator; its hinge joints."""
    spec = mujoco.MjSpec.from_string(xml)
    if not spec.actuators:
        for joint in spec.joints:
            if joint.type == mujoco.mjtJoint.mjJNT_HINGE:
                spec.add_actuator(name=joint.name, target=joint.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
    model = spec.compile()
    hinges = [
        model.joint(j).name for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE
    ]
    return model, hinges


def segment_errors(model: mujoco.MjModel, joints: list[str], log: dict[str, np.ndarray]) -> np.ndarray:
    """``[k, n]`` predicted minus logged positions at every sample after each segment's first."""
    data = mujoco.MjData(model)
    qadr = [model.jnt_qposadr[model.joint(j).id] for j in joints]
    dadr = [model.jnt_dofadr[model.joint(j).id] for j in joints]
    motor = []
    for j in joints:
        found = [a for a in range(model.nu) if model.actuator_trnid[a, 0] == model.joint(j).id]
        motor.append(found[0])
    gear = model.actuator_gear[motor, 0]
    t, q, qd, tau = log["t"], log["q"], log["qd"], log["tau"]
    dt = model.opt.timestep
    errors = []
    first = 0
    while first < t.size - 1:
        last = int(np.searchsorted(t, t[first] + SEGMENT, side="right"))
        mujoco.mj_resetData(model, data)
        data.qpos[qadr], data.qvel[dadr] = q[first], qd[first]
        now = t[first]
        for k in range(first + 1, min(last, t.size)):
            data.ctrl[motor] = tau[k - 1] / gear
            while now + dt <= t[k] + 1e-12:
                mujoco.mj_step(model, data)
                now += dt
            # the position at t[k], between two steps: the last one moved on at its velocity
            errors.append(data.qpos[qadr] + (t[k] - now) * data.qvel[dadr] - q[k])
        first = max(last, first + 1)
    return np.array(errors)


def read_log(path: Path, scale: np.ndarray, offset: np.ndarray) -> dict[str, np.ndarray]:
    with np.load(path) as f:
        t = f["times"] - f["times"][0]
        return {"t": t, "q": f["positions"], "qd": f["velocities"], "tau": f["torques"] * scale - offset}


def torque_terms(folder: Path) -> tuple[list[str], np.ndarray, np.ndarray]:
    result = json.loads((folder / "result.json").read_text())
    joints = result["payload"]["joint_names"]
    scale = result["config"]["robot"].get("effort_scale")
    scale = np.ones(len(joints)) if scale is None else np.asarray(scale, dtype=float)
    params = result["payload"]["estimate"]["params"]
    return joints, scale, np.array([params.get(f"{j}.offset", 0.0) for j in joints])


def torque_model(folder: Path) -> str:
    if (folder / "identified.xml").is_file():
        return (folder / "identified.xml").read_text()
    from idkit.sim.from_run import read_torque_run

    return read_torque_run(folder).mjcf


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="/work/shared/data/kuka-lwr4")
    parser.add_argument("--out", default="/tmp/real_arm")
    parser.add_argument("--torque-options", nargs="*", default=[])
    parser.add_argument("--rollout-options", nargs="*", default=[])
    parser.add_argument("--torque-run", help="reuse this torque fit's run folder")
    args = parser.parse_args()
    data = Path(args.data)
    train, held = data / "measurements_1.npz", [data / "measurements_2.npz", data / "measurements_3.npz"]
    out = Path(args.out)
    idkit = str(Path(sys.executable).with_name("idkit"))
    if args.torque_run:
        torque = Path(args.torque_run)
        torque_cpu = float("nan")
    else:
        torque = out / "torque"
        shutil.rmtree(torque, ignore_errors=True)
        command = [
            idkit, "robot=urdf", f"robot.urdf={data / 'kuka_lwr4.urdf'}", f"data={train}",
            f"validate=[{','.join(map(str, held))}]", "identified_mjcf=true", "plots=false",
            f"hydra.run.dir={torque}", *args.torque_options,
        ]  # fmt: skip
        torque_cpu, _, _ = run(command)
    refined = out / "rollout"
    shutil.rmtree(refined, ignore_errors=True)
    command = [
        idkit, "+experiment=rollout", f"rollout.model={torque}", f"data={train}",
        f"hydra.run.dir={refined}", "plots=false", *args.rollout_options,
    ]  # fmt: skip
    rollout_cpu, rollout_wall, output = run(command)
    result = json.loads((refined / "result.json").read_text())
    details = result["payload"]["estimate"]["details"]
    joints, scale, offset = torque_terms(torque)
    models = {"torque fit": torque_model(torque), "refined": (refined / "identified.xml").read_text()}
    print(f"load: {os.getloadavg()[0]:.1f} (1 min) on {os.cpu_count()} CPUs")
    print(f"torque fit CPU {torque_cpu:.1f} s; rollout refine CPU {rollout_cpu:.1f} s")
    print(f"(wall {rollout_wall:.1f} s), {details.get('rollouts')} segment rollouts")
    header = f"{'log':<16} {'model':<11} " + " ".join(f"{j[:9]:>9}" for j in joints) + f" {'all':>7}"
    print("held-out 0.5 s segments from the logged state under the logged torques: RMS position error (mrad)")
    print(header)
    for path in held:
        log = read_log(path, scale, offset)
        for label, xml in models.items():
            model, hinges = motor_model(xml)
            error = segment_errors(model, [j for j in joints if j in hinges], log)
            per_joint = 1e3 * np.sqrt(np.mean(error**2, axis=0))
            overall = 1e3 * np.sqrt(np.mean(error**2))
            print(
                f"{path.stem:<16} {label:<11} "
                + " ".join(f"{v:9.1f}" for v in per_joint)
                + f" {overall:7.1f}"
            )
    for line in output.splitlines():
        if line.startswith("note:") or line.startswith("warning:"):
            print(line[:300])


if __name__ == "__main__":
    main()
