"""Registry behaviour: discovery without import, lazy cached loading, actionable errors."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from idkit import registry


def make_distribution(root: Path, name: str, entry_points: str, modules: dict[str, str]) -> None:
    """Write an installed-looking distribution (dist-info + modules) into ``root``."""
    info = root / f"{name}-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(textwrap.dedent(entry_points))
    for module, source in modules.items():
        (root / f"{module}.py").write_text(textwrap.dedent(source))


@pytest.fixture
def extra_path(tmp_path, monkeypatch):
    """A sys.path entry for test distributions; the registry cache is reset around each test."""
    monkeypatch.syspath_prepend(str(tmp_path))
    registry.refresh()
    yield tmp_path
    monkeypatch.undo()
    registry.refresh()


def test_builtins_are_registered_through_entry_points():
    assert {f"f{i}" for i in range(1, 17)} <= set(registry.available("cost"))
    assert "cylindrical" in registry.available("robot")
    meta = registry.info("robot", "cylindrical")
    assert meta.distribution == "robot-idkit"
    assert meta.value == "idkit.robots.cylindrical:CylindricalRobot"


def test_names_are_naturally_sorted():
    costs = [c for c in registry.available("cost") if c[0] == "f" and c[1:].isdigit()]
    assert costs == sorted(costs, key=lambda c: int(c[1:]))


def test_listing_does_not_import_plugin_modules():
    code = (
        "import sys; from idkit import registry; registry.available('cost'); "
        "registry.available('robot'); registry.available('estimator'); "
        "print(sorted(m for m in sys.modules if m.startswith('idkit.') or m == 'torch'))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "['idkit.options', 'idkit.registry']"  # no plugin, no torch


def test_load_is_cached_and_create_passes_options():
    assert registry.load("cost", "f13") is registry.load("cost", "f13")
    cost = registry.create("cost", "f13", floor=0.01)
    assert cost.floor == 0.01


def test_unknown_name_lists_available_closest_first():
    with pytest.raises(registry.UnknownPluginError) as err:
        registry.load("cost", "f133")
    message = str(err.value)
    assert "unknown cost 'f133'" in message
    listed = message.split("closest first): ")[1].split(", ")
    assert listed[0] == "f13"
    assert set(listed) == set(registry.available("cost"))


def test_unknown_kind():
    with pytest.raises(registry.UnknownPluginError, match="the kinds are robot, estimator, cost"):
        registry.available("optimizer")  # type: ignore[arg-type]


def test_bad_constructor_options_name_the_plugin():
    with pytest.raises(
        registry.OptionError, match=r"^cost 'f13' has no option 'flor'; its options \(closest first\): floor$"
    ):
        registry.create("cost", "f13", flor=0.1)


def test_broken_plugin_is_reported_and_others_still_work(extra_path):
    make_distribution(
        extra_path,
        "broken-idkit-plugin",
        """
        [idkit.costs]
        broken = broken_idkit_plugin:BrokenCost
        """,
        {"broken_idkit_plugin": "raise ImportError('needs libfoo')\n"},
    )
    assert "broken" in registry.available("cost")  # listed without importing
    with pytest.raises(registry.PluginLoadError) as err:
        registry.load("cost", "broken")
    message = str(err.value)
    assert "broken_idkit_plugin:BrokenCost" in message
    assert "broken-idkit-plugin 0.1" in message
    assert "needs libfoo" in message
    assert registry.create("cost", "f1") is not None


def test_third_party_plugin_is_found_by_installing_only(extra_path):
    make_distribution(
        extra_path,
        "tiny-idkit-plugin",
        """
        [idkit.costs]
        tiny = tiny_idkit_plugin:Tiny
        """,
        {
            "tiny_idkit_plugin": """
            from idkit.interfaces import Cost

            class Tiny(Cost):
                def __init__(self, scale: float = 1.0):
                    self.scale = scale

                def __call__(self, error, measured):
                    return self.scale * error.abs().sum(dim=(-2, -1))
            """
        },
    )
    cost = registry.create("cost", "tiny", scale=2.0)
    assert registry.info("cost", "tiny").distribution == "tiny-idkit-plugin"
    import torch

    assert cost(torch.ones(2, 3, 4), torch.ones(3, 4)).tolist() == [24.0, 24.0]


def test_same_name_from_two_distributions_is_an_error(extra_path):
    make_distribution(
        extra_path,
        "clashing-idkit-plugin",
        """
        [idkit.costs]
        f13 = clashing:F13
        """,
        {"clashing": ""},
    )
    with pytest.raises(registry.DuplicatePluginError) as err:
        registry.available("cost")
    assert "robot-idkit" in str(err.value) and "clashing-idkit-plugin" in str(err.value)
    assert registry.available("robot")  # other groups unaffected
