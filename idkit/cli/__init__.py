"""The ``idkit`` command: a Hydra app composed from ``conf/`` and the plugin registry.

This module stays import-light on purpose: ``idkit --help`` must answer without importing torch,
so the app, the config source and every experiment are imported inside ``main``.
"""

from __future__ import annotations


def main() -> None:
    """Console-script entry point (``idkit = idkit.cli:main``)."""
    import os
    import sys

    from idkit.cli.app import main as app_main

    try:
        app_main()
        sys.stdout.flush()
    except BrokenPipeError:  # `idkit --help | head`: the reader left; say nothing more (Python docs' recipe)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        sys.exit(1)
