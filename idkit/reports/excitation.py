"""The ``excitation`` task's report: the motion as files a scenario loads, a plot, result.json.

* ``excitation.yaml`` — family name and coefficients (``idkit.excitation.files``), loadable back as
  ``scenario.excitation=<file>``;
* ``excitation.npz`` — arrays ``t[N]``, ``q``, ``qd``, ``qdd`` ``[N, n]`` at the scenario's sample times;
* ``excitation.png`` — ``q``, ``q̇``, ``q̈`` on the dense check grid against the limits;
* ``result.json`` — the common envelope, payload ``ExcitationStudy.payload()``.
"""

from __future__ import annotations

from pathlib import Path

from idkit.limits import MOTION_VARIABLES
from idkit.reports import files
from idkit.reports import plots as figures
from idkit.reports.result_file import claim, write_result
from idkit.studies.excitation import ExcitationStudy

#: How each criterion is read: which direction is better.
BETTER = {"cond": "smaller is better", "logdet": "larger is better"}


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


def text(study: ExcitationStudy) -> str:
    """The criterion before and after, and whether each motion stays within the limits."""
    r = study.result
    n, t_end = int(r.t.numel()), float(r.grid[-1])
    ratio = r.before / r.after if r.criterion == "cond" else r.after - r.before
    change = f"{ratio:.2f} times smaller" if r.criterion == "cond" else f"{ratio:+.3g}"
    return "\n".join(
        [
            f"Excitation `{r.name}` for {study.robot_name}, criterion {r.criterion} ({BETTER[r.criterion]}) "
            f"at N = {n} samples over {t_end:g} s",
            "",
            f"  before ({study.baseline_name or 'default'}): {r.criterion} = {r.before:.6g}; "
            f"outside the limits: {_excursions(study, 'before')}",
            f"  after  ({r.name}, optimised): {r.criterion} = {r.after:.6g} ({change}); "
            f"outside the limits: {_excursions(study, 'after')}",
            f"  checked on {r.grid.numel()} points over [0, {t_end:g}] s; "
            f"load it with scenario.excitation=<run dir>/excitation.yaml",
            "",
        ]
    )


def write(study: ExcitationStudy, out_dir: str | Path, plots: bool = True) -> dict[str, str]:
    """Write ``excitation.yaml``, ``excitation.npz``, ``excitation.png`` (with ``plots``), ``result.json``."""
    from idkit.excitation.files import excitation_yaml

    out = claim(out_dir, study.provenance)
    r = study.result
    t, q, qd, qdd = (x.numpy() for x in r.samples())
    written = {
        "excitation": str(files.write_text(out / "excitation.yaml", excitation_yaml(r.name, r.excitation))),
        "samples": str(files.write_npz(out / "excitation.npz", {"t": t, "q": q, "qd": qd, "qdd": qdd})),
    }
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
