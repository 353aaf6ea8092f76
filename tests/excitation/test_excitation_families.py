"""The ``paper`` and ``fourier`` excitations: eq. (39), exact derivatives, periodicity, batching,
the robots' defaults (unchanged numbers), and errors."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit.data.scenarios import clean_samples
from idkit.excitation.fourier import FourierExcitation
from idkit.excitation.paper import PaperExcitation
from idkit.interfaces import Robot
from idkit.registry import create
from idkit.robots.urdf import URDFRobot


def paper_numpy(t: np.ndarray) -> np.ndarray:
    """Eq. (39) typed in again from the paper: ``[N, 3]``."""
    s = np.sin
    return np.stack(
        (
            0.43 * s(2.2 * t) + 0.23 * s(1.8 * t) - 3.4 * s(0.06 * t) - 0.36,
            s(0.1 * t) - 0.3 * s(0.07 * t) + 0.35 * s(1.3 * t) - 0.014,
            0.1 * s(0.1 * t) - 0.1 * s(2.7 * t) + 0.06 * s(0.14 * t) + 0.26,
        ),
        axis=1,
    )


def golden_numpy(t: np.ndarray, n_joints: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """idkit's default series before excitations became plugins: ``sum_k (0.5/k) sin(k w t + phi_jk)``."""
    golden = (math.sqrt(5.0) - 1.0) / 2.0
    k = np.arange(1, 6)
    w = 2 * math.pi / 10.0 * k
    phase = 2 * math.pi * np.modf(np.arange(1, n_joints + 1)[:, None] * k * golden)[0]  # [n, K]
    angle = t[:, None, None] * w + phase  # [T, n, K]
    amplitude = 0.5 / k
    return (
        (amplitude * np.sin(angle)).sum(-1),
        (amplitude * w * np.cos(angle)).sum(-1),
        -(amplitude * w**2 * np.sin(angle)).sum(-1),
    )


def random_fourier(
    n_joints: int, harmonics: int, period: float, seed: int, rest: bool = False
) -> FourierExcitation:
    g = torch.Generator().manual_seed(seed)
    a, b = torch.randn(2, n_joints, harmonics, generator=g, dtype=torch.float64)
    offset = torch.randn(n_joints, generator=g, dtype=torch.float64)
    return FourierExcitation(n_joints, harmonics, period, offset.tolist(), a.tolist(), b.tolist(), rest)


FAMILIES = {
    "paper": PaperExcitation(),
    "fourier-default": FourierExcitation(3),
    "fourier-random": random_fourier(7, 3, 4.0, seed=1),
    "fourier-rest": random_fourier(7, 5, 10.0, seed=2, rest=True),
}


def autograd_derivatives(excitation, t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """d/dt and d²/dt² of ``q[T, n]`` by autograd; rows depend only on their own t."""
    t = t.clone().requires_grad_(True)
    q = excitation(t)[0]
    n = q.shape[1]
    first = torch.stack([torch.autograd.grad(q[:, j].sum(), t, create_graph=True)[0] for j in range(n)], 1)
    second = torch.stack(
        [torch.autograd.grad(first[:, j].sum(), t, retain_graph=True)[0] for j in range(n)], 1
    )
    return first.detach(), second.detach()


def test_paper_is_the_printed_equation_39():
    t = np.linspace(0.0, 10.0, 101)
    q, _, _ = PaperExcitation()(torch.from_numpy(t))
    np.testing.assert_allclose(q.numpy(), paper_numpy(t), rtol=0, atol=1e-14)


@pytest.mark.parametrize("name", FAMILIES)
def test_derivatives_match_autograd(name):
    t = torch.linspace(0.0, 10.0, 57, dtype=torch.float64)
    _, qd, qdd = FAMILIES[name](t)
    first, second = autograd_derivatives(FAMILIES[name], t)
    torch.testing.assert_close(qd, first, rtol=0, atol=1e-12)
    torch.testing.assert_close(qdd, second, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", FAMILIES)
def test_derivatives_match_central_differences(name):
    excitation, h = FAMILIES[name], 1e-4
    t = torch.linspace(0.3, 9.7, 41, dtype=torch.float64)
    q_plus, qd_plus, _ = excitation(t + h)
    q_minus, qd_minus, _ = excitation(t - h)
    q, qd, qdd = excitation(t)
    # O(h²) accurate: |error| <= h²/6 · max|q'''| (at most ~1e-6 for these series).
    scale = 1 + qdd.abs().max()
    torch.testing.assert_close((q_plus - q_minus) / (2 * h), qd, rtol=0, atol=1e-6 * scale)
    torch.testing.assert_close((qd_plus - qd_minus) / (2 * h), qdd, rtol=0, atol=1e-6 * scale)


@given(
    n_joints=st.integers(1, 4),
    harmonics=st.integers(1, 4),
    period=st.floats(0.5, 20.0),
    seed=st.integers(0, 2**31),
    start=st.floats(-50.0, 50.0),
)
@settings(max_examples=30, deadline=None)
def test_fourier_is_periodic(n_joints, harmonics, period, seed, start):
    excitation = random_fourier(n_joints, harmonics, period, seed)
    t = start + torch.linspace(0.0, period, 17, dtype=torch.float64)
    for a, b in zip(excitation(t), excitation(t + period), strict=True):
        scale = 1 + a.abs().max()
        torch.testing.assert_close(a, b, rtol=0, atol=1e-12 * scale * (1 + abs(start) / period))
    # Start and end of one period are the same state.
    ends = excitation(torch.tensor([start, start + period], dtype=torch.float64))
    for x in ends:
        torch.testing.assert_close(x[0], x[1], rtol=0, atol=1e-12 * (1 + x.abs().max()) * (1 + abs(start)))


@given(
    n_joints=st.integers(1, 4),
    harmonics=st.integers(2, 6),
    period=st.floats(0.5, 30.0),
    seed=st.integers(0, 2**31),
    periods=st.integers(0, 3),
)
@settings(max_examples=40, deadline=None)
def test_fourier_at_rest_starts_and_ends_every_period_at_rest(n_joints, harmonics, period, seed, periods):
    excitation = random_fourier(n_joints, harmonics, period, seed, rest=True)
    _, qd, qdd = excitation(
        torch.tensor([0.0, periods * period, (periods + 0.37) * period], dtype=torch.float64)
    )
    scale = float(excitation.to_vector().abs().max()) * harmonics * (1 + 2 * math.pi * harmonics / period)
    assert qd[:2].abs().max() <= 1e-14 * scale * (1 + periods) and qdd[:2].abs().max() <= 1e-14 * scale * (
        1 + periods
    )
    assert qd[2].abs().max() > 1e-6 * scale  # it does move in between


def test_fourier_at_rest_computes_two_coefficients_and_keeps_the_others():
    free = random_fourier(2, 4, 6.0, seed=3)
    rest = FourierExcitation(
        2, 4, 6.0, free.options()["offset"], free.options()["a"], free.options()["b"], True
    )
    a, b = (torch.tensor(rest.options()[k], dtype=torch.float64) for k in ("a", "b"))
    a0, b0 = (torch.tensor(free.options()[k], dtype=torch.float64) for k in ("a", "b"))
    torch.testing.assert_close(a[:, :3], a0[:, :3], rtol=0, atol=0)
    torch.testing.assert_close(b[:, 1:], b0[:, 1:], rtol=0, atol=0)
    torch.testing.assert_close(a.sum(1), torch.zeros(2, dtype=torch.float64), rtol=0, atol=1e-14)
    torch.testing.assert_close(
        (b * torch.arange(1, 5)).sum(1), torch.zeros(2, dtype=torch.float64), rtol=0, atol=1e-14
    )
    assert rest.options()["rest"] is True and free.options()["rest"] is False
    # Scaling a joint's motion (what the optimiser's limit fitting does) keeps it at rest.
    scaled = rest.from_vector(torch.cat((rest.to_vector()[:2], 0.3 * rest.to_vector()[2:])))
    _, qd, qdd = scaled(torch.tensor([0.0, 6.0], dtype=torch.float64))
    assert qd.abs().max() < 1e-14 and qdd.abs().max() < 1e-13


@pytest.mark.parametrize("name", FAMILIES)
@pytest.mark.parametrize("batch", [(), (2,), (2, 3)])
def test_evaluate_is_batched_over_coefficient_sets(name, batch):
    excitation = FAMILIES[name]
    g = torch.Generator().manual_seed(7)
    vector = excitation.to_vector()
    coefficients = vector + 0.1 * torch.randn(*batch, vector.numel(), generator=g, dtype=torch.float64)
    t = torch.linspace(0.0, 10.0, 9, dtype=torch.float64)
    out = excitation.evaluate(coefficients, t)
    assert [x.shape for x in out] == [(*batch, 9, excitation.n_joints)] * 3
    flat = coefficients.reshape(-1, vector.numel())
    for i, row in enumerate(flat):
        single = excitation.from_vector(row)(t)
        for x, y in zip(out, single, strict=True):
            torch.testing.assert_close(x.reshape(-1, 9, excitation.n_joints)[i], y, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("name", FAMILIES)
def test_vector_round_trip_and_float32(name):
    excitation = FAMILIES[name]
    again = excitation.from_vector(excitation.to_vector())
    assert again.options() == excitation.options()
    t = torch.linspace(0.0, 10.0, 5, dtype=torch.float32)
    assert all(x.dtype == torch.float32 and x.shape == (5, excitation.n_joints) for x in excitation(t))


def test_default_fourier_keeps_the_previous_numbers():
    """The default series is the old golden-ratio series; only rounding differs (≤ 2e-15 relative).

    Not bit-identical: the old code added the phase to angles of up to 37 rad before the sine,
    the Fourier form expands ``sin(x + phi)`` in ``sin x``, ``cos x``; both round differently.
    """
    t = np.linspace(0.0, 10.0, 2001)  # the scenarios' window
    for n in (1, 3, 7):
        for new, old in zip(FourierExcitation(n)(torch.from_numpy(t)), golden_numpy(t, n), strict=True):
            np.testing.assert_allclose(new.numpy(), old, rtol=0, atol=2e-15 * np.abs(old).max())


class Point(Robot):
    joint_names = ("a", "b")
    param_names = ("m",)

    def bounds(self):
        return torch.zeros(1), torch.ones(1)

    def inverse_dynamics(self, params, q, qd, qdd):
        return params[..., 0, None, None] * qdd


def test_robot_defaults_come_from_the_registry(cylindrical):
    assert isinstance(cylindrical.default_excitation(), PaperExcitation)
    assert cylindrical.default_excitation().options() == create("excitation", "paper").options()
    default = Point().default_excitation()
    assert isinstance(default, FourierExcitation) and default.options() == FourierExcitation(2).options()
    t = torch.linspace(0.5, 10.0, 7, dtype=torch.float64)
    for a, b in zip(cylindrical.excitation(t), PaperExcitation()(t), strict=True):
        assert torch.equal(a, b)


def test_simulated_samples_keep_the_previous_numbers(cylindrical):
    """Clean samples as before the move: eq. (39) bit for bit, the URDF default within 2e-15 relative."""
    t_np = np.arange(1, 21) / 2.0
    t, clean = clean_samples(cylindrical, 20)
    np.testing.assert_array_equal(t.numpy(), t_np)
    np.testing.assert_allclose(clean.q.numpy(), paper_numpy(t_np), rtol=0, atol=1e-14)
    robot = URDFRobot("cylindrical")
    states = [torch.from_numpy(x) for x in golden_numpy(t_np, 3)]
    tau_old = robot.inverse_dynamics(robot.nominal_params(), *states)
    _, clean = clean_samples(robot, 20)
    for new, old in zip((clean.q, clean.qd, clean.qdd, clean.tau), (*states, tau_old), strict=True):
        torch.testing.assert_close(new, old, rtol=0, atol=2e-15 * float(old.abs().max()))


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"n_joints": 0}, "n_joints must be an integer >= 1"),
        ({"n_joints": 2, "harmonics": 1.5}, "harmonics must be an integer"),
        ({"n_joints": 2, "period": 0.0}, "period must be a finite number > 0"),
        ({"n_joints": 2, "a": [[1.0] * 5] * 2}, "give both a and b"),
        (
            {"n_joints": 2, "a": [[1.0] * 4] * 2, "b": [[1.0] * 4] * 2},
            r"a: expected shape \[2, 5\], got \[2, 4\]",
        ),
        ({"n_joints": 2, "offset": [0.0, math.nan]}, "offset: every value must be finite"),
        ({"n_joints": 2, "harmonics": 1, "rest": True}, "rest=true needs harmonics >= 2"),
        ({"n_joints": 2, "rest": "yes"}, "rest must be true or false"),
    ],
)
def test_fourier_rejects_bad_options(options, match):
    with pytest.raises(ValueError, match=match):
        FourierExcitation(**options)


def test_paper_and_fourier_reject_bad_coefficient_vectors():
    with pytest.raises(ValueError, match=r"paper excitation: coefficients must be \[\.\.\., 12\]"):
        PaperExcitation().evaluate(torch.zeros(11, dtype=torch.float64), torch.zeros(3))
    with pytest.raises(ValueError, match=r"fourier excitation: coefficients must be \[\.\.\., 33\]"):
        FourierExcitation(3).from_vector(torch.zeros(30))
    with pytest.raises(ValueError, match="amplitude: expected shape"):
        PaperExcitation(amplitude=[[1.0, 2.0]] * 3)


LOAD_DEFAULTS = """
import sys
import torch
from idkit import registry
from idkit.robots.cylindrical import CylindricalRobot

CylindricalRobot().excitation(torch.ones(2))
registry.create("excitation", "fourier", n_joints=2)
study = ("idkit.data", "idkit.excitation.optimize", "idkit.estimators")
print(registry.available("excitation"), sorted(m for m in sys.modules if m.startswith(study)))
"""


def test_registered_and_light_to_load():
    """Both built-ins are registered; loading them (as a robot's default does) imports no study code."""
    out = subprocess.run([sys.executable, "-c", LOAD_DEFAULTS], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "['fourier', 'paper'] []"
