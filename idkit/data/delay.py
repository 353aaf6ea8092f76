"""A torque stream that lags the state stream (the *torque lag*): shift it back, or estimate the lag.

Drives and loggers often stamp the measured effort later than the positions it belongs to (a current
filter, a second topic, a bus cycle). With ``recording.torque_lag=<seconds>`` the torque at time ``t``
is read at ``t + lag`` (:func:`shift_torques`); with ``recording.torque_lag=auto`` the lag is the one
at which the robot's regressor explains the shifted torques best (:func:`estimate_torque_lag`, called
by :mod:`idkit.data.pipeline` with the robot's regressor). Not the rollout's ``command_delay`` (the
states behind the commands, :mod:`idkit.sim.timing`). Why not the plain cross-correlation
with the a-priori (CAD) model's torques: on a 0.2 Hz trajectory of the cylindrical test arm whose
torques trail by 20 ms, the friction the CAD model lacks (~12 % of the torque) moved that peak to
41–59 ms per joint; fitting the regressor (friction included) at each lag finds 20 ms.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from idkit.data.raw import Recording

#: Lags searched by :func:`estimate_torque_lag` (s, either sign).
MAX_LAG = 0.25
#: A step between timestamps longer than this many median steps is a gap (as ``preprocess.max_gap``).
GAP_STEPS = 5.0


def shift_torques(recording: Recording, delay: float) -> tuple[Recording, int]:
    """``recording`` with ``tau(t)`` replaced by the logged ``tau(t + delay)`` (linear interpolation),
    and how many samples were dropped: those whose ``t + delay`` lies outside the recording or inside a
    gap of it (never interpolated across)."""
    if delay == 0:
        return recording, 0
    t = recording.t
    target = t + delay
    steps = np.diff(t)
    after = np.searchsorted(t, target, side="right")  # t[after - 1] <= target < t[after]
    inside = (target >= t[0]) & (target <= t[-1])
    bracket = np.clip(after - 1, 0, steps.size - 1)
    inside &= (steps[bracket] <= GAP_STEPS * np.median(steps)) | (
        target == t[np.clip(after - 1, 0, t.size - 1)]
    )
    rows = np.flatnonzero(inside)
    if rows.size < 2:
        raise ValueError(f"{recording.source}: recording.torque_lag={delay:g} s leaves no samples")
    tau = np.stack([np.interp(target[rows], t, column) for column in recording.tau.T], axis=1)
    qd = None if recording.qd is None else recording.qd[rows]
    shifted = replace(recording, t=t[rows], q=recording.q[rows], tau=tau, qd=qd)
    return shifted, int(t.size - rows.size)


def estimate_torque_lag(
    measured: np.ndarray, regressor: np.ndarray, times: np.ndarray, max_lag: float = MAX_LAG
) -> tuple[float, float]:
    """The lag (s) by which ``measured`` torques ``[N, n]`` trail the states, on uniformly spaced
    ``times[N]``, and the share of the torques' energy the model explains at that lag.

    For every lag ``|L| <= max_lag`` the torques read ``L`` later, ``tau(t + L)``, are fitted by least
    squares with the robot's regressor ``Y(t)`` ``[N, n, B]`` (friction and offsets included, so what
    the a-priori model leaves out cannot pull the peak); the lag is the one where the fit explains the
    most, ``‖Qᵀ tau_L‖² / ‖tau_L‖²`` with ``Q`` an orthonormal basis of ``Y`` — the cross-correlation
    between the torques and the model's column space — refined by a parabola through its neighbours.
    Every lag uses the same states: the middle of each run between gaps, ``max_lag`` in from its ends.

    Raises:
        ValueError: the best lag at the edge of the searched lags (no delay within ``max_lag`` explains
            the torques: wrong joints, units or model), or no run longer than ``2 max_lag``.
    """
    steps = np.diff(times)
    h = float(np.median(steps))
    reach = int(round(max_lag / h))
    lags = np.arange(-reach, reach + 1)
    runs = [
        r for r in np.split(np.arange(times.size), np.flatnonzero(steps > 1.5 * h) + 1) if r.size > 2 * reach
    ]
    if not runs:
        raise ValueError(
            f"recording.torque_lag=auto: no stretch between gaps is longer than 2 × {max_lag:g} s"
        )
    centre = np.concatenate([r[reach : r.size - reach] for r in runs])
    basis = regressor[centre].reshape(-1, regressor.shape[-1])
    q, _ = np.linalg.qr(basis / np.maximum(np.linalg.norm(basis, axis=0), 1e-300))
    explained = np.empty(lags.size)
    for k, lag in enumerate(lags):
        tau = measured[centre + lag].reshape(-1)
        explained[k] = float(np.sum((q.T @ tau) ** 2) / np.sum(tau**2))
    best = int(np.argmax(explained))
    if best in (0, lags.size - 1):
        raise ValueError(
            f"recording.torque_lag=auto: the model explains the torques best at the edge of the searched "
            f"±{max_lag:g} s ({lags[best] * h:+.3g} s): no delay explains them (joints, units, model?); "
            "give recording.torque_lag in s"
        )
    below, peak, above = explained[best - 1 : best + 2]
    curvature = below - 2 * peak + above
    offset = 0.5 * (below - above) / curvature if curvature < 0 else 0.0
    return float((lags[best] + offset) * h), float(peak)
