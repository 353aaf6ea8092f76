"""A simulated arm and its logs, so that the documentation's examples run anywhere.

``python -m idkit.data.demo [folder]`` writes, into ``folder`` (default: the current one):

* ``arm.urdf`` — the paper's cylindrical robot (shipped with idkit), its rods given a small axial
  inertia (MuJoCo refuses a zero one);
* ``train.csv`` and ``test.csv`` — 20 s logs at 200 Hz of two different motions of the "real" arm
  (link2 heavier than its URDF says, Coulomb and viscous friction, a torque offset per joint), with
  1 % torque noise and encoder noise, one column per joint and quantity (``t, theta1.q, …,
  theta1.tau, …``), as a driver would log them;
* ``tool.csv`` — the first motion with a 2 kg tool on the last link.

The values it sets are in :data:`TRUTH` and :data:`TOOL`; every random draw comes from ``seed``.
The motions are sums of sines, not an optimised excitation (``docs/excitation.md`` designs one).
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from importlib.resources import files
from pathlib import Path

import numpy as np

#: The simulated arm's parameters where they differ from its URDF.
TRUTH: Mapping[str, float] = {
    "link2.m": 5.5,
    "theta1.fc": 0.5,
    "d2.fc": 2.0,
    "d3.fc": 1.0,
    "theta1.fv": 0.2,
    "d2.fv": 1.0,
    "d3.fv": 0.5,
    "theta1.offset": 0.1,
    "d2.offset": -0.5,
    "d3.offset": 0.3,
}
#: The tool: 2 kg at (0.05, 0, -0.1) m in link3's frame, added to link3's mass, first moment and
#: inertia about link3's origin.
TOOL: Mapping[str, float] = {
    "m": 2.0,
    "mcx": 0.1,
    "mcz": -0.2,
    "Ixx": 0.024,
    "Iyy": 0.029,
    "Izz": 0.009,
    "Ixz": 0.01,
}

RATE_HZ = 200.0
DURATION_S = 20.0


def motion(speed: float) -> tuple[np.ndarray, ...]:
    """``t, q, qd, qdd`` of a sum of sines per joint, inside the URDF's limits (rad, m)."""
    t = np.arange(0.0, DURATION_S, 1.0 / RATE_HZ)
    centre, amplitude = np.array([0.0, 0.5, 0.5]), np.array([2.0, 0.3, 0.3])
    w1, w2 = speed * np.array([0.7, 1.1, 1.6]), speed * np.array([1.9, 2.6, 0.9])
    s1, s2 = np.sin(np.outer(t, w1)), np.sin(np.outer(t, w2))
    c1, c2 = np.cos(np.outer(t, w1)), np.cos(np.outer(t, w2))
    q = centre + amplitude * (0.7 * s1 + 0.3 * s2)
    qd = amplitude * (0.7 * w1 * c1 + 0.3 * w2 * c2)
    qdd = -amplitude * (0.7 * w1**2 * s1 + 0.3 * w2**2 * s2)
    return t, q, qd, qdd


def write(folder: str | Path = ".", seed: int = 0) -> list[Path]:
    """Write the URDF and the three logs into ``folder``; returns their paths."""
    import torch

    from idkit.data.recording import Recording, save_recording
    from idkit.robots.urdf import URDFRobot

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    urdf = (files("idkit") / "robots/assets/cylindrical.urdf").read_text()
    urdf_path = folder / "arm.urdf"
    urdf_path.write_text(urdf.replace('izz="0"', 'izz="0.05"').replace('izz="1.0"', 'izz="0.9"'))
    arm = URDFRobot(str(urdf_path), friction=True, offset=True)
    cad = dict(zip(arm.param_names, arm.nominal_params().tolist(), strict=True))
    with_tool = dict(TRUTH) | {f"link3.{k}": cad[f"link3.{k}"] + v for k, v in TOOL.items()}
    rng = np.random.default_rng(seed)

    def log(name: str, truth: Mapping[str, float], states: Sequence[np.ndarray]) -> Path:
        params = arm.nominal_params().clone()
        for key, value in truth.items():
            params[arm.param_names.index(key)] = value
        t, q, qd, qdd = (np.array(x) for x in states)
        tau = arm.inverse_dynamics(params, *map(torch.from_numpy, (q, qd, qdd))).numpy()
        tau += 0.01 * tau.std(0) * rng.standard_normal(tau.shape)
        q += 1e-4 * rng.standard_normal(q.shape)
        return save_recording(Recording(t, q, tau, joint_names=arm.joint_names), folder / name)

    return [
        urdf_path,
        log("train.csv", TRUTH, motion(1.0)),
        log("test.csv", TRUTH, motion(1.4)),
        log("tool.csv", with_tool, motion(1.0)),
    ]


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m idkit.data.demo", description=__doc__.splitlines()[0])
    parser.add_argument("folder", nargs="?", default=".", help="where to write (default: here)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the noise (default 0)")
    options = parser.parse_args(argv)
    for path in write(options.folder, options.seed):
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
