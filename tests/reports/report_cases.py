"""One small measured-data fit with a held-out file, for the report tests (each module makes its own,
module-scoped: a ``conftest.py`` here would shadow the suite's own ``conftest`` module)."""

from __future__ import annotations

from pathlib import Path

import torch

import idkit
from idkit.data.io import save_samples
from idkit.problem import Samples
from idkit.robots.urdf import URDFRobot


def simulated(robot: URDFRobot, seed: int, n: int = 300) -> Samples:
    """Random states of ``robot`` and its torques with 0.5 % noise (a slightly heavier link3)."""
    generator = torch.Generator().manual_seed(seed)
    q, qd, qdd = robot.random_states(n, generator)
    params = robot.nominal_params().clone()
    params[robot.param_names.index("link3.m")] *= 1.2
    tau = robot.inverse_dynamics(params, q, qd, qdd)
    tau = tau + 0.005 * tau.std(0) * torch.randn(tau.shape, generator=generator, dtype=torch.float64)
    return Samples(q, qd, qdd, tau)


def validated_run(folder: Path) -> tuple[idkit.api.Run, Path]:
    """``(result, report folder)``: ``ls`` on the bundled cylindrical URDF, trained on ``folder /
    train.npz`` and validated on ``folder / test.npz`` (both written here), its report written with
    plots into ``folder / out``."""
    robot = URDFRobot("cylindrical")
    save_samples(simulated(robot, 0), folder / "train.npz")
    save_samples(simulated(robot, 1), folder / "test.npz")
    result = idkit.run(
        robot={"_name_": "urdf", "urdf": "cylindrical"},
        estimator={"_name_": "ls"},
        cost=None,
        data=str(folder / "train.npz"),
        validate=[str(folder / "test.npz")],
        identified_urdf=False,
        out_dir=folder / "out",
        plots=True,
    )
    return result, folder / "out"
