"""Re-check a trajectory file before it is run: ``python -m idkit.excitation.check <file> --robot <urdf>``.

What is checked, on every sample of the file (``.csv`` or ``.npz``, joints by name:
``idkit.excitation.export``):

* position, velocity and acceleration within the robot's limits (a URDF's ``<limit>``; its missing
  acceleration limits from ``--acceleration-limit``, else the effort-derived default of
  ``idkit.excitation.effort``), each by its safety margin (``--margin``, default 5 % of the limit's
  half-range: :mod:`idkit.excitation.margins`);
* the nominal model's torques (the URDF's CAD parameters) within each joint's ``<limit effort>``,
  by the same margin;
* at rest at both ends: ``|qd|``, ``|qdd| <= --rest-tolerance`` (1e-6) at the first and last sample;
* time that moves forwards (a repeated or earlier time is named with its sample) and a regular sample
  rate: every step within 1e-6 of the median step;
* velocities and accelerations that are the derivatives of the positions and velocities: a robot
  follows the positions, so ``qd`` columns in another unit (or ``t`` in milliseconds) would check
  a motion the robot does not make. Between two samples the change of ``q`` over the step must match
  the mean of their ``qd`` (the trapezoid rule), within :data:`DERIVATIVE_TOLERANCE` of the joint's
  peak rate (a sampled smooth motion misses it by ``(ω Δt)² / 12``: 1 % at an eighth of the rate);
  the same for ``qdd`` and ``qd``;
* no self-collision, where pinocchio + coal are installed and the URDF has collision geometry
  (``idkit.excitation.collision``; otherwise the report says it was not checked, and why).

Prints the margin of every joint and quantity (how far its worst sample stays from the limit, and
that as a share of the half-range), then one line per violation (joint, time, value, limit: beyond
the limit, or inside it but within the margin) and exits with status 1 if there is any — "all
checks passed" means every margin is met; a file or option it cannot use is refused in one line with
status 2. :func:`check_trajectory` is the same check from Python (the ``excitation`` task runs it on
the samples it writes).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from idkit.excitation.collision import NotChecked, SelfCollision
from idkit.excitation.export import Trajectory
from idkit.excitation.margins import QUANTITIES, SHARE_TOLERANCE, Margins
from idkit.limits import MOTION_VARIABLES, MotionLimits

#: Largest ``|qd|``, ``|qdd|`` at the ends of a motion that counts as at rest.
REST_TOLERANCE = 1e-6

#: Largest relative deviation of a time step from the median step.
RATE_TOLERANCE = 1e-6

#: Largest mismatch between a derivative column and the change of what it is the derivative of, as
#: a share of the joint's peak rate over the file (module doc).
DERIVATIVE_TOLERANCE = 0.05

#: The derivative columns: which column is the rate of change of which, and what the quantity is called.
DERIVATIVES = (("qd", "q", "velocity"), ("qdd", "qd", "acceleration"))

#: Exit status for a file with violations, and for an input that cannot be checked.
VIOLATED, UNUSABLE = 1, 2


@dataclass(frozen=True)
class Violation:
    """One broken requirement: what, where, when, how far.

    Attributes:
        subject: a joint name, a pair of links (``a–b``), or ``t``.
        quantity: ``position``, ``velocity``, ``acceleration``, ``effort``, ``qd at rest``,
            ``qdd at rest``, ``time order``, ``sample rate``, ``qd derivative``, ``qdd derivative`` or
            ``self-collision``.
        value, limit: for a derivative, the column's mean over the step and the rate of change.
        time: the (first or worst) offending instant, seconds.
        value, limit: the offending value and the limit it breaks (``None`` for a contact).
        samples: how many samples break it.
        margin: for a sample inside the limit but within its safety margin, the margin it misses
            (a share of the half-range); ``None`` for a sample beyond the limit.
        index: the (first) offending sample, where its time alone does not find it (time order).
    """

    subject: str
    quantity: str
    time: float
    value: float | None = None
    limit: float | None = None
    samples: int = 1
    margin: float | None = None
    index: int | None = None

    def line(self) -> str:
        """``lwr_1_joint: effort 180.2 at t = 3.21 s beyond the limit ±176 (41 samples)``."""
        more = f" ({self.samples} samples)" if self.samples > 1 else ""
        if self.quantity == "self-collision":
            return f"{self.subject}: in contact at t = {self.time:.6g} s{more}"
        if self.quantity.endswith("at rest"):
            return (
                f"{self.subject}: not at rest at t = {self.time:.6g} s: |{self.quantity.split()[0]}| = "
                f"{self.value:.3g} > {self.limit:.3g}"
            )
        if self.quantity == "time order":
            how = "repeats" if self.value == self.limit else "goes backwards"
            return (
                f"t: time {how} at sample {self.index}: t = {self.value:.9g} s after t = {self.limit:.9g} s"
                f"{more}"
            )
        if self.quantity.endswith("derivative"):
            column = self.quantity.split()[0]
            source = dict((d, v) for d, v, _ in DERIVATIVES)[column]
            return (
                f"{self.subject}: {column} {self.value:.4g} at t = {self.time:.6g} s where {source} changes "
                f"at {self.limit:.4g}/s{more}: not {source}'s derivative ({column} in another unit, or t "
                "not in seconds?)"
            )
        if self.quantity == "sample rate":
            return (
                f"t: step {self.value:.9g} s after t = {self.time:.9g} s, expected {self.limit:.9g} s "
                f"(±{RATE_TOLERANCE:g} relative){more}"
            )
        if self.margin is not None:
            return (
                f"{self.subject}: {self.quantity} {self.value:.6g} at t = {self.time:.6g} s within the "
                f"{100 * self.margin:.3g} % safety margin of the limit {self.limit:.6g}{more}"
            )
        return (
            f"{self.subject}: {self.quantity} {self.value:.6g} at t = {self.time:.6g} s beyond the limit "
            f"{self.limit:.6g}{more}"
        )


@dataclass(frozen=True)
class TrajectoryCheck:
    """What :func:`check_trajectory` found.

    Attributes:
        joint_names: the joints, in the rows' order.
        samples, duration, rate: number of samples, ``t[-1] - t[0]`` (s), ``1 / median step`` (Hz).
        margins: ``{joint: {quantity: {"worst", "lower", "upper", "margin", "share", "at"}}}``:
            the sample closest to (or furthest beyond) a limit, the limits, ``margin`` = its distance
            inside (negative beyond), ``share`` = margin / half-range, ``at`` its time. Effort is
            missing when the robot declares no effort limits.
        rest: ``{"start"|"end": {"velocity": max |qd|, "acceleration": max |qdd|}}`` over joints.
        collision: the self-collision status (``checked with …`` or ``not checked (…)``).
        effort: the effort status (``checked …`` or ``not checked (…)``).
        violations: every broken requirement (a missed margin included).
        required: the safety margins enforced (:class:`~idkit.excitation.margins.Margins`).
    """

    joint_names: tuple[str, ...]
    samples: int
    duration: float
    rate: float
    margins: dict[str, dict[str, dict[str, float]]]
    rest: dict[str, dict[str, float]]
    collision: str
    effort: str
    violations: tuple[Violation, ...] = field(default_factory=tuple)
    required: Margins = field(default_factory=Margins)

    @property
    def ok(self) -> bool:
        return not self.violations

    def as_dict(self) -> dict[str, Any]:
        """Plain values for ``result.json``."""
        return {
            "samples": self.samples,
            "duration": self.duration,
            "rate": self.rate,
            "margins": self.margins,
            "rest": self.rest,
            "self_collision": self.collision,
            "effort": self.effort,
            "required_margins": self.required.as_dict(),
            "violations": [v.line() for v in self.violations],
        }

    def table(self) -> str:
        """Margins per joint (Markdown): distance of the worst sample from each limit, and its share."""
        present = [q for q in QUANTITIES if any(q in by_joint for by_joint in self.margins.values())]
        header = "| joint | " + " | ".join(f"{q} margin" for q in present) + " |"
        lines = [header, "|---|" + "---:|" * len(present)]
        for joint in self.joint_names:
            cells = []
            for quantity in present:
                m = self.margins[joint].get(quantity)
                cells.append("—" if m is None else f"{m['margin']:.4g} ({100 * m['share']:.1f} %)")
            lines.append(f"| {joint} | " + " | ".join(cells) + " |")
        return "\n".join(lines)

    def summary(self) -> str:
        """Samples, rate, rest at the ends, self-collision status, and the verdict, a line each."""
        rest = ", ".join(
            f"{end}: |qd| ≤ {v['velocity']:.2g}, |qdd| ≤ {v['acceleration']:.2g}"
            for end, v in self.rest.items()
        )
        verdict = (
            f"all checks passed (every margin at least the required {self.required.describe()})"
            if self.ok
            else f"{len(self.violations)} violation(s) (required margins: {self.required.describe()})"
        )
        return "\n".join(
            [
                f"{self.samples} samples over {self.duration:g} s at {self.rate:.6g} Hz; at the ends {rest}",
                f"effort: {self.effort}",
                f"self-collision: {self.collision}",
                verdict,
            ]
        )


def _margins(
    name: str,
    values: np.ndarray,
    t: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    joints: Sequence[str],
    required: float = 0.0,
) -> tuple[dict[str, dict[str, float]], list[Violation]]:
    """Per joint: the worst sample of ``values[T, n]`` against ``[lower, upper]`` (``±inf``: none); a
    violation for samples beyond a limit, else for samples inside it by less than ``required`` of the
    half-range."""
    inside = np.minimum(values - lower, upper - values)  # [T, n], negative beyond a limit
    found, violations = {}, []
    for j, joint in enumerate(joints):
        if not (np.isfinite(lower[j]) or np.isfinite(upper[j])):
            continue
        k = int(np.argmin(inside[:, j]))
        half = (upper[j] - lower[j]) / 2
        found[joint] = {
            "worst": float(values[k, j]),
            "lower": float(lower[j]),
            "upper": float(upper[j]),
            "margin": float(inside[k, j]),
            "share": float(inside[k, j] / half) if np.isfinite(half) else float("nan"),
            "at": float(t[k]),
        }
        limit = float(upper[j] if upper[j] - values[k, j] < values[k, j] - lower[j] else lower[j])
        beyond = int((inside[:, j] < 0).sum())
        if beyond:
            violations.append(Violation(joint, name, float(t[k]), float(values[k, j]), limit, beyond))
        elif np.isfinite(half) and required > 0:
            short = int((inside[:, j] < (required - SHARE_TOLERANCE) * half).sum())
            if short:
                violations.append(
                    Violation(joint, name, float(t[k]), float(values[k, j]), limit, short, required)
                )
    return found, violations


def _rest(trajectory: Trajectory, tolerance: float) -> tuple[dict[str, dict[str, float]], list[Violation]]:
    found, violations = {}, []
    for end, k in (("start", 0), ("end", -1)):
        found[end] = {
            "velocity": float(np.abs(trajectory.qd[k]).max()),
            "acceleration": float(np.abs(trajectory.qdd[k]).max()),
        }
        for name, values in (("qd", trajectory.qd[k]), ("qdd", trajectory.qdd[k])):
            for j in np.flatnonzero(np.abs(values) > tolerance):
                joint, value = trajectory.joint_names[j], abs(float(values[j]))
                violations.append(
                    Violation(joint, f"{name} at rest", float(trajectory.t[k]), value, tolerance)
                )
    return found, violations


def _rate(t: np.ndarray) -> tuple[float, list[Violation]]:
    """The rate (1 / the median forward step) and what breaks it: time that repeats or goes back
    (named by its sample: no step size describes it), then forward steps off the median."""
    steps = np.diff(t)
    forward = steps > 0
    step = float(np.median(steps[forward])) if forward.any() else float("nan")
    violations = []
    back = np.flatnonzero(~forward)
    if back.size:
        k = int(back[0])
        violations.append(
            Violation(
                "t", "time order", float(t[k + 1]), float(t[k + 1]), float(t[k]), int(back.size), index=k + 1
            )
        )
    irregular = np.flatnonzero(forward & (np.abs(steps - step) > RATE_TOLERANCE * abs(step)))
    if irregular.size:
        k = int(irregular[0])
        violations.append(
            Violation("t", "sample rate", float(t[k]), float(steps[k]), step, int(irregular.size))
        )
    return 1.0 / step, violations


def _derivatives(trajectory: Trajectory) -> list[Violation]:
    """Each derivative column against the change of its source between two samples (module doc); steps
    off the regular rate (backwards, repeated, irregular) are left to :func:`_rate`, which names them."""
    dt = np.diff(trajectory.t)
    step = float(np.median(dt[dt > 0])) if (dt > 0).any() else float("nan")
    forward = np.abs(dt - step) <= RATE_TOLERANCE * abs(step)
    mid = trajectory.t[:-1][forward] + dt[forward] / 2
    violations = []
    for column, source, _ in DERIVATIVES:
        values, of = getattr(trajectory, column), getattr(trajectory, source)
        rate = np.diff(of, axis=0)[forward] / dt[forward, None]  # [S, n]
        mean = ((values[:-1] + values[1:]) / 2)[forward]
        miss = np.abs(rate - mean)
        peak = np.maximum(np.abs(rate).max(0, initial=0.0), np.abs(mean).max(0, initial=0.0))
        wrong = miss > DERIVATIVE_TOLERANCE * peak
        for j in np.flatnonzero(wrong.any(0)):
            k = int(np.argmax(miss[:, j]))
            violations.append(
                Violation(
                    trajectory.joint_names[j],
                    f"{column} derivative",
                    float(mid[k]),
                    float(mean[k, j]),
                    float(rate[k, j]),
                    int(wrong[:, j].sum()),
                )
            )
    return violations


def _contacts(trajectory: Trajectory, collision: SelfCollision) -> list[Violation]:
    first: dict[tuple[str, str], list[float]] = {}
    for contact in collision.contacts(trajectory.q):
        first.setdefault((contact.first, contact.second), []).append(float(trajectory.t[contact.index]))
    return [
        Violation(f"{a}–{b}", "self-collision", times[0], samples=len(times))
        for (a, b), times in first.items()
    ]


def check_trajectory(
    trajectory: Trajectory,
    limits: MotionLimits,
    torques: np.ndarray | None,
    effort: np.ndarray | None,
    collision: SelfCollision | NotChecked,
    rest_tolerance: float = REST_TOLERANCE,
    margins: Margins | None = None,
) -> TrajectoryCheck:
    """Check ``trajectory`` (module docstring).

    Args:
        trajectory: the samples, joints in ``limits``' order.
        limits: the position, velocity and acceleration box.
        torques: the nominal model's torques ``[T, n]`` at the samples, or ``None`` (not checked).
        effort: the effort limits ``[n]``, or ``None`` (the robot declares none).
        collision: a self-collision test, or why there is none.
        rest_tolerance: largest ``|qd|``, ``|qdd|`` at the first and last sample.
        margins: the safety margins every sample must keep (``None``: the default, 5 %).
    """
    required = Margins.of(margins)
    if tuple(limits.joint_names) != trajectory.joint_names:
        raise ValueError(
            f"check: limits are for {limits.joint_names}, the trajectory has {trajectory.joint_names}"
        )
    joints, t = trajectory.joint_names, trajectory.t
    kept: dict[str, dict[str, dict[str, float]]] = {joint: {} for joint in joints}  # the margins kept
    violations: list[Violation] = []
    checks = [
        (name, values, limits.lower[row].numpy(), limits.upper[row].numpy())
        for row, (name, values) in enumerate(
            zip(MOTION_VARIABLES, (trajectory.q, trajectory.qd, trajectory.qdd), strict=True)
        )
    ]
    effort_status = "not checked (the robot declares no effort limits)"
    if torques is not None and effort is not None:
        checks.append(("effort", torques, -effort, effort))
        effort_status = "checked: the nominal model's torques against each joint's effort limit"
    for name, values, lower, upper in checks:
        found, broken = _margins(name, values, t, lower, upper, joints, required.share(name))
        for joint, margin in found.items():
            kept[joint][name] = margin
        violations += broken
    rest, broken = _rest(trajectory, rest_tolerance)
    violations += broken
    rate, broken = _rate(t)
    violations += broken + _derivatives(trajectory)
    if isinstance(collision, SelfCollision):
        violations += _contacts(trajectory, collision)
    return TrajectoryCheck(
        joints,
        len(t),
        float(t[-1] - t[0]),
        rate,
        kept,
        rest,
        collision.status(),
        effort_status,
        tuple(violations),
        required,
    )


def check_file(
    path: str,
    urdf: str,
    acceleration_limit: Sequence[float] | None = None,
    collision: bool = True,
    package_dirs: Sequence[str] = (),
    rest_tolerance: float = REST_TOLERANCE,
    margins: Margins | None = None,
) -> tuple[TrajectoryCheck, str]:
    """Check the trajectory file ``path`` for the URDF robot ``urdf``; also says where the
    acceleration limits came from."""
    import torch

    from idkit.excitation.collision import self_collision
    from idkit.excitation.effort import acceleration_bounded_limits, effort_limits, nominal_torques
    from idkit.excitation.export import read_trajectory
    from idkit.robots.urdf import URDFRobot

    robot = URDFRobot(urdf)
    limits, source = acceleration_bounded_limits(
        robot, list(acceleration_limit) if acceleration_limit else None
    )
    trajectory = read_trajectory(path, robot.joint_names)
    effort = effort_limits(robot)
    torques = None
    if effort is not None:
        states = (torch.from_numpy(x) for x in (trajectory.q, trajectory.qd, trajectory.qdd))
        torques = nominal_torques(robot, *states).numpy()
    test = self_collision(robot, package_dirs) if collision else NotChecked("switched off (--no-collision)")
    checked = check_trajectory(
        trajectory, limits, torques, None if effort is None else effort.numpy(), test, rest_tolerance, margins
    )
    accelerations = ", ".join(f"{v:.4g}" for v in limits.upper[2].tolist())
    where = {
        "given": "given (--acceleration-limit)",
        "robot": "the robot's",
        "effort": "not in the URDF: the effort-derived default (idkit.excitation.effort)",
    }[source]
    return checked, f"acceleration limits ±[{accelerations}]: {where}"


def margin_option(words: Sequence[str] | None) -> Margins:
    """``--margin``'s words as margins: none (the default), one share, or ``quantity=share`` pairs.

    Raises:
        ValueError: a word that is neither, naming it.
    """
    if not words:
        return Margins()
    try:
        if len(words) == 1 and "=" not in words[0]:
            return Margins.of(float(words[0]), "--margin")
        pairs = dict(word.split("=", 1) for word in words)
        return Margins.of({key: float(value) for key, value in pairs.items()}, "--margin")
    except ValueError as exc:
        if str(exc).startswith("--margin"):
            raise
        raise ValueError(
            f"--margin takes one share (0.05) or quantity=share pairs (position=0.05 effort=0.1), "
            f"got {' '.join(words)}"
        ) from None


def main(argv: Sequence[str] | None = None) -> int:
    """The command line (module docstring); returns the exit status."""
    parser = argparse.ArgumentParser(
        prog="python -m idkit.excitation.check", description=__doc__.splitlines()[0].split(": ")[0]
    )
    parser.add_argument("file", help="trajectory file: .csv or .npz with t and <joint>.q/.qd/.qdd")
    parser.add_argument("--robot", required=True, help="the robot's URDF file")
    parser.add_argument(
        "--acceleration-limit", type=float, nargs="+", metavar="A", help="|qdd| bound: one, or one per joint"
    )
    parser.add_argument("--rest-tolerance", type=float, default=REST_TOLERANCE)
    parser.add_argument(
        "--margin",
        nargs="+",
        metavar="M",
        help="safety margin, a share of each limit's half-range: one number for every limit (default "
        "0.05), or quantity=share pairs (position=0.05 effort=0.1)",
    )
    parser.add_argument("--no-collision", action="store_true", help="skip the self-collision check")
    parser.add_argument(
        "--package-dir", action="append", default=[], help="folder holding packages of package:// meshes"
    )
    args = parser.parse_args(argv)
    try:
        margins = margin_option(args.margin)
        checked, acceleration = check_file(
            args.file,
            args.robot,
            args.acceleration_limit,
            not args.no_collision,
            args.package_dir,
            args.rest_tolerance,
            margins,
        )
    except (ValueError, FileNotFoundError, TypeError) as exc:
        print(f"idkit: {exc}", file=sys.stderr)
        return UNUSABLE
    print(f"{args.file}: {acceleration}")
    print(checked.table())
    print(checked.summary())
    for violation in checked.violations:
        print(violation.line())
    return VIOLATED if checked.violations else 0


if __name__ == "__main__":
    sys.exit(main())
