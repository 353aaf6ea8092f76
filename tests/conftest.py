"""Shared fixtures."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

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
