"""The memory check: what the machine has, and the one-line refusal."""

from __future__ import annotations

import pytest

from idkit import memory


def test_available_memory_is_meminfo_capped_by_a_cgroup_limit(tmp_path, monkeypatch):
    (tmp_path / "meminfo").write_text("MemTotal:  8000000 kB\nMemFree:  1000 kB\nMemAvailable:  4000000 kB\n")
    cgroup = tmp_path / "cgroup"
    cgroup.mkdir()
    monkeypatch.setattr(memory, "MEMINFO", tmp_path / "meminfo")
    monkeypatch.setattr(memory, "CGROUP", cgroup)
    assert memory.available_memory() == 4_000_000 * 1024  # no cgroup files: meminfo alone
    (cgroup / "memory.max").write_text("max\n")
    assert memory.available_memory() == 4_000_000 * 1024
    (cgroup / "memory.max").write_text("3000000000\n")
    (cgroup / "memory.current").write_text("1000000000\n")
    assert memory.available_memory() == 2_000_000_000  # the container's room is smaller


def test_without_meminfo_the_system_pages_answer(tmp_path, monkeypatch):
    monkeypatch.setattr(memory, "MEMINFO", tmp_path / "absent")
    monkeypatch.setattr(memory, "CGROUP", tmp_path / "absent")
    available = memory.available_memory()
    assert available is None or available > 0


@pytest.mark.parametrize(
    ("size", "text"),
    [(999, "999 B"), (1000, "1 kB"), (21_600_000_000, "21.6 GB"), (4.3e13, "43 TB"), (2e20, "2e+05 PB")],
)
def test_format_bytes(size, text):
    assert memory.format_bytes(size) == text


def test_check_memory_refuses_in_one_line_and_passes_what_fits(monkeypatch):
    monkeypatch.setattr(memory, "available_memory", lambda: 2_000_000_000)
    memory.check_memory("x=1", 1_999_999_999)
    with pytest.raises(
        memory.SizeError, match=r"^x=9 needs about 3 GB of memory; this machine has 2 GB available; lower x$"
    ):
        memory.check_memory("x=9", 3e9, "lower x")
    monkeypatch.setattr(memory, "available_memory", lambda: None)
    memory.check_memory("x=9", 3e20)  # unknown: no guess
