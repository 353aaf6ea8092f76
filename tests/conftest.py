"""Shared fixtures."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest
import torch

# The suite runs many tiny tensor programs: on a 2-core machine torch's default intra-op threading
# makes them slower and erratic (see bench/ for measured thread effects). Speed is not asserted here.
torch.set_num_threads(1)

# idkit's cache (the fast kernel's machine code, base-map tapes) in a folder of the system's temporary
# directory, never ~/.cache: set before idkit.optim imports numba, and inherited by the CLI processes
# tests start. Kept across sessions (the kernel compiles once); idkit refuses it should another
# user own it or be able to write it.
os.environ["IDKIT_CACHE_DIR"] = str(Path(tempfile.gettempdir()) / f"idkit-tests-{os.getuid()}")

REPO = Path(__file__).resolve().parents[1]
KUKA_DIR = REPO.parent / "shared" / "data" / "kuka-lwr4"


@pytest.fixture
def cylindrical():
    from idkit.robots.cylindrical import CylindricalRobot

    return CylindricalRobot()


@pytest.fixture
def rng() -> torch.Generator:
    return torch.Generator().manual_seed(1234)


@pytest.fixture
def kuka_dir() -> Path:
    if not (KUKA_DIR / "measurements_1.npz").exists():
        pytest.skip(f"KUKA LWR4+ recordings not found in {KUKA_DIR} (they are not part of this repo)")
    return KUKA_DIR


@pytest.fixture
def hydra_compose():
    """``compose(overrides)`` over idkit's primary config with the registry source registered."""
    from hydra import compose, initialize_config_module
    from hydra.core.global_hydra import GlobalHydra

    from idkit.cli.app import setup

    setup()
    GlobalHydra.instance().clear()
    with initialize_config_module(config_module="idkit.conf", version_base="1.3"):

        def _compose(*overrides: str, hydra_cfg: bool = False):
            return compose("config", overrides=list(overrides), return_hydra_config=hydra_cfg)

        yield _compose
    GlobalHydra.instance().clear()


@pytest.fixture
def run_idkit(monkeypatch, capsys):
    """``run(*overrides) -> (exit status, stderr lines)`` of the ``idkit`` command, in process."""
    import sys

    from hydra.core.global_hydra import GlobalHydra

    from idkit.cli import app

    def _run(*overrides: str) -> tuple[int, list[str]]:
        monkeypatch.setattr(sys, "argv", ["idkit", *overrides])
        monkeypatch.delenv(app.FULL_ERROR, raising=False)
        GlobalHydra.instance().clear()
        try:
            app.main()
            status = 0
        except SystemExit as exit_:
            status = exit_.code
        finally:
            GlobalHydra.instance().clear()
        return status, capsys.readouterr().err.strip().splitlines()

    return _run
