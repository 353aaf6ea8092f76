"""Held-out validation of an identified model, for any robot: how well it predicts measured torques.

There are no true parameters for a real robot, so the honest score is prediction on a recording the
fit never saw. The yardstick is one fixed metric, the same whatever cut-off the training data were
filtered with (so tuning ``preprocess.cutoff`` to the reported figure tunes the model, not the ruler):

* **predicted** torques: the model on the held-out file's states *as the training states were
  made* — a raw recording resampled, filtered at the training cut-off and differentiated
  (:mod:`idkit.data.preprocess`), a samples file's own ``q, qd, qdd`` — since the model needs
  accelerations and they have to be estimated somehow;
* **measured** torques: as recorded (resampled onto the samples' times, never filtered at the
  training cut-off);
* ``E = measured − predicted`` and ``T = measured``, both **band-limited** at
  :data:`~idkit.data.preprocess.SCORE_BAND_HZ`
  (6 Hz; ``0.4 ×`` the sampling rate if that is lower) by the zero-phase Butterworth filter of the
  preprocessing (order 4 per pass, run forwards and backwards) on the file's own timestamps
  (:func:`idkit.data.preprocess.band_limit`). Identification motion lives below ~2 Hz; above the
  band a torque record holds sensor noise and structural vibration, which no rigid-body model
  predicts and which would otherwise be scored as model error (or, filtered at the user's cut-off,
  make the score depend on it). A file without timestamps cannot be filtered: it is scored
  unfiltered, and says so.

Over ``N`` samples and ``n`` joints, with ``E`` and ``T`` as above:

* ``rms[j] = sqrt(mean_t E_tj²)`` (N·m) and ``relative[j] = rms[j] / sqrt(mean_t T_tj²)``;
* ``rel_all = ‖E‖_F / ‖T‖_F``: the RMS error over all joints relative to the RMS measured torque
  (dominated by the joints that carry the most torque);
* ``nrms_limit = sqrt(mean_tj (E_tj / τmax_j)²)`` with ``τmax`` the joints' effort limits, when
  known (a ``urdf`` robot reads them from ``<limit effort>``);
* ``rel_all_raw``: ``‖E‖_F / ‖T‖_F`` without the band (every frequency, sensor noise included).

Pure computation: no files, no text but the ``metric`` description.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor

from idkit.data.load import DataFile
from idkit.data.preprocess import BAND_OF_RATE, SCORE_BAND_HZ, band_limit
from idkit.interfaces import Robot
from idkit.model import IdentifiedModel
from idkit.problem import Samples


def scoring_band(times: np.ndarray | None) -> float | None:
    """The scoring band (Hz) for samples at ``times[N]`` (s), or ``None`` without timestamps."""
    if times is None or len(times) < 2:
        return None
    return min(SCORE_BAND_HZ, BAND_OF_RATE / float(np.median(np.diff(times))))


def metric_description(band: float | None) -> str:
    """How :func:`score` computed its figures, in one sentence for ``result.json``."""
    if band is None:
        return (
            "||E||/||T||, E = measured - predicted torques, unfiltered (the file has no timestamps to "
            "band-limit them)"
        )
    return (
        f"||E||/||T||, E = measured - predicted torques and T = measured torques, both low-passed at "
        f"{band:g} Hz (zero-phase Butterworth, order 4 per pass, on the file's timestamps); predicted "
        "from the file's states as the training states were made; rel_all_raw: the same, unfiltered"
    )


@dataclass(frozen=True)
class Validation:
    """Torque prediction scores on one recording (arrays float64 numpy, joints in robot order).

    Attributes:
        predicted: ``[N, n]`` predicted torques (plot-ready, same order as ``measured``).
        measured: ``[N, n]`` measured torques, as recorded.
        rms: ``[n]`` RMS of the band-limited error per joint.
        relative: ``[n]`` that over the joint's RMS band-limited measured torque.
        rel_all: ``‖E‖_F / ‖T‖_F`` in the scoring band.
        nrms_limit: RMS of ``E / effort`` over all entries, or ``None`` without effort limits.
        rel_all_raw: ``‖E‖_F / ‖T‖_F`` unfiltered.
        band: the scoring band (Hz), ``None`` without timestamps (then every figure is unfiltered).
    """

    predicted: np.ndarray
    measured: np.ndarray
    rms: np.ndarray
    relative: np.ndarray
    rel_all: float
    nrms_limit: float | None
    rel_all_raw: float
    band: float | None = None

    @property
    def metric(self) -> str:
        """How the figures were computed (:func:`metric_description`)."""
        return metric_description(self.band)

    def to_dict(self) -> dict[str, Any]:
        """The scores for ``result.json`` (per-joint lists in robot order; no torque traces)."""
        return {
            "samples": int(self.measured.shape[0]),
            "rms": self.rms.tolist(),
            "relative": self.relative.tolist(),
            "rel_all": self.rel_all,
            "nrms_limit": self.nrms_limit,
            "rel_all_raw": self.rel_all_raw,
            "band_hz": self.band,
            "metric": self.metric,
        }


def effort_limits(robot: Robot) -> np.ndarray | None:
    """The robot's effort limits ``[n]`` if it declares them (``effort_limits`` attribute), else ``None``."""
    limits = getattr(robot, "effort_limits", None)
    return None if limits is None else np.asarray(limits, dtype=np.float64)


def predict(
    robot: Robot, samples: Samples, params: Tensor | None = None, base_params: Tensor | None = None
) -> Tensor:
    """Predicted torques ``[N, n]`` from standard ``params[P]`` (through :class:`IdentifiedModel`) or
    ``base_params[B]`` (through the regressor): exactly one."""
    if (params is None) == (base_params is None):
        raise ValueError("validation: give exactly one of params [P] or base_params [B]")
    if samples.n_joints != robot.n_joints:
        raise ValueError(
            f"validation: samples have {samples.n_joints} joints but robot {type(robot).__name__} has "
            f"{robot.n_joints} ({', '.join(robot.joint_names)})"
        )
    with torch.no_grad():
        if params is not None:
            return IdentifiedModel.from_params(robot, params).predict(samples.q, samples.qd, samples.qdd)
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
    times: np.ndarray | None = None,
    measured: np.ndarray | None = None,
) -> Validation:
    """Score the torques the model predicts on held-out ``samples`` (module doc).

    Args:
        robot: any robot plugin.
        samples: held-out states (and torques) ``[N, n]``, made as the training samples were.
        params: standard parameters ``[P]``; or ``base_params[B]`` for robots with a regressor.
        effort: effort limits ``[n]`` for ``nrms_limit``; ``None`` = the robot's, if it declares them.
        times: ``[N]`` the samples' times (s): the torques are compared in the scoring band; ``None``:
            unfiltered.
        measured: ``[N, n]`` the measured torques as recorded; ``None``: ``samples.tau``.
    """
    predicted = predict(robot, samples, params, base_params).detach().cpu().double().numpy()
    effort = effort_limits(robot) if effort is None else effort
    if measured is None:
        measured = samples.tau.detach().cpu().double().numpy()
    return score(measured, predicted, effort, times)


def score(
    measured: np.ndarray,
    predicted: np.ndarray,
    effort: np.ndarray | None = None,
    times: np.ndarray | None = None,
) -> Validation:
    """The metrics of the module doc for measured and predicted torques ``[N, n]`` (any source of the
    prediction, e.g. another recording's torques replayed); ``effort[n]`` for ``nrms_limit``;
    ``times[N]`` (s) to compare them in the scoring band (``None``: unfiltered)."""
    measured, predicted = np.asarray(measured, dtype=np.float64), np.asarray(predicted, dtype=np.float64)
    error = measured - predicted
    raw = float(np.linalg.norm(error) / np.linalg.norm(measured))
    band = scoring_band(times)
    reference = measured
    if band is not None and times is not None:  # a band needs times
        error, reference = band_limit(times, error, band), band_limit(times, measured, band)
    rms = np.sqrt((error**2).mean(0))
    scale = np.sqrt((reference**2).mean(0))
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
        rel_all=float(np.linalg.norm(error) / np.linalg.norm(reference)),
        nrms_limit=nrms,
        rel_all_raw=raw,
        band=band,
    )


def validate_model(
    model: IdentifiedModel,
    samples: Samples,
    *,
    times: np.ndarray | None = None,
    measured: np.ndarray | None = None,
) -> Validation:
    """:func:`score` of an identified model on held-out ``samples`` (``times``, ``measured``: as for
    :func:`validate`; the effort limits are the model's robot's)."""
    with torch.no_grad():
        predicted = model.predict(samples.q, samples.qd, samples.qdd).detach().cpu().double().numpy()
    if measured is None:
        measured = samples.tau.detach().cpu().double().numpy()
    return score(measured, predicted, effort_limits(model.robot), times)


def validate_file(model: IdentifiedModel, held: DataFile) -> Validation:
    """:func:`validate_model` on one loaded held-out file: its states, its measured torques as recorded
    and its timestamps."""
    return validate_model(model, held.samples, times=held.times, measured=held.measured_tau)


def validate_files(model: IdentifiedModel, held_out: Sequence[DataFile]) -> list[Validation]:
    """:func:`validate_file` on each held-out file."""
    return [validate_file(model, held) for held in held_out]
