"""The whole real-robot command, end to end: ``prior_weight=auto`` (the default) against a fixed weight.

Run: ``python bench/pcls_command.py [--repeats 3] [--only kuka|ur5e] [--levers]``. Prints one Markdown
table.

The budget of issue 24 is "the whole default command on a 6–7 joint arm with a few thousand samples
in ≤ 2× (fixed-weight fit + start-up)"; the fixed-weight command is exactly that (start-up, loading,
the fit, validation, the plausible alternative, the files), so the table's ratio is the default
command's time over the same command with ``estimator=pcls estimator.prior_weight=300``. Each
command runs as a new process (this environment's ``idkit`` script), ``repeats`` times
alternately; wall time and the child's CPU time (user + system), medians. Two arms:

* the KUKA LWR4+ (7 joints): ``measurements_1`` (5,027 samples), validated on ``measurements_3`` and
  ``measurements_2`` (needs ``../shared/data/kuka-lwr4``);
* a UR5e (6 joints; MuJoCo Menagerie's model, :data:`UR5E_MJCF`) with simulated raw recordings
  (:func:`simulated_recordings`): 3,000 samples at 200 Hz for training and two other trajectories
  for validation, so the command also chooses the filter cut-off (``preprocess.cutoff=auto``).

``--levers`` adds what the rest of the command costs: both commands with ``OMP_NUM_THREADS=1`` (one
torch and BLAS thread), the fixed-weight command with ``plots=false``, and for raw recordings also
with ``preprocess.cutoff=`` given (the value the default chose), so the cut-off is not
cross-validated. The chosen prior weight and the held-out ``‖E‖/‖T‖`` of each command
are printed beside the times (same choice quality). The load average is printed before and after: on
a shared machine wall times move with it, CPU times much less.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

KUKA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "kuka-lwr4"
FIXED = ("estimator=pcls", "estimator.prior_weight=300")
#: The ``idkit`` script of this environment (what a user runs).
IDKIT = Path(sys.executable).with_name("idkit")

#: MuJoCo Menagerie's ``universal_robots_ur5e/ur5e.xml`` reduced to its kinematics, inertials and joint
#: ranges (meshes, visuals, actuators, joint damping and armature removed: the bench simulates its own
#: friction, and idkit refuses an armature it is not asked to model).
UR5E_MJCF = """<!--
Copyright 2018 ROS Industrial Consortium

Redistribution and use in source and binary forms, with or without modification,
are permitted provided that the following conditions are met:

1. Redistributions of source code must retain the above copyright notice, this
list of conditions and the following disclaimer.

2. Redistributions in binary form must reproduce the above copyright notice,
this list of conditions and the following disclaimer in the documentation and/or
other materials provided with the distribution.

3. Neither the name of the copyright holder nor the names of its contributors
may be used to endorse or promote products derived from this software without
specific prior written permission.

THIS SOFTWARE IS PROVIDED BY THE COPYRIGHT HOLDERS AND CONTRIBUTORS "AS IS" AND
ANY EXPRESS OR IMPLIED WARRANTIES, INCLUDING, BUT NOT LIMITED TO, THE IMPLIED
WARRANTIES OF MERCHANTABILITY AND FITNESS FOR A PARTICULAR PURPOSE ARE
DISCLAIMED. IN NO EVENT SHALL THE COPYRIGHT HOLDER OR CONTRIBUTORS BE LIABLE FOR
ANY DIRECT, INDIRECT, INCIDENTAL, SPECIAL, EXEMPLARY, OR CONSEQUENTIAL DAMAGES
(INCLUDING, BUT NOT LIMITED TO, PROCUREMENT OF SUBSTITUTE GOODS OR SERVICES;
LOSS OF USE, DATA, OR PROFITS; OR BUSINESS INTERRUPTION) HOWEVER CAUSED AND ON
ANY THEORY OF LIABILITY, WHETHER IN CONTRACT, STRICT LIABILITY, OR TORT
(INCLUDING NEGLIGENCE OR OTHERWISE) ARISING IN ANY WAY OUT OF THE USE OF THIS
SOFTWARE, EVEN IF ADVISED OF THE POSSIBILITY OF SUCH DAMAGE.

Reduced from MuJoCo Menagerie's universal_robots_ur5e/ur5e.xml (BSD-3-Clause, above).
-->
<mujoco model="ur5e">
  <compiler angle="radian" autolimits="true"/>
  <default>
    <joint axis="0 1 0" range="-6.28319 6.28319"/>
    <default class="collision"><geom type="capsule" group="3"/></default>
    <default class="size3_limited"><joint range="-3.1415 3.1415"/></default>
  </default>
  <worldbody>
    <body name="base" quat="1 0 0 1">
      <inertial mass="4.0" pos="0 0 0" diaginertia="0.00443333156 0.00443333156 0.0072"/>
      <body name="shoulder_link" pos="0 0 0.163">
        <inertial mass="3.7" pos="0 0 0" diaginertia="0.0102675 0.0102675 0.00666"/>
        <joint name="shoulder_pan_joint" axis="0 0 1"/>
        <geom class="collision" size="0.06 0.06" pos="0 0 -0.04"/>
        <body name="upper_arm_link" pos="0 0.138 0" quat="1 0 1 0">
          <inertial mass="8.393" pos="0 0 0.2125" diaginertia="0.133886 0.133886 0.0151074"/>
          <joint name="shoulder_lift_joint"/>
          <geom class="collision" pos="0 -0.04 0" quat="1 1 0 0" size="0.06 0.06"/>
          <geom class="collision" size="0.05 0.2" pos="0 0 0.2"/>
          <body name="forearm_link" pos="0 -0.131 0.425">
            <inertial mass="2.275" pos="0 0 0.196" diaginertia="0.0311796 0.0311796 0.004095"/>
            <joint name="elbow_joint" class="size3_limited"/>
            <geom class="collision" pos="0 0.08 0" quat="1 1 0 0" size="0.055 0.06"/>
            <geom class="collision" size="0.038 0.19" pos="0 0 0.2"/>
            <body name="wrist_1_link" pos="0 0 0.392" quat="1 0 1 0">
              <inertial mass="1.219" pos="0 0.127 0" diaginertia="0.0025599 0.0025599 0.0021942"/>
              <joint name="wrist_1_joint"/>
              <geom class="collision" pos="0 0.05 0" quat="1 1 0 0" size="0.04 0.07"/>
              <body name="wrist_2_link" pos="0 0.127 0">
                <inertial mass="1.219" pos="0 0 0.1" diaginertia="0.0025599 0.0025599 0.0021942"/>
                <joint name="wrist_2_joint" axis="0 0 1"/>
                <geom class="collision" size="0.04 0.06" pos="0 0 0.04"/>
                <body name="wrist_3_link" pos="0 0 0.1">
                  <inertial mass="0.1889" pos="0 0.0771683 0" quat="1 0 0 1"
                    diaginertia="0.000132134 9.90863e-05 9.90863e-05"/>
                  <joint name="wrist_3_joint"/>
                </body>
              </body>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""
#: The UR5e recordings: samples per recording, rate (Hz), relative torque noise, position noise (rad).
SAMPLES, RATE, TORQUE_NOISE, POSITION_NOISE = 3000, 200.0, 0.015, 1e-4


def trajectory(n_joints: int, rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    """``(t, q, qd, qdd)``: per joint a sum of four harmonics of 0.1 Hz, random amplitudes and phases
    (peak speeds of about 1–2 rad/s), around a random centre in [-1, 1] rad."""
    t = np.arange(SAMPLES) / RATE
    q, qd, qdd = (np.zeros((SAMPLES, n_joints)) for _ in range(3))
    for j in range(n_joints):
        q[:, j] = rng.uniform(-1.0, 1.0)
        for k in range(1, 5):
            omega = 2 * np.pi * 0.1 * k
            amplitude, phase = rng.uniform(0.2, 0.6) / k, rng.uniform(0, 2 * np.pi)
            q[:, j] += amplitude * np.sin(omega * t + phase)
            qd[:, j] += amplitude * omega * np.cos(omega * t + phase)
            qdd[:, j] -= amplitude * omega**2 * np.sin(omega * t + phase)
    return t, q, qd, qdd


def simulated_recordings(folder: Path, seed: int = 0) -> tuple[Path, list[Path]]:
    """``(ur5e.xml, [train.csv, held_a.csv, held_b.csv])`` in ``folder``: one true model — every CAD link
    scaled by its own factor in [0.7, 1.4] (a scaled body stays physical), Coulomb and viscous friction
    and an offset per joint sized to a few % of the joint's torque — and three raw recordings (``t``,
    ``q`` with encoder noise, torques with ``TORQUE_NOISE`` × their RMS of white noise) of three
    trajectories."""
    import torch

    from idkit import registry
    from idkit.data.raw import Recording
    from idkit.data.recording import save_recording

    model = folder / "ur5e.xml"
    model.write_text(UR5E_MJCF, encoding="utf-8")
    robot = registry.create("robot", "mjcf", mjcf=str(model), friction=True, offset=True)
    rng = np.random.default_rng(seed)
    states = [trajectory(robot.n_joints, rng) for _ in range(3)]
    truth = robot.nominal_params().clone()
    for i in range(len(robot.link_names)):
        truth[10 * i : 10 * i + 10] *= rng.uniform(0.7, 1.4)
    with torch.no_grad():
        rigid = robot.inverse_dynamics(truth, *(torch.from_numpy(a) for a in states[0][1:])).numpy()
    size = np.sqrt((rigid**2).mean(0))
    speed = np.sqrt((states[0][2] ** 2).mean(0))
    for j, joint in enumerate(robot.joint_names):
        truth[robot.param_names.index(f"{joint}.fc")] = rng.uniform(0.03, 0.08) * size[j]
        truth[robot.param_names.index(f"{joint}.fv")] = rng.uniform(0.02, 0.06) * size[j] / speed[j]
        truth[robot.param_names.index(f"{joint}.offset")] = rng.uniform(-0.03, 0.03) * size[j]
    files = []
    for name, (t, q, qd, qdd) in zip(("train", "held_a", "held_b"), states, strict=True):
        with torch.no_grad():
            tau = robot.inverse_dynamics(truth, *(torch.from_numpy(a) for a in (q, qd, qdd))).numpy()
        tau = tau + TORQUE_NOISE * np.sqrt((tau**2).mean(0)) * rng.standard_normal(tau.shape)
        measured = q + POSITION_NOISE * rng.standard_normal(q.shape)
        recording = Recording(t, measured, tau, joint_names=robot.joint_names)
        files.append(save_recording(recording, folder / f"{name}.csv"))
    return model, files


@dataclass
class Timing:
    """One command's runs: wall and CPU seconds, the weight it chose and its held-out figures."""

    wall: list[float]
    cpu: list[float]
    weight: float
    held_out: list[float]


def run_command(arguments: list[str], folder: Path, env: dict[str, str]) -> tuple[float, float, dict]:
    """Run ``idkit`` with ``arguments`` (and ``env`` added to the environment) into the new run folder
    ``folder``: (wall s, CPU s, result.json)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    command = [str(IDKIT), *arguments, f"hydra.run.dir={folder}"]
    done = subprocess.run(command, capture_output=True, text=True, env={**os.environ, **env})
    wall = time.perf_counter() - started
    if done.returncode:
        raise RuntimeError(f"{' '.join(command)} failed:\n{done.stderr[-2000:]}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, json.loads((folder / "result.json").read_text())


#: A command beside the default: its extra arguments and environment.
Command = tuple[list[str], dict[str, str]]
ONE_THREAD = {"OMP_NUM_THREADS": "1"}


def variants(result: dict, levers: bool) -> dict[str, Command]:
    """The commands beside the default (label → extra arguments and environment), given the default's
    ``result.json``: the fixed weight and, with ``levers``, both on one thread (``OMP_NUM_THREADS=1``:
    torch's intra-op pool, BLAS), the fixed weight without plots and, for a raw recording, also with
    the cut-off the default chose given (so not cross-validated)."""
    out: dict[str, Command] = {"prior_weight=300": (list(FIXED), {})}
    if levers:
        out["default, OMP_NUM_THREADS=1"] = ([], ONE_THREAD)
        out["prior_weight=300, OMP_NUM_THREADS=1"] = (list(FIXED), ONE_THREAD)
        out["prior_weight=300 plots=false"] = ([*FIXED, "plots=false"], {})
        cutoff = (result.get("data", {}).get("preprocess") or {}).get("cutoff_choice")
        if cutoff:
            given = f"preprocess.cutoff={cutoff['cutoff']:g}"
            out[f"prior_weight=300 plots=false {given}"] = ([*FIXED, "plots=false", given], {})
    return out


def timings(arguments: list[str], repeats: int, folder: Path, levers: bool) -> dict[str, Timing]:
    """The default command and the others (:func:`variants`, known once the default has run),
    ``repeats`` rounds of each, alternately."""
    runs: dict[str, Timing] = {}
    commands: dict[str, Command] = {"default (auto)": ([], {})}
    for k in range(repeats):
        n = 0
        while n < len(commands):  # the first default run adds the variants to this very round
            label, (extra, env) = list(commands.items())[n]
            wall, cpu, result = run_command(arguments + extra, folder / f"{n}-{k}", env)
            if label not in runs:
                payload = result["payload"]
                weight = payload["estimate"]["details"]["prior_weight"]
                held_out = [100 * v["rel_all"] for v in payload["validation"].values()]
                runs[label] = Timing([], [], weight, held_out)
                if n == 0:
                    commands.update(variants(result, levers))
            runs[label].wall.append(wall)
            runs[label].cpu.append(cpu)
            n += 1
    return runs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="runs of each command (median)")
    parser.add_argument("--only", choices=("kuka", "ur5e"), help="one arm only")
    parser.add_argument(
        "--levers",
        action="store_true",
        help="also both on one thread, the fixed weight without plots, then with the cut-off given",
    )
    args = parser.parse_args()
    load_before = os.getloadavg()
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        arms = {}
        if args.only in (None, "kuka"):
            arms["KUKA LWR4+ (7 joints, 5,027 samples)"] = [
                "robot=urdf",
                f"robot.urdf={KUKA / 'kuka_lwr4.urdf'}",
                f"data={KUKA / 'measurements_1.npz'}",
                f"validate=[{KUKA / 'measurements_3.npz'},{KUKA / 'measurements_2.npz'}]",
            ]
        if args.only in (None, "ur5e"):
            model, (train, *held) = simulated_recordings(folder)
            arms[f"UR5e (6 joints, {SAMPLES:,} samples, simulated raw recordings)"] = [
                "robot=mjcf",
                f"robot.mjcf={model}",
                f"data={train}",
                f"validate=[{held[0]},{held[1]}]",
            ]
        for k, (arm, arguments) in enumerate(arms.items()):
            runs = timings(arguments, args.repeats, folder / f"arm{k}", args.levers)
            auto = runs["default (auto)"]
            fixed = runs["prior_weight=300"]
            ratio = statistics.median(auto.wall) / statistics.median(fixed.wall)
            cpu_ratio = statistics.median(auto.cpu) / statistics.median(fixed.cpu)
            for label, timing in runs.items():
                rows.append(
                    f"| {arm} | {label} | {statistics.median(timing.wall):.1f} ({min(timing.wall):.1f}) | "
                    f"{statistics.median(timing.cpu):.1f} | {timing.weight:g} | "
                    + " / ".join(f"{x:.2f} %" for x in timing.held_out)
                    + (f" | {ratio:.2f} | {cpu_ratio:.2f} |" if timing is auto else " | | |")
                )
    print(
        "| arm | command | wall s, median (min) | CPU s, median | prior weight | held-out ‖E‖/‖T‖ "
        "| default / fixed, wall | default / fixed, CPU |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    print("\n".join(rows))
    shown = [" ".join(f"{x:.2f}" for x in load) for load in (load_before, os.getloadavg())]
    print(
        f"\n{args.repeats} runs of each command, alternately, as new processes. Load average (1, 5, 15 min): "
        f"{shown[0]} before, {shown[1]} after."
    )


if __name__ == "__main__":
    main()
