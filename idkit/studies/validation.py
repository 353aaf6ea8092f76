"""Held-out validation of an identified model, for any robot: how well it predicts measured torques.

There are no true parameters for a real robot, so the honest score is prediction on a recording the
fit never saw. For ``E = measured − predicted`` over ``N`` samples and ``n`` joints:

* ``rms[j] = sqrt(mean_t E_tj²)`` (N·m) and ``relative[j] = rms[j] / sqrt(mean_t τ_tj²)``;
* ``rel_all = ‖E‖_F / ‖T‖_F``: the RMS error over all joints relative to the RMS measured torque
  (dominated by the joints that carry the most torque);
* ``nrms_limit = sqrt(mean_tj (E_tj / τmax_j)²)`` with ``τmax`` the joints' effort limits, when
  known (a ``urdf`` robot reads them from ``<limit effort>``).

Pure computation: no files, no text.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor

from idkit.interfaces import Robot
from idkit.problem import Samples


@dataclass(frozen=True)
class Validation:
    """Torque prediction scores on one recording (arrays float64 numpy, joints in robot order).

    Attributes:
        predicted: ``[N, n]`` predicted torques (plot-ready, same order as ``measured``).
        measured: ``[N, n]`` measured torques.
        rms: ``[n]`` RMS error per joint.
        relative: ``[n]`` RMS error per joint over that joint's RMS measured torque.
        rel_all: ``‖E‖_F / ‖T‖_F``.
        nrms_limit: RMS of ``E / effort`` over all entries, or ``None`` without effort limits.
    """

    predicted: np.ndarray
    measured: np.ndarray
    rms: np.ndarray
    relative: np.ndarray
    rel_all: float
    nrms_limit: float | None

    def to_dict(self) -> dict[str, Any]:
        """The scores for ``result.json`` (per-joint lists in robot order; no torque traces)."""
        return {
            "samples": int(self.measured.shape[0]),
            "rms": self.rms.tolist(),
            "relative": self.relative.tolist(),
            "rel_all": self.rel_all,
            "nrms_limit": self.nrms_limit,
        }


def effort_limits(robot: Robot) -> np.ndarray | None:
    """The robot's effort limits ``[n]`` if it declares them (``effort_limits`` attribute), else ``None``."""
    limits = getattr(robot, "effort_limits", None)
    return None if limits is None else np.asarray(limits, dtype=np.float64)


def predict(
    robot: Robot, samples: Samples, params: Tensor | None = None, base_params: Tensor | None = None
) -> Tensor:
    """Predicted torques ``[N, n]`` from standard ``params[P]`` or ``base_params[B]`` (exactly one)."""
    if (params is None) == (base_params is None):
        raise ValueError("validation: give exactly one of params [P] or base_params [B]")
    if samples.n_joints != robot.n_joints:
        raise ValueError(
            f"validation: samples have {samples.n_joints} joints but robot {type(robot).__name__} has "
            f"{robot.n_joints} ({', '.join(robot.joint_names)})"
        )
    with torch.no_grad():
        if params is not None:
            params = torch.as_tensor(params).to(samples.q)
            return robot.inverse_dynamics(params, samples.q, samples.qd, samples.qdd)
        base = torch.as_tensor(base_params).to(samples.q)
        if base.shape != (len(robot.base_param_names),):
            raise ValueError(
                f"validation: base_params must be [{len(robot.base_param_names)}], got {tuple(base.shape)}"
            )
        return robot.regressor(samples.q, samples.qd, samples.qdd) @ base


def validate(
    robot: Robot,
    samples: Samples,
    params: Tensor | None = None,
    *,
    base_params: Tensor | None = None,
    effort: np.ndarray | None = None,
) -> Validation:
    """Score the torques the model predicts on held-out ``samples`` (module doc).

    Args:
        robot: any robot plugin.
        samples: held-out recording ``[N, n]``.
        params: standard parameters ``[P]``; or ``base_params[B]`` for robots with a regressor.
        effort: effort limits ``[n]`` for ``nrms_limit``; ``None`` = the robot's, if it declares them.
    """
    predicted = predict(robot, samples, params, base_params).detach().cpu().double().numpy()
    effort = effort_limits(robot) if effort is None else effort
    return score(samples.tau.detach().cpu().double().numpy(), predicted, effort)


def score(measured: np.ndarray, predicted: np.ndarray, effort: np.ndarray | None = None) -> Validation:
    """The metrics of the module doc for measured and predicted torques ``[N, n]`` (any source of the
    prediction, e.g. another recording's torques replayed); ``effort[n]`` for ``nrms_limit``."""
    measured, predicted = np.asarray(measured, dtype=np.float64), np.asarray(predicted, dtype=np.float64)
    error = measured - predicted
    rms = np.sqrt((error**2).mean(0))
    scale = np.sqrt((measured**2).mean(0))
    nrms = None
    if effort is not None:
        effort = np.asarray(effort, dtype=np.float64)
        if np.isfinite(effort).all() and (effort > 0).all():
            nrms = float(np.sqrt(((error / effort) ** 2).mean()))
    return Validation(
        predicted=predicted,
        measured=measured,
        rms=rms,
        relative=rms / scale,
        rel_all=float(np.linalg.norm(error) / np.linalg.norm(measured)),
        nrms_limit=nrms,
    )


def validate_files(
    robot: Robot, params: Mapping[str, float], held_out: Sequence[Samples]
) -> list[Validation]:
    """:func:`validate` of an estimate's parameter map (``Estimate.params``) on each held-out recording."""
    vector = torch.tensor([float(params[name]) for name in robot.param_names], dtype=torch.float64)
    return [validate(robot, samples, vector) for samples in held_out]
