"""An excitation as a YAML document: its registry name and its constructor options.

::

    excitation: fourier
    options: {n_joints: 3, harmonics: 5, period: 10.0, offset: [...], a: [[...]], b: [[...]]}

The options are the plugin's constructor keyword arguments (coefficients included), so loading is
``registry.create("excitation", name, **options)``. Floats are written with ``repr``, so a round
trip gives back the same coefficients bit for bit. Writing the file is left to the caller (the
report layer's atomic writes); this module turns documents into text and reads files back.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from idkit.interfaces import Excitation
from idkit.registry import create

DOCUMENT_KEYS = ("excitation", "options")


def excitation_document(name: str, excitation: Excitation) -> dict[str, Any]:
    """``{"excitation": name, "options": excitation.options()}``: what a file stores."""
    return {"excitation": name, "options": excitation.options()}


def excitation_yaml(name: str, excitation: Excitation) -> str:
    """The YAML text of ``excitation_document(name, excitation)``."""
    return yaml.safe_dump(excitation_document(name, excitation), sort_keys=False, default_flow_style=None)


def excitation_from_document(document: Mapping[str, Any], where: str = "excitation document") -> Excitation:
    """Build the excitation a document describes; errors name ``where`` and what is wrong."""
    if not isinstance(document, Mapping) or set(document) != set(DOCUMENT_KEYS):
        keys = sorted(document) if isinstance(document, Mapping) else type(document).__name__
        raise ValueError(f"{where}: expected exactly the keys {list(DOCUMENT_KEYS)}, got {keys}")
    name, options = document["excitation"], document["options"]
    if not isinstance(name, str) or not isinstance(options, Mapping):
        raise ValueError(f"{where}: 'excitation' must be a plugin name and 'options' a mapping")
    try:
        return create("excitation", name, **options)
    except (TypeError, ValueError, LookupError) as exc:
        raise ValueError(f"{where}: {exc}") from exc


def excitation_from_yaml(text: str, where: str = "excitation YAML") -> Excitation:
    """Parse YAML text written by ``excitation_yaml``."""
    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ValueError(f"{where}: not valid YAML: {exc}") from None
    return excitation_from_document(document, where)


def load_excitation(path: str | os.PathLike[str]) -> Excitation:
    """Read an excitation file (e.g. ``excitation.yaml`` of an optimisation run)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ValueError(f"excitation file {path}: cannot read it: {exc.strerror}") from None
    return excitation_from_yaml(text, f"excitation file {path}")
