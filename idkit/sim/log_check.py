"""Logs a model cannot have produced, and bounds a log cannot support: refused in one line before a fit.

A log in degrees, or with velocities in other units than its positions, ends a fit "complete" with
hundreds of MuJoCo acceleration warnings and parameters at their bounds; a delay bound of 100 s on a
2 s log ends with every damping at a bound. Both are cheap to see from the log and the model:

* **Velocities against positions.** A joint's logged ``qd`` must be its ``q``'s rate: their robust
  sizes over windows of ``WINDOW`` seconds (noise averaged out) agree within a factor ``RATE_FACTOR``
  (a wrong scale, rad/s against deg, is 57×).
* **Speeds the model cannot reach.** A hinge faster than ``MAX_HINGE_SPEED`` rad/s or a slide faster
  than ``MAX_SLIDE_SPEED`` m/s is a unit mistake (degrees per second), not a robot.
* **Positions outside the joint's range.** A limited joint further than its range's width beyond it.
* **A delay longer than a tenth of the log** (:data:`DELAY_SHARE`): the log cannot tell it.

A fit that ends with an unknown on a bound or with an infinite standard deviation is said by
:func:`warn_unsupported` in one :class:`RolloutWarning` line each.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

from idkit.sim.model import SimModel
from idkit.sim.quantities import Unknowns

#: Velocities and position rates of one joint that differ by more than this factor are other units.
RATE_FACTOR = 4.0
#: Seconds over which the position rate and the mean velocity are compared.
WINDOW = 0.02
#: A joint faster than this (rad/s, hinge; m/s, slide) is a unit mistake.
MAX_HINGE_SPEED = 50.0
MAX_SLIDE_SPEED = 10.0
#: Speeds and positions are read at this percentile of the log (glitched samples do not count).
TYPICAL = 95.0
#: A delay's upper bound may be at most this share of the log's duration.
DELAY_SHARE = 0.1
#: A joint must move this many of its noise levels over a window for its rate to be compared.
MOVING = 10.0


class RolloutWarning(UserWarning):
    """A rollout fit's result the log does not support (an unknown on a bound, an infinite σ)."""


def check_log(
    sim: SimModel, t: np.ndarray, q: np.ndarray, qd: np.ndarray, joints: Sequence[str], source: str
) -> None:
    """Refuse a log the model cannot have produced (module docstring), naming the file, the joint and
    the likely cause.

    Raises:
        ValueError: one line.
    """
    model = sim.model
    for j, name in enumerate(joints):
        joint = sim.joint_id(name)
        hinge = int(model.jnt_type[joint]) == 3
        unit, top = ("rad/s", MAX_HINGE_SPEED) if hinge else ("m/s", MAX_SLIDE_SPEED)
        fastest = float(np.percentile(np.abs(qd[:, j]), TYPICAL))  # a glitched sample is no speed
        if fastest > top:
            raise ValueError(
                f"{source}: joint {name} moves at {fastest:.4g} {unit} or faster in {100 - TYPICAL:g} % of "
                "the log, faster than any "
                f"{'hinge' if hinge else 'slide'} of a robot ({top:g} {unit}): positions and velocities "
                f"in {'degrees' if hinge else 'millimetres'}, or a wrong scale? idkit reads "
                f"{'radians' if hinge else 'metres'}"
            )
        ratio = _rate_ratio(t, q[:, j], qd[:, j])
        if ratio == 0:
            raise ValueError(
                f"{source}: joint {name}'s logged velocities are zero while its positions move: does the "
                "driver log no velocities? A rollout compares them; give the joint's velocities (qd)"
            )
        if ratio is not None and not 1 / RATE_FACTOR <= ratio <= RATE_FACTOR:
            raise ValueError(
                f"{source}: joint {name}'s logged velocities are {ratio:.3g}× the rate of its logged "
                "positions (dq/dt): they are in other units (degrees against radians: 57×) or of another "
                "joint, scale or column"
            )
        if model.jnt_limited[joint]:
            low, high = (float(v) for v in model.jnt_range[joint])
            width = high - low
            least, most = (float(v) for v in np.percentile(q[:, j], [100 - TYPICAL, TYPICAL]))
            if width > 0 and max(low - least, most - high) > width:
                raise ValueError(
                    f"{source}: joint {name} reaches {least:.4g} .. {most:.4g} in the log, "
                    f"far outside its range [{low:.4g}, {high:.4g}] in the model: positions in "
                    f"{'degrees' if hinge else 'millimetres'}, an offset, or another model?"
                )


def _rate_ratio(t: np.ndarray, q: np.ndarray, qd: np.ndarray) -> float | None:
    """Median |mean qd| / median |Δq/Δt| over windows of about ``WINDOW`` s (``None``: the joint barely
    moves, or the log is too short to tell)."""
    step = float(np.median(np.diff(t)))
    width = max(1, int(round(WINDOW / step)))
    if q.size <= 2 * width:
        return None
    rate = (q[width:] - q[:-width]) / (t[width:] - t[:-width])
    cumulative = np.concatenate([[0.0], np.cumsum(qd)])
    mean = (cumulative[width + 1 :] - cumulative[1:-width]) / width  # qd over the same window
    d4 = np.diff(q, n=4)
    noise = 1.4826 * float(np.median(np.abs(d4 - np.median(d4)))) / np.sqrt(70.0)
    moving = np.abs(q[width:] - q[:-width]) > MOVING * max(noise, 1e-12)
    if moving.sum() < max(10, 0.1 * moving.size):
        return None
    low = float(np.median(np.abs(rate[moving])))
    return float(np.median(np.abs(mean[moving]))) / low if low > 0 else None


def check_delay_bound(unknowns: Unknowns, t: np.ndarray, source: str) -> None:
    """Refuse a delay whose upper bound exceeds a tenth of the log's duration (module docstring).

    Raises:
        ValueError: one line naming the bound, the log's duration and the largest the log supports.
    """
    index = unknowns.delay_index
    if index is None:
        return
    upper = unknowns.items[index].upper
    duration = float(t[-1] - t[0])
    if upper > DELAY_SHARE * duration:
        name = unknowns.items[index].name
        raise ValueError(
            f"{source}: the bound of {name} reaches {upper:g} s, more than a tenth of the log "
            f"({duration:.4g} s): a log cannot tell a delay that long from the motion; bound it at most "
            f"{DELAY_SHARE * duration:.3g} s (rollout.bounds.{name}=[0, …]) or give a longer log"
        )


def warn_unsupported(unknowns: Unknowns, values: np.ndarray, std: dict[str, float]) -> list[str]:
    """One :class:`RolloutWarning` per unknown that ended on a bound or with an infinite standard
    deviation (the log does not determine it there); returns the lines."""
    at = set(unknowns.at_bound(values))
    lines = []
    for unknown, value in zip(unknowns.items, values, strict=True):
        on_bound = unknown.name in at
        infinite = not np.isfinite(std.get(unknown.name, 0.0))
        if not (on_bound or infinite):
            continue
        parts = []
        if on_bound:
            side = "lower" if abs(value - unknown.lower) <= abs(value - unknown.upper) else "upper"
            bound = unknown.lower if side == "lower" else unknown.upper
            parts.append(
                f"ended on its {side} bound {bound:.4g} ([{unknown.lower:.4g}, {unknown.upper:.4g}])"
            )
        if infinite:
            parts.append("has an infinite σ (the log does not determine it)")
        advice = (
            "widen the bound, fix it, or give a richer log" if on_bound else "fix it or give a richer log"
        )
        lines.append(f"rollout: {unknown.name} = {value:.4g} {' and '.join(parts)}: {advice}")
    for line in lines:
        warnings.warn(line, RolloutWarning, stacklevel=3)
    return lines
