"""Fixtures of the command-line tests."""

from __future__ import annotations

import pytest
from hydra import compose, initialize_config_module
from hydra.core.global_hydra import GlobalHydra

from idkit.cli.app import setup


@pytest.fixture
def hydra_compose():
    """``compose(overrides)`` over idkit's primary config with the registry source registered."""
    setup()
    GlobalHydra.instance().clear()
    with initialize_config_module(config_module="idkit.conf", version_base="1.3"):

        def _compose(*overrides: str, hydra_cfg: bool = False):
            return compose("config", overrides=list(overrides), return_hydra_config=hydra_cfg)

        yield _compose
    GlobalHydra.instance().clear()
