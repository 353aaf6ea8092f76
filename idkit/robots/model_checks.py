"""Refuse a robot model that would give a silently wrong answer, whatever file format it came from.

Every model reader (``idkit.robots.urdf_model.parse_urdf``, and any other reader producing a
:class:`~idkit.robots.urdf_model.KinematicTree`) calls :func:`check_model` before returning. It
refuses, in one line naming the element and the file:

* a joint name or a link name used twice (parameters are named after them: two ``r2.fc`` would
  be merged into one);
* a number that is not finite in a joint's placement, axis or limits, or in a link's inertial;
* a negative link mass (the least-squares family would fit it and return meaningless parameters);
* a joint whose lower position limit exceeds its upper one (an excitation would drop the limit).

A link whose inertia is not that of any rigid body (:func:`inertia_problem`) is warned about
(:class:`ModelWarning`): most estimators fit such a model all the same, whose a-priori values
then only seed search boxes. Physically consistent fitting (``pcls``) refuses it through
:func:`nonphysical_links`, as its prior is the CAD mass distribution.
"""

from __future__ import annotations

import warnings
from collections import Counter
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from idkit.robots.urdf_model import KinematicTree, LinkInertial

#: Round-off allowed in the triangle inequality, relative to the largest principal moment: CAD
#: files print inertias to a few digits, and thin rods or flat plates sit exactly on the boundary.
INERTIA_TOLERANCE = 1e-6


class ModelError(ValueError):
    """A robot model that cannot describe a real robot (one line: element, file, what is wrong)."""


class ModelWarning(UserWarning):
    """A robot model that is fitted, but whose a-priori inertials are not physical."""


def inertia_problem(inertia: np.ndarray) -> str | None:
    """Why ``inertia[3, 3]`` (about the centre of mass) is no rigid body's, or ``None``.

    A mass distribution with a mass ``>= 0`` exists iff the principal moments ``a <= b <= c`` about
    the centre of mass satisfy ``a + b >= c`` (the triangle inequality, which also makes every
    moment ``>= 0``). That is the same condition as a positive semidefinite 4×4 pseudo-inertia
    (Wensing, Kim & Slotine 2017): its second-moment block about the centre of mass has the
    eigenvalues ``(a + b - c) / 2, …``. Checked up to :data:`INERTIA_TOLERANCE`.
    """
    a, b, c = np.linalg.eigvalsh((inertia + inertia.T) / 2)
    slack = INERTIA_TOLERANCE * max(abs(a), abs(c))
    moments = f"principal moments {a:.4g}, {b:.4g}, {c:.4g} kg·m² about the centre of mass"
    if a < -slack:
        return f"{moments}: {a:.4g} is negative"
    if a + b < c - slack:
        return f"{moments} violate the triangle inequality ({a:.4g} + {b:.4g} < {c:.4g})"
    return None


def nonphysical_links(tree: KinematicTree) -> list[str]:
    """One message per link whose inertial is no rigid body's (``link 'x' (file): why``)."""
    found = []
    for link in tree.links:
        problem = inertia_problem(link.inertia)
        if problem is not None:
            found.append(f"link {link.name!r} ({tree.source}): {problem}")
    return found


def check_model(tree: KinematicTree) -> None:
    """Refuse what cannot be a real robot; warn about non-physical inertias (module docstring).

    Raises:
        ModelError: the first problem found, in one line naming the element and ``tree.source``.

    Warns:
        ModelWarning: once per link whose inertia is not physical.
    """
    where = tree.source
    links = tuple(link.name for link in tree.links)
    for kind, names in (("joint", tree.joint_names + tree.fixed_joints), ("link", links)):
        repeated = [name for name, count in Counter(names).items() if count > 1]
        if repeated:
            raise ModelError(
                f"{kind} {repeated[0]!r} ({where}) is defined {names.count(repeated[0])} times; "
                f"{kind} names must be unique (parameters are named after them)"
            )
    for body in tree.bodies:
        numbers = (body.rotation, body.translation, body.axis, body.limits or ())
        if not all(np.isfinite(x).all() for x in numbers):
            raise ModelError(f"joint {body.joint!r} ({where}): its placement, axis or limits are not finite")
        if body.limits is not None and body.limits[0] > body.limits[1]:
            lower, upper = body.limits
            raise ModelError(f"joint {body.joint!r} ({where}): lower limit {lower:g} > upper limit {upper:g}")
    for link in tree.links:
        _check_link(link, where)
    for message in nonphysical_links(tree):
        warnings.warn(
            f"{message}: not a rigid body; fitted all the same (pcls takes the nearest physical body as "
            "its prior)",
            ModelWarning,
            stacklevel=3,
        )


def _check_link(link: LinkInertial, where: str) -> None:
    values = {"mass": np.asarray(link.mass), "centre of mass": link.com, "inertia": link.inertia}
    for what, value in values.items():
        if not np.isfinite(value).all():
            raise ModelError(f"link {link.name!r} ({where}): {what} {value.tolist()} is not finite")
    if link.mass < 0:
        raise ModelError(f"link {link.name!r} ({where}): mass {link.mass:g} kg is negative")
