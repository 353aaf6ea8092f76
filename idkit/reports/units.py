"""Numbers as people read them in the reports."""

from __future__ import annotations


def format_time(seconds: float | None) -> str:
    """Seconds in the paper's style: µs below a millisecond, ms below a second."""
    if seconds is None:
        return ""
    if seconds < 1e-3:
        return f"{seconds * 1e6:.0f} µs"
    if seconds < 1:
        return f"{seconds * 1e3:.1f} ms"
    return f"{seconds:.2f} s"
