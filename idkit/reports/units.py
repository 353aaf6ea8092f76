"""Numbers as people read them in the reports."""

from __future__ import annotations

from collections.abc import Sequence


def format_time(seconds: float | None) -> str:
    """Seconds in the paper's style: µs below a millisecond, ms below a second."""
    if seconds is None:
        return ""
    if seconds < 1e-3:
        return f"{seconds * 1e6:.0f} µs"
    if seconds < 1:
        return f"{seconds * 1e3:.1f} ms"
    return f"{seconds:.2f} s"


def effort_unit(kind: str | None) -> str:
    """A joint's effort unit: N for a prismatic (sliding) joint, N·m for a revolute one, both where
    the robot does not say which (a plugin without ``joint_kinds``)."""
    return {"prismatic": "N", "revolute": "N·m"}.get(kind or "", "N·m or N")


def effort_units(kinds: Sequence[str] | None, n: int) -> list[str]:
    """Per joint, :func:`effort_unit` of ``kinds`` (a robot's ``joint_kinds``; ``None``: unknown)."""
    known = list(kinds or [])
    return [effort_unit(kind) for kind in known] if len(known) == n else [effort_unit(None)] * n
