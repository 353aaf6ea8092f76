"""``python -m idkit.examples NAME [FOLDER]``: copy an example's files into ``FOLDER`` (default: here)."""

from __future__ import annotations

import sys

from idkit.examples import EXAMPLES, copy_example


def main(argv: list[str]) -> int:
    if not argv or argv[0] not in EXAMPLES or len(argv) > 2:
        print(f"usage: python -m idkit.examples {{{','.join(EXAMPLES)}}} [FOLDER]", file=sys.stderr)
        return 2
    try:
        for path in copy_example(argv[0], argv[1] if len(argv) > 1 else "."):
            print(path)
    except (FileExistsError, OSError) as error:
        print(f"idkit.examples: {error}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
