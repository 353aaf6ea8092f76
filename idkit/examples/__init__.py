"""Small robots and their logs, shipped with the package so that the docs run anywhere.

``servo_arm``: a 3-joint arm under position servos (``servo_arm.xml``, the model a user starts
from) with two logs of the arm as built: ``train.csv`` and ``held_out.csv`` (written by
:mod:`idkit.examples.make_servo_arm`). ``python -m idkit.examples servo_arm [FOLDER]`` copies them
into ``FOLDER`` (default: here), as :func:`copy_example` does.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

#: Each example's files.
EXAMPLES = {"servo_arm": ("servo_arm.xml", "train.csv", "held_out.csv")}


def copy_example(name: str, folder: str | Path = ".") -> list[Path]:
    """Copy example ``name``'s files into ``folder`` (created if missing); returns their paths.

    Raises:
        ValueError: no such example.
        FileExistsError: ``folder`` holds a file of that name with other content (nothing is copied).
    """
    if name not in EXAMPLES:
        raise ValueError(f"no example {name!r}; the examples: {', '.join(EXAMPLES)}")
    source = files("idkit.examples") / name
    texts = {file: (source / file).read_text(encoding="utf-8") for file in EXAMPLES[name]}
    folder = Path(folder)
    clashes = [
        str(folder / file)
        for file, text in texts.items()
        if (folder / file).exists() and (folder / file).read_text(encoding="utf-8") != text
    ]
    if clashes:
        raise FileExistsError(f"example {name}: {', '.join(clashes)} exist with other content; not copied")
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for file, text in texts.items():
        (folder / file).write_text(text, encoding="utf-8")
        paths.append(folder / file)
    return paths
