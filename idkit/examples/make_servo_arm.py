"""Writes the shipped servo arm's files into ``idkit/examples/servo_arm/``:
``python -m idkit.examples.make_servo_arm [FOLDER]``.

The arm "as built" is :data:`MODEL` with the :data:`TRUTH` values in it; ``servo_arm.xml`` is the
model a user starts from (its armature, damping and friction loss are guesses, 2–4× off). Each log
is that arm tracking smooth position references under its own servos, rolled out by MuJoCo alone
(``mujoco.rollout``, not idkit's simulator), logged at 250 Hz with encoder noise: ``train.csv`` to
fit on, ``held_out.csv`` (another motion) to validate on. Every random choice comes from ``SEED``;
``tests/test_examples.py`` checks that the shipped files are what this script writes.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

#: The arm: three hinges (a yaw and two pitches) under gravity, each driven by a position servo with a
#: velocity gain (``<position kp kv>``: commands ``<joint>.q_ref``). ``{armature}`` … are filled in.
MODEL = """<mujoco model="servo_arm">
  <compiler angle="radian" autolimits="true"/>
  <option integrator="implicitfast" timestep="0.002">
    <flag contact="disable"/>
  </option>
  <default>
    <joint range="-3 3"/>
    <geom type="capsule" size="0.03"/>
  </default>
  <worldbody>
    <body name="base_link" pos="0 0 0.1">
      <inertial pos="0 0 0.05" mass="2.0" diaginertia="0.02 0.02 0.008"/>
      <joint name="j1" axis="0 0 1" armature="{a1}" damping="{d1}" frictionloss="{f1}"/>
      <geom fromto="0 0 0 0 0 0.1"/>
      <body name="upper_arm" pos="0 0 0.1">
        <inertial pos="0.125 0 0" mass="1.5" diaginertia="0.002 0.009 0.009"/>
        <joint name="j2" axis="0 1 0" armature="{a2}" damping="{d2}" frictionloss="{f2}"/>
        <geom fromto="0 0 0 0.25 0 0"/>
        <body name="forearm" pos="0.25 0 0">
          <inertial pos="0.1 0 0" mass="0.8" diaginertia="0.001 0.003 0.003"/>
          <joint name="j3" axis="0 1 0" armature="{a3}" damping="{d3}" frictionloss="{f3}"/>
          <geom fromto="0 0 0 0.2 0 0"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="servo1" joint="j1" kp="150" kv="8"/>
    <position name="servo2" joint="j2" kp="120" kv="6"/>
    <position name="servo3" joint="j3" kp="60" kv="3"/>
  </actuator>
</mujoco>
"""
JOINTS = ("j1", "j2", "j3")
#: The arm as built: what a fit of ``train.csv`` should find.
TRUTH = {
    "j1.armature": 0.12, "j2.armature": 0.09, "j3.armature": 0.03,
    "j1.damping": 1.6, "j2.damping": 1.1, "j3.damping": 0.4,
    "j1.frictionloss": 0.35, "j2.frictionloss": 0.25, "j3.frictionloss": 0.08,
}  # fmt: skip
#: The model a user starts from: guesses.
GUESS = {
    "j1.armature": 0.05, "j2.armature": 0.05, "j3.armature": 0.05,
    "j1.damping": 0.5, "j2.damping": 0.5, "j3.damping": 0.5,
    "j1.frictionloss": 0.1, "j2.frictionloss": 0.1, "j3.frictionloss": 0.1,
}  # fmt: skip
SEED = 7
#: The simulator steps per logged sample (500 Hz / 250 Hz), seconds per log, encoder noise (rad, rad/s).
DECIMATE, SECONDS, NOISE = 2, {"train.csv": 4.0, "held_out.csv": 3.0}, (2e-4, 2e-2)


def model_text(values: dict[str, float]) -> str:
    """:data:`MODEL` with ``values`` (``{"j1.armature": …}``) written in."""
    short = {"armature": "a", "damping": "d", "frictionloss": "f"}
    fields = {f"{short[name.split('.')[1]]}{name[1]}": f"{value:g}" for name, value in values.items()}
    return MODEL.format(**fields)


def references(t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``[N, 3]`` smooth position references from 0: three sines a joint, amplitudes of ~0.3–0.8 rad."""
    q = np.zeros((t.size, len(JOINTS)))
    for j in range(len(JOINTS)):
        for k in range(3):
            amplitude = rng.uniform(0.25, 0.6) / (k + 1)
            omega, phase = 2 * np.pi * rng.uniform(0.2, 0.9) * (k + 1), rng.uniform(0, 2 * np.pi)
            q[:, j] += amplitude * (np.sin(omega * t + phase) - np.sin(phase))
    return q


def rollout(text: str, commands: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(q, qd)`` ``[N, 3]`` of the model under ``commands[N, 3]`` (row ``k`` acts from step ``k``; the
    state at row ``k`` is the one before step ``k``), from rest at 0."""
    import mujoco
    from mujoco import rollout as batch

    model = mujoco.MjModel.from_xml_string(text)
    data = mujoco.MjData(model)
    kind = mujoco.mjtState.mjSTATE_FULLPHYSICS
    initial = np.empty(mujoco.mj_stateSize(model, kind))
    mujoco.mj_getState(model, data, initial, kind)
    state, _ = batch.rollout(model, data, initial, commands[:-1])
    rows = np.vstack([initial[None], state[0]])
    return rows[:, 1 : 1 + model.nq], rows[:, 1 + model.nq : 1 + model.nq + model.nv]


def log_csv(seconds: float, rng: np.random.Generator) -> str:
    """A CSV log (``t``, ``<joint>.q``, ``<joint>.qd``, ``<joint>.q_ref``) of the true arm."""
    steps = int(round(seconds / 0.002)) + 1
    t = np.arange(steps) * 0.002
    logged = np.arange(0, steps, DECIMATE)
    held = references(t[logged], rng)  # the command changes at the log's samples and is held between
    commands = np.repeat(held, DECIMATE, axis=0)[:steps]
    q, qd = rollout(model_text(TRUTH), commands)
    q = q[logged] + NOISE[0] * rng.standard_normal((logged.size, len(JOINTS)))
    qd = qd[logged] + NOISE[1] * rng.standard_normal((logged.size, len(JOINTS)))
    header = ["t", *(f"{j}.q" for j in JOINTS), *(f"{j}.qd" for j in JOINTS), *(f"{j}.q_ref" for j in JOINTS)]
    lines = [",".join(header)]
    for k, i in enumerate(logged):
        row = [f"{t[i]:.3f}", *(f"{v:.6f}" for v in q[k]), *(f"{v:.5f}" for v in qd[k])]
        lines.append(",".join(row + [f"{v:.6f}" for v in held[k]]))
    return "\n".join(lines) + "\n"


def files() -> dict[str, str]:
    """Every shipped file's name and text."""
    rng = np.random.default_rng(SEED)
    return {"servo_arm.xml": model_text(GUESS), **{name: log_csv(s, rng) for name, s in SECONDS.items()}}


def main(argv: list[str]) -> None:
    folder = Path(argv[0]) if argv else Path(__file__).parent / "servo_arm"
    for name, text in files().items():
        (folder / name).write_text(text, encoding="utf-8")
        print(folder / name)


if __name__ == "__main__":
    main(sys.argv[1:])
