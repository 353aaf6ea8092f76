"""The payload fit's part of the printed report: mass, centre of mass, inertia and the SDK calls.

Reads only the estimate's ``details`` (``payload``, ``arm_model``, ``reference``) that
:mod:`idkit.estimators.payload` writes, so a ``result.json`` prints the same lines again.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

#: Significant digits of the numbers handed to an SDK (a payload's values are known to ~4).
DIGITS = 6


def _g(value: float) -> str:
    return f"{value:.{DIGITS}g}"


def _pm(value: float, std: float, unit: str = "") -> str:
    spread = "not identified" if std == float("inf") else f"± {std:.2g}"
    return f"{_g(value)} {spread}{unit}"


def _vector(values: Sequence[float], sep: str = ", ") -> str:
    return sep.join(_g(v) for v in values)


def lines(details: Mapping[str, Any]) -> list[str]:
    """The report lines of a payload fit's ``details`` (``[]`` for other estimates)."""
    block = details.get("payload")
    if not isinstance(block, Mapping) or "sdk" not in block:  # not estimator=payload's block
        return []
    link = block["link"]
    out = ["", f"payload on {link}" + (f" (welded to {block['body']})" if block["body"] != link else "")]
    out.append(
        f"{block['equations']} equations · rank {block['rank']} of {block['unknowns']} unknowns · "
        f"condition number {block['cond']:.3g} · ‖E‖/‖T‖ {100 * block['rel_error']:.2f} % "
        f"(arm model alone {100 * block['rel_error_arm_only']:.2f} %)"
    )
    out += _arm_lines(details.get("arm_model") or {}) + _reference_lines(details.get("reference"))
    out.append(f"mass             {_pm(block['mass'], block['mass_std'], ' kg')}")
    if block["com"] is None:
        out.append("no payload mass found: centre of mass and inertia undefined, nothing to set")
        return out
    com = ", ".join(_pm(c, s) for c, s in zip(block["com"], block["com_std"], strict=True))
    out.append(f"centre of mass   [{com}] m")
    out.append("inertia about the centre of mass (kg·m²), ± standard deviation:")
    for row, std in zip(block["inertia"], block["inertia_std"], strict=True):
        out.append(
            "    ["
            + "  ".join(f"{v:+.4e}" for v in row)
            + "]   ± ["
            + "  ".join(f"{s:.1e}" for s in std)
            + "]"
        )
    if block["unidentifiable"]:
        out.append("not identified by this recording: " + "; ".join(block["unidentifiable"]))
    if float("inf") in (block["mass_std"], *block["com_std"]):
        out.append(
            "the recording does not identify the mass and centre of mass: do not hand these values to a "
            "controller; record a motion that moves every joint"
        )
    out += _sdk_lines(link, block["sdk"])
    return out


def _arm_lines(arm: Mapping[str, Any]) -> list[str]:
    terms = arm.get("joint_terms") or {}
    kinds = sorted({name.rpartition(".")[2] for name in terms})
    out = [
        f"arm model: {arm.get('source')}: inertials" + (f", {', '.join(kinds)} as recorded" if kinds else "")
    ]
    if arm.get("not_recorded"):
        out.append(f"  not recorded in the file, taken as 0: {', '.join(arm['not_recorded'])}")
    if arm.get("not_used"):
        shown = ", ".join(arm["not_used"][:6]) + (" …" if len(arm["not_used"]) > 6 else "")
        out.append(
            f"  recorded but not held by the robot, left out: {shown} (robot.friction=true / "
            "robot.offset=true to use them)"
        )
    return out


#: How the reference was preprocessed (``details["reference"]["preprocess"]``), in the report's words.
_HOW = {"as data=": " as data= was", "defaults": " with the default options, not as data="}


def _reference_lines(reference: Mapping[str, Any] | None) -> list[str]:
    if not reference:
        return []
    head = (
        f"reference {reference['file']} ({reference['samples']} samples"
        + (
            f", preprocessed{_HOW.get(reference.get('preprocess'), '')}"
            if reference.get("preprocessed")
            else ""
        )
        + f"; arm model ‖E‖/‖T‖ {100 * reference['rel_error_arm']:.2f} % on it): "
    )
    if reference["correction"] == "samples":
        return [
            head + f"its residual subtracted sample by sample (positions within "
            f"{reference['max_mismatch']:.3g} of the data)"
        ]
    return [head + f"{100 * reference['rel_error_corrected']:.2f} % with the fitted correction of the arm"]


def _sdk_lines(link: str, sdk: Mapping[str, Any]) -> list[str]:
    franka, ur = sdk["libfranka"], sdk["ur"]
    cog = f"[{_vector(ur['cog'])}]"
    return [
        f"SDK calls (values in the frame of {link}; libfranka and UR take the flange frame: if {link}'s",
        "frame is not your flange, name the flange link with estimator.link=<link welded to it>,",
        "or transform):",
        f"  libfranka  robot.setLoad({_g(franka['load_mass'])}, {{{_vector(franka['F_x_Cload'])}}}, "
        f"{{{_vector(franka['load_inertia'])}}});  // load_inertia column-major",
        f"  URScript   set_target_payload({_g(ur['mass'])}, {cog}, [{_vector(ur['inertia'])}])"
        "  # inertia [Ixx, Iyy, Izz, Ixy, Ixz, Iyz]",
        f"             set_payload({_g(ur['mass'])}, {cog})",
        f"  ur_rtde    rtde_c.setPayload({_g(ur['mass'])}, {cog})",
    ]
