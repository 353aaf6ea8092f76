"""idkit's on-disk cache: one directory that only its owner can write, and entries checked on load.

Why: the fast engine's compiled machine code (numba's cache) and the base-map translations are read
back by later processes. Code loaded from a place that others can write runs their code, and a
damaged entry must not turn into a traceback on every fit or a silent slow path. So:

- the directory is ``IDKIT_CACHE_DIR`` or the platform's user cache directory
  (``platformdirs.user_cache_dir("idkit")``), created with mode 0700;
- a directory that is group- or world-writable, or owned by another user, is refused: one warning
  line says why and how to fix it, and this process keeps its cache in a private temporary
  directory instead (nothing is read from the refused one);
- every file written through ``Manifest`` is recorded with its SHA-256; before anything is read, a
  file whose hash does not match is removed, with one warning, and rebuilt by whoever needs it;
- several processes share the cache (a sweep's jobs): the manifest is read, checked and written
  under a file lock, and a writer holds it from its write to its record, so no process sees
  another's half-recorded entry. A file the manifest does not know yet is left alone: another
  process may be about to record it (writes are atomic renames, so it is whole), and its reader
  checks it anyway (numba's index, a base-map tape's probe).
"""

from __future__ import annotations

import atexit
import contextlib
import hashlib
import json
import os
import shutil
import stat
import tempfile
import warnings
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import filelock

#: Environment variable that overrides the cache's root directory.
ENVIRONMENT = "IDKIT_CACHE_DIR"
#: The manifest's file name inside each cache part.
MANIFEST = "manifest.json"
#: The lock held while the manifest is read, checked or written (never removed: see ``clear``).
LOCK = "manifest.lock"


class CacheWarning(UserWarning):
    """The cache was refused, damaged or could not be written; what idkit did instead."""


def root() -> Path:
    """The configured cache root: ``IDKIT_CACHE_DIR`` or ``platformdirs.user_cache_dir("idkit")``."""
    configured = os.environ.get(ENVIRONMENT)
    if configured:
        return Path(configured)
    import platformdirs

    return Path(platformdirs.user_cache_dir("idkit", appauthor=False))


def refusal(path: Path) -> str | None:
    """Why ``path`` (an existing directory) is unsafe to load code from, or ``None``.

    Unsafe: owned by another user, or writable by its group or by everyone. On systems without
    POSIX owners (Windows) only the existence is checked.
    """
    info = path.stat()
    if not stat.S_ISDIR(info.st_mode):
        return f"{path} is not a directory"
    if hasattr(os, "getuid") and info.st_uid != os.getuid():
        return f"{path} is owned by another user (uid {info.st_uid})"
    if os.name == "posix" and info.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        who = "everyone" if info.st_mode & stat.S_IWOTH else "its group"
        return f"{path} is writable by {who} (mode {stat.S_IMODE(info.st_mode):o})"
    return None


@cache
def directory(part: str) -> Path:
    """The checked directory of one cache part (``root() / part``), created 0700 where missing.

    A refused root or part (``refusal``), or one that cannot be created, gives one
    ``CacheWarning`` and a private temporary directory for this process instead.
    """
    path = root() / part
    try:
        for folder in (root(), path):
            folder.mkdir(mode=0o700, parents=True, exist_ok=True)
            why = refusal(folder)
            if why is not None:
                return _private(part, f"{why}; fix it with `chmod 700` or set {ENVIRONMENT}")
    except OSError as error:
        return _private(part, f"cannot create {path}: {error.strerror or error}")
    return path


def _private(part: str, why: str) -> Path:
    """A temporary 0700 directory for this process (removed at exit), after warning ``why``."""
    warnings.warn(
        f"idkit's cache directory is refused: {why}; using a private temporary cache for this run",
        CacheWarning,
        stacklevel=3,
    )
    path = Path(tempfile.mkdtemp(prefix=f"idkit-{part}-"))
    atexit.register(shutil.rmtree, path, ignore_errors=True)
    return path


def digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


class Manifest:
    """What one cache directory holds: the sources its entries were built from, and the SHA-256
    of every file (its ``manifest.json``).

    ``check`` runs before anything in the folder is read: entries built from other sources are
    removed (an update of idkit), and so is every file whose hash does not match — with one
    ``CacheWarning``, since that is damage. A file it does not know is left for its writer to
    record (module doc). ``record`` adds what a build wrote. Both hold ``locked()``, as a writer
    does from its write to its ``record``. The manifest lives in the same owner-only directory: it
    guards against damage (a full disk, garbage), the directory's mode against other users.
    """

    def __init__(self, folder: Path, sources: str = "") -> None:
        import filelock

        self.folder = folder
        self.file = folder / MANIFEST
        self.sources = sources
        self._lock = filelock.FileLock(folder / LOCK)  # re-entrant: record() inside locked() is fine

    def locked(self) -> filelock.FileLock:
        """The folder's lock, for ``with``: hold it from a write to its ``record``, so that another
        process's ``check`` never sees the new file with the old manifest."""
        return self._lock

    def _read(self) -> dict | None:
        """The manifest's content; ``None`` if it is missing; ``{}`` if it is unreadable."""
        try:
            known = json.loads(self.file.read_bytes())
        except FileNotFoundError:
            return None
        except (OSError, ValueError):  # unreadable, not UTF-8, not JSON: damaged
            return {}
        return known if isinstance(known, dict) and isinstance(known.get("files"), dict) else {}

    def _entries(self) -> list[Path]:
        return [
            p
            for p in sorted(self.folder.rglob("*"))
            if p.is_file() and p.name not in (MANIFEST, LOCK) and ".tmp" not in p.name
        ]

    def check(self) -> list[str]:
        """Remove what cannot be trusted (class docstring); return the names of damaged files."""
        with self._lock:
            return self._check()

    def _check(self) -> list[str]:
        known = self._read()
        entries = self._entries()
        if known is not None and known.get("sources", self.sources) != self.sources:
            self.clear()  # built from another version of the sources: stale, not damaged
            return []
        files = (known or {}).get("files", {})
        damaged = []
        for path in entries:
            name = path.relative_to(self.folder).as_posix()
            if known != {} and name not in files:
                continue  # not recorded yet: its writer records it (module doc)
            try:
                good = files.get(name) == digest(path.read_bytes())
            except OSError:
                good = False
            if not good:
                with contextlib.suppress(OSError):
                    path.unlink()
                damaged.append(name)
        if known == {}:
            with contextlib.suppress(OSError):
                self.file.unlink()
            damaged.append(MANIFEST)
        return damaged

    def record(self) -> None:
        """Record every file now in the folder, with the sources (written atomically, under the lock:
        two processes recording at once cannot drop each other's entries)."""
        with self._lock:
            files = {}
            for path in self._entries():
                with contextlib.suppress(OSError):
                    files[path.relative_to(self.folder).as_posix()] = digest(path.read_bytes())
            text = json.dumps({"sources": self.sources, "files": files}, indent=0, sort_keys=True)
            write_atomically(self.file, text.encode())

    def clear(self) -> None:
        """Remove every file of the folder (a rebuild from nothing), under the lock; the lock file
        itself stays (removing a held lock's file would let a second process take a new one)."""
        with self._lock:
            for path in sorted(self.folder.rglob("*"), reverse=True):
                if path.name != LOCK:
                    with contextlib.suppress(OSError):
                        path.rmdir() if path.is_dir() else path.unlink()


def prepared(part: str, sources: str = "") -> tuple[Path, Manifest]:
    """The checked directory of ``part`` (``directory``) after ``Manifest.check``: what is left in
    it can be read. Damage is reported in one ``CacheWarning``; whoever needs an entry rebuilds it
    and calls ``Manifest.record``."""
    folder = directory(part)
    manifest = Manifest(folder, sources)
    try:
        damaged = manifest.check()
    except OSError as error:  # a folder that cannot even be listed: use a private one
        folder = _private(part, f"cannot read {folder}: {error.strerror or error}")
        manifest = Manifest(folder, sources)
        damaged = []
    if damaged:
        warnings.warn(
            f"idkit's cache {folder} had {len(damaged)} damaged file(s) ({', '.join(damaged[:3])}"
            f"{', …' if len(damaged) > 3 else ''}); removed them, they are rebuilt once",
            CacheWarning,
            stacklevel=3,
        )
    return folder, manifest


def write_atomically(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename: a reader (another process)
    sees the old file or the new one, never half of one. A failure only warns (the cache is an
    optimisation)."""
    temporary = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    try:
        temporary.write_bytes(data)
        os.replace(temporary, path)
    except OSError as error:
        with contextlib.suppress(OSError):
            temporary.unlink()
        warnings.warn(f"idkit could not write its cache file {path}: {error}", CacheWarning, stacklevel=2)
