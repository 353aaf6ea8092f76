"""The base map as a kernel tape: which maps translate, that the tape computes the map, its cache."""

from __future__ import annotations

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit.costs import paper
from idkit.data.scenarios import simulate
from idkit.estimators.objective import Objective
from idkit.optim import base_map
from idkit.optim.base_map import Tape, cached_tape, identity, trace
from idkit.problem import Problem
from idkit.robots.cylindrical import CylindricalRobot


class _MatrixMap(CylindricalRobot):
    """A base map through a matmul: not an elementwise formula, so it is not translated."""

    def base_params(self, params: torch.Tensor) -> torch.Tensor:
        return params @ torch.eye(4, dtype=params.dtype)


def _formula(x: torch.Tensor) -> torch.Tensor:
    """Every tape operation once, constants included."""
    a, b, c = x.unbind(-1)
    return torch.stack([a * b - c / 2.5, torch.sin(a) + torch.cos(b), torch.sqrt(c) ** 2, -(a + 1.0)], dim=-1)


def test_elementwise_maps_translate_and_others_do_not():
    assert trace(CylindricalRobot().base_params, 4) is not None
    assert trace(_MatrixMap().base_params, 4) is None


@settings(max_examples=20, deadline=None)
@given(st.lists(st.floats(0.1, 5.0), min_size=3, max_size=3))
def test_the_tape_computes_the_traced_function(x):
    tape = trace(_formula, 3)
    point = torch.tensor([x], dtype=torch.float64)
    torch.testing.assert_close(tape(point), _formula(point), rtol=1e-15, atol=0)
    assert torch.equal(Tape.from_json(tape.to_json())(point), tape(point))


def test_the_robots_tape_equals_its_base_params():
    robot = CylindricalRobot()
    x = torch.rand(7, 4, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    torch.testing.assert_close(trace(robot.base_params, 4)(x), robot.base_params(x), rtol=0, atol=0)
    torch.testing.assert_close(identity(4)(x), x, rtol=0, atol=0)


def test_a_tape_is_cached_on_disk_as_data(tmp_path, monkeypatch):
    monkeypatch.setenv("IDKIT_CACHE_DIR", str(tmp_path))
    base_map.cache.directory.cache_clear()
    robot = CylindricalRobot()
    objective = Objective(Problem(robot, simulate(robot, "clean", seed=0)), [paper.f1()])
    tape = objective.spec().tape
    (file,) = [f for f in (tmp_path / "maps").glob("*.json") if f.name != "manifest.json"]
    assert tape is not None and Tape.from_json(file.read_text()).outputs.tolist() == tape.outputs.tolist()

    def no_tracing(*_):
        raise AssertionError("traced again despite the disk cache")

    monkeypatch.setattr(base_map, "trace", no_tracing)
    again = CylindricalRobot()  # a new object: not in the in-memory cache
    read, _ = cached_tape(again, again.base_params, 4, lambda: file.stem)
    assert read is not None and read.ops.tolist() == tape.ops.tolist()
    base_map.cache.directory.cache_clear()


def test_a_damaged_tape_file_is_traced_again_with_a_warning(tmp_path, monkeypatch):
    monkeypatch.setenv("IDKIT_CACHE_DIR", str(tmp_path))
    base_map.cache.directory.cache_clear()
    try:
        robot = CylindricalRobot()
        first, _ = cached_tape(robot, robot.base_params, 4, lambda: "key")
        (tmp_path / "maps" / "key.json").write_text("garbage")
        other = CylindricalRobot()
        with pytest.warns(base_map.cache.CacheWarning, match="damaged"):
            second, _ = cached_tape(other, other.base_params, 4, lambda: "key")
        assert second is not None and second.ops.tolist() == first.ops.tolist()
    finally:
        base_map.cache.directory.cache_clear()


def test_a_stale_or_altered_tape_is_detected_and_traced_again(tmp_path, monkeypatch):
    """A tape file that the manifest vouches for (so not damaged) but that computes another map — an
    older translation, or an edit — is checked against the map on a probe point and replaced."""
    monkeypatch.setenv("IDKIT_CACHE_DIR", str(tmp_path))
    base_map.cache.directory.cache_clear()
    try:
        robot = CylindricalRobot()
        first, _ = cached_tape(robot, robot.base_params, 4, lambda: "key")
        altered = Tape(first.ops, first.constants, first.outputs[::-1].copy())  # base parameters swapped
        folder, manifest = base_map.cache.prepared("maps")
        (folder / "key.json").write_text(altered.to_json())
        manifest.record()
        other = CylindricalRobot()
        with pytest.warns(base_map.cache.CacheWarning, match="disagrees with the map"):
            second, _ = cached_tape(other, other.base_params, 4, lambda: "key")
        assert second.ops.tolist() == first.ops.tolist() and second.outputs.tolist() == first.outputs.tolist()
        assert Tape.from_json((folder / "key.json").read_text()).outputs.tolist() == first.outputs.tolist()
    finally:
        base_map.cache.directory.cache_clear()


def test_the_disk_key_changes_with_idkit_and_the_translator(monkeypatch):
    import idkit
    from idkit.estimators.objective import _map_key

    robot = CylindricalRobot()
    before = _map_key(robot, 4)
    monkeypatch.setattr(idkit, "_version", lambda: "999.0")
    assert _map_key(robot, 4) not in (None, before)
