"""The CAD reference bodies of the consistent program, in the units the program solves in.

A URDF's inertials are the prior of ``pcls`` and what the unidentifiable directions are resolved
towards. Shipped URDFs often describe bodies no solver can work near: a rod with no inertia about
its axis, a flat disc, a point mass (their pseudo-inertia is singular, so the entropic divergence to
them is infinite and its gradient ``J0⁻¹`` huge), or an impossible inertia (a triangle inequality
broken). Rather than hand a solver that ill-conditioning, each reference body is made *thick*:
every principal second moment about the centre of mass is raised to at least that of a body
``MIN_THICKNESS`` times its own largest extent, and at least ``MIN_SIZE`` times the link's size (a
point mass). The data are not touched and a fitted body may still be as thin as the data say; only
the reference the prior pulls towards and its conditioning change, and the command says which links
were changed (:class:`ReferenceNote`, :class:`ReferenceWarning`).

Units. The program's unknowns are the standard parameters divided by the CAD magnitudes
``(m0, m0 L, m0 L²)`` of their link (``L`` the CAD radius of gyration about the link origin, at least
``MIN_LENGTH``), so that a solver sees O(1) numbers. The pseudo-inertia of the scaled parameters is a
congruence of the physical one, ``J(p) = m0 S J(z) S`` with ``S = diag(L, L, L, 1)``: positive
semidefinite together, same divergence. A CAD body is ``m = 1`` in these units.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from idkit.notes import Note
from idkit.robots.inertia import link_count, pseudo_inertia_rows

if TYPE_CHECKING:
    from idkit.robots.urdf import URDFRobot

#: A reference body is at least this fraction of its own largest extent thick in every direction
#: (second moments ``>= MIN_THICKNESS² λ_max``): a rod 10 % as wide as it is long.
MIN_THICKNESS = 0.1
#: ... and at least this fraction of its link's size ``L`` (a point mass becomes a small ball).
MIN_SIZE = 0.01
#: Floor of the link size ``L`` (m): links with tiny CAD inertia still get sensible units.
MIN_LENGTH = 0.05


class ReferenceNote(Note):
    """Degenerate CAD bodies (thin, flat, point masses) were thickened for the prior: which."""


class ReferenceWarning(UserWarning):
    """CAD inertias no rigid body has were replaced by the nearest physical ones for the prior: which."""


@dataclass(frozen=True)
class CadReference:
    """The CAD model as the consistent program sees it.

    Attributes:
        unit: ``[P]`` the magnitude each parameter is divided by (``m0, m0 L, m0 L²`` per link, 1 for
            friction, offsets and armature).
        pseudo: ``[nb, 4, 4]`` the reference pseudo-inertias in scaled units, positive definite.
        thickened: links whose CAD body was degenerate (thin, flat or a point mass).
        replaced: links whose CAD inertia no rigid body has (replaced by the nearest physical one).
    """

    unit: np.ndarray
    pseudo: np.ndarray
    thickened: tuple[str, ...]
    replaced: tuple[str, ...]

    def announce(self, who: str) -> None:
        """Say on the console which CAD bodies the prior uses changed (nothing if none)."""
        if self.replaced:
            warnings.warn(
                f"{who}: the CAD inertia of {_listed(self.replaced)} is no rigid body's (a principal moment "
                "negative or larger than the other two together); its prior is the nearest physical body",
                ReferenceWarning,
                stacklevel=3,
            )
        if self.thickened:
            warnings.warn(
                f"{who}: the CAD body of {_listed(self.thickened)} is degenerate (a thin rod, a flat plate "
                f"or a point mass); its prior is thickened to at least {MIN_THICKNESS:g} of its length in "
                "every direction (the fit itself is not constrained by this)",
                ReferenceNote,
                stacklevel=3,
            )


def _listed(names: tuple[str, ...]) -> str:
    shown = ", ".join(names[:4])
    return shown + (f" and {len(names) - 4} more links" if len(names) > 4 else "")


def parameter_units(robot: URDFRobot) -> np.ndarray:
    """Typical magnitude ``[P]`` of each parameter: ``m0``, ``m0 L``, ``m0 L²`` per link (``L`` the
    CAD radius of gyration about the link origin, at least ``MIN_LENGTH``); 1 for the rest."""
    nb = link_count(robot)
    nominal = robot.nominal_params().double().numpy()
    unit = np.ones(robot.n_params)
    for i in range(nb):
        m0 = nominal[10 * i]
        if not m0 > 0:
            continue  # refused by cad_reference; the projection only needs some scale
        trace = nominal[10 * i + 4] + nominal[10 * i + 7] + nominal[10 * i + 9]
        length = max(float(np.sqrt(max(trace, 0.0) / (2 * m0))), MIN_LENGTH)
        unit[10 * i : 10 * i + 10] = [m0, *[m0 * length] * 3, *[m0 * length**2] * 6]
    return unit


def cad_reference(robot: URDFRobot) -> CadReference:
    """The CAD reference bodies of a ``urdf`` robot, well-posed (module doc).

    Raises:
        ValueError: a moving link without ``<inertial>`` (CAD mass 0 or less): there is no scale to
            fit it in and nothing to pull it towards.
    """
    nb = link_count(robot)
    nominal = robot.nominal_params().double().numpy()[: 10 * nb].reshape(nb, 10)
    empty = [name for name, row in zip(robot.link_names, nominal, strict=True) if not row[0] > 0.0]
    if empty:
        raise ValueError(
            f"urdf: link(s) {', '.join(map(repr, empty))} have no <inertial> (CAD mass 0); physically "
            "consistent fitting needs a-priori inertials in the URDF (any rough mass and box inertia)"
        )
    unit = parameter_units(robot)
    pseudo, thickened, replaced = [], [], []
    for name, row, scale in zip(robot.link_names, nominal, unit[: 10 * nb].reshape(nb, 10), strict=True):
        body, change = _thick_body(np.array(pseudo_inertia_rows(list(row / scale)), dtype=np.float64))
        pseudo.append(body)
        if change == "replaced":
            replaced.append(name)
        elif change == "thickened":
            thickened.append(name)
    return CadReference(unit, np.stack(pseudo), tuple(thickened), tuple(replaced))


def reference_body(j: np.ndarray) -> np.ndarray:
    """The reference a CAD pseudo-inertia ``j`` (scaled units) stands for in the prior: thickened where
    degenerate (module doc). What a fitted body's thinness is measured against."""
    return _thick_body(j)[0]


def _thick_body(j: np.ndarray) -> tuple[np.ndarray, str | None]:
    """A scaled pseudo-inertia (mass 1) with its central second moments floored (module doc), and what
    was done: ``None``, ``"thickened"`` or ``"replaced"`` (a negative central second moment)."""
    mass, first = j[3, 3], j[:3, 3]
    centre = first / mass
    central = j[:3, :3] - mass * np.outer(centre, centre)
    values, vectors = np.linalg.eigh((central + central.T) / 2)
    floor = max(MIN_THICKNESS**2 * max(values[-1], 0.0), MIN_SIZE**2 * mass)
    tolerance = 1e-9 * max(values[-1], MIN_SIZE**2 * mass)
    change = None
    if values[0] < -tolerance:
        change = "replaced"
    elif values[0] < floor * (1 - 1e-9):
        change = "thickened"
    raised = vectors @ np.diag(np.maximum(values, floor)) @ vectors.T
    out = np.empty((4, 4))
    out[:3, :3] = raised + mass * np.outer(centre, centre)
    out[:3, 3] = out[3, :3] = first
    out[3, 3] = mass
    return out, change
