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
  (:mod:`idkit.robots.geometry` builds the ellipsoids; placeholder geometry is not among them).

And the one verdict every report reads: :func:`plausibility_report` decides, per link, whether a fit
is plausible and why not (:func:`plausibility_rule`), once, into ``details["plausibility"]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from idkit.robots.inertia import link_count, pseudo_inertia_rows

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
#: A link is *degenerate* — a rod or a plate — when its thinnest radius of gyration about its centre of
#: mass is under this fraction of its largest (a body 1:20 thin; a forearm tube is about 1:5, and the
#: prior's reference bodies are at least 1:10, :data:`idkit.conic.prior.MIN_THICKNESS`) ...
ROD_FRACTION = 0.05
#: ... or a point mass, when its largest radius of gyration is under this fraction of the size its
#: geometry gives (a solid filling the bounding ellipsoid: the largest semi-axis over √5), or without
#: trusted geometry, of the CAD body's (the prior's reference, :mod:`idkit.conic.prior`).
POINT_FRACTION = 0.1
#: A pseudo-inertia eigenvalue below ``-BODY_TOLERANCE × max(1, |m|)`` is no body's (round-off above).
BODY_TOLERANCE = 1e-9


def plausibility_rule() -> str:
    """The rule every report states beside the verdicts (:func:`plausibility_report` applies it)."""
    lo, hi = PLAUSIBLE_MASS_RATIO
    return (
        f"plausible: a body that can exist (pseudo-inertia positive semidefinite), a mass within "
        f"[{lo:g}, {hi:g}] x CAD, not degenerate (no rod or plate thinner than 1:{1 / ROD_FRACTION:g}, no "
        f"point mass under {POINT_FRACTION:g} of the link's size), and a centre of mass inside the link's "
        "geometry where the model has real geometry for it"
    )


def degenerate(robot: URDFRobot, params: np.ndarray) -> dict[str, str]:
    """The links ``params`` make a rod, a plate or a point mass (:data:`ROD_FRACTION`,
    :data:`POINT_FRACTION`), each with why; bodies that cannot exist are not judged here."""
    from idkit.conic.prior import parameter_units, reference_body
    from idkit.robots.geometry import body_geometry

    nb = link_count(robot)
    unit = parameter_units(robot)[: 10 * nb].reshape(nb, 10)
    rows = np.asarray(params[: 10 * nb], dtype=np.float64).reshape(nb, 10)
    cad = robot.nominal_params().double().numpy()[: 10 * nb].reshape(nb, 10)
    shapes = body_geometry(robot).bodies
    out = {}
    for name, row, cad_row, scale in zip(robot.link_names, rows, cad, unit, strict=True):
        if not row[0] > 0 or np.linalg.eigvalsh(_pseudo(row))[0] < -BODY_TOLERANCE * max(1.0, row[0]):
            continue
        smallest, largest = _radii(_pseudo(row))
        shape = shapes.get(name)
        if shape is not None:
            size, whose = float(np.linalg.eigvalsh(shape.ellipsoid_shape)[0] ** -0.5 / np.sqrt(5)), "geometry"
        elif cad_row[0] > 0:  # the reference in scaled units, back in metres
            length = np.sqrt(scale[4] / scale[0])
            size, whose = _radii(reference_body(_pseudo(cad_row / scale)))[1] * length, "CAD body"
        else:
            continue
        if largest < POINT_FRACTION * size:
            out[name] = (
                f"a point mass: radius of gyration {1e3 * largest:.3g} mm against {1e3 * size:.3g} mm for "
                f"its {whose}"
            )
        elif smallest < ROD_FRACTION * largest:
            out[name] = f"a rod or plate: thinnest radius of gyration {smallest / largest:.2g} of its largest"
    return out


def _radii(j: np.ndarray) -> tuple[float, float]:
    """The smallest and largest principal radius of gyration about the centre of mass."""
    mass, first = j[3, 3], j[:3, 3]
    central = j[:3, :3] - np.outer(first, first) / mass
    values = np.linalg.eigvalsh((central + central.T) / 2) / mass
    return float(np.sqrt(max(values[0], 0.0))), float(np.sqrt(max(values[-1], 0.0)))


def _pseudo(row: np.ndarray) -> np.ndarray:
    return np.array(pseudo_inertia_rows(list(row)), dtype=np.float64)


def plausibility_report(robot: URDFRobot, bounds: Plausibility | None, params: Any) -> dict[str, Any]:
    """The one plausibility verdict of a fit (``details["plausibility"]``), which every report reads.

    Per link (``links``): its mass and centre of mass beside CAD, the smallest pseudo-inertia
    eigenvalue, what bounds it, whether an enforced mass bound is active, and its
    verdict with the reasons (:func:`plausibility_rule`): no body can have it; its mass outside
    :data:`PLAUSIBLE_MASS_RATIO` times CAD; degenerate (:data:`DEGENERATE_FRACTION`); its centre of mass
    moved out of the box bounding its trusted geometry (where CAD's is inside it). Also the lists the
    reports print (``implausible``, ``mass_outside``, ``com_outside_geometry``, ``degenerate``,
    ``not_a_body``, ``at_bound``: an enforced mass bound within 1e-6 relative, where the data pulled
    against plausibility), what was enforced, and which bodies the geometry bounds, by name."""
    from idkit.robots.geometry import body_geometry

    bounds = bounds or Plausibility()
    nb = link_count(robot)
    values = np.asarray(torch_free(params)[: 10 * nb], dtype=np.float64).reshape(nb, 10)
    cad_values = robot.nominal_params().double().numpy()[: 10 * nb].reshape(nb, 10)
    fitted, cad = values[:, 0], cad_values[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        centres = values[:, 1:4] / np.where(fitted > 0, fitted, np.nan)[:, None]
        cad_centres = cad_values[:, 1:4] / np.where(cad > 0, cad, np.nan)[:, None]
        ratio = fitted / np.where(cad > 0, cad, np.nan)
    lowest = np.array([np.linalg.eigvalsh(_pseudo(row))[0] for row in values])
    thin = degenerate(robot, values.reshape(-1))
    geometry = body_geometry(robot)
    bounded = geometry.bounded_by()
    lo, hi = PLAUSIBLE_MASS_RATIO
    links: dict[str, dict[str, Any]] = {}
    for i, name in enumerate(robot.link_names):
        reasons = []
        if lowest[i] < -BODY_TOLERANCE * max(1.0, abs(fitted[i])) or not fitted[i] > 0:
            reasons.append(f"no body has this inertia (pseudo-inertia eigenvalue {lowest[i]:.3g})")
        body = not reasons
        if np.isfinite(ratio[i]) and not lo <= ratio[i] <= hi:
            reasons.append(f"mass {ratio[i]:.3g} x CAD, outside [{lo:g}, {hi:g}]")
        if body and name in thin:
            reasons.append(f"degenerate: {thin[name]}")
        shape = geometry.bodies.get(name)
        if (
            shape is not None
            and np.isfinite(cad_centres[i]).all()
            and shape.in_box(cad_centres[i])
            and not (np.isfinite(centres[i]).all() and shape.in_box(centres[i]))
        ):
            reasons.append("centre of mass outside its geometry")
        at_bound = bounds.mass_ratio is not None and bool(
            abs(ratio[i] - bounds.mass_ratio[0]) <= 1e-6 * max(bounds.mass_ratio[0], 1e-12)
            or abs(ratio[i] - bounds.mass_ratio[1]) <= 1e-6 * bounds.mass_ratio[1]
        )
        links[name] = {
            "plausible": not reasons,
            "reasons": reasons,
            "mass": float(fitted[i]),
            "cad_mass": float(cad[i]),
            "ratio": float(ratio[i]),
            "com": centres[i].tolist(),
            "cad_com": cad_centres[i].tolist(),
            "min_eigenvalue": float(lowest[i]),
            "bounded_by": bounded.get(name, "nothing: no usable geometry"),
            "at_bound": at_bound,
        }

    def having(word: str) -> list[str]:
        return [name for name, link in links.items() if any(r.startswith(word) for r in link["reasons"])]

    return {
        "rule": plausibility_rule(),
        "enforced": bounds.describe(),
        "links": links,
        "implausible": [name for name, link in links.items() if not link["plausible"]],
        "mass_outside": having("mass "),
        "com_outside_geometry": having("centre of mass"),
        "degenerate": having("degenerate"),
        "not_a_body": having("no body"),
        "at_bound": [name for name, link in links.items() if link["at_bound"]],
        "mass": {name: link["mass"] for name, link in links.items()},
        "cad_mass": {name: link["cad_mass"] for name, link in links.items()},
        "com": {name: link["com"] for name, link in links.items()},
        "cad_com": {name: link["cad_com"] for name, link in links.items()},
        "flagged_outside": list(PLAUSIBLE_MASS_RATIO),
        "geometry": geometry.summary(),
        "bounded_by": bounded,
        "placeholders": dict(geometry.placeholders),
    }


def torch_free(params: Any) -> np.ndarray:
    """``params`` (a tensor, array or list) as a float64 array."""
    if hasattr(params, "detach"):
        params = params.detach().cpu().double().numpy()
    return np.asarray(params, dtype=np.float64)
