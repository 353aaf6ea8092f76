"""Simulated robots and logs for rollout identification: the bench's cases, the tests', the docs' —
fixtures, so they live beside the other test helpers of :mod:`idkit.testing`, not in the simulator.

* ``a``: the 5-DOF arm of ``mujoco.sysid``'s integration test (torque motors), its five armatures,
  2 s of sinusoidal torques logged at 500 Hz;
* ``b``: a 7-joint arm under position and velocity servos (per joint a ``<position kp>`` and a
  ``<velocity kv>`` actuator, commands ``q_ref`` and ``qd_ref``), 36 unknowns — per joint armature,
  damping, friction loss, kp, kv — and one delay, 3 s logged at 500 Hz;
* ``c``: ``b``'s log corrupted: Gaussian noise, 1.5 % glitched samples (encoder spikes of 0.05–0.5 rad,
  velocity spikes of 0.5–5 rad/s, dropped packets that repeat the previous sample) and a 7 ms delay
  (the states measured 3.5 steps late: the trajectory interpolated there).

Each log follows :mod:`idkit.sim.timing`: the command at ``t_k`` acts from ``t_k``, the state at ``t_k`` is
the one before step ``k``. A held-out log is another motion with the same corruptions.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from idkit.data.commands import RobotLog
from idkit.robots.mjcf import import_mujoco

ARM5 = """<mujoco model="arm">
  <compiler angle="radian" autolimits="true"/>
  <option integrator="implicitfast" timestep="0.002">
    <flag contact="disable"/>
  </option>
  <worldbody>
    <body name="link1" pos="0 0 0.1">
      <inertial pos="0 0 0.05" mass="1.0" diaginertia="0.01 0.01 0.005"/>
      <joint name="joint1" type="hinge" axis="0 0 1" range="-3.14 3.14" armature="0.5" damping="1.0"/>
      <geom type="capsule" fromto="0 0 0 0 0 0.1" size="0.04"/>
      <body name="link2" pos="0 0 0.1">
        <inertial pos="0 0 0.05" mass="0.8" diaginertia="0.008 0.008 0.004"/>
        <joint name="joint2" type="hinge" axis="0 1 0" range="-3.14 3.14" armature="0.4" damping="0.8"/>
        <geom type="capsule" fromto="0 0 0 0 0 0.1" size="0.035"/>
        <body name="link3" pos="0 0 0.1">
          <inertial pos="0 0 0.05" mass="0.6" diaginertia="0.006 0.006 0.003"/>
          <joint name="joint3" type="hinge" axis="0 1 0" range="-3.14 3.14" armature="0.3" damping="0.6"/>
          <geom type="capsule" fromto="0 0 0 0 0 0.1" size="0.03"/>
          <body name="link4" pos="0 0 0.1">
            <inertial pos="0 0 0.04" mass="0.4" diaginertia="0.004 0.004 0.002"/>
            <joint name="joint4" type="hinge" axis="0 0 1" range="-3.14 3.14" armature="0.2" damping="0.4"/>
            <geom type="capsule" fromto="0 0 0 0 0 0.08" size="0.025"/>
            <body name="link5" pos="0 0 0.08">
              <inertial pos="0 0 0.03" mass="0.2" diaginertia="0.002 0.002 0.001"/>
              <joint name="joint5" type="hinge" axis="0 1 0" range="-3.14 3.14" armature="0.1" damping="0.2"/>
              <geom type="capsule" fromto="0 0 0 0 0 0.06" size="0.02"/>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor name="act1" joint="joint1"/>
    <motor name="act2" joint="joint2"/>
    <motor name="act3" joint="joint3"/>
    <motor name="act4" joint="joint4"/>
    <motor name="act5" joint="joint5"/>
  </actuator>
</mujoco>
"""

_ARM7_JOINTS = [  # (axis, mass, link length, armature, damping, frictionloss, kp, kv)
    ("0 0 1", 4.0, 0.2, 0.30, 2.0, 0.60, 300, 30),
    ("0 1 0", 3.5, 0.2, 0.30, 1.8, 0.50, 300, 30),
    ("0 0 1", 3.0, 0.2, 0.20, 1.5, 0.40, 200, 20),
    ("0 -1 0", 2.5, 0.2, 0.20, 1.2, 0.30, 200, 20),
    ("0 0 1", 1.5, 0.15, 0.10, 0.8, 0.20, 100, 10),
    ("0 1 0", 1.0, 0.1, 0.08, 0.5, 0.15, 80, 8),
    ("0 0 1", 0.5, 0.06, 0.05, 0.3, 0.10, 50, 5),
]


def _arm7() -> str:
    bodies, closing = "", ""
    for i, (axis, mass, length, armature, damping, friction, _, _) in enumerate(_ARM7_JOINTS, start=1):
        inertia = f"{mass * length**2 / 3:.6g} {mass * length**2 / 3:.6g} {mass * 0.03**2:.6g}"
        pos = "0 0 0.1" if i == 1 else f"0 0 {_ARM7_JOINTS[i - 2][2]}"
        bodies += (
            f'<body name="l{i}" pos="{pos}">'
            f'<inertial pos="0 0 {length / 2}" mass="{mass}" diaginertia="{inertia}"/>'
            f'<joint name="j{i}" axis="{axis}" armature="{armature}" damping="{damping}" '
            f'frictionloss="{friction}"/><geom fromto="0 0 0 0 0 {length}"/>'
        )
        closing += "</body>"
    actuators = "".join(
        f'<position name="p{i}" joint="j{i}" kp="{j[6]}"/>' for i, j in enumerate(_ARM7_JOINTS, 1)
    )
    actuators += "".join(
        f'<velocity name="v{i}" joint="j{i}" kv="{j[7]}"/>' for i, j in enumerate(_ARM7_JOINTS, 1)
    )
    return (
        '<mujoco model="arm7"><compiler angle="radian" autolimits="true"/>'
        '<option integrator="implicitfast" timestep="0.002"><flag contact="disable"/></option>'
        '<default><joint range="-3 3"/><geom type="capsule" size="0.04"/></default>'
        f"<worldbody>{bodies}{closing}</worldbody><actuator>{actuators}</actuator></mujoco>"
    )


ARM7 = _arm7()
#: Case ``c``'s corruption.
NOISE = (1e-4, 1e-2)  # rad, rad/s
GLITCHES = 0.015
DELAY = 0.007


@dataclass(frozen=True)
class Case:
    """A model, its truth, a fit log and a held-out log, and the unknowns with bounds and a start.

    Attributes:
        name: ``a``, ``b`` or ``c``.
        model: MJCF text.
        params: the unknowns (kinds or names, as ``select_unknowns`` takes them).
        truth: ``{name: value}`` of every unknown.
        fit, held_out: the logs.
        bounds: ``{name: [lower, upper]}``.
        start: ``{name: value}`` (one start; :meth:`starts` draws others).
    """

    name: str
    model: str
    params: tuple[str, ...]
    truth: dict[str, float]
    fit: RobotLog
    held_out: RobotLog
    bounds: dict[str, list[float]]
    start: dict[str, float] = field(default_factory=dict)

    def starts(
        self, count: int, seed: int = 0, low: float = 0.2, high: float = 5.0
    ) -> list[dict[str, float]]:
        """``count`` starts, each unknown log-uniform in ``[low, high]`` × the truth (``delay``: 0)."""
        rng = np.random.default_rng(seed)
        out = []
        for _ in range(count):
            draw = np.exp(rng.uniform(np.log(low), np.log(high), len(self.truth)))
            out.append(
                {
                    k: (0.0 if k == "command_delay" else v * f)
                    for (k, v), f in zip(self.truth.items(), draw, strict=True)
                }
            )
        return out


def simulate(
    model_text: str, commands: np.ndarray, q0: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``(q [N, nq], qd [N, nv])`` of the model under ``commands[N, nu]`` (row ``k`` applied from ``t_k``;
    the state at ``t_k`` is the one before step ``k``), from ``q0`` at rest."""
    mujoco = import_mujoco()
    from mujoco import rollout

    model = mujoco.MjModel.from_xml_string(model_text)
    data = mujoco.MjData(model)
    if q0 is not None:
        data.qpos[:] = q0
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    initial = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, initial, spec)
    state, _ = rollout.rollout(model, data, initial, commands[:-1])
    rows = np.vstack([initial[None], state[0]])
    return rows[:, 1 : 1 + model.nq], rows[:, 1 + model.nq : 1 + model.nq + model.nv]


def delayed(t: np.ndarray, q: np.ndarray, qd: np.ndarray, delay: float) -> tuple[np.ndarray, np.ndarray]:
    """The states measured ``delay`` late: the trajectory at ``t − delay`` (cubic Hermite in ``q``, linear
    in ``qd``; before the start, the first state)."""
    h = t[1] - t[0]
    at = np.clip(t - delay, t[0], None)
    k = np.clip(np.floor((at - t[0]) / h + 1e-9).astype(int), 0, t.size - 2)
    f = ((at - t[k]) / h)[:, None]
    h00, h10, h01, h11 = 2 * f**3 - 3 * f**2 + 1, f**3 - 2 * f**2 + f, -2 * f**3 + 3 * f**2, f**3 - f**2
    return h00 * q[k] + h10 * h * qd[k] + h01 * q[k + 1] + h11 * h * qd[k + 1], (1 - f) * qd[k] + f * qd[
        k + 1
    ]


def corrupt(
    q: np.ndarray, qd: np.ndarray, noise: tuple[float, float], glitches: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian noise, then ``glitches`` × N glitched samples (module docstring)."""
    q = q + noise[0] * rng.standard_normal(q.shape)
    qd = qd + noise[1] * rng.standard_normal(qd.shape)
    for i in rng.choice(np.arange(1, len(q)), int(round(glitches * len(q))), replace=False):
        kind, j = rng.integers(3), rng.integers(q.shape[1])
        if kind == 0:
            q[i, j] += rng.choice([-1.0, 1.0]) * rng.uniform(0.05, 0.5)
        elif kind == 1:
            qd[i, j] += rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 5.0)
        else:
            q[i], qd[i] = q[i - 1], qd[i - 1]
    return q, qd


def stalled(log: RobotLog, stretches: int = 3, seconds: float = 0.04, seed: int = 0) -> RobotLog:
    """``log`` with ``stretches`` stalls of its driver: for ``seconds`` each, the states repeat the row
    before (the commands go on), at evenly spread places jittered by ``seed``."""
    rng = np.random.default_rng(seed)
    rows = max(1, int(round(seconds / float(np.median(np.diff(log.t))))))
    q, qd = log.q.copy(), log.qd.copy()
    places = np.linspace(0, log.n_samples, stretches + 2)[1:-1].astype(int)
    for place in places + rng.integers(-rows, rows + 1, size=stretches):
        q[place + 1 : place + 1 + rows] = q[place]
        qd[place + 1 : place + 1 + rows] = qd[place]
    return RobotLog(
        log.t, q, qd, log.command_t, log.commands, log.joint_names, log.command_names,
        f"{log.source} with {stretches} stalls",
    )  # fmt: skip


def _references(t: np.ndarray, n: int, seed: int) -> np.ndarray:
    """``[N, 2n]`` smooth position references (three sines a joint, from 0) and their rates."""
    rng = np.random.default_rng(seed)
    q, qd = np.zeros((t.size, n)), np.zeros((t.size, n))
    for j in range(n):
        for k in range(3):
            a = rng.uniform(0.2, 0.5) / (k + 1)
            w, p = 2 * np.pi * rng.uniform(0.3, 1.5) * (k + 1), rng.uniform(0, 2 * np.pi)
            q[:, j] += a * (np.sin(w * t + p) - np.sin(p))
            qd[:, j] += a * w * np.cos(w * t + p)
    return np.hstack([q, qd])


def _truth(
    model_text: str, params: tuple[str, ...], joints: tuple[str, ...], delay: float
) -> dict[str, float]:
    from idkit.sim.model import load_model
    from idkit.sim.quantities import select_unknowns

    unknowns = select_unknowns(
        load_model(model_text), joints, params, start={"command_delay": delay} if delay else None
    )
    return dict(zip(unknowns.names, unknowns.vector("start").tolist(), strict=True))


def case_a() -> Case:
    """Case ``a`` (module docstring)."""
    t = np.arange(1000) * 0.002
    joints = tuple(f"joint{i}" for i in range(1, 6))
    logs = []
    for phase in (0.0, 1.0):
        ctrl = np.column_stack(
            [a * np.sin(2 * np.pi * f * t + p + phase) for a, f, p in
             [(5, 0.5, 0.0), (4, 0.7, 0.5), (3, 0.4, 1.0), (2, 0.9, 1.5), (1, 0.6, 2.0)]]
        )  # fmt: skip
        q, qd = simulate(ARM5, ctrl)
        actuators = tuple(f"act{i}.ctrl" for i in range(1, 6))
        logs.append(RobotLog(t, q, qd, t, ctrl, joints, actuators, f"case a ({phase})"))
    params = ("armature",)
    truth = _truth(ARM5, params, joints, 0.0)
    bounds = {name: [0.001, 10.0] for name in truth}
    return Case("a", ARM5, params, truth, logs[0], logs[1], bounds, {name: 0.01 for name in truth})


def case_b(corrupted: bool = False, seed: int = 0) -> Case:
    """Case ``b``, or with ``corrupted`` case ``c`` (module docstring); ``seed`` draws the corruption."""
    t = np.arange(1500) * 0.002
    joints = tuple(f"j{i}" for i in range(1, 8))
    names = tuple(f"{j}.q_ref" for j in joints) + tuple(f"{j}.qd_ref" for j in joints)
    rng = np.random.default_rng(seed)
    logs = []
    for motion in (0, 1):
        references = _references(t, len(joints), motion)
        q, qd = simulate(ARM7, references)
        if corrupted:
            q, qd = delayed(t, q, qd, DELAY)
            q, qd = corrupt(q, qd, NOISE, GLITCHES, rng)
        logs.append(
            RobotLog(t, q, qd, t, references, joints, names, f"case {'c' if corrupted else 'b'} ({motion})")
        )
    params = ("armature", "damping", "frictionloss", "kp", "kv", "command_delay")
    truth = _truth(ARM7, params, joints, DELAY if corrupted else 0.0)
    bounds: dict[str, list[float]] = {
        k: [0.1 * v, 10.0 * v] for k, v in truth.items() if k != "command_delay"
    }
    bounds["command_delay"] = [0.0, 0.02]
    start = Case("", "", (), truth, logs[0], logs[0], bounds).starts(1, seed=12345)[0]
    return Case("c" if corrupted else "b", ARM7, params, truth, logs[0], logs[1], bounds, start)


def problem_of(case: Case, start: dict[str, float] | None = None, **options: Any) -> Any:
    """The rollout problem of ``case`` from ``start`` (default the case's); ``options`` go to the problem."""
    from idkit.sim.model import load_model
    from idkit.sim.problem import RolloutProblem, SimRobot
    from idkit.sim.quantities import select_unknowns

    sim = load_model(case.model)
    unknowns = select_unknowns(
        sim, case.fit.joint_names, case.params, bounds=case.bounds, start=start or case.start
    )
    return RolloutProblem(SimRobot(sim, unknowns, case.fit.joint_names), case.fit, **options)


def conformance_problem(*, dtype: str = "float64", seed: int = 0) -> Any:
    """A small rollout problem for the conformance suite: two joints of a pendulum on motors, 0.4 s,
    their armatures and dampings, cost ``f1``."""
    from idkit import registry

    text = (
        ARM5.split('<body name="link3"')[0]
        + "</body></body></worldbody><actuator>"
        + ('<motor name="act1" joint="joint1"/><motor name="act2" joint="joint2"/></actuator></mujoco>')
    )
    t = np.arange(200) * 0.002
    ctrl = np.column_stack([3 * np.sin(2 * np.pi * 2 * t), 2 * np.cos(2 * np.pi * 3 * t)])
    q, qd = simulate(text, ctrl)
    log = RobotLog(t, q, qd, t, ctrl, ("joint1", "joint2"), ("act1.ctrl", "act2.ctrl"), "conformance log")
    case = Case("conformance", text, ("armature", "damping"), {}, log, log, {}, {})
    return problem_of(
        case,
        {"armature": 0.2, "damping": 0.5},
        cost=registry.create("cost", "f1"),
        seed=seed,
        dtype=dtype,
        segment=0.2,
    )
