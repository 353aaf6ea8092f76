"""Sampling instants of the scenarios (the trajectories themselves: tests/excitation/)."""

from __future__ import annotations

import pytest
import torch

from idkit.data.trajectory import sample_times


def test_sample_times_uniform_period_ending_at_t_end():
    assert sample_times(10).tolist() == [float(i) for i in range(1, 11)]
    torch.testing.assert_close(sample_times(20), torch.arange(1, 21, dtype=torch.float64) / 2)
    assert sample_times(1, t_end=3.0).tolist() == [3.0]
    with pytest.raises(ValueError, match="n_samples"):
        sample_times(0)
    with pytest.raises(ValueError, match="t_end"):
        sample_times(5, t_end=0.0)
