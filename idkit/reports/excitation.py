"""The ``excitation`` task's report: the motion as files a scenario loads and a controller runs.

* ``excitation.yaml`` — family name and coefficients (``idkit.excitation.files``), loadable back as
  ``scenario.excitation=<file>``;
* ``excitation.csv``, ``excitation.npz`` — with a controller rate: ``t``, ``q``, ``qd``, ``qdd`` per
  joint name at that rate (``idkit.excitation.export``), the samples the check's margins are of;
* ``excitation.png`` — ``q``, ``q̇``, ``q̈`` on the dense check grid against the limits;
* ``result.json`` — the common envelope, payload ``ExcitationStudy.payload()`` (margins per joint
  under ``check``).
"""

from __future__ import annotations

from pathlib import Path

from idkit.limits import MOTION_VARIABLES
from idkit.reports import excitation_page, files
from idkit.reports import plots as figures
from idkit.reports.result_file import claim, write_result
from idkit.studies.excitation import ExcitationStudy

#: How each criterion is read: which direction is better.
BETTER = {"cond": "smaller is better", "logdet": "larger is better", "ls_error": "smaller is better"}


def _excursions(study: ExcitationStudy, which: str) -> str:
    """``"none"``, or each offending joint's worst excursion, e.g. ``d2 position by 0.0893``."""
    payload = study.payload()[f"excess_{which}"]
    found = [
        f"{joint} {variable} by {value:.3g}"
        for joint, by_variable in payload.items()
        for variable, value in by_variable.items()
        if value > 0
    ]
    return ", ".join(found) if found else "none"


def _default_excursions(study: ExcitationStudy) -> str:
    """The default motion's excursions, and that it cannot be run as it is when it has any."""
    found = _excursions(study, "before")
    return found if found == "none" else f"{found} (not runnable as it is)"


def criterion_change(criterion: str, before: float, after: float) -> str:
    """How ``after`` compares with ``before`` in words (``1.52 times smaller``, ``+3.1``)."""
    if criterion == "logdet":
        return f"{after - before:+.3g}"
    ratio = before / after
    return f"{ratio:.2f} times smaller" if ratio >= 1 else f"{1 / ratio:.2f} times larger"


def _outcome(study: ExcitationStudy) -> list[str]:
    """The start, and the optimised motion against it, or that the search did not beat it.

    The robot's default motion (``before``) may leave the limits; the start is the family's member
    made runnable with the same margins, so it is what an optimised motion must improve on.
    """
    r = study.result
    start = r.details.get("start") or {}
    if r.start is None:
        lines = [
            f"  start ({r.name} as configured): not runnable ({start.get('why', 'unknown')}); no comparison"
        ]
    else:
        shrunk = (start.get("shrink") or {}).get("shrunk_by", 1.0)
        centred = start.get("offsets_centred") or []
        made = (
            (f"offsets of {', '.join(centred)} moved to mid-range, " if centred else "")
            + "fitted into the limits less their margins"
            + (f", shrunk by {shrunk:.4g}" if shrunk != 1.0 else "")
        )
        lines = [f"  start  ({r.name} as configured, {made}): {r.criterion} = {r.start:.6g}"]
    if r.improved:
        versus = (
            "" if r.start is None else f" ({criterion_change(r.criterion, r.start, r.after)} than the start)"
        )
        lines.append(
            f"  after  ({r.name}, optimised): {r.criterion} = {r.after:.6g}{versus}; "
            f"outside the limits: {_excursions(study, 'after')}"
        )
    else:
        lines.append(
            f"  no improvement found: the search's best ({r.criterion} = "
            f"{r.details['search_result']:.6g}) is not better than the start, so the start is kept "
            f"({r.criterion} = {r.after:.6g}); outside the limits: {_excursions(study, 'after')}"
        )
    return lines


def text(study: ExcitationStudy) -> str:
    """The default motion, the start and the optimised motion, the margins, and the check's verdict."""
    from idkit.studies.excitation import ACCELERATION_SOURCES

    r = study.result
    n, t_end = int(r.t.numel()), float(r.grid[-1])
    shrunk = r.details.get("shrunk_by", 1.0)
    shrink = (
        []
        if shrunk == 1.0 or not r.improved
        else [
            f"  shrunk by {shrunk:.4g} for {' and '.join(r.details['shrunk_for'])} "
            f"({r.criterion} {r.details['criterion_before_shrink']:.6g} before)"
        ]
    )
    exported = (
        f"exported at {study.rate:g} Hz to excitation.csv and excitation.npz"
        if study.trajectory is not None
        else "not exported (no excitation.rate)"
    )
    return "\n".join(
        [
            f"Excitation `{r.name}` for {study.robot_name}, criterion {r.criterion} ({BETTER[r.criterion]}) "
            f"at N = {n} samples over {t_end:g} s",
            "",
            f"  robot's default motion ({study.baseline_name or 'default'}): {r.criterion} = {r.before:.6g}; "
            f"outside the limits: {_default_excursions(study)}",
            *_outcome(study),
            *shrink,
            f"  safety margin inside every limit: {r.margins.describe()}",
            f"  acceleration limits: {ACCELERATION_SOURCES[study.acceleration_source]}",
            f"  {exported}; load it with scenario.excitation=<run dir>/excitation.yaml",
            "",
            "Margins (the worst checked sample's distance from each limit, and its share of the half-range):",
            "",
            study.check.table(),
            "",
            study.check.summary(),
            *(violation.line() for violation in study.check.violations),
            "",
        ]
    )


def write(study: ExcitationStudy, out_dir: str | Path, plots: bool = True) -> dict[str, str]:
    """Write ``excitation.yaml``, ``excitation.csv`` and ``.npz`` (with a rate), ``excitation.png``
    (with ``plots``), ``result.json``."""
    from idkit.excitation.export import columns
    from idkit.excitation.files import excitation_yaml

    out = claim(out_dir, study.provenance)
    r = study.result
    t, q, qd, qdd = (x.numpy() for x in r.samples())
    written = {
        "excitation": str(files.write_text(out / "excitation.yaml", excitation_yaml(r.name, r.excitation))),
    }
    if study.trajectory is not None:
        trajectory = study.trajectory
        header = columns(trajectory.joint_names)
        written["csv"] = str(files.write_csv(out / "excitation.csv", header, trajectory.rows().tolist()))
        written["npz"] = str(files.write_npz(out / "excitation.npz", trajectory.arrays()))
    if plots:
        dense = [x.numpy() for x in r.excitation(r.grid)]
        inner = r.margins.narrowed(r.limits, extra=0.0)
        written["plot"] = str(
            figures.motion_against_limits(
                r.grid.numpy(),
                dense,
                r.limits.lower.numpy(),
                r.limits.upper.numpy(),
                (t, (q, qd, qdd)),
                r.limits.joint_names,
                f"{study.robot_name}: {'optimised' if r.improved else 'start (no improvement found)'} "
                f"{r.name} excitation ({r.criterion} {r.after:.3g}); dashed: limits "
                f"({', '.join(MOTION_VARIABLES)}), dotted: less the safety margins",
                out / "excitation.png",
                (inner.lower.numpy(), inner.upper.numpy()),
            )
        )
    return write_result(
        out,
        study.provenance,
        study.payload(),
        written,
        lambda document: excitation_page.render(document, out),
    )
