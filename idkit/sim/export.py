"""``identified.xml``: the model with the fitted values written in, and the state to start it from.

The fitted quantities go into a copy of the model's spec (:meth:`idkit.sim.quantities.Unknowns.write`)
and MuJoCo writes it (``MjSpec.to_xml``: 6 significant digits, the element types MuJoCo compiles them
to, e.g. a ``<position>`` as ``<general>``; asset folders made absolute). A fitted ``delay`` becomes
every actuator's own ``delay`` (MuJoCo's history buffer, ``interp="linear"``, ``nsample`` covering it),
which reproduces idkit's timing (:mod:`idkit.sim.timing`) exactly once the buffer holds the commands
before the start: :func:`start_state` fills it with the first command, held, as idkit does.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from idkit.robots.mjcf import import_mujoco
from idkit.sim.model import SimModel, logged_state
from idkit.sim.quantities import DELAY, Unknowns

#: ``interp`` value of MuJoCo's history buffer: linear interpolation between the logged commands.
LINEAR = 1


def identified_xml(sim: SimModel, unknowns: Unknowns, values: np.ndarray) -> str:
    """The MJCF text of ``sim`` with ``values[P]`` written in; loaded by MuJoCo before it is returned.

    Raises:
        ValueError: MuJoCo refuses the written model (its message, on one line).
    """
    mujoco = import_mujoco()
    spec = sim.copy_spec()
    unknowns.write(spec, sim, values)
    delay = next((float(v) for u, v in zip(unknowns.items, values, strict=True) if u.kind == DELAY), 0.0)
    if delay > 0:
        samples = math.ceil(delay / sim.timestep) + 2
        for actuator in spec.actuators:
            actuator.delay, actuator.nsample, actuator.interp = delay, samples, LINEAR
    text = spec.to_xml()
    try:
        mujoco.MjModel.from_xml_string(text)
    except ValueError as error:
        raise ValueError(
            f"identified.xml: MuJoCo refuses the written model: {' '.join(str(error).split())}"
        ) from None
    return text


def start_state(
    sim: SimModel, joints: Sequence[str], q: np.ndarray, qd: np.ndarray, first_command: np.ndarray
) -> np.ndarray:
    """The ``mjSTATE_FULLPHYSICS`` vector at a log's first sample, delayed actuators' buffers holding
    ``first_command[nu]`` (the commands before a log are its first, held: :mod:`idkit.sim.timing`)."""
    mujoco = import_mujoco()
    state = logged_state(sim, tuple(joints), q, qd)
    model = sim.model
    if not model.nhistory:
        return state
    data = mujoco.MjData(model)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    mujoco.mj_setState(model, data, state, spec)
    for a in range(model.nu):
        samples = int(model.actuator_history[a, 0])
        if samples <= 0:
            continue
        times = data.time - model.opt.timestep * np.arange(samples, 0, -1, dtype=np.float64)
        values = np.full((samples, int(model.actuator_ctrlnum[a])), float(first_command[a]))
        mujoco.mj_initCtrlHistory(model, data, a, np.ascontiguousarray(times[:, None]), values)
    mujoco.mj_getState(model, data, state, spec)
    return state
