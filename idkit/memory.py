"""How much memory a size option will need, checked before anything is allocated.

A size option such as ``trials=1e9`` is a valid integer, and what goes wrong with it is the
allocator: a traceback from deep inside torch, or a machine that swaps for an hour. So a study (or
estimator) estimates the bytes a size will need, from its own model of what it allocates, and
:func:`check_memory` refuses in one line that states the estimate and what the machine has.

"What the machine has" is the memory a new allocation can get without swapping: Linux's
``MemAvailable`` (free memory plus caches it can drop), capped by a cgroup v2 limit (a container's)
when one is set; elsewhere the free physical pages, or the physical memory, that ``os.sysconf``
reports. Where none of these exists the check says nothing rather than guess.
"""

from __future__ import annotations

import os
from pathlib import Path

#: Where Linux says how much memory is available, and a cgroup v2 container's limit and usage.
MEMINFO = Path("/proc/meminfo")
CGROUP = Path("/sys/fs/cgroup")


class SizeError(ValueError):
    """A size option would need more memory than the machine has (the message gives both)."""


def available_memory() -> int | None:
    """Bytes a new allocation can get without swapping, or ``None`` where the system does not say."""
    found = [value for value in (_meminfo_available(), _cgroup_room()) if value is not None]
    if found:
        return min(found)
    for pages in ("SC_AVPHYS_PAGES", "SC_PHYS_PAGES"):
        try:
            return os.sysconf(pages) * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):  # a name this system does not define
            continue
    return None


def _meminfo_available() -> int | None:
    try:
        for line in MEMINFO.read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _cgroup_room() -> int | None:
    """A cgroup v2 limit minus the usage, when this process runs under one."""
    try:
        limit = (CGROUP / "memory.max").read_text().strip()
        if limit == "max":
            return None
        return max(int(limit) - int((CGROUP / "memory.current").read_text()), 0)
    except (OSError, ValueError):
        return None


def format_bytes(size: float) -> str:
    """``1.5 GB``: decimal units, three significant digits."""
    units = ("B", "kB", "MB", "GB", "TB", "PB")
    step = 0
    while abs(size) >= 1000 and step < len(units) - 1:
        size, step = size / 1000, step + 1
    return f"{size:.3g} {units[step]}"


def check_memory(what: str, needed: float, hint: str = "") -> None:
    """Raise :class:`SizeError` if ``needed`` bytes exceed the available memory.

    Args:
        what: the option and what it sizes, e.g. ``"robustness: trials=1000000000 (noise draws and
            results of 4 scenarios)"``.
        needed: the estimate in bytes.
        hint: what to do instead, appended after a semicolon.
    """
    available = available_memory()
    if available is not None and needed > available:
        advice = f"; {hint}" if hint else ""
        raise SizeError(
            f"{what} needs about {format_bytes(needed)} of memory; this machine has "
            f"{format_bytes(available)} available{advice}"
        )
