"""The ``idkit`` command: a Hydra app composed from ``conf/`` and the plugin registry.

This module stays import-light on purpose: ``idkit --help`` must answer without importing torch,
so the app, the config source and every experiment are imported inside ``main``.
"""

from __future__ import annotations

#: Exit status after Ctrl-C (128 + SIGINT), as shells report it.
INTERRUPTED = 130


def main() -> None:
    """Console-script entry point (``idkit = idkit.cli:main``)."""
    import os
    import sys

    try:
        from idkit.cli.app import main as app_main

        app_main()
        sys.stdout.flush()
    except KeyboardInterrupt:  # outside a task (which says what it wrote): importing, composing the config
        print("idkit: interrupted", file=sys.stderr)
        sys.exit(INTERRUPTED)
    except BrokenPipeError:  # `idkit --help | head`: the reader left; say nothing more (Python docs' recipe)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        sys.exit(1)
