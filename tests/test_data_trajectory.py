"""Sampling instants and the bounds report of eq. (39) (the trajectories: tests/excitation/)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from idkit.data.trajectory import (
    PAPER_BOUNDS,
    check_bounds,
    format_violations,
    paper_bounds_report,
    sample_times,
)


def paper_numpy(t: np.ndarray) -> np.ndarray:
    """Eq. (39) typed in again from the paper, independently of PAPER_TERMS: ``[N, 3]``."""
    s = np.sin
    return np.stack(
        (
            0.43 * s(2.2 * t) + 0.23 * s(1.8 * t) - 3.4 * s(0.06 * t) - 0.36,
            s(0.1 * t) - 0.3 * s(0.07 * t) + 0.35 * s(1.3 * t) - 0.014,
            0.1 * s(0.1 * t) - 0.1 * s(2.7 * t) + 0.06 * s(0.14 * t) + 0.26,
        ),
        axis=1,
    )


def test_sample_times_uniform_period_ending_at_t_end():
    assert sample_times(10).tolist() == [float(i) for i in range(1, 11)]
    torch.testing.assert_close(sample_times(20), torch.arange(1, 21, dtype=torch.float64) / 2)
    assert sample_times(1, t_end=3.0).tolist() == [3.0]
    with pytest.raises(ValueError, match="n_samples"):
        sample_times(0)
    with pytest.raises(ValueError, match="t_end"):
        sample_times(5, t_end=0.0)


def test_paper_bounds_report_finds_d2_below_zero():
    """Measured: eq. (39) leaves eq. (38) only through d2 < 0, at the start and around t = 3.5 s."""
    found = paper_bounds_report(n_points=10001)
    assert [(v.variable, v.side) for v in found] == [("d2", "lower")]
    (v,) = found
    # Independent check with numpy on the same grid.
    t = np.linspace(0.0, 10.0, 10001)
    d2 = paper_numpy(t)[:, 1]
    assert v.worst == pytest.approx(d2.min(), abs=1e-14)
    assert v.t_worst == pytest.approx(t[d2.argmin()])
    assert v.excess == pytest.approx(-d2.min())
    assert v.fraction == pytest.approx((d2 < 0).mean())
    negative = t[d2 < 0]
    assert v.intervals[0][0] == 0.0 and v.intervals[-1][1] == pytest.approx(negative.max())
    assert len(v.intervals) == 2
    # Each interval is a maximal run: d2 < 0 at its ends, >= 0 one grid step outside.
    dt = t[1] - t[0]
    for a, b in v.intervals:
        assert paper_numpy(np.array([a, b]))[:, 1].max() < 0
        outside = np.array([x for x in (a - dt, b + dt) if 0 <= x <= 10])
        assert (paper_numpy(outside)[:, 1] >= 0).all()
    assert "d2 < 0" in format_violations(found)


def test_check_bounds_on_a_known_signal():
    t = torch.linspace(0.0, 2 * math.pi, 6284, dtype=torch.float64)
    q = torch.sin(t)[:, None]
    qd = torch.cos(t)[:, None]
    qdd = -q
    found = check_bounds(t, q, qd, qdd, {"x": (-0.5, 0.5), "x_d": (-2, 2)}, joint_names=("x",))
    assert [(v.variable, v.side) for v in found] == [("x", "lower"), ("x", "upper")]
    lower, upper = found
    assert upper.excess == pytest.approx(0.5, abs=1e-6) and upper.t_worst == pytest.approx(
        math.pi / 2, abs=1e-3
    )
    assert upper.intervals[0] == pytest.approx((math.pi / 6, 5 * math.pi / 6), abs=2e-3)
    assert lower.intervals[0] == pytest.approx((7 * math.pi / 6, 11 * math.pi / 6), abs=2e-3)
    assert upper.fraction == pytest.approx(1 / 3, abs=1e-3)
    assert check_bounds(t, q, qd, qdd, {"x": (-1.5, 1.5)}, joint_names=("x",)) == []
    assert format_violations([]) == "within bounds"
    with pytest.raises(ValueError, match="no variable named"):
        check_bounds(t, q, qd, qdd, {"y": (0, 1)}, joint_names=("x",))


def test_paper_bounds_cover_all_nine_variables():
    assert set(PAPER_BOUNDS) == {f"{j}{s}" for j in ("theta1", "d2", "d3") for s in ("", "_d", "_dd")}
