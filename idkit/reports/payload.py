"""The payload fit's part of the printed report: mass, centre of mass, inertia and the SDK calls.

Reads only the estimate's ``details`` (``payload``, ``arm_model``, ``reference``) that
:mod:`idkit.estimators.payload` writes, so a ``result.json`` prints the same lines again.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from idkit.estimators.payload_verdict import AXES, IDENTIFIED_SHARE, INERTIA_ENTRIES

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
    """The report lines of a payload fit's ``details`` (``[]`` for other estimates).

    Every line follows the block's one verdict per quantity (``block["verdict"]``): a quantity is
    shown as identified, or not identified with why; SDK calls appear only for what is identified.
    """
    block = details.get("payload")
    if not isinstance(block, Mapping) or "sdk" not in block:  # not estimator=payload's block
        return []
    link = block["link"]
    out = ["", f"payload on {link}" + (f" (welded to {block['body']})" if block["body"] != link else "")]
    free = block["unknowns"] - block["rank"]
    conditioning = f"{free} combinations free" if free else f"condition number {block['cond']:.3g}"
    out.append(
        f"{block['equations']} equations · rank {block['rank']} of {block['unknowns']} unknowns "
        f"({conditioning}) · ‖E‖/‖T‖ {100 * block['rel_error']:.2f} % "
        f"(arm model alone {100 * block['rel_error_arm_only']:.2f} %)"
    )
    out += arm_lines(details.get("arm_model") or {}) + reference_lines(details.get("reference"))
    out += (block.get("recordings") or {}).get("notes", [])
    judged = block.get("verdict")
    if block["com"] is None or judged is None:
        out.append(f"mass             {_pm(block['mass'], block['mass_std'], ' kg')}")
        out.append("no payload mass found: centre of mass and inertia undefined, nothing to set")
        return out
    out.append(f"verdict — {judged['rule']}:")
    out += _verdict_lines(block, judged)
    if block.get("std_source"):  # where every ± above comes from (idkit.std_source), model-conditional
        out.append(block["std_source"])
    if judged["unusable"] is None:
        out += not_identified(judged, block.get("free") or ())
    out += sdk_lines(link, block["sdk"])
    return out


def _state(identified: bool) -> str:
    return f"{'identified' if identified else 'not identified':<16}"


def _entry(name: str, value: float, std: float, unit: str = "") -> str:
    """``x 0.0495 ± 0.00044`` or ``y free`` (an infinite standard deviation: no value to show)."""
    return f"{name} free" if std == float("inf") else f"{name} {_g(value)} ± {std:.2g}{unit}"


def _verdict_lines(block: Mapping[str, Any], judged: Mapping[str, Any]) -> list[str]:
    """Mass, centre of mass and inertia, each with its verdict and the values it rests on."""
    out = [f"  mass            {_state(judged['mass'])}{_pm(block['mass'], block['mass_std'], ' kg')}"]
    coordinates = ", ".join(
        _entry(axis, c, s) for axis, c, s in zip(AXES, block["com"], block["com_std"], strict=True)
    )
    out.append(f"  centre of mass  {_state(judged['com'])}[{coordinates}] m")
    if judged["inertia"]:
        out.append(f"  inertia         {_state(True)}about the centre of mass (kg·m²), ± standard deviation:")
        for row, std in zip(block["inertia"], block["inertia_std"], strict=True):
            values = "  ".join(f"{v:+.4e}" for v in row)
            out.append(f"      [{values}]   ± [" + "  ".join(f"{s:.1e}" for s in std) + "]")
    else:
        entries = ", ".join(
            _entry(name, block["inertia"][i][j], block["inertia_std"][i][j]) for name, i, j in INERTIA_ENTRIES
        )
        out.append(f"  inertia         {_state(False)}about the centre of mass (kg·m²): {entries}")
    if judged["unusable"] is not None:
        out.append(f"  nothing is identified: {judged['unusable']}")
    return out


def _named(keys: Sequence[str], shown: Mapping[str, str] | None = None) -> str:
    """``the mass; the centre of mass along y; the inertia's Ixx, Izz`` (``shown``: text after each)."""
    shown = shown or {}
    words = {"m": "the mass", **{f"c{a}": f"the centre of mass along {a}" for a in AXES}}
    parts = [words[k] + shown.get(k, "") for k in keys if k in words]
    inertia = [k + shown.get(k, "") for k in keys if k not in words]
    return "; ".join(parts + (["the inertia's " + ", ".join(inertia)] if inertia else []))


def not_identified(judged: Mapping[str, Any], free: Sequence[str] = ()) -> list[str]:
    """What is not identified, in words: quantities the recording leaves free (infinite standard
    deviation) and those it determines too loosely (their share of the scale), and the arm's own
    parameters (``correction.*`` among ``free``) that trade against them."""
    shares = judged["shares"]
    unknown = [k for k, s in shares.items() if not np.isfinite(s)]
    loose = {k: f" (σ {100 * s:.3g} %)" for k, s in shares.items() if np.isfinite(s) and s > IDENTIFIED_SHARE}
    lines = []
    if unknown:
        lines.append(
            f"not identified, free: {_named(unknown)} — the torques of this recording do not change when "
            "these change together in the combinations it leaves free, so any values along them fit equally"
        )
    if loose:
        lines.append(
            f"not identified, too uncertain (σ over {100 * IDENTIFIED_SHARE:g} % of the scale): "
            + _named(list(loose), loose)
        )
    arm = [name.removeprefix("correction.") for name in free if name.startswith("correction.")]
    if arm:
        lines.append(
            f"the arm's own {', '.join(arm)} (its correction) take part in those combinations: the reference "
            "does not fix them"
        )
    return lines


def arm_lines(arm: Mapping[str, Any]) -> list[str]:
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


#: Said when no reference was given: the σ cannot see an arm model's error, which the payload absorbs.
NO_REFERENCE = (
    "no reference: the arm model (its inertials, friction and offsets) is taken as exact; where it is "
    "not, its error goes into the payload and the stds do not count it. Record the arm without "
    "the payload and give estimator.reference=<file> (docs/payload.md)"
)


def reference_lines(reference: Mapping[str, Any] | None) -> list[str]:
    if not reference:
        return [NO_REFERENCE]
    head = (
        f"reference {reference['file']} ({reference['samples']} samples"
        + (
            f", preprocessed{_HOW.get(reference.get('preprocess', ''), '')}"
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


def sdk_lines(link: str, sdk: Mapping[str, Any]) -> list[str]:
    """The SDK calls the verdict allows (``sdk``: :func:`idkit.estimators.payload_verdict.sdk_calls`),
    then the calls withheld and why."""
    franka, ur = sdk.get("libfranka"), sdk.get("ur")
    withheld = [f"  not printed: {why}" for why in sdk.get("withheld", [])]
    if franka is None and ur is None:
        return ["no SDK call: each takes a quantity this recording does not identify", *withheld]
    out = [
        f"SDK calls (values in the frame of {link}; libfranka and UR take the flange frame: if {link}'s",
        "frame is not your flange, name the flange link with estimator.link=<link welded to it>,",
        "or transform):",
    ]
    if franka is not None:
        out.append(
            f"  libfranka  robot.setLoad({_g(franka['load_mass'])}, {{{_vector(franka['F_x_Cload'])}}}, "
            f"{{{_vector(franka['load_inertia'])}}});  // load_inertia column-major"
        )
    if ur is not None:
        cog = f"[{_vector(ur['cog'])}]"
        if "inertia" in ur:
            out.append(
                f"  URScript   set_target_payload({_g(ur['mass'])}, {cog}, [{_vector(ur['inertia'])}])"
                "  # inertia [Ixx, Iyy, Izz, Ixy, Ixz, Iyz]"
            )
        out += [
            f"  URScript   set_payload({_g(ur['mass'])}, {cog})",
            f"  ur_rtde    rtde_c.setPayload({_g(ur['mass'])}, {cog})",
        ]
    return out + withheld
