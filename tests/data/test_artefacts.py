"""A driver's artefacts in a log of joint states: stalled repeats found, true repeats kept."""

from __future__ import annotations

import numpy as np
import pytest

from idkit.data.artefacts import find_artefacts, resolution


def _log(n: int = 400, dt: float = 0.002):
    t = np.arange(n) * dt
    q = np.column_stack([np.sin(2 * t), 0.5 * np.cos(3 * t)])
    qd = np.column_stack([2 * np.cos(2 * t), -1.5 * np.sin(3 * t)])
    commands = np.column_stack([np.sin(2 * t + 0.1), np.cos(3 * t)])
    return t, q, qd, t, commands


def _stall(q, qd, at: int, rows: int):
    q, qd = q.copy(), qd.copy()
    q[at + 1 : at + 1 + rows] = q[at]
    qd[at + 1 : at + 1 + rows] = qd[at]
    return q, qd


@pytest.mark.parametrize("rows", [2, 5, 20])
def test_a_stall_of_a_moving_arm_leaves_out_exactly_its_repeats(rows):
    t, q, qd, ct, c = _log()
    q, qd = _stall(q, qd, 100, rows)
    found = find_artefacts(t, q, qd, ct, c)
    assert np.array_equal(np.flatnonzero(found.stalled), np.arange(101, 101 + rows))
    assert found.counts() == {"stalled": rows, "stalls": 1, "dropped": 0}


def test_one_repeated_row_is_left_to_the_robust_loss():
    t, q, qd, ct, c = _log()
    q, qd = _stall(q, qd, 100, 1)  # two identical rows: a glitch, not a stall
    assert find_artefacts(t, q, qd, ct, c).counts()["stalled"] == 0


def test_a_robot_at_rest_repeats_true_rows():
    t, _, _, ct, c = _log()
    q, qd = np.ones((t.size, 2)), np.zeros((t.size, 2))
    assert not find_artefacts(t, q, qd, ct, c).stalled.any()
    assert not find_artefacts(t, q, qd, ct, np.zeros_like(c)).stalled.any()


def test_a_quantised_encoder_with_differentiated_velocities_is_not_a_stall():
    """A slow joint stays within one count for many samples; its velocity (the counts' difference) is
    zero meanwhile: the rows repeat and are true."""
    t, _, _, ct, c = _log(2000)
    count = 2 * np.pi / 4096
    q = np.round(np.column_stack([0.1 * np.sin(t), 0.05 * t]) / count) * count
    qd = np.vstack([np.zeros((1, 2)), np.diff(q, axis=0) / np.diff(t)[:, None]])
    assert np.all(q[1:] == q[:-1], axis=1).sum() > 100  # many repeats
    assert resolution(q)[1] == pytest.approx(count)
    assert not find_artefacts(t, q, qd, ct, c).stalled.any()


def test_dropped_stretches_are_counted_in_samples():
    t, q, qd, ct, c = _log()
    keep = np.ones(t.size, dtype=bool)
    keep[50:60] = False  # 10 samples dropped
    keep[200:203] = False  # 3 more
    found = find_artefacts(t[keep], q[keep], qd[keep], ct, c)
    assert found.counts() == {"stalled": 0, "stalls": 0, "dropped": 13}
