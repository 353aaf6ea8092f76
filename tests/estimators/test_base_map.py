"""The base map translated to C: which maps translate, and that both kernel paths agree."""

from __future__ import annotations

import pytest
import torch

from idkit.costs import paper
from idkit.data.scenarios import simulate
from idkit.estimators import native
from idkit.estimators.base_map import map_source
from idkit.estimators.pso import ParticleSwarm
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot


class _MatrixMap(CylindricalRobot):
    """A base map through a matmul: not an elementwise formula, so it is not translated."""

    def base_params(self, params: torch.Tensor) -> torch.Tensor:
        return params @ torch.eye(4, dtype=params.dtype)


def test_elementwise_maps_translate_and_others_do_not():
    source = map_source(CylindricalRobot(), 4)
    assert source is not None and "alpha[3]" in source and "x[2]" in source
    assert map_source(_MatrixMap(), 4) is None


@pytest.mark.skipif(native.kernel()[0] is None, reason="no C compiler for the native kernel")
def test_kernel_map_and_torch_map_give_the_same_estimate(monkeypatch):
    robot = CylindricalRobot()
    problem = Problem(robot, simulate(robot, "all_noise", seed=2), paper.f13(), seed=4)
    pso = ParticleSwarm(runs=3, particles=6, iterations=20, history=False)
    in_c = pso.fit(problem)
    monkeypatch.setattr(native, "robot_map", lambda objective: None)  # base map in torch, move by move
    in_torch = pso.fit(problem)
    assert in_c.details["engine"] == in_torch.details["engine"] == "native"
    assert in_c.params == pytest.approx(in_torch.params, rel=1e-9)


def test_translated_map_is_cached_on_disk(tmp_path, monkeypatch):
    from idkit.estimators.objective import Objective

    monkeypatch.setenv("IDKIT_CACHE_DIR", str(tmp_path))
    robot = CylindricalRobot()
    objective = Objective(Problem(robot, simulate(robot, "clean", seed=0)), [paper.f1()])
    source = native.robot_map(objective)
    cached = [f.read_text() for f in (tmp_path / "native" / "maps").glob("*.c")]
    assert source is not None and cached == [source]

    def no_tracing(*_):
        raise AssertionError("traced again despite the disk cache")

    monkeypatch.setattr(native, "map_source", no_tracing)
    again = CylindricalRobot()  # a new object: not in the in-memory cache
    problem = Problem(again, simulate(again, "clean", seed=0))
    assert native.robot_map(Objective(problem, [paper.f1()])) == source
