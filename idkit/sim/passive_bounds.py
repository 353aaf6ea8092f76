"""Bounds of a torque-driven joint's passive terms that start at zero, from the model and the log.

A torque fit without armature (or whose viscous friction ended at 0) hands the rollout unknowns that
start at 0, where ``box × start`` gives no range. Their bounds come from one physical rule: *no
passive term alone may need more than what the log and the model say the joint saw* —

* ``armature`` ≤ ``τ_rms / q̈_rms``: a rotor inertia alone taking all of the joint's RMS torque at its
  RMS acceleration (``q̈`` from the logged speeds over :data:`ACCELERATION_SPAN`, which noise hardly
  inflates). Not the arm's own inertia ``M[i, i]``: behind a high gear ratio the reflected rotor
  inertia of a wrist joint is many times its link's (and a drive measuring torque on the link side
  sees none);
* ``damping`` ≤ ``τ_rms / q̇_rms``: viscous friction alone taking all of the joint's RMS torque at
  its RMS speed;
* ``frictionloss`` ≤ ``τ_rms``: dry friction alone taking all of the joint's RMS torque;
* ``bias`` (a motor's constant torque, the sensor offset left after the torque fit's) within
  ``± 0.1 τ_rms``.

``τ`` is the logged motor torque (the commands), ``q̇`` the logged speed. An unknown whose start is
positive and at least :data:`MEANINGFUL` of its cap keeps the usual ``box × start``; one below (0, or
a fit's 3e-10) gets ``[0, cap]``. Each kind's derived bounds are said in one ``note:`` line.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence

import numpy as np

from idkit.data.commands import RobotLog
from idkit.notes import Note
from idkit.sim.model import SimModel

#: The kinds given derived bounds, and why (for the note).
RULES = {
    "armature": "RMS torque / RMS acceleration",
    "damping": "RMS torque / RMS speed",
    "frictionloss": "RMS torque",
    "bias": "±0.1 × RMS torque",
}
#: A start below this fraction of its cap counts as zero (box × start would give no range).
MEANINGFUL = 1e-3
#: Seconds over which logged speeds are differenced for the RMS acceleration.
ACCELERATION_SPAN = 0.02
BIAS_SHARE = 0.1


def rms_acceleration(log: RobotLog) -> np.ndarray:
    """``[n]`` RMS joint acceleration: logged speed differences over at least ``ACCELERATION_SPAN``."""
    step = float(np.median(np.diff(log.t)))
    m = max(1, min(log.n_samples - 1, int(np.ceil(ACCELERATION_SPAN / step))))
    acceleration = (log.qd[m:] - log.qd[:-m]) / (log.t[m:] - log.t[:-m])[:, None]
    return np.sqrt(np.mean(acceleration**2, axis=0))


def caps(log: RobotLog, kind: str) -> np.ndarray:
    """``[n]`` the cap of ``kind`` per logged joint (module docstring)."""
    torque = np.sqrt(np.mean(log.commands**2, axis=0))
    by_joint = {name.removesuffix(".ctrl"): k for k, name in enumerate(log.command_names)}
    tau = np.array([torque[by_joint[j]] if j in by_joint else np.nan for j in log.joint_names])
    if kind == "armature":
        return tau / np.maximum(rms_acceleration(log), 1e-12)
    if kind == "damping":
        return tau / np.maximum(np.sqrt(np.mean(log.qd**2, axis=0)), 1e-12)
    if kind == "frictionloss":
        return tau
    return BIAS_SHARE * tau


def derived_bounds(
    sim: SimModel,
    log: RobotLog,
    joints: Sequence[str],
    params: Sequence[str],
    bounds: Mapping[str, Sequence[float]] | None,
) -> dict[str, list[float]]:
    """``bounds`` with derived ones added for the kinds of :data:`RULES` in ``params`` whose start is
    (nearly) 0 and whose bounds are not given by name or kind (module docstring); a note per kind."""
    out: dict[str, list[float]] = {k: list(v) for k, v in (bounds or {}).items()}
    wanted = {p: list(joints) for p in params if p in RULES}
    for entry in params:
        element, _, kind = entry.rpartition(".")
        if kind in RULES and element in joints:
            wanted.setdefault(kind, []).append(element)
    for kind, names in wanted.items():
        if kind in out:
            continue
        cap = dict(zip(log.joint_names, caps(log, kind), strict=True))
        said = []
        for joint in dict.fromkeys(names):
            name = f"{joint}.{kind}"
            if name in out or joint not in cap or not np.isfinite(cap[joint]) or cap[joint] <= 0:
                continue
            start = _start(sim, kind, joint)
            if kind == "bias":
                out[name] = [-cap[joint], cap[joint]]
            elif start < MEANINGFUL * cap[joint]:
                out[name] = [0.0, float(cap[joint])]
            else:
                continue
            said.append(f"{joint} {out[name][1]:.3g}")
        if said:
            warnings.warn(
                f"{kind} bounds from the model and log ({RULES[kind]}; its start is 0): upper "
                + ", ".join(said),
                Note,
                stacklevel=3,
            )
    return out


def _start(sim: SimModel, kind: str, joint: str) -> float:
    if kind == "bias":
        return 0.0
    dof = sim.model.jnt_dofadr[sim.joint_id(joint)]
    field = {"armature": "dof_armature", "damping": "dof_damping", "frictionloss": "dof_frictionloss"}[kind]
    return float(getattr(sim.model, field)[dof])
