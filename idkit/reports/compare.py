"""The compare page of two runs (``idkit compare RUN_A RUN_B``): what changed, and whether it matters.

Read from the two runs' ``result.json`` documents only:

* **held-out** figures of the files both runs scored (per joint and ``‖E‖/‖T‖``), side by side;
* **parameters** side by side: base parameters with their σ and the difference in σ units,
  ``z = (b − a) / √(σa² + σb²)`` (``|z| > 3``: a change the runs' own uncertainties do not explain),
  then the standard parameters (no σ of their own);
* **plausibility**: each link's verdict in each run, as the runs recorded it (one rule:
  :func:`idkit.conic.plausible.plausibility_report`; never judged again here);
* an excitation's criterion and margins, for two excitation runs;
* for two rollout runs, each held-out log's verdict per joint and the unknowns in σ units;
* **config differences**: every setting whose value differs (or that one run lacks).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Mapping
from typing import Any

from idkit.reports import html as h

#: A difference larger than this many combined standard deviations is flagged.
SIGNIFICANT_Z = 3.0


def flatten(node: Any, prefix: str = "") -> Iterator[tuple[str, Any]]:
    """``(dotted key, value)`` of every leaf of a config (lists are leaves)."""
    if isinstance(node, Mapping):
        for key, value in node.items():
            yield from flatten(value, f"{prefix}.{key}" if prefix else str(key))
    else:
        yield prefix, node


def settings(document: Mapping[str, Any]) -> dict[str, Any]:
    """The run's settings: its config, or (a run from Python, without one) its plugins and data."""
    config = document.get("config")
    source = config if config else {"plugins": document.get("plugins"), "data": document.get("data")}
    return dict(flatten(source))


def config_differences(a: Mapping[str, Any], b: Mapping[str, Any]) -> list[tuple[str, Any, Any]]:
    """``(key, value in a, value in b)`` for every setting that differs (``None``: missing)."""
    first, second = settings(a), settings(b)
    keys = sorted(set(first) | set(second))
    return [(k, first.get(k), second.get(k)) for k in keys if first.get(k) != second.get(k)]


def z_score(a: float, sa: float | None, b: float, sb: float | None) -> float | None:
    """``(b − a) / √(σa² + σb²)``, or ``None`` without both standard deviations."""
    if sa is None or sb is None or not (math.isfinite(sa) and math.isfinite(sb)):
        return None
    spread = math.hypot(sa, sb)
    return (b - a) / spread if spread > 0 else (0.0 if a == b else math.inf)


def _shown(value: Any) -> str:
    return "—" if value is None else json.dumps(value) if not isinstance(value, str) else value


def _held_out(a: Mapping[str, Any], b: Mapping[str, Any]) -> str:
    va, vb = (d["payload"].get("validation") or {} for d in (a, b))
    common = [file for file in va if file in vb]
    if not common:
        only = sorted(set(va) ^ set(vb))
        return h.paragraph(
            "No held-out file scored by both runs"
            + (f" (scored by one: {', '.join(only)})." if only else ".")
        )
    parts = []
    for file in common:
        sa, sb = va[file], vb[file]
        names = list(a["payload"].get("joint_names") or [f"j{j + 1}" for j in range(len(sa["relative"]))])
        if len(names) != len(sa["relative"]):
            names = [f"j{j + 1}" for j in range(len(sa["relative"]))]
        rows = [
            [
                name,
                h.num(ra, shown=h.percent(ra)),
                h.num(rb, shown=h.percent(rb)),
                h.num(rb - ra, digits=3, shown=f"{100 * (rb - ra):+.3g} pp"),
            ]
            for name, ra, rb in zip(names, sa["relative"], sb["relative"], strict=True)
        ]
        ra, rb = sa["rel_all"], sb["rel_all"]
        rows.append(
            [
                "‖E‖/‖T‖",
                h.num(ra, shown=h.percent(ra)),
                h.num(rb, shown=h.percent(rb)),
                h.num(rb - ra, digits=3, shown=f"{100 * (rb - ra):+.3g} pp"),
            ]
        )
        parts.append(
            f"<h3>{h.escape(file)}</h3>"
            + h.table(["joint", "A relative", "B relative", "B − A"], rows, "held-out")
        )
    return "".join(parts)


def _parameters(a: Mapping[str, Any], b: Mapping[str, Any]) -> str:
    ea, eb = a["payload"]["estimate"], b["payload"]["estimate"]
    parts = []
    ba, bb = ea.get("base_params") or {}, eb.get("base_params") or {}
    stda = ((ea.get("details") or {}).get("uncertainty") or {}).get("std") or {}
    stdb = ((eb.get("details") or {}).get("uncertainty") or {}).get("std") or {}
    common = [name for name in ba if name in bb]
    if common:
        rows = []
        for name in common:
            z = z_score(ba[name], stda.get(name), bb[name], stdb.get(name))
            flag = "poor" if z is not None and abs(z) > SIGNIFICANT_Z else ""
            rows.append(
                [
                    name,
                    h.num(ba[name]),
                    h.num(stda.get(name), digits=3),
                    h.num(bb[name]),
                    h.num(stdb.get(name), digits=3),
                    h.num(bb[name] - ba[name], digits=4),
                    h.num(z, flag, digits=3),
                ]
            )
        parts += [
            "<h3>Base parameters</h3>",
            h.paragraph(
                f"z = (B − A) / √(σA² + σB²); |z| > {SIGNIFICANT_Z:g} is flagged: a change the runs' own "
                "uncertainties do not explain.",
                "rule",
            ),
            h.table(["base parameter", "A", "σA", "B", "σB", "B − A", "z"], rows, "base-parameters"),
        ]
    pa, pb = ea.get("params") or {}, eb.get("params") or {}
    names = [name for name in pa if name in pb]
    if names:
        rows = [
            [name, h.num(pa[name]), h.num(pb[name]), h.num(pb[name] - pa[name], digits=4)] for name in names
        ]
        parts += ["<h3>Parameters</h3>", h.table(["parameter", "A", "B", "B − A"], rows, "parameters")]
    only = sorted(set(pa) ^ set(pb))
    if only:
        parts.append(h.paragraph(f"In one run only: {', '.join(only)}.", "rule"))
    return "".join(parts) or h.paragraph("No parameters in common.")


def _plausibility(a: Mapping[str, Any], b: Mapping[str, Any]) -> str:
    """Each link's recorded verdict in A and B, with its mass over CAD's and the reasons."""
    ra, rb = (
        ((d["payload"]["estimate"].get("details") or {}).get("plausibility") or {}).get("links") or {}
        for d in (a, b)
    )
    if not ra and not rb:
        return h.paragraph("Neither run recorded a plausibility verdict.")

    def cell(row: Mapping[str, Any] | None) -> list[Any]:
        if row is None:
            return ["—", "", ""]
        badge = h.badge("good" if row["plausible"] else "poor", "yes" if row["plausible"] else "no")
        return [h.raw(badge), h.num(row["ratio"], digits=3), "; ".join(row["reasons"])]

    links = list(ra) + [link for link in rb if link not in ra]
    rows = [[link, *cell(ra.get(link)), *cell(rb.get(link))] for link in links]
    header = ["link", "A plausible", "A mass / CAD", "A why not", "B plausible", "B mass / CAD", "B why not"]
    enforced = [
        ((d["payload"]["estimate"].get("details") or {}).get("plausibility") or {}).get("enforced", "—")
        for d in (a, b)
    ]
    return h.paragraph(f"Enforced: A {enforced[0]}; B {enforced[1]}.", "rule") + h.table(
        header, rows, "plausibility"
    )


def _excitation(a: Mapping[str, Any], b: Mapping[str, Any]) -> str:
    pa, pb = a["payload"], b["payload"]
    rows = [
        ["criterion", pa["criterion"], pb["criterion"]],
        ["result", h.num(pa["after"]), h.num(pb["after"])],
        ["start", h.num(pa.get("start")), h.num(pb.get("start"))],
        ["improved on its start", str(pa.get("improved")), str(pb.get("improved"))],
        ["violations", str(len(pa["check"]["violations"])), str(len(pb["check"]["violations"]))],
    ]
    return h.table(["", "A", "B"], rows, "excitation")


def _rollout(a: Mapping[str, Any], b: Mapping[str, Any]) -> list[str]:
    """Two rollout runs: each held-out log's verdict per joint, then the unknowns in σ units (each record
    read by :func:`idkit.reports.rollout_page.record`, its verdicts as recorded)."""
    from idkit.reports import rollout_page as page

    ra, rb = page.record(a), page.record(b)
    held_a, held_b = {s.file: s for s in ra.verdicts()}, {s.file: s for s in rb.verdicts()}
    common = [file for file in held_a if file in held_b]
    parts = [
        h.paragraph(
            "Per joint: the position error (1.4826 × the median absolute error) and its ratio to what the "
            "run held it to (a perfect model's error, or the log's noise level), in each run's default mode.",
            "rule",
        )
    ]
    for file in common:
        sa, sb = held_a[file], held_b[file]
        rows = []
        for joint in (j for j in sa.robust if j in sb.robust):
            rows.append(
                [joint]
                + [
                    cell
                    for s in (sa, sb)
                    for cell in (
                        h.num(s.robust[joint][0], digits=3),
                        h.num(s.ratio[joint], page.grade(s.verdicts[joint]), 3, f"{s.ratio[joint]:.3g}×"),
                    )
                ]
            )
        parts.append(
            f"<h3>{h.escape(file)}</h3>"
            + h.paragraph(
                f"A simulated {sa.described}: {sa.verdict}; B simulated {sb.described}: {sb.verdict}.", "rule"
            )
            + h.table(["joint", "A error", "A ratio", "B error", "B ratio"], rows, "held-out")
        )
    if not common:
        only = sorted(set(held_a) ^ set(held_b))
        parts.append(
            h.paragraph(
                "No held-out log scored by both runs"
                + (f" (scored by one: {', '.join(only)})." if only else ".")
            )
        )
    ua, ub = {u.name: u for u in ra.unknowns}, {u.name: u for u in rb.unknowns}
    rows = []
    for name in (n for n in ua if n in ub):
        x, y = ua[name], ub[name]
        z = z_score(x.value, x.std, y.value, y.std)
        flag = "poor" if z is not None and abs(z) > SIGNIFICANT_Z else ""
        bounds = ", ".join(
            f"{run} at its {u.at_bound} bound" for run, u in (("A", x), ("B", y)) if u.at_bound
        )
        rows.append(
            [
                name,
                h.num(x.value),
                h.num(x.std, digits=3),
                h.num(y.value),
                h.num(y.std, digits=3),
                h.num(z, flag, digits=3),
                bounds,
            ]
        )
    table = h.table(["unknown", "A", "σA", "B", "σB", "z", "on a bound"], rows, "parameters")
    only = sorted(set(ua) ^ set(ub))
    limited = [
        [
            "model-limited",
            *("not assessed" if r.model_limited is None else str(r.model_limited) for r in (ra, rb)),
        ],
        ["flat directions", str(len(ra.flat)), str(len(rb.flat))],
        ["rollouts", _shown(ra.rollouts), _shown(rb.rollouts)],
    ]
    return [
        h.section("held-out", "Held-out prediction", "".join(parts)),
        h.section(
            "parameters",
            "Unknowns",
            h.paragraph(
                f"z = (B − A) / √(σA² + σB²); |z| > {SIGNIFICANT_Z:g} is flagged: a change the runs' own "
                "uncertainties do not explain.",
                "rule",
            )
            + table
            + (h.paragraph(f"In one run only: {', '.join(only)}.", "rule") if only else "")
            + h.table(["", "A", "B"], limited, "fit"),
        ),
    ]


def render(a: Mapping[str, Any], b: Mapping[str, Any], names: tuple[str, str]) -> str:
    """The compare page of runs ``a`` and ``b`` (their ``result.json`` documents), shown as ``names``."""
    who = h.table(
        ["", "A", "B"],
        [
            ["folder", names[0], names[1]],
            *(
                [key, _shown(a.get(key)), _shown(b.get(key))]
                for key in ("task", "label", "status", "seed", "run_id", "created", "idkit_version")
            ),
        ],
        "runs",
    )
    sections = [h.section("runs", "The runs", who)]
    tasks = {a.get("task"), b.get("task")}
    if tasks == {"single"}:
        sections += [
            h.section("held-out", "Held-out prediction", _held_out(a, b)),
            h.section("plausibility", "Plausibility", _plausibility(a, b)),
            h.section("parameters", "Parameters", _parameters(a, b)),
        ]
    elif tasks == {"excitation"}:
        sections.append(h.section("excitation", "Excitation", _excitation(a, b)))
    elif tasks == {"rollout"}:
        sections += _rollout(a, b)
    else:
        sections.append(
            h.section(
                "tasks",
                "Tasks",
                h.paragraph(
                    f"Runs of tasks {' and '.join(sorted(map(str, tasks)))}: only their settings are "
                    "compared."
                ),
            )
        )
    differences = config_differences(a, b)
    rows = [[key, _shown(x), _shown(y)] for key, x, y in differences]
    sections.append(
        h.section(
            "config",
            "Config differences",
            h.table(["setting", "A", "B"], rows, "config") if rows else h.paragraph("The same settings."),
        )
    )
    return h.page(f"{a.get('label')} (A) vs {b.get('label')} (B)", f"{names[0]} · {names[1]}", sections)
