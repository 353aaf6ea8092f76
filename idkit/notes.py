"""Notes: choices idkit made on the user's behalf that they should see, printed as ``note:`` lines.

A chosen cut-off or prior weight is not a problem, so the command does not print it as a
``warning:``; it is still a ``UserWarning`` subclass so that it flows through Python's warning
machinery: printed once, one line, recorded by ``warnings.catch_warnings`` and ``pytest.warns``.
"""

from __future__ import annotations


class Note(UserWarning):
    """A choice made automatically (which, and why), shown as ``note: …`` by the command."""
