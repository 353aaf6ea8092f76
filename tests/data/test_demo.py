"""The demo arm the documentation starts from: its logs are the URDF's dynamics with the stated
changes (``TRUTH``, the tool) plus the stated noise, and a fit of them finds those values."""

from __future__ import annotations

import numpy as np
import torch

from idkit.data.demo import TRUTH, main, motion
from idkit.data.recording import load_recording
from idkit.robots.urdf import URDFRobot


def test_the_logs_are_the_stated_arm_plus_noise(tmp_path, capsys):
    main([str(tmp_path), "--seed", "3"])
    assert {p.name for p in tmp_path.iterdir()} >= {"arm.urdf", "train.csv", "test.csv", "tool.csv"}
    assert "wrote" in capsys.readouterr().out
    arm = URDFRobot(str(tmp_path / "arm.urdf"), friction=True, offset=True)
    params = arm.nominal_params().clone()
    for name, value in TRUTH.items():
        params[arm.param_names.index(name)] = value
    t, q, qd, qdd = motion(1.0)
    noiseless = arm.inverse_dynamics(params, *map(torch.from_numpy, (q, qd, qdd))).numpy()
    log = load_recording(tmp_path / "train.csv", joints=arm.joint_names)
    assert np.allclose(log.t, t) and np.abs(log.q - q).max() < 1e-3  # encoder noise 1e-4
    residual = (log.tau - noiseless).std(0) / noiseless.std(0)
    assert np.all((residual > 0.005) & (residual < 0.02))  # the stated 1 % torque noise
    tool = load_recording(tmp_path / "tool.csv", joints=arm.joint_names)
    assert np.abs(tool.tau - log.tau).max() > 1.0  # the 2 kg tool shows
    # inside the URDF's limits: theta1 within ±pi, the slides d2 and d3 within [0, 1] m
    assert np.abs(q[:, 0]).max() < np.pi and q[:, 1:].min() > 0 and q[:, 1:].max() < 1
