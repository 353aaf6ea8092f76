"""A body's inertia in log-Cholesky coordinates: every value is a body that can exist.

A body's 10 standard parameters ``(m, h = m c, I_O)`` (:mod:`idkit.robots.inertia`) describe a real mass
distribution iff its pseudo-inertia ``J = [[Σ, h], [hᵀ, m]]`` is positive semidefinite. Writing
``J = U Uᵀ`` with ``U`` upper triangular,

    U = e^α · [[e^d1, s12, s13, t1], [0, e^d2, s23, t2], [0, 0, e^d3, t3], [0, 0, 0, 1]]

maps any 10 real numbers ``θ = (α, d1, d2, d3, s12, s23, s13, t1, t2, t3)`` to a positive definite
``J`` — a physical body — and every such body to one ``θ`` (Rucker & Wensing 2022). So a search and a
Levenberg–Marquardt step move freely in ``θ`` and never leave physics. ``m = e^{2α}``; ``t`` is the
centre of mass; ``α`` and ``d`` are logarithms, ``s`` shapes the second moment about it.

For MuJoCo the body's ``mass``, ``ipos`` (the centre of mass) and the principal moments and axes of the
inertia about it (``inertia``, ``iquat``), in the body frame.
"""

from __future__ import annotations

import numpy as np

from idkit.robots.inertia import centroidal, pseudo_inertia_rows, standard_parameters

#: The coordinates' names, in order.
COORDINATES = ("alpha", "d1", "d2", "d3", "s12", "s23", "s13", "t1", "t2", "t3")
_REVERSE = np.eye(4)[::-1]


def coordinates(standard: np.ndarray) -> np.ndarray:
    """``θ[10]`` of standard parameters ``[10]`` (a positive definite pseudo-inertia)."""
    pseudo = np.array(pseudo_inertia_rows(list(standard)), dtype=np.float64)
    lower = np.linalg.cholesky(_REVERSE @ pseudo @ _REVERSE)  # raises LinAlgError if not definite
    u = _REVERSE @ lower @ _REVERSE  # upper triangular, J = U Uᵀ
    u *= np.sign(np.diag(u))[None, :]  # a positive diagonal
    scale = u[3, 3]
    v = u / scale
    return np.array(
        [np.log(scale), *np.log(np.diag(v)[:3]), v[0, 1], v[1, 2], v[0, 2], v[0, 3], v[1, 3], v[2, 3]]
    )


def standard(theta: np.ndarray) -> np.ndarray:
    """Standard parameters ``[10]`` of ``θ[10]``."""
    alpha, d1, d2, d3, s12, s23, s13, t1, t2, t3 = theta
    u = np.exp(alpha) * np.array(
        [
            [np.exp(d1), s12, s13, t1],
            [0.0, np.exp(d2), s23, t2],
            [0.0, 0.0, np.exp(d3), t3],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )
    pseudo = u @ u.T
    mass, h, sigma = pseudo[3, 3], pseudo[:3, 3], pseudo[:3, :3]
    inertia = np.trace(sigma) * np.eye(3) - sigma
    return np.array(
        [mass, *h, inertia[0, 0], inertia[0, 1], inertia[0, 2], inertia[1, 1], inertia[1, 2], inertia[2, 2]]
    )


def mujoco_inertial(theta: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """``(mass, ipos[3], inertia[3], iquat[4])`` of ``θ[10]`` for a MuJoCo body (moments ascending)."""
    mass, com, about_com = centroidal(standard(theta))
    moments, axes = np.linalg.eigh(0.5 * (about_com + about_com.T))
    if np.linalg.det(axes) < 0:
        axes[:, 2] = -axes[:, 2]
    return mass, com, moments, _quaternion(axes)


def from_mujoco(mass: float, ipos: np.ndarray, inertia: np.ndarray, iquat: np.ndarray) -> np.ndarray:
    """``θ[10]`` of a MuJoCo body's ``mass``, ``ipos``, principal ``inertia`` and ``iquat``."""
    rotation = _rotation(iquat)
    about_com = rotation @ np.diag(inertia) @ rotation.T
    return coordinates(standard_parameters(mass, np.asarray(ipos, dtype=np.float64), about_com))


def _rotation(quat: np.ndarray) -> np.ndarray:
    w, x, y, z = np.asarray(quat, dtype=np.float64) / np.linalg.norm(quat)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _quaternion(rotation: np.ndarray) -> np.ndarray:
    """A unit quaternion ``(w, x, y, z)`` of a rotation matrix (Shepperd's method)."""
    r = rotation
    trace = np.trace(r)
    if trace > 0:
        s = 2.0 * np.sqrt(1.0 + trace)
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
        q = [0.0, 0.0, 0.0, 0.0]
        q[0] = (r[k, j] - r[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (r[j, i] + r[i, j]) / s
        q[1 + k] = (r[k, i] + r[i, k]) / s
    quaternion = np.array(q)
    return quaternion / np.linalg.norm(quaternion)
