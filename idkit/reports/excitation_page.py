"""``report.html`` of an ``excitation`` run: the check's verdict first, then the limits and margins.

Built from the run's ``result.json`` document and the ``excitation.png`` beside it:

1. **Verdicts**: the check of the exported samples (every limit kept by its safety margin, at rest
   at both ends, regular rate, no contact), and whether the search improved on its start;
2. **criterion**: the robot's default motion, the start, the optimised motion;
3. **limits and margins** per joint and quantity: the limits, the margin required, the margin kept;
4. the motion against its limits; the run.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from idkit.reports import html as h

QUANTITIES = ("position", "velocity", "acceleration", "effort")


def _verdicts(payload: Mapping[str, Any]) -> str:
    check = payload["check"]
    required = check.get("required_margins") or {}
    violations = check.get("violations") or []
    margins = ", ".join(f"{q} {100 * v:.3g} %" for q, v in required.items())
    if violations:
        head = h.badge("poor", f"{len(violations)} violation(s)")
        body = h.listing(map(h.escape, violations))
    else:
        head = h.badge("good", "all checks passed")
        body = h.paragraph(
            f"Every sample keeps the required margin inside every limit ({margins} of the half-range)."
        )
    improved = payload.get("improved", True)
    start = payload.get("start")
    criterion = payload["criterion"]
    if start is None:
        search = h.paragraph(
            f"The start could not be made runnable; the optimised motion's {criterion} is shown."
        )
    elif improved:
        search = h.paragraph(
            f"The search improved on its start: {criterion} {h.number(start)} → {h.number(payload['after'])}."
        )
    else:
        search = (
            f"<p>{h.badge('fair', 'no improvement found')} the search did not beat its start "
            f"({criterion} {h.number(payload['details'].get('search_result'))} against {h.number(start)}): "
            "the start is kept.</p>"
        )
    rest = check.get("rest") or {}
    ends = ", ".join(
        f"{end}: |q̇| ≤ {h.number(v.get('velocity'), 2)}, |q̈| ≤ {h.number(v.get('acceleration'), 2)}"
        for end, v in rest.items()
    )
    return (
        f"<p>{head}</p>"
        + body
        + search
        + h.paragraph(
            f"At the ends {ends}. Effort: {check.get('effort')}. "
            f"Self-collision: {check.get('self_collision')}."
        )
    )


def _criterion(payload: Mapping[str, Any]) -> str:
    criterion = payload["criterion"]
    rows = [
        [f"robot's default motion ({payload.get('baseline') or 'default'})", h.num(payload["before"])],
        ["start (made runnable)", h.num(payload.get("start"))],
        ["result" + ("" if payload.get("improved", True) else " (the start, kept)"), h.num(payload["after"])],
    ]
    return h.table(["motion", criterion], rows, "criterion") + h.paragraph(
        f"{payload['n_samples']} samples over {payload['t_end']:g} s; acceleration limits: "
        f"{payload.get('acceleration_limits')}",
        "rule",
    )


def _limits(payload: Mapping[str, Any]) -> str:
    check = payload["check"]
    required = check.get("required_margins") or {}
    limits, efforts = payload["limits"], payload.get("effort_limits") or {}
    rows = []
    for joint, by_quantity in limits.items():
        kept = check["margins"].get(joint, {})
        for quantity in QUANTITIES:
            bounds = by_quantity.get(quantity) or (
                [-efforts[joint], efforts[joint]] if quantity == "effort" and joint in efforts else None
            )
            if bounds is None:
                continue
            found = kept.get(quantity)
            need = required.get(quantity, 0.0)
            share = None if found is None else found["share"]
            css = "" if share is None or share != share else ("good" if share >= need else "poor")
            rows.append(
                [
                    joint,
                    quantity,
                    h.num(bounds[0]),
                    h.num(bounds[1]),
                    h.num(need, shown=h.percent(need)),
                    h.num(None if found is None else found["worst"]),
                    h.num(share, css, shown="—" if share is None else h.percent(share)),
                ]
            )
    header = ["joint", "quantity", "lower", "upper", "margin required", "worst sample", "margin kept"]
    return h.paragraph(
        "Margins are shares of each limit's half-range: the worst sample's distance from the nearest limit.",
        "rule",
    ) + h.table(header, rows, "limits")


def render(document: Mapping[str, Any], folder: str | Path) -> str:
    """The page of an ``excitation`` run's ``result.json`` ``document``; the figure from ``folder``."""
    payload = document["payload"]
    plot = (document.get("files") or {}).get("plot")
    figure = (
        h.png_file(Path(folder) / Path(plot).name, "the motion against its limits")
        if plot
        else h.paragraph("Plots were not written for this run (plots=false).")
    )
    robot = ((document.get("plugins") or {}).get("robot") or {}).get("name", "?")
    return h.page(
        f"{payload['excitation']} excitation · robot {robot}",
        h.run_subtitle(document),
        [
            h.section("verdicts", "Verdicts", _verdicts(payload)),
            h.section("criterion", f"Criterion ({payload['criterion']})", _criterion(payload)),
            h.section("limits", "Limits and margins", _limits(payload)),
            h.section("motion", "The motion against its limits", figure),
            h.section(
                "run",
                "The run",
                h.preformatted(
                    json.dumps(
                        {"options": payload.get("options"), "details": payload.get("details")}, indent=2
                    )
                ),
                h.collapsed("the config", h.preformatted(json.dumps(document.get("config"), indent=2))),
            ),
        ],
    )
