"""One XML policy for every robot model idkit reads (``robot=urdf``, ``robot=mjcf``, ``rollout.model``).

A model file is anyone's text, and the parsers behind idkit disagree on DTDs: Python's expat expands
internal entities (a "billion laughs" file grows exponentially), MuJoCo's tinyxml2 ignores them, so
the same file meant different things to ``robot=mjcf`` and ``rollout.model``. URDF and MJCF never
need a DTD, so every loader refuses one — a ``<!DOCTYPE …>`` declaration, and with it any entity,
internal or external — in the same words, before any parser sees the text. A file that is not UTF-8
text is refused naming the file and the option, instead of with a codec's message.
"""

from __future__ import annotations

import contextlib
import xml.parsers.expat


class _Prolog(Exception):
    """Raised by the scanner at the root element: the prolog, where a DTD would be, is over."""


def refuse_dtd(data: bytes, label: str, option: str) -> None:
    """Refuse XML ``data`` that declares a DTD (module doc); anything else passes unchanged.

    Only the prolog is scanned (it stops at the root element); XML errors are left to the parser
    that reads the model, which names them.

    Args:
        data: the file's bytes.
        label: the file (or ``<… text>``), for the message.
        option: the setting that named it (``robot.urdf``, ``rollout.model``), for the message.

    Raises:
        ValueError: ``data`` declares a DTD.
    """
    parser = xml.parsers.expat.ParserCreate()
    declared: list[str] = []

    def doctype(name: str, *_: object) -> None:
        declared.append(name)
        raise _Prolog

    def root(*_: object) -> None:
        raise _Prolog

    parser.StartDoctypeDeclHandler = doctype
    parser.StartElementHandler = root
    with contextlib.suppress(_Prolog, xml.parsers.expat.ExpatError):
        parser.Parse(data, True)
    if declared:
        raise ValueError(
            f"{option}: {label} declares a DTD (<!DOCTYPE {declared[0]} …>); idkit reads models without "
            "one (no entities, no files named inside the XML): remove the declaration"
        )


def model_text(data: bytes, label: str, option: str) -> str:
    """``data`` as text once it passes :func:`refuse_dtd` and decodes as UTF-8.

    Raises:
        ValueError: a DTD, or bytes that are not UTF-8 text (the message names the file, the option
            and the first byte that is not).
    """
    refuse_dtd(data, label, option)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ValueError(
            f"{option}: {label} is not a text model file (byte 0x{data[error.start]:02x} at offset "
            f"{error.start} is not UTF-8): give an MJCF (.xml) or URDF (.urdf) file"
        ) from None
