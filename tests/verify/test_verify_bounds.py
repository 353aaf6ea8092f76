"""The bounds report: eq. (39) against eq. (38), and a signal whose excursions are known in closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from idkit.verify.bounds import PAPER_BOUNDS, check_bounds, format_violations, paper_bounds_report


def d2_printed(t: np.ndarray) -> np.ndarray:
    """d2 of eq. (39), typed from the paper (independent of ``PAPER_TERMS``)."""
    return np.sin(0.1 * t) - 0.3 * np.sin(0.07 * t) + 0.35 * np.sin(1.3 * t) - 0.014


def test_paper_bounds_report_finds_d2_below_zero():
    """Measured: eq. (39) leaves eq. (38) only through d2 < 0, at the start and around t = 3.5 s."""
    found = paper_bounds_report(n_points=10001)
    assert [(v.variable, v.side) for v in found] == [("d2", "lower")]
    (v,) = found
    # Independent check with numpy on the same grid.
    t = np.linspace(0.0, 10.0, 10001)
    d2 = d2_printed(t)
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
        assert d2_printed(np.array([a, b])).max() < 0
        outside = np.array([x for x in (a - dt, b + dt) if 0 <= x <= 10])
        assert (d2_printed(outside) >= 0).all()
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


def test_command_prints_the_paper_report(capsys):
    from idkit.verify.__main__ import main

    assert main(["bounds", "--points", "2001"]) == 0
    assert "d2 < 0" in capsys.readouterr().out
