"""The plugins arrive through entry points only, and leave without a trace when uninstalled."""

from __future__ import annotations

import subprocess
import sys
from importlib.metadata import distribution

import pytest
from idkit import registry

DISTRIBUTION = "idkit-robust"
GROUPS = {"idkit.robots": "robot", "idkit.costs": "cost", "idkit.estimators": "estimator"}
#: What the installed metadata of this distribution declares.
OURS = {(GROUPS[ep.group], ep.name) for ep in distribution(DISTRIBUTION).entry_points if ep.group in GROUPS}


def test_every_name_comes_from_this_distribution():
    assert {("robot", "planar2"), ("cost", "huber"), ("cost", "trimmed"), ("estimator", "irls")} == OURS
    for kind, name in OURS:
        assert name in registry.available(kind)
        info = registry.info(kind, name)
        assert info.distribution == DISTRIBUTION
        assert registry.load(kind, name).__module__.startswith("idkit_robust.")


@pytest.fixture
def uninstalled(monkeypatch):
    """The registry as it is once this distribution's metadata is gone (what pip uninstall does)."""
    real = registry.entry_points

    def without_us(**selection):
        return [ep for ep in real(**selection) if ep.dist is None or ep.dist.metadata["Name"] != DISTRIBUTION]

    monkeypatch.setattr(registry, "entry_points", without_us)
    registry.refresh()
    yield
    monkeypatch.undo()
    registry.refresh()


def test_uninstalling_removes_the_names_and_nothing_else(uninstalled):
    for kind, name in OURS:
        assert name not in registry.available(kind)
        with pytest.raises(registry.UnknownPluginError, match=f"unknown {kind} '{name}'"):
            registry.load(kind, name)
    assert "cylindrical" in registry.available("robot") and "f13" in registry.available("cost")
    registry.create("robot", "cylindrical")  # the core still loads


def test_idkit_never_imports_this_package():
    """Loading every other plugin and the conformance suite leaves ``idkit_robust`` unimported,
    so removing it cannot break anything else."""
    code = (
        "import sys\n"
        "from idkit import registry\n"
        "import idkit.testing\n"
        f"ours = {sorted(OURS)!r}\n"
        "for kind in ('robot', 'cost', 'estimator'):\n"
        "    for name in registry.available(kind):\n"
        "        if (kind, name) not in ours:\n"
        "            try:\n"
        "                registry.load(kind, name)\n"
        "            except registry.PluginLoadError:\n"
        "                pass  # another package's problem; not ours to judge here\n"
        "print(sorted(m for m in sys.modules if m.startswith('idkit_robust')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
