"""Mesh files a URDF names: where they are, and their vertices (STL binary or ASCII, OBJ).

Only vertices are read: a bounding ellipsoid or box depends on the convex hull alone. No mesh
library is needed for that (``trimesh`` would be a dependency for two formats of a few lines each).
A mesh that cannot be found or read is the caller's to leave out and say: every function here
returns ``None`` or raises :class:`MeshError` with the reason, never a half-read mesh.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

#: Suffixes read (lower case); others (``.dae``, ``.ply``) are refused with their name.
READ = (".stl", ".obj")
_STL_VERTEX = re.compile(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)")


class MeshError(ValueError):
    """A mesh file that exists but gives no vertices (the message says why)."""


def checked_package_dirs(package_dirs: object, who: str) -> tuple[Path, ...]:
    """``package_dirs`` as paths, or ``ValueError`` in one line naming ``who`` and the entry that is not
    an existing folder: a typo would otherwise leave every ``package://`` mesh out without a word."""
    if isinstance(package_dirs, (str, Path)) or not isinstance(package_dirs, Sequence):
        raise ValueError(f"{who}: package_dirs must be a list of folders, got {package_dirs!r}")
    out = []
    for entry in package_dirs:
        if not isinstance(entry, (str, Path)) or not str(entry):
            raise ValueError(f"{who}: package_dirs entries must be folder paths, got {entry!r}")
        path = Path(entry)
        if not path.is_dir():
            why = "is a file, not a folder" if path.exists() else "does not exist"
            raise ValueError(f"{who}: package_dirs names {str(entry)!r}, which {why}")
        out.append(path)
    return tuple(out)


def mesh_file(filename: str, base: Path | None, package_dirs: Sequence[Path]) -> Path | None:
    """The file a URDF ``<mesh filename>`` names, or ``None`` when it is not found.

    ``package://pkg/rest`` is looked up as ``d/pkg/rest`` and ``d/rest`` for each ``d`` in
    ``package_dirs``, then in any folder above the URDF that is named ``pkg`` (the usual layout
    ``pkg/urdf/robot.urdf``, ``pkg/meshes/…``); ``file://`` is an absolute path; anything else is a
    path, relative to the URDF's folder ``base`` (``None`` for URDF text: only absolute paths work).
    """
    if filename.startswith("package://"):
        package, _, rest = filename[len("package://") :].partition("/")
        candidates = [d / package / rest for d in package_dirs] + [d / rest for d in package_dirs]
        if base is not None:
            candidates += [folder / rest for folder in (base, *base.parents) if folder.name == package]
    elif filename.startswith("file://"):
        candidates = [Path(filename[len("file://") :])]
    else:
        path = Path(filename)
        candidates = [path] if path.is_absolute() else [] if base is None else [base / path]
    return next((c for c in candidates if c.is_file()), None)


def mesh_vertices(path: Path) -> np.ndarray:
    """``[n, 3]`` vertices of an STL (binary or ASCII) or OBJ file, in the file's units.

    Raises:
        MeshError: another format, an unreadable or truncated file, no vertices, a number that is
            not finite.
    """
    suffix = path.suffix.lower()
    if suffix not in READ:
        raise MeshError(f"{suffix or 'no suffix'} is not read (STL and OBJ are)")
    try:
        data = path.read_bytes()
    except OSError as error:
        raise MeshError(f"cannot be read ({error.strerror})") from None
    vertices = _stl(data) if suffix == ".stl" else _obj(data)
    if len(vertices) == 0:
        raise MeshError("has no vertices")
    if not np.isfinite(vertices).all():
        raise MeshError("has a vertex that is not a finite number")
    return vertices


def _stl(data: bytes) -> np.ndarray:
    """Binary when the size matches the triangle count in the header (ASCII files start with
    ``solid``, but so do some binary ones), else ASCII."""
    if len(data) >= 84:
        count = int.from_bytes(data[80:84], "little")
        if len(data) == 84 + 50 * count:
            record = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
            triangles = np.frombuffer(data, dtype=record, count=count, offset=84)
            return triangles["corners"].reshape(-1, 3).astype(np.float64)
    if not data.lstrip().startswith(b"solid"):
        raise MeshError("is neither binary STL (its size disagrees with its triangle count) nor ASCII STL")
    return _numbers(_STL_VERTEX.findall(data))


def _obj(data: bytes) -> np.ndarray:
    """``v x y z [w | r g b]`` lines: the first three numbers of each."""
    rows = [line.split()[1:4] for line in data.splitlines() if line.startswith((b"v ", b"v\t"))]
    if any(len(row) < 3 for row in rows):
        raise MeshError("has a vertex line with fewer than three numbers")
    return _numbers(rows)


def _numbers(rows: Sequence[Sequence[bytes]]) -> np.ndarray:
    try:
        return np.array([[float(x) for x in row] for row in rows], dtype=np.float64).reshape(-1, 3)
    except ValueError:
        raise MeshError("has a vertex coordinate that is not a number") from None
