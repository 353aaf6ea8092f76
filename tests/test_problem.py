"""Samples validation, Problem helpers and the Estimate JSON contract."""

from __future__ import annotations

import json
import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit.estimate import Estimate
from idkit.interfaces import Robot
from idkit.problem import IdentificationError, Problem, Samples, resolve_dtype


def samples(n: int = 5, joints: int = 3) -> dict[str, torch.Tensor]:
    return {k: torch.ones(n, joints, dtype=torch.float64) for k in ("q", "qd", "qdd", "tau")}


def test_nan_is_reported_with_array_and_sample():
    arrays = samples()
    arrays["qd"][3, 1] = float("nan")
    with pytest.raises(ValueError, match=r"array 'qd' has a non-finite value \(nan\) at sample 3, joint 1"):
        Samples(**arrays)


def test_shape_mismatch_names_the_array():
    arrays = samples()
    arrays["tau"] = torch.ones(4, 3)
    with pytest.raises(ValueError, match=r"array 'tau' has shape \(4, 3\) but 'q' has \(5, 3\)"):
        Samples(**arrays)
    arrays["tau"] = torch.ones(5)
    with pytest.raises(ValueError, match="'tau' must be 2-D"):
        Samples(**arrays)


def test_arrays_become_float_tensors():
    s = Samples(q=[[1, 2]], qd=[[0, 0]], qdd=[[0, 0]], tau=[[1, 1]])
    assert s.q.dtype == torch.float64 and s.n_samples == 1 and s.n_joints == 2
    assert s.measured_matrix().shape == (2, 1)


def test_problem_checks_joint_count(cylindrical):
    with pytest.raises(ValueError, match="samples have 2 joints but robot CylindricalRobot has 3"):
        Problem(cylindrical, Samples(**samples(joints=2)))


def test_error_layout_and_evaluate(cylindrical, rng):
    q, qd, qdd = (torch.rand(6, 3, generator=rng, dtype=torch.float64) for _ in range(3))
    truth = cylindrical.nominal_params()
    tau = cylindrical.inverse_dynamics(truth, q, qd, qdd)
    from idkit.costs.paper import f1

    problem = Problem(cylindrical, Samples(q, qd, qdd, tau), cost=f1())
    params = torch.stack([truth, truth + 1])
    error = problem.error(params)
    assert error.shape == (2, 3, 6)
    torch.testing.assert_close(error[1], (tau - cylindrical.inverse_dynamics(truth + 1, q, qd, qdd)).T)
    cost = problem.evaluate(params)
    assert cost[0].item() == 0.0 and cost[1].item() > 0
    with pytest.raises(ValueError, match="no cost"):
        Problem(cylindrical, problem.samples).evaluate(truth)


def test_dtype_and_generator(cylindrical):
    problem = Problem(cylindrical, Samples(**samples()), seed=7, dtype="float32")
    assert problem.tensors().tau.dtype == torch.float32
    a = torch.rand(3, generator=problem.generator())
    assert torch.equal(a, torch.rand(3, generator=problem.generator()))
    with pytest.raises(ValueError, match="unknown dtype 'float16'"):
        resolve_dtype("float16")


@settings(max_examples=30, deadline=None)
@given(
    params=st.dictionaries(st.sampled_from(["m2", "m3", "s3z", "I"]), st.floats(allow_nan=False), min_size=1),
    cost=st.one_of(st.none(), st.floats(allow_nan=False, allow_infinity=False)),
    history=st.lists(st.floats(0, 1e6), max_size=5),
)
def test_estimate_json_round_trip(params, cost, history):
    details = {"history": torch.tensor(history, dtype=torch.float64)}
    estimate = Estimate("PSO-f13", params, cost, 0.01, details=details)
    back = Estimate.from_json(estimate.to_json())
    assert back.params == params and back.cost == cost  # infinities come back as floats
    assert back.details["history"] == history
    document = json.loads(estimate.to_json())  # strict JSON: no bare NaN/Infinity tokens
    assert all(isinstance(v, float) or v in ("Infinity", "-Infinity") for v in document["params"].values())


# --- options checked when a Problem is built ---------------------------------------------------


@pytest.mark.skipif(torch.cuda.is_available(), reason="needs a machine without CUDA")
def test_cuda_without_cuda_names_the_option_and_what_is_available(cylindrical):
    for device in ("cuda", "cuda:1"):
        with pytest.raises(ValueError) as err:
            Problem(cylindrical, Samples(**samples()), device=device)
        message = str(err.value)
        assert message.startswith(f"device {device!r} requested but CUDA is not available")
        assert "torch.cuda.is_available() is False" in message and message.endswith("available here: cpu")


def test_bad_device_dtype_and_seed_are_named(cylindrical):
    data = Samples(**samples())
    with pytest.raises(ValueError, match=r"^device 'gpu' is not a torch device name \(option device\)"):
        Problem(cylindrical, data, device="gpu")
    with pytest.raises(ValueError, match=r"^unknown dtype 'float16' \(option dtype\); use one of float64"):
        Problem(cylindrical, data, dtype="float16")
    with pytest.raises(ValueError, match=r"unknown dtype torch.int64"):
        Problem(cylindrical, data, dtype=torch.int64)
    with pytest.raises(ValueError, match=r"^seed must be an integer in \[0, 2\*\*64\), got 'abc' \(str\)$"):
        Problem(cylindrical, data, seed="abc")  # type: ignore[arg-type]
    typed = Problem(cylindrical, data, device=torch.device("cpu"), dtype=torch.float32)
    assert typed.torch_dtype == torch.float32


def test_too_few_equations_names_counts_and_remedy(cylindrical):
    problem = Problem(cylindrical, Samples(**samples(n=1)))  # building it is fine
    with pytest.raises(IdentificationError) as err:
        problem.check_identifiable()
    assert str(err.value) == (
        "robot CylindricalRobot: 1 sample × 3 joints = 3 equations < 4 base parameters; "
        "give at least 2 samples"
    )
    Problem(cylindrical, Samples(**samples(n=2))).check_identifiable()  # 6 equations >= 4


@given(st.integers(1, 6), st.integers(1, 12))
@settings(max_examples=40, deadline=None)
def test_identifiable_exactly_when_equations_cover_parameters(n_joints, n_params):
    class Toy(Robot):
        joint_names = tuple(f"j{i}" for i in range(n_joints))
        param_names = tuple(f"p{i}" for i in range(n_params))

        def bounds(self):
            return torch.zeros(n_params), torch.ones(n_params)

        def inverse_dynamics(self, params, q, qd, qdd):
            return q

    for n in range(1, n_params + 2):
        problem = Problem(Toy(), Samples(**samples(n=n, joints=n_joints)))
        if n * n_joints >= n_params:
            problem.check_identifiable()
        else:
            needed = math.ceil(n_params / n_joints)
            with pytest.raises(IdentificationError, match=f"give at least {needed} samples"):
                problem.check_identifiable()
