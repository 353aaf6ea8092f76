"""What a payload fit identified, in one verdict per quantity that every line of its report follows.

A controller takes a payload's mass, centre of mass and inertia; it should be handed only what the
recording determined. Each is judged once, here, and the printed block, ``result.json`` and the
SDK calls all read that verdict:

* a value is **identified** when its standard deviation is finite and at most
  :data:`IDENTIFIED_SHARE` (10 %) of the quantity's scale: the mass itself; for a coordinate of
  the centre of mass, the centre's distance from the frame's origin (at least :data:`MIN_LENGTH`,
  1 cm); for an entry of the inertia, its largest principal moment (at least ``m · MIN_LENGTH²``);
* the centre of mass is identified when all three coordinates are, the inertia when all six
  entries are — an SDK call takes the whole vector or matrix;
* a call is printed only when every quantity it takes is identified
  (:func:`sdk_calls`); the others are named with the quantity they lack.

Two recordings the fit cannot use are recognised by what they are, not only by their numbers
(:func:`motion_share`):

* a **static** recording (its torques change by less than :data:`STATIC_SHARE` when its velocities
  and accelerations are set to zero: a robot held still, or creeping) shows the weight, never the
  inertia;
* a **reference** (``correction=model``) that is static or whose base regressor is worse
  conditioned than :data:`REFERENCE_COND` cannot fix the arm's correction: the correction is then
  fitted from the payload's recording, where it trades against the payload, so nothing of the
  payload counts as identified.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch

#: A value is identified when its standard deviation is at most this share of its scale.
IDENTIFIED_SHARE = 0.1
#: The smallest length scale (m) of a centre of mass, and of a radius of gyration.
MIN_LENGTH = 0.01
#: A recording whose inertial torque columns lose less than this share of their norm when its
#: velocities and accelerations are zeroed is static (the tour's excitation: 0.73; held at rest
#: with 1e-4 rad of encoder noise: 0.0013).
STATIC_SHARE = 0.01
#: A reference whose column-equilibrated base regressor is worse conditioned than this does not
#: show every base parameter of the arm (the tour's excitation: 34; the KUKA recordings: about 77;
#: the tour's arm held at rest: 2.5e4).
REFERENCE_COND = 1e3

AXES = ("x", "y", "z")
#: The inertia's entries as SDKs list them, with their place in the 3×3 matrix.
INERTIA_ENTRIES = (("Ixx", 0, 0), ("Iyy", 1, 1), ("Izz", 2, 2), ("Ixy", 0, 1), ("Ixz", 0, 2), ("Iyz", 1, 2))


def _share(std: float, scale: float) -> float:
    """``std / scale`` (``inf`` for an infinite or undefined standard deviation)."""
    return float(std / scale) if np.isfinite(std) and scale > 0 else float("inf")


def verdict(
    mass: float,
    mass_std: float,
    com: Sequence[float],
    com_std: Sequence[float],
    inertia: Sequence[Sequence[float]],
    inertia_std: Sequence[Sequence[float]],
    unusable: str | None = None,
) -> dict[str, Any]:
    """The verdict of each quantity (module doc): ``{"mass": bool, "com": bool, "inertia": bool,
    "shares": {name: std / scale}, "unusable": why or None, "rule": …}``.

    ``shares`` holds ``m``, ``cx``, ``cy``, ``cz`` and the six inertia entries; ``unusable`` (a
    reference that cannot fix the arm) makes every quantity unidentified.
    """
    com_, inertia_ = np.asarray(com, dtype=float), np.asarray(inertia, dtype=float)
    length = max(float(np.linalg.norm(com_)), MIN_LENGTH)
    moment = max(float(np.linalg.eigvalsh(inertia_).max()), mass * MIN_LENGTH**2)
    shares = {"m": _share(mass_std, abs(mass))}
    shares |= {f"c{axis}": _share(com_std[k], length) for k, axis in enumerate(AXES)}
    shares |= {name: _share(inertia_std[i][j], moment) for name, i, j in INERTIA_ENTRIES}
    known = {name: share <= IDENTIFIED_SHARE and unusable is None for name, share in shares.items()}
    return {
        "mass": known["m"],
        "com": all(known[f"c{axis}"] for axis in AXES),
        "inertia": all(known[name] for name, _, _ in INERTIA_ENTRIES),
        "identified": known,
        "shares": shares,
        "unusable": unusable,
        "rule": (
            f"identified: standard deviation at most {100 * IDENTIFIED_SHARE:g} % of the quantity's scale, "
            f"which is the mass itself, the centre of mass's distance from the origin (at least "
            f"{100 * MIN_LENGTH:g} cm), the inertia's largest principal moment"
        ),
    }


def sdk_calls(sdk: Mapping[str, Any], judged: Mapping[str, Any]) -> dict[str, Any]:
    """The SDK arguments (``payload.sdk_conventions``) of the calls whose every quantity is identified,
    and ``withheld``: each other call with the quantities it lacks."""
    lacking = [
        name
        for name, key in (("mass", "mass"), ("centre of mass", "com"), ("inertia", "inertia"))
        if not judged[key]
    ]
    out: dict[str, Any] = {"withheld": []}
    full = not lacking
    if full:
        out["libfranka"] = sdk["libfranka"]
        out["ur"] = sdk["ur"]
        return out
    missing = lacking[0] if len(lacking) == 1 else ", ".join(lacking[:-1]) + " and " + lacking[-1]
    out["withheld"].append(
        f"libfranka setLoad and URScript set_target_payload (they take the inertia): {missing} not identified"
    )
    if judged["mass"] and judged["com"]:
        out["ur"] = {"mass": sdk["ur"]["mass"], "cog": sdk["ur"]["cog"]}
    else:
        out["withheld"].append(f"URScript set_payload and ur_rtde setPayload: {missing} not identified")
    return out


def motion_share(robot: Any, q: torch.Tensor, qd: torch.Tensor, qdd: torch.Tensor, columns: slice) -> float:
    """The share of the standard regressor's ``columns`` (a body's inertial parameters) that comes from
    motion: ``‖Y(q, q̇, q̈) − Y(q, 0, 0)‖ / ‖Y(q, q̇, q̈)‖`` over the samples ``[N, n]`` (0: static)."""
    with torch.no_grad():
        moving = robot.standard_regressor(q, qd, qdd)[..., columns]
        still = robot.standard_regressor(q, torch.zeros_like(qd), torch.zeros_like(qdd))[..., columns]
    total = float(moving.norm())
    return float((moving - still).norm()) / total if total > 0 else 0.0


def equilibrated_cond(W: torch.Tensor) -> float:
    """The condition number of ``W[M, B]`` with unit-norm columns (``inf`` with a zero column)."""
    norms = torch.linalg.vector_norm(W, dim=0)
    if not bool((norms > 0).all()):
        return float("inf")
    s = torch.linalg.svdvals(W / norms)
    return float(s[0] / s[-1]) if float(s[-1]) > 0 else float("inf")


def recording_notes(excitation: Mapping[str, Any], reference: str | None) -> tuple[list[str], str | None]:
    """Lines for a static data file or an unusable reference (module doc), and why the reference makes
    the fit unusable (``None`` when it does not)."""
    lines, unusable = [], None
    share = excitation.get("data_motion_share")
    if share is not None and share < STATIC_SHARE:
        lines.append(
            f"the data hardly move: {100 * share:.2g} % of the payload's torque comes from motion "
            "(velocities and accelerations), the rest is its weight; the inertia cannot be identified from "
            "it, the mass and centre of mass only across the poses it holds"
        )
    ref_share, cond = excitation.get("reference_motion_share"), excitation.get("reference_cond")
    if reference is not None and ref_share is not None and cond is not None:
        static = ref_share < STATIC_SHARE
        if static or cond > REFERENCE_COND:
            why = (
                f"it hardly moves ({100 * ref_share:.2g} % of the arm's torque comes from motion)"
                if static
                else f"it excites the arm poorly (base regressor's condition number {cond:.3g} > "
                f"{REFERENCE_COND:g})"
            )
            unusable = f"the reference {reference} cannot show the arm's errors: {why}"
            lines.append(
                f"reference {reference} is no reference: {why}. The arm's correction it should fix is then "
                f"fitted from the data themselves, where it trades against the payload, so nothing here is "
                "identified; record the reference with the same motion as the data (correction=samples), "
                "or a motion that moves every joint"
            )
    return lines, unusable
