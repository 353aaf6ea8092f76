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
from idkit.reports import files
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


def criterion_change(criterion: str, before: float, after: float) -> str:
    """How the optimised motion's criterion compares with the default motion's, in words: a
    motion kept inside the limits can end worse than a default that leaves them, and says so."""
    if criterion == "logdet":
        return f"{after - before:+.3g}"
    ratio = before / after
    return f"{ratio:.2f} times smaller" if ratio >= 1 else f"{1 / ratio:.2f} times larger"


def text(study: ExcitationStudy) -> str:
    """The criterion before and after, and whether each motion stays within the limits."""
    from idkit.studies.excitation import ACCELERATION_SOURCES

    r = study.result
    n, t_end = int(r.t.numel()), float(r.grid[-1])
    change = criterion_change(r.criterion, r.before, r.after)
    shrunk = r.details.get("shrunk_by", 1.0)
    shrink = (
        []
        if shrunk == 1.0
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
            f"  before ({study.baseline_name or 'default'}): {r.criterion} = {r.before:.6g}; "
            f"outside the limits: {_excursions(study, 'before')}",
            f"  after  ({r.name}, optimised): {r.criterion} = {r.after:.6g} ({change}); "
            f"outside the limits: {_excursions(study, 'after')}",
            *shrink,
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
        written["plot"] = str(
            figures.motion_against_limits(
                r.grid.numpy(),
                dense,
                r.limits.lower.numpy(),
                r.limits.upper.numpy(),
                (t, (q, qd, qdd)),
                r.limits.joint_names,
                f"{study.robot_name}: optimised {r.name} excitation ({r.criterion} "
                f"{r.before:.3g} → {r.after:.3g}); dashed: limits ({', '.join(MOTION_VARIABLES)})",
                out / "excitation.png",
            )
        )
    return write_result(out, study.provenance, study.payload(), written)
