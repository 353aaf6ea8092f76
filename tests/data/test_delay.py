"""Torque delay: shifting a recording's torques, and estimating the lag by cross-correlation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit.data.delay import estimate_torque_lag, shift_torques
from idkit.data.recording import Recording

RATE = 200.0


def signal(t: np.ndarray) -> np.ndarray:
    """Three joints of a multi-sine torque ``[N, 3]``."""
    w = 2 * np.pi * np.array([[0.3, 1.1], [0.5, 1.7], [0.7, 2.3]])
    return np.stack([np.sin(w[j, 0] * t) + 0.4 * np.cos(w[j, 1] * t + j) for j in range(3)], axis=1)


@settings(max_examples=15, deadline=None)
@given(delay=st.floats(-0.2, 0.2))
def test_the_lag_of_a_delayed_copy_is_found_to_a_tenth_of_a_step(delay):
    t = np.arange(4000) / RATE
    estimate, peak = estimate_torque_lag(signal(t - delay), signal(t)[:, :, None], t)
    assert estimate == pytest.approx(delay, abs=0.1 / RATE) and peak > 0.95


def test_runs_between_gaps_are_correlated_apart_and_no_lag_at_the_edge_is_believed():
    t = np.arange(4000) / RATE
    t[2000:] += 3.0
    estimate, _ = estimate_torque_lag(signal(t - 0.02), signal(t)[:, :, None], t)
    assert estimate == pytest.approx(0.02, abs=0.1 / RATE)
    t = np.arange(4000) / RATE  # a lag of 0.3 s, beyond the ±0.25 s searched: the edge wins
    with pytest.raises(ValueError, match=r"best at the edge of the searched ±0.25 s \(\+0.25 s\)"):
        estimate_torque_lag(signal(t - 0.3), signal(t)[:, :, None], t)


def test_shift_reads_each_torque_later_and_never_across_a_gap():
    t = np.arange(100) / RATE
    t[60:] += 1.0  # a gap after sample 59
    tau = np.stack([t, 2 * t], axis=1)  # linear in time: interpolation is exact
    recording = Recording(t, np.zeros((100, 2)), tau, source="r.csv")
    shifted, dropped = shift_torques(recording, 0.0123)
    np.testing.assert_allclose(shifted.tau, np.stack([shifted.t + 0.0123, 2 * (shifted.t + 0.0123)], 1))
    # t + delay falls in the gap for the last 3 samples before it, beyond the end for the last 3
    assert dropped == 6 and shifted.t.size == 94
    assert not ((shifted.t > t[56]) & (shifted.t < t[60])).any()
    assert shift_torques(recording, 0.0) == (recording, 0)
