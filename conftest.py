"""Test-session set-up shared by idkit's suite and the plugin's: caches go to a temporary folder.

Why here (the repository root): pytest loads this file before it collects ``tests/`` or
``plugins/idkit-robust/tests``, so every cache — idkit's compiled kernels, matplotlib's font cache,
anything that follows the XDG convention — lands in one folder made for this session and removed
after it, never in the user's real ``~/.cache``. Subprocesses (the command-line tests) inherit it.
"""

from __future__ import annotations

import os
import shutil
import tempfile

_CACHE = tempfile.mkdtemp(prefix="idkit-test-cache-")
for _name, _sub in (("XDG_CACHE_HOME", ""), ("IDKIT_CACHE_DIR", "idkit"), ("MPLCONFIGDIR", "matplotlib")):
    os.environ[_name] = os.path.join(_CACHE, _sub)


def pytest_unconfigure(config) -> None:
    shutil.rmtree(_CACHE, ignore_errors=True)
