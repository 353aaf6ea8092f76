"""idkit's cache: owner-only, refused when others can write it, damaged entries rebuilt once."""

from __future__ import annotations

import json
import os
import pickle
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from idkit.optim import cache


@pytest.fixture
def root(tmp_path, monkeypatch):
    """A fresh cache root for this test (``cache.directory`` re-reads it)."""
    monkeypatch.setenv(cache.ENVIRONMENT, str(tmp_path / "cache"))
    cache.directory.cache_clear()
    yield tmp_path / "cache"
    cache.directory.cache_clear()


class _Planted:
    """Unpickling this object writes a marker file: code run from the cache."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (Path.write_text, (self.marker, "ran"))


def test_the_cache_is_created_owner_only(root):
    folder = cache.directory("kernel")
    assert folder == root / "kernel"
    for path in (root, folder):
        assert stat.S_IMODE(path.stat().st_mode) == 0o700


@pytest.mark.skipif(os.name != "posix", reason="POSIX permissions")
def test_a_world_writable_cache_is_refused_and_never_read(root, tmp_path):
    marker = tmp_path / "planted-code-ran"
    (root / "kernel").mkdir(parents=True)
    os.chmod(root, 0o777)
    planted = root / "kernel" / "run_trial.nbi"
    planted.write_bytes(pickle.dumps(_Planted(marker)))
    with pytest.warns(cache.CacheWarning, match="writable by everyone.*chmod 700"):
        folder, _ = cache.prepared("kernel")
    assert root not in folder.parents and not marker.exists()
    assert planted.exists()  # refused, not touched
    assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    assert [p.name for p in folder.iterdir()] in ([], [cache.LOCK])


@pytest.mark.skipif(
    not hasattr(os, "geteuid") or os.geteuid() != 0, reason="needs root to give the cache away"
)
def test_a_cache_owned_by_someone_else_is_refused(root):
    root.mkdir(mode=0o700)
    os.chown(root, 12345, 12345)
    with pytest.warns(cache.CacheWarning, match="owned by another user"):
        folder = cache.directory("maps")
    assert root not in folder.parents


def test_damaged_files_are_removed_with_a_warning_and_unknown_ones_left_to_their_writer(root):
    folder, manifest = cache.prepared("part", "sources-1")
    (folder / "a.bin").write_bytes(b"built")
    (folder / "sub").mkdir()
    (folder / "sub" / "b.bin").write_bytes(b"built too")
    manifest.record()
    assert cache.Manifest(folder, "sources-1").check() == []  # intact: nothing removed
    (folder / "sub" / "b.bin").write_bytes(b"garbage")
    (folder / "c.tmp.1234").write_bytes(b"a write in progress")  # another process's: left alone
    (folder / "fresh.bin").write_bytes(b"another process's entry, not recorded yet")
    with pytest.warns(cache.CacheWarning, match="1 damaged file"):
        cache.prepared("part", "sources-1")
    assert sorted(p.name for p in folder.rglob("*") if p.is_file()) == [
        "a.bin",
        "c.tmp.1234",
        "fresh.bin",
        "manifest.json",
        cache.LOCK,
    ]


def test_an_entry_being_written_by_another_process_is_neither_removed_nor_called_damaged(root, recwarn):
    """The interleaving of a sweep's jobs: B checks the cache between A's write and A's record.
    Before, B removed A's fresh file (A's record then listed nothing) or, for a rewritten file,
    warned of damage."""
    folder, writer = cache.prepared("part", "s")
    (folder / "index.bin").write_bytes(b"version 1")
    writer.record()
    cache.write_atomically(folder / "new.bin", b"just built")  # A: written, not yet recorded
    assert cache.Manifest(folder, "s").check() == []  # B
    writer.record()  # A
    assert cache.Manifest(folder, "s").check() == []
    assert (folder / "new.bin").read_bytes() == b"just built"
    assert not [w for w in recwarn if w.category is cache.CacheWarning]


def _job(folder: str, job: int, entries: int) -> list[str]:
    """One of two processes sharing a cache part: write entries as the base-map cache does (under the
    lock, from the write to the record), check the cache before each; returns the damage it saw."""
    import warnings

    seen = []
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for k in range(entries):
            manifest = cache.Manifest(Path(folder), "s")
            seen += manifest.check()
            with manifest.locked():
                cache.write_atomically(Path(folder) / f"job{job}-{k}.bin", os.urandom(2000))
                manifest.record()
    return seen


def test_two_processes_sharing_the_cache_keep_each_others_entries(root):
    import multiprocessing

    folder, _ = cache.prepared("part", "s")
    entries = 60
    with multiprocessing.get_context("spawn").Pool(2) as pool:
        seen = pool.starmap(_job, [(str(folder), job, entries) for job in (0, 1)])
    assert seen == [[], []]  # no false damage
    names = sorted(p.name for p in folder.glob("job*.bin"))
    assert len(names) == 2 * entries  # nothing of the other job removed
    assert cache.Manifest(folder, "s").check() == []
    assert set(json.loads((folder / cache.MANIFEST).read_text())["files"]) == set(names)


def test_a_cache_overwritten_with_garbage_is_emptied_once(root):
    folder, manifest = cache.prepared("part", "s")
    (folder / "a.bin").write_bytes(b"built")
    manifest.record()
    for path in folder.rglob("*"):
        path.write_bytes(b"\xff\xfe garbage, not even UTF-8")
    with pytest.warns(cache.CacheWarning, match="damaged"):
        folder, manifest = cache.prepared("part", "s")
    assert [p.name for p in folder.iterdir()] == [cache.LOCK]  # the lock file stays (Manifest.clear)
    manifest.record()
    assert json.loads((folder / cache.MANIFEST).read_text()) == {"files": {}, "sources": "s"}


def test_entries_of_other_sources_are_cleared_without_a_warning(root, recwarn):
    folder, manifest = cache.prepared("part", "old")
    (folder / "a.bin").write_bytes(b"old build")
    manifest.record()
    folder, _ = cache.prepared("part", "new")
    assert not (folder / "a.bin").exists() and not [w for w in recwarn if w.category is cache.CacheWarning]


# --- the kernel's own cache, end to end (each compiles the kernel: tens of seconds) ----------------

CHILD = (
    "import warnings; warnings.simplefilter('always'); from idkit.optim import fast; "
    "b = fast.kernel(); print(type(b).__name__, getattr(b, 'how', b))"
)


def _child(cache_root: Path) -> subprocess.CompletedProcess:
    environment = {**os.environ, cache.ENVIRONMENT: str(cache_root)}
    return subprocess.run(
        [sys.executable, "-c", CHILD], env=environment, capture_output=True, text=True, timeout=600
    )


@pytest.mark.slow
def test_a_kernel_cache_of_garbage_still_gives_the_kernel_after_one_rebuild(tmp_path):
    first = _child(tmp_path)
    assert first.stdout.startswith("Build compiled"), first.stderr
    for path in (tmp_path / "kernel").rglob("*"):
        if path.is_file():
            path.write_bytes(os.urandom(64))
    rebuilt = _child(tmp_path)
    assert rebuilt.stdout.startswith("Build compiled") and "damaged" in rebuilt.stderr, rebuilt.stderr
    assert "Traceback" not in rebuilt.stderr
    again = _child(tmp_path)
    assert again.stdout.startswith("Build loaded from the cache") and "damaged" not in again.stderr


@pytest.mark.slow
@pytest.mark.skipif(os.name != "posix", reason="POSIX permissions")
def test_the_kernel_never_loads_a_library_planted_in_a_world_writable_cache(tmp_path):
    """A real kernel cache, made world-writable and its index replaced by a malicious pickle."""
    warm = tmp_path / "warm"
    assert _child(warm).stdout.startswith("Build")
    planted = tmp_path / "planted"
    shutil.copytree(warm, planted)
    marker = tmp_path / "planted-code-ran"
    for index in planted.rglob("*.nbi"):
        index.write_bytes(pickle.dumps(_Planted(marker)))
    for folder in (planted, *[p for p in planted.rglob("*") if p.is_dir()]):
        os.chmod(folder, 0o777)
    done = _child(planted)
    assert done.stdout.startswith("Build compiled") and "refused" in done.stderr, done.stderr
    assert not marker.exists()
