"""Seeds: every integer in [0, 2**64) is its own stream, the same seed the same numbers, others refused."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit import registry
from idkit.cli import errors
from idkit.options import OptionError, check_setting
from idkit.problem import Problem
from idkit.seeds import SEED_BOUND, Seed, check_seed, torch_generator, trial_seed

seeds = st.integers(0, SEED_BOUND - 1)
BOUNDARY = (0, 1, 2**32, 2**63, SEED_BOUND - 1)


def draws(seed: int, n: int = 4, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    return torch.rand(n, generator=torch_generator(seed), dtype=dtype)


@settings(max_examples=200, deadline=None)
@given(seed=seeds, other=seeds)
def test_distinct_seeds_distinct_streams_same_seed_same_numbers(seed, other):
    assert torch.equal(draws(seed), draws(seed))
    if seed != other:
        assert not torch.equal(draws(seed), draws(other))


@settings(max_examples=100, deadline=None)
@given(seed=seeds, bit=st.integers(32, 63))
def test_seeds_differing_only_in_high_bits_are_distinct(seed, bit):
    """torch's manual_seed keeps 32 bits (2**32 and 0 drew the same numbers); here every bit counts."""
    assert not torch.equal(draws(seed), draws(seed ^ (1 << bit)))


def test_boundary_values_are_accepted_and_distinct():
    streams = [draws(seed) for seed in BOUNDARY]
    for i, a in enumerate(streams):
        for b in streams[i + 1 :]:
            assert not torch.equal(a, b)
    assert [torch_generator(seed).initial_seed() for seed in BOUNDARY] == list(BOUNDARY)


@pytest.mark.parametrize("seed", [0, 12345, 2**63 + 7])
def test_cpu_stream_is_numpy_mt19937_from_the_seed_sequence(seed):
    """Independent reference: numpy's Mersenne Twister with the state words of ``SeedSequence(seed)``
    gives torch's float32 (24 bits of one word) and float64 (53 bits of two words) draws exactly."""
    twister = np.random.MT19937()
    state = twister.state
    state["state"] = {"key": np.random.SeedSequence(seed).generate_state(624, np.uint32), "pos": 624}
    twister.state = state
    raw = np.array([twister.random_raw() for _ in range(32)], dtype=np.uint64)
    expected32 = (raw[:16] & np.uint64(2**24 - 1)).astype(np.float64) * 2.0**-24
    np.testing.assert_array_equal(draws(seed, 16, torch.float32).double().numpy(), expected32)
    twister.state = state
    raw = np.array([twister.random_raw() for _ in range(32)], dtype=np.uint64)
    bits = ((raw[0::2] << np.uint64(32)) | raw[1::2]) & np.uint64(2**53 - 1)
    np.testing.assert_array_equal(draws(seed, 16).numpy(), bits.astype(np.float64) * 2.0**-53)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_generators_follow_the_seed():
    a, b = (torch.rand(4, generator=torch_generator(s, "cuda"), device="cuda") for s in (0, 2**63))
    assert not torch.equal(a, b)
    assert torch.equal(a, torch.rand(4, generator=torch_generator(0, "cuda"), device="cuda"))


@pytest.mark.parametrize("bad", [-1, SEED_BOUND, 2**70, True, np.bool_(False), 1.0, 1.5, "7", None])
def test_anything_else_is_refused_in_one_line(bad):
    with pytest.raises(ValueError, match=r"^seed must be an integer in \[0, 2\*\*64\), got ") as error:
        check_seed(bad)
    assert "\n" not in str(error.value)


def test_numpy_integers_are_seeds():
    assert check_seed(np.uint64(SEED_BOUND - 1)) == SEED_BOUND - 1
    assert torch.equal(draws(np.int64(5)), draws(5))


def test_problem_and_robot_seeds_are_checked(cylindrical):
    from idkit.data.scenarios import simulate

    samples = simulate(cylindrical, "clean", seed=SEED_BOUND - 1)
    assert Problem(cylindrical, samples, seed=np.int64(3)).seed == 3
    with pytest.raises(
        ValueError, match=r"^seed must be an integer in \[0, 2\*\*64\), got 18446744073709551616"
    ):
        Problem(cylindrical, samples, seed=SEED_BOUND)
    with pytest.raises(
        OptionError, match=r"^robot 'urdf' option 'seed' must be an int, got -1 .*2\*\*64 - 1$"
    ):
        registry.create("robot", "urdf", seed=-1)


def test_trial_seeds_wrap_and_stay_distinct():
    assert [trial_seed(SEED_BOUND - 2, t) for t in range(4)] == [SEED_BOUND - 2, SEED_BOUND - 1, 0, 1]


@pytest.mark.parametrize(
    ("value", "expected"), [("7", 7), (" 7 ", 7), (2**64 - 1, 2**64 - 1), ("18446744073709551615", 2**64 - 1)]
)
def test_a_config_seed_is_converted_like_an_int(value, expected):
    assert check_setting("seed", value, Seed) == expected


@pytest.mark.parametrize("value", [2**64, -1, True, 1e3, "1e3", "7.0", "-3"])
def test_a_config_seed_out_of_range_is_one_line(value):
    with pytest.raises(
        OptionError, match=r"^setting 'seed' must be an int, got .*; seeds are the integers 0 to"
    ):
        check_setting("seed", value, Seed)


def test_the_command_line_refuses_seed_2_to_the_64_in_one_line(tmp_path, run_idkit):
    status, said = run_idkit(f"seed={2**64}", f"hydra.run.dir={tmp_path / 'run'}")
    assert status == errors.USAGE
    assert said == [
        "idkit: setting 'seed' must be an int, got 18446744073709551616 (int); "
        "seeds are the integers 0 to 2**64 - 1"
    ]
