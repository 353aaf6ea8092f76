"""The ``idkit`` command: a Hydra app composed from ``conf/`` and the plugin registry.

This module stays import-light on purpose: ``idkit --help`` must answer without importing torch,
so the app, the config source and every experiment are imported inside ``main``.
"""

from __future__ import annotations


def main() -> None:
    """Console-script entry point (``idkit = idkit.cli:main``)."""
    from idkit.cli.app import main as app_main

    app_main()
