"""Coverage of the rollout fit's 95 % intervals where the model is wrong and where the log is corrupted.

A 2-joint pendulum on torque motors (joint 1 about z, joint 2 about y: gravity acts on it), 2.5 s at
500 Hz (5 segments of 0.5 s), its armatures and dampings fitted with the defaults from 1.5 × the
truth, every draw a new excitation (random amplitudes, frequencies and phases) and new noise. Each
test counts the intervals (4 per draw) that hold the truth, for the intervals reported and for the
textbook (white-noise) ones of the same fits.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from idkit.data.commands import RobotLog
from idkit.estimators.rollout import RolloutEstimator
from idkit.testing import rollout_cases as cases
from idkit.testing.rollout_cases import Case, corrupt, simulate

PENDULUM = cases.ARM5.split('<body name="link3"')[0] + (
    "</body></body></worldbody><actuator>"
    '<motor name="act1" joint="joint1"/><motor name="act2" joint="joint2"/></actuator></mujoco>'
)
TRUTH = {"joint1.armature": 0.5, "joint2.armature": 0.4, "joint1.damping": 1.0, "joint2.damping": 0.8}
DRAWS = 50
SAMPLES = 1250


def heavier(text: str, factor: float) -> str:
    """``text`` with every link's mass and inertia times ``factor``."""
    text = re.sub(r'mass="([^"]+)"', lambda m: f'mass="{float(m.group(1)) * factor:g}"', text)
    return re.sub(
        r'diaginertia="([^"]+)"',
        lambda m: 'diaginertia="' + " ".join(f"{float(v) * factor:g}" for v in m.group(1).split()) + '"',
        text,
    )


def stalled(q: np.ndarray, qd: np.ndarray, rng: np.random.Generator, stalls: int = 2, rows: int = 20):
    """``stalls`` stretches of ``rows`` samples where the driver repeats its last row."""
    q, qd = q.copy(), qd.copy()
    for first in rng.choice(np.arange(10, len(q) - rows, 3 * rows), stalls, replace=False):
        q[first : first + rows], qd[first : first + rows] = q[first - 1], qd[first - 1]
    return q, qd


def _fit(seed: int, truth_model: str, glitches: float, stalls: int) -> dict:
    """The fit's details on a log the ``truth_model`` made (module docstring)."""
    rng = np.random.default_rng(seed)
    t = np.arange(SAMPLES) * 0.002
    waves = [(rng.uniform(2, 4), rng.uniform(0.8, 2.0)), (rng.uniform(1.5, 3), rng.uniform(1.0, 2.5))]
    ctrl = np.column_stack([a * np.sin(2 * np.pi * f * t + rng.uniform(0, 6)) for a, f in waves])
    q, qd = simulate(truth_model, ctrl)
    q, qd = corrupt(q, qd, (1e-4, 1e-2), glitches, rng)
    if stalls:
        q, qd = stalled(q, qd, rng, stalls)
    log = RobotLog(t, q, qd, t, ctrl, ("joint1", "joint2"), ("act1.ctrl", "act2.ctrl"), f"draw {seed}")
    start = {k: 1.5 * v for k, v in TRUTH.items()}
    case = Case("coverage", PENDULUM, ("armature", "damping"), TRUTH, log, log, {}, start)
    estimate = RolloutEstimator().fit(cases.problem_of(case, threads=1))
    found = estimate.details.uncertainty
    return {
        "model_limited": found.model_limited, "ci95": found.interval95, "sigma": found.std,
        "textbook_sigma": found.textbook_std, "heavier_links": found.heavier_links, "params": estimate.params,
    }  # fmt: skip


def _coverage(truth_model, glitches: float = 0.0, stalls: int = 0, seed: int = 0) -> dict[str, float]:
    """Shares of intervals holding the truth (reported, textbook), of fits called model-limited, and
    the median widening of the intervals over the textbook's."""
    inside, textbook, limited, widened = [], [], [], []
    for draw in range(DRAWS):
        model = truth_model(draw) if callable(truth_model) else truth_model
        details = _fit(seed + draw, model, glitches, stalls)
        limited.append(bool(details["model_limited"]))
        for name, value in TRUTH.items():
            low, high = details["ci95"][name]
            inside.append(low <= value <= high)
            estimate, sigma = details["params"][name], details["textbook_sigma"][name]
            textbook.append(abs(np.log(value / estimate)) <= 1.96 * sigma / estimate)  # log coordinates
            widened.append(details["sigma"][name] / sigma)
    return {
        "coverage": float(np.mean(inside)),
        "textbook": float(np.mean(textbook)),
        "model_limited": float(np.mean(limited)),
        "median_widening": float(np.median(widened)),
    }


def test_the_heavier_links_shift_predicts_a_wrong_models_bias():
    """A log made with every link 10 % heavier, fitted with the lighter model: the reported move of each
    estimate were the links 10 % heavier, applied, brings the biased estimates near the truth (measured:
    errors of 0.2–2 % down to 0.02–0.2 %)."""
    details = _fit(1002, heavier(PENDULUM, 1.1), 0.0, 0)
    for name in ("joint1.armature", "joint2.damping"):  # the two the heavier links bias
        estimate, shift = details["params"][name], details["heavier_links"][name]
        error, corrected = abs(estimate / TRUTH[name] - 1), abs(estimate * (1 + shift) / TRUTH[name] - 1)
        assert error > 1e-3 and corrected < 0.3 * error, name


@pytest.mark.slow
@pytest.mark.statistical
def test_intervals_cover_the_truth_when_the_links_are_10_percent_off():
    """50 draws, the log made by the pendulum with links 10 % heavier (even draws) or lighter (odd):
    measured 0.935 of the 200 intervals hold the truth (the textbook ones: 0.265); 0.94 of the fits
    are called model-limited (median widening 26×). Band: ≥ 0.8 (the issue's bar)."""
    found = _coverage(lambda draw: heavier(PENDULUM, 1.1 if draw % 2 == 0 else 0.9), seed=1000)
    print(found)
    assert found["coverage"] >= 0.8
    assert found["textbook"] < 0.6  # the old intervals did not: the case is a real test
    assert found["model_limited"] >= 0.8


@pytest.mark.slow
@pytest.mark.statistical
def test_intervals_cover_the_truth_on_a_corrupted_log():
    """50 draws, the model right, the log corrupted: noise (1e-4 rad, 1e-2 rad/s), 2 % glitched rows
    and two 40 ms stalls (the driver repeating its last row; the problem leaves stalls out): measured
    0.96 of the 200 intervals hold the truth (the textbook ones: 0.96), 0.02 of the fits called
    model-limited. (Before stalls were left out they biased the estimate: textbook 0.62, reported 0.955,
    0.80 called model-limited.) Bands: coverage ≥ 0.8, at most 1 fit in 10 widened."""
    found = _coverage(PENDULUM, glitches=0.02, stalls=2, seed=2000)
    print(found)
    assert found["coverage"] >= 0.8
    assert found["model_limited"] <= 0.1


@pytest.mark.slow
@pytest.mark.statistical
def test_intervals_stay_narrow_on_a_glitched_log():
    """50 draws, the model right, noise and 2 % glitched rows (no stalls: nothing biases the estimate):
    measured 0.915 of the 200 intervals hold the truth (the textbook ones: the same), none of the fits
    called model-limited, the intervals the textbook's (median widening 1). Bands: coverage ≥ 0.8, at most
    1 fit in 10 widened."""
    found = _coverage(PENDULUM, glitches=0.02, seed=3000)
    print(found)
    assert found["coverage"] >= 0.8
    assert found["model_limited"] <= 0.1 and found["median_widening"] == 1.0
