"""Bounding ellipsoids and boxes of rigid solids: the geometry behind density realisability.

A link's mass lies inside its geometry. Wensing, Kim & Slotine (RA-L 2017) turn "inside the
ellipsoid ``(x − c)ᵀ Q (x − c) ≤ 1``" into one linear inequality on the pseudo-inertia
``J = ∫ [x; 1][x; 1]ᵀ dm``: ``tr(J Q4) = ∫ 1 − (x − c)ᵀ Q (x − c) dm ≥ 0`` with
``Q4 = [[−Q, Q c], [cᵀ Q, 1 − cᵀ Q c]]`` (:func:`ellipsoid_bound`); with ``J ⪰ 0`` it is also
sufficient for some mass distribution inside the ellipsoid to have these moments. The tighter the
ellipsoid, the more the bound says, so each body gets the *minimum-volume* ellipsoid enclosing its
solids (:func:`minimum_volume_ellipsoid`), or the exact one of a single primitive.

Curved solids enter through points whose convex hull contains them (circumscribing polygons and
polyhedra), so the ellipsoid of the points contains the whole solid, not only the samples.
"""

from __future__ import annotations

import contextlib
import functools
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

#: Directions sampled on the unit sphere and circle; their hulls, inflated to contain the ball and the
#: disc, are at most 2.2 % (sphere: 512 points) and 0.3 % (circle: 64 points) larger in volume.
SPHERE_POINTS = 512
CIRCLE_POINTS = 64
#: Kinds of :class:`Solid` and what ``size`` holds for each.
SIZES = {
    "box": "half-extents (3)",
    "sphere": "radius (1)",
    "ellipsoid": "semi-axes (3)",
    "cylinder": "radius and half-length along z (2)",
    "capsule": "radius and half-length of the segment along z (2)",
    "mesh": "nothing: the vertices are the solid's hull",
}


@dataclass(frozen=True)
class Solid:
    """One primitive or mesh placed in a body frame.

    Attributes:
        kind: a key of :data:`SIZES`.
        size: ``[k]`` the dimensions :data:`SIZES` names (m).
        rotation: ``[3, 3]`` the solid's frame in the body frame.
        translation: ``[3]`` its origin in the body frame (m).
        vertices: ``[n, 3]`` a mesh's vertices in its own frame, scaled (m); ``None`` otherwise.
    """

    kind: str
    size: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    vertices: np.ndarray | None = None

    def points(self) -> np.ndarray:
        """``[k, 3]`` points in the body frame whose convex hull contains the whole solid."""
        s = self.size
        if self.kind == "box":
            local = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * s
        elif self.kind in ("sphere", "ellipsoid"):
            local = _ball() * (s[0] if self.kind == "sphere" else s)
        elif self.kind == "cylinder":
            rim = np.column_stack([_disc() * s[0], np.zeros(CIRCLE_POINTS)])
            local = np.concatenate([rim + [0, 0, s[1]], rim - [0, 0, s[1]]])
        elif self.kind == "capsule":
            local = np.concatenate([_ball() * s[0] + [0, 0, s[1]], _ball() * s[0] - [0, 0, s[1]]])
        else:
            local = self.vertices
        return local @ self.rotation.T + self.translation

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The solid's exact axis-aligned bounding box in the body frame, ``(lo[3], hi[3])``."""
        s, r = self.size, self.rotation
        if self.kind == "mesh":
            points = self.points()
            return points.min(axis=0), points.max(axis=0)
        if self.kind in ("box", "sphere", "ellipsoid"):
            semi = np.full(3, s[0]) if self.kind == "sphere" else s
            half = np.abs(r) @ semi if self.kind == "box" else np.sqrt((r**2) @ semi**2)
        else:  # a disc of radius s[0] swept ±s[1] along the axis r[:, 2] (a capsule: a ball swept)
            radial = s[0] if self.kind == "capsule" else s[0] * np.hypot(r[:, 0], r[:, 1])
            half = s[1] * np.abs(r[:, 2]) + radial
        return self.translation - half, self.translation + half

    def exact_ellipsoid(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The solid's own minimum-volume ellipsoid ``(c, Q)`` where symmetry gives it in closed form
        (box: √3 × the half-extents; cylinder: √(3/2) × the radius, √3 × the half-length), else ``None``
        (also for a flat one: a zero size has no ellipsoid of positive volume)."""
        s = self.size
        if self.kind == "sphere":
            semi = np.full(3, s[0])
        elif self.kind == "ellipsoid":
            semi = s
        elif self.kind == "box":
            semi = np.sqrt(3.0) * s
        elif self.kind == "cylinder":
            semi = np.array([np.sqrt(1.5) * s[0], np.sqrt(1.5) * s[0], np.sqrt(3.0) * s[1]])
        else:
            return None
        if semi.min() <= 1e-6 * semi.max():  # as flat as :func:`thickened` thickens
            return None
        return self.translation.copy(), self.rotation @ np.diag(1.0 / semi**2) @ self.rotation.T


@functools.cache
def _ball() -> np.ndarray:
    """``[SPHERE_POINTS, 3]`` points whose hull contains the unit ball: a Fibonacci lattice on the
    sphere pushed out by the hull's inradius."""
    i = np.arange(SPHERE_POINTS) + 0.5
    z = 1 - 2 * i / SPHERE_POINTS
    rho, phi = np.sqrt(1 - z**2), np.pi * (1 + np.sqrt(5.0)) * i
    directions = np.column_stack([rho * np.cos(phi), rho * np.sin(phi), z])
    inradius = -ConvexHull(directions).equations[:, 3].max()
    return directions / inradius


@functools.cache
def _disc() -> np.ndarray:
    """``[CIRCLE_POINTS, 2]`` vertices of the regular polygon circumscribing the unit circle."""
    angle = 2 * np.pi * np.arange(CIRCLE_POINTS) / CIRCLE_POINTS
    return np.column_stack([np.cos(angle), np.sin(angle)]) / np.cos(np.pi / CIRCLE_POINTS)


def minimum_volume_ellipsoid(points: np.ndarray, gap: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """The minimum-volume ellipsoid ``(c[3], Q[3, 3])`` enclosing ``points[n, 3]`` (full-dimensional).

    The ellipsoid ``{x : |A x + b| ≤ 1}`` of largest ``log det A`` (Boyd & Vandenberghe §8.4.1), by a
    log-barrier Newton method on the 9 unknowns ``(A, b)`` over the convex hull's vertices, to a
    relative volume within ``gap`` of the minimum. Khachiyan's first-order iteration needs thousands
    of steps where many points touch the ellipsoid (sampled spheres and cylinders); this needs about
    a hundred. The result is scaled until the farthest point lies on it, so every point satisfies
    ``(x − c)ᵀ Q (x − c) ≤ 1`` to round-off even if the barrier stopped early.
    """
    if len(points) > 12:
        with contextlib.suppress(QhullError):  # nearly flat: every point takes part (only slower)
            points = points[ConvexHull(points).vertices]
    mean = points.mean(axis=0)
    scale = np.linalg.norm(points - mean, axis=1).max()
    unit = (points - mean) / scale  # inside the unit ball: A = 2/3 · 1, b = 0 is strictly feasible
    n = len(unit)
    jacobian = np.zeros((n, 3, 9))  # d(A x + b)/dz for z = (A11, A22, A33, A12, A13, A23, b)
    jacobian[:, :, :6] = np.einsum("kij,nj->nik", _SYMMETRIC, unit)
    jacobian[:, :, 6:] = np.eye(3)
    z = np.array([2 / 3, 2 / 3, 2 / 3, 0, 0, 0, 0, 0, 0])
    weight = 1.0
    while True:
        z = _centre(z, weight, jacobian)
        if n / weight < gap:  # the barrier's duality gap bounds the excess of -log det A
            break
        weight *= 10
    a = np.einsum("k,kij->ij", z[:6], _SYMMETRIC)
    centre = mean - scale * np.linalg.solve(a, z[6:])
    shape = a @ a / scale**2
    offsets = points - centre
    shape /= np.einsum("ij,jk,ik->i", offsets, shape, offsets).max()
    return centre, (shape + shape.T) / 2


#: The basis of symmetric 3 × 3 matrices in which ``A`` is ``z[:6]``.
_SYMMETRIC = np.zeros((6, 3, 3))
for _k, (_i, _j) in enumerate([(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]):
    _SYMMETRIC[_k, _i, _j] = _SYMMETRIC[_k, _j, _i] = 1.0


def _centre(z: np.ndarray, weight: float, jacobian: np.ndarray, max_steps: int = 100) -> np.ndarray:
    """Damped Newton steps to the minimum of ``−weight · log det A − Σ log(1 − |A xᵢ + b|²)``."""
    flat = jacobian.reshape(-1, 9)

    def parts(z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r = (flat @ z).reshape(-1, 3)
        return np.einsum("k,kij->ij", z[:6], _SYMMETRIC), r, 1.0 - (r * r).sum(axis=1)

    def value(z: np.ndarray) -> float:
        a, _, slack = parts(z)
        if slack.min() <= 0:
            return np.inf
        try:
            log_det = 2 * np.log(np.diag(np.linalg.cholesky(a))).sum()
        except np.linalg.LinAlgError:
            return np.inf
        return -weight * log_det - np.log(slack).sum()

    for _ in range(max_steps):
        a, r, slack = parts(z)
        inverse_basis = np.linalg.inv(a) @ _SYMMETRIC  # A⁻¹ E_k
        pull = (jacobian * (r / slack[:, None])[:, :, None]).sum(axis=1)  # Jᵢᵀ rᵢ / sᵢ
        scaled = flat / np.repeat(np.sqrt(slack), 3)[:, None]
        gradient = 2 * pull.sum(axis=0)
        gradient[:6] -= weight * np.trace(inverse_basis, axis1=1, axis2=2)
        hessian = 4 * pull.T @ pull + 2 * scaled.T @ scaled
        hessian[:6, :6] += weight * np.einsum("kij,lji->kl", inverse_basis, inverse_basis)
        try:
            step = -np.linalg.solve(hessian, gradient)
        except np.linalg.LinAlgError:
            break
        decrement = -gradient @ step
        if decrement < 1e-10:
            break
        start, length = value(z), 1.0
        while length > 1e-12:  # backtrack: stay inside and decrease (near the minimum: stay inside)
            trial = value(z + length * step)
            if trial <= start - 0.25 * length * decrement or (decrement < 1e-3 and np.isfinite(trial)):
                break
            length /= 2
        else:
            break  # no progress in round-off: the ellipsoid is scaled to the points all the same
        z = z + length * step
    return z


def thickened(points: np.ndarray, floor: float = 0.01) -> tuple[np.ndarray, float]:
    """``points[n, 3]`` extruded along the principal directions in which they are flat (a plate, a
    segment: no ellipsoid of positive volume is tight), and the half-thickness given them: ``floor``
    times the largest half-width (0 when none is flat). Flat means under 1e-6 of the largest.

    Raises:
        ValueError: the points coincide (to 1e-9 m): nothing to bound.
    """
    offsets = points - points.mean(axis=0)
    directions = np.linalg.eigh(offsets.T @ offsets)[1].T
    widths = np.abs(offsets @ directions.T).max(axis=0)
    if widths.max() < 1e-9:
        raise ValueError("the geometry is a single point")
    flat = directions[widths < 1e-6 * widths.max()]
    pad = floor * widths.max() if len(flat) else 0.0
    for direction in flat:
        points = np.concatenate([points + pad * direction, points - pad * direction])
    return points, pad


def ellipsoid_bound(centre: np.ndarray, shape: np.ndarray) -> np.ndarray:
    """``Q4[4, 4]`` of the ellipsoid ``(c, Q)``: a pseudo-inertia ``J ⪰ 0`` (idkit's layout,
    :func:`idkit.robots.inertia.pseudo_inertia_rows`) has its mass inside iff ``tr(J Q4) ≥ 0``."""
    qc = shape @ centre
    bound = np.empty((4, 4))
    bound[:3, :3], bound[:3, 3], bound[3, :3] = -shape, qc, qc
    bound[3, 3] = 1.0 - centre @ qc
    return bound
