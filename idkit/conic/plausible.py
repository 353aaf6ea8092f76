"""Plausible, not only consistent: bounds that keep each identified link a body like its CAD one.

A positive semidefinite pseudo-inertia says a body *can exist*; it does not say it is this robot's
link. On real logs an unconstrained consistent fit can move mass between links the motion cannot
tell apart (an upper arm at four times its CAD mass, a forearm at three): the held-out torque error
does not see it, a controller or a simulator does. The options here, all linear in the standard
parameters (so they join the same conic program, :mod:`idkit.conic.program`):

* ``mass_ratio = (lo, hi)``: every link mass within ``[lo, hi]`` times its CAD mass;
* ``total_mass``: the moving links' masses sum to a known value (kg), e.g. from the data sheet;
* ``geometry``: where the model has collision (or else visual) geometry for a link, its mass lies
  inside the ellipsoid bounding that geometry — the density-realisability condition of Wensing, Kim
  & Slotine (RA-L 2017), ``tr(J Q) >= 0``, which also puts the centre of mass inside it
  (:mod:`idkit.robots.geometry` builds the ellipsoids).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from idkit.robots.inertia import link_count

if TYPE_CHECKING:
    from idkit.robots.urdf import URDFRobot


@dataclass(frozen=True)
class Plausibility:
    """Plausibility bounds of the consistent program (module doc); all off by default here, the
    estimators choose their own defaults.

    Attributes:
        mass_ratio: ``(lo, hi)`` with ``0 <= lo <= 1 <= hi``: link masses within these multiples of CAD.
        total_mass: the moving links' total mass (kg), or ``None``.
        geometry: each link's mass inside the ellipsoid bounding its geometry, where it has some.
    """

    mass_ratio: tuple[float, float] | None = None
    total_mass: float | None = None
    geometry: bool = False

    @classmethod
    def checked(
        cls, who: str, mass_ratio: Any = None, total_mass: Any = None, geometry: bool = False
    ) -> Plausibility:
        """The bounds, or ``ValueError`` naming ``who`` and the option."""
        ratio = None
        if mass_ratio is not None:
            try:
                lo, hi = (float(x) for x in mass_ratio)
            except (TypeError, ValueError):
                raise ValueError(
                    f"{who}: mass_ratio must be [lo, hi] (multiples of each link's CAD mass), "
                    f"got {mass_ratio!r}"
                ) from None
            if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo <= 1 <= hi):
                raise ValueError(
                    f"{who}: mass_ratio [lo, hi] needs 0 <= lo <= 1 <= hi, got [{lo:g}, {hi:g}]: the band is "
                    "around each link's CAD mass (1 x CAD, also the prior the fit is drawn to); if the CAD "
                    "masses are off, correct them in the model file, or bound the sum with total_mass"
                )
            ratio = (lo, hi)
        total = None
        if total_mass is not None:
            if isinstance(total_mass, bool) or not isinstance(total_mass, (int, float)):
                raise ValueError(f"{who}: total_mass must be a number of kg or null, got {total_mass!r}")
            if not (math.isfinite(total_mass) and total_mass > 0):
                raise ValueError(f"{who}: total_mass must be > 0 kg, got {total_mass!r}")
            total = float(total_mass)
        return cls(ratio, total, bool(geometry))

    @property
    def active(self) -> bool:
        return self.mass_ratio is not None or self.total_mass is not None or self.geometry

    def describe(self) -> str:
        """One phrase for reports: what was bounded."""
        parts = []
        if self.mass_ratio is not None:
            parts.append(f"link masses within [{self.mass_ratio[0]:g}, {self.mass_ratio[1]:g}] x CAD")
        if self.total_mass is not None:
            parts.append(f"total mass {self.total_mass:g} kg")
        if self.geometry:
            parts.append("mass inside each link's geometry (where the model has some)")
        return "; ".join(parts) or "none"


def plausibility_constraints(
    robot: URDFRobot, bounds: Plausibility, z: Any, unit: np.ndarray, who: str
) -> list[Any]:
    """cvxpy constraints on the scaled unknowns ``z`` (``p = unit * z``) for ``bounds``.

    Raises:
        ValueError: bounds that cannot hold together (a total mass outside what the ratios allow).
    """
    nb = link_count(robot)
    masses = z[0 : 10 * nb : 10]  # in units of each link's CAD mass
    cad = unit[0 : 10 * nb : 10]
    out = []
    if bounds.mass_ratio is not None:
        lo, hi = bounds.mass_ratio
        out += [masses >= lo, masses <= hi]
    if bounds.total_mass is not None:
        if bounds.mass_ratio is not None:
            lo, hi = bounds.mass_ratio
            if not lo * cad.sum() <= bounds.total_mass <= hi * cad.sum():
                raise ValueError(
                    f"{who}: total_mass={bounds.total_mass:g} kg is outside what mass_ratio allows "
                    f"([{lo * cad.sum():g}, {hi * cad.sum():g}] kg for the CAD total {cad.sum():g} kg)"
                )
        out.append(cad @ masses == bounds.total_mass)
    if bounds.geometry:
        out += _inside_geometry(robot, z, unit)
    return out


def _inside_geometry(robot: URDFRobot, z: Any, unit: np.ndarray) -> list[Any]:
    """``tr(J_i Q4_i) >= 0`` for every link with geometry, on the scaled unknowns: ``J(p) = m0 S J(z) S``
    with ``S = diag(L, L, L, 1)`` (:mod:`idkit.conic.prior`), so ``tr(J(z) S Q4 S) >= 0``."""
    import cvxpy as cp

    from idkit.conic.program import pseudo_inertia_expression
    from idkit.robots.geometry import body_geometry

    found = body_geometry(robot).bodies
    out = []
    for i, link in enumerate(robot.link_names):
        geometry = found.get(link)
        if geometry is None:
            continue
        length = unit[10 * i + 1] / unit[10 * i]
        stretch = np.diag([length, length, length, 1.0])
        bound = stretch @ geometry.q4() @ stretch
        out.append(cp.trace(pseudo_inertia_expression(z[10 * i : 10 * i + 10], cp) @ bound) >= 0)
    return out


#: A link mass outside these multiples of its CAD mass is flagged as implausible in every report,
#: and is the default bound of ``plausible=true``: a link weighs what its CAD says to within a factor
#: of two, or the CAD (or the fit) is wrong.
PLAUSIBLE_MASS_RATIO = (0.5, 2.0)


def plausibility_report(robot: URDFRobot, bounds: Plausibility, params: Any) -> dict[str, Any]:
    """For ``details["plausibility"]``: what was enforced, each link's mass and centre of mass beside
    CAD, the links that are implausible — a mass outside :data:`PLAUSIBLE_MASS_RATIO` times CAD, or a
    centre of mass the fit moved out of the box bounding the link's geometry (where the CAD's is
    inside it) — and those that ended at an enforced mass bound (within 1e-6 relative: where the
    data pulled against plausibility)."""
    from idkit.robots.geometry import body_geometry

    nb = link_count(robot)
    values = np.asarray(params[: 10 * nb].tolist(), dtype=np.float64).reshape(nb, 10)
    cad_values = robot.nominal_params().double().numpy()[: 10 * nb].reshape(nb, 10)
    fitted, cad = values[:, 0], cad_values[:, 0]
    centres = values[:, 1:4] / np.where(fitted > 0, fitted, np.nan)[:, None]
    cad_centres = cad_values[:, 1:4] / cad[:, None]
    ratio = fitted / cad
    lo, hi = PLAUSIBLE_MASS_RATIO
    names = robot.link_names
    heavy = {name for name, r in zip(names, ratio, strict=True) if not lo <= r <= hi}
    geometry = body_geometry(robot)
    moved = {
        name
        for name, centre, cad_centre in zip(names, centres, cad_centres, strict=True)
        if (shape := geometry.bodies.get(name)) is not None
        and shape.in_box(cad_centre)
        and not (np.isfinite(centre).all() and shape.in_box(centre))
    }
    at_bound: list[str] = []
    if bounds.mass_ratio is not None:
        lo, hi = bounds.mass_ratio
        at_bound = [
            name
            for name, r in zip(names, ratio, strict=True)
            if abs(r - lo) <= 1e-6 * max(lo, 1e-12) or abs(r - hi) <= 1e-6 * hi
        ]
    return {
        "enforced": bounds.describe(),
        "mass": dict(zip(names, fitted.tolist(), strict=True)),
        "cad_mass": dict(zip(names, cad.tolist(), strict=True)),
        "com": dict(zip(names, centres.tolist(), strict=True)),
        "cad_com": dict(zip(names, cad_centres.tolist(), strict=True)),
        "implausible": [name for name in names if name in heavy or name in moved],
        "mass_outside": [name for name in names if name in heavy],
        "com_outside_geometry": [name for name in names if name in moved],
        "flagged_outside": list(PLAUSIBLE_MASS_RATIO),
        "geometry": geometry.summary(),
        "at_bound": at_bound,
    }
