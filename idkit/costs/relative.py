"""Former home of the relative-error policy, kept so that old imports keep working.

The policy now lives in the core, ``idkit.relative``; import it from there.
"""

from idkit.relative import DEFAULT_FLOOR, RelativeFloorWarning, relative_denominator, relative_error

__all__ = ["DEFAULT_FLOOR", "RelativeFloorWarning", "relative_denominator", "relative_error"]
