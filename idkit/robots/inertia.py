"""One rigid body's inertia in its 10 standard parameters: pseudo-inertia and the parallel axis.

A link's standard parameters ``pi = (m, h = m c, I_O)`` — mass, first moment, and the inertia about
the link-frame origin ``(xx, xy, xz, yy, yz, zz)``, the order of :mod:`idkit.robots.urdf_model` —
are what the regressor is linear in. Two views of them live here because the URDF reader and
writer, the physically consistent estimator (``pcls``) and the KUKA study all need them, and
``robots/`` must not import an estimator:

* the **parallel-axis** pair :func:`standard_parameters` (URDF's ``m, c, I_c`` → ``pi``) and
  :func:`centroidal` (back): ``I_O = I_c + m (|c|² 1 − c cᵀ)``;
* the **pseudo-inertia** ``J(pi) = [[Σ, h], [hᵀ, m]]`` with ``Σ = tr(I_O)/2 · 1 − I_O`` the second
  moment of mass: ``pi`` describes a real mass distribution iff ``J ⪰ 0`` (Wensing, Kim & Slotine
  2017), and ``J`` is linear in ``pi``, so the condition is a linear matrix inequality.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

import numpy as np
import torch
from torch import Tensor

if TYPE_CHECKING:
    from idkit.robots.urdf import URDFRobot


class _Arithmetic(Protocol):
    """What :func:`pseudo_inertia_rows` does to an entry: sums, differences, negation, halving."""

    def __add__(self, other: Any, /) -> Any: ...
    def __sub__(self, other: Any, /) -> Any: ...
    def __neg__(self) -> Any: ...
    def __truediv__(self, other: Any, /) -> Any: ...


T = TypeVar("T", bound=_Arithmetic)


def pseudo_inertia_rows(pi: Sequence[T]) -> list[list[T]]:
    """The 4 × 4 entries of ``J(pi)`` as nested rows of ``pi``'s own entries.

    One layout for every array type that supports ``+``, ``-`` and ``/ 2``: torch stacks it
    (:func:`pseudo_inertia`), ``pcls`` hands it to ``cvxpy.bmat`` for its constraints.
    """
    m, hx, hy, hz, xx, xy, xz, yy, yz, zz = pi
    half_trace = (xx + yy + zz) / 2
    return [
        [half_trace - xx, -xy, -xz, hx],
        [-xy, half_trace - yy, -yz, hy],
        [-xz, -yz, half_trace - zz, hz],
        [hx, hy, hz, m],
    ]


def pseudo_inertia(inertial: Tensor) -> Tensor:
    """Pseudo-inertia ``J[..., 4, 4]`` of standard parameters ``inertial[..., 10]``."""
    rows = pseudo_inertia_rows(inertial.unbind(-1))
    return torch.stack([torch.stack(row, -1) for row in rows], -2)


def link_count(robot: object) -> int:
    """How many links carry 10 standard parameters each (the first ``10 nb`` of ``[P]``).

    Raises:
        ValueError: the robot is not a ``urdf`` robot (:func:`linked`).
    """
    return len(linked(robot).tree.bodies)


def linked(robot: object) -> URDFRobot:
    """``robot`` itself, once known to be a ``urdf`` robot (a kinematic ``tree``, ``link_names`` and a
    ``base_map``): only those order their parameters by link.

    Raises:
        ValueError: any other robot, named.
    """
    from idkit.robots.urdf import URDFRobot  # urdf.py reads its links through this module

    if not isinstance(robot, URDFRobot):
        raise ValueError(
            f"physical consistency needs a 'urdf' robot (10 standard parameters per link and a base "
            f"map), got {type(robot).__name__}"
        )
    return robot


def min_pseudo_inertia_eigenvalues(robot: Any, params: Tensor) -> Tensor:
    """Smallest eigenvalue ``[..., nb]`` of each link's pseudo-inertia for ``params[..., P]``.

    ``≥ 0`` for every link iff the parameters are physically consistent (units mix kg, kg·m, kg·m²:
    compare signs, not sizes, across links).
    """
    nb = link_count(robot)
    inertials = params[..., : 10 * nb].unflatten(-1, (nb, 10))
    return torch.linalg.eigvalsh(pseudo_inertia(inertials.double()))[..., 0]


def standard_parameters(mass: float, com: np.ndarray, inertia_c: np.ndarray) -> np.ndarray:
    """Standard parameters ``[10]`` from mass, centre of mass ``c[3]`` and the inertia about it
    ``I_c[3, 3]`` (all in one frame), by the parallel-axis theorem."""
    inertia_o = inertia_c + mass * (com @ com * np.eye(3) - np.outer(com, com))
    (xx, xy, xz), (_, yy, yz), (_, _, zz) = inertia_o
    return np.array([mass, *(mass * com), xx, xy, xz, yy, yz, zz])


def centroidal(standard: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """``(m, c[3], I_c[3, 3])`` of standard parameters ``[10]``: :func:`standard_parameters` backwards
    (``m`` must be non-zero)."""
    m, h = float(standard[0]), standard[1:4]
    xx, xy, xz, yy, yz, zz = standard[4:]
    inertia_o = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    c = h / m
    return m, c, inertia_o - m * (c @ c * np.eye(3) - np.outer(c, c))


def frame_change(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """The linear map ``T[10, 10]`` of standard parameters from a frame ``F`` to a frame ``B`` in
    which ``F`` has orientation ``rotation[3, 3]`` and origin ``translation[3]``: ``pi_B = T pi_F``.

    The pseudo-inertia moves by congruence, ``J_B = X J_F Xᵀ`` with ``X = [[R, p], [0, 1]]`` (the
    mass distribution's moments under ``x_B = R x_F + p``), which is linear in ``pi_F``: a payload
    fitted in a flange frame ``F`` enters the regressor of the moving body ``B`` it is welded to
    through ``Y_B T``, and ``J_F ⪰ 0`` iff ``J_B ⪰ 0``.
    """
    transform = np.eye(4)
    transform[:3, :3], transform[:3, 3] = rotation, translation
    columns = []
    for unit in np.eye(10):
        moved = transform @ np.array(pseudo_inertia_rows(list(unit)), dtype=np.float64) @ transform.T
        second, first, mass = moved[:3, :3], moved[:3, 3], moved[3, 3]
        inertia = np.trace(second) * np.eye(3) - second  # I_O = tr(Σ) 1 − Σ
        (xx, xy, xz), (_, yy, yz), (_, _, zz) = inertia
        columns.append([mass, *first, xx, xy, xz, yy, yz, zz])
    return np.array(columns).T
