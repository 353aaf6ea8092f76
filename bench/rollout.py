"""Rollout identification: idkit's ``rollout`` estimator beside ``mujoco.sysid`` on the same models and logs.

Run: ``python bench/rollout.py [--cases a b c] [--starts 20] [--threads 2] [--sysid mujoco scipy robust]
[--labels physical|shifted|both] [--jacobian-every 1 3]``
(needs the ``bench`` extra: ``mujoco[sysid]``). The cases are :mod:`idkit.testing.rollout_cases`:

* ``a``: ``mujoco.sysid``'s own integration-test arm (5 torque motors), its 5 armatures;
* ``b``: a 7-joint arm under position and velocity servos, per joint armature, damping, friction loss,
  kp, kv, and one delay (36 unknowns);
* ``c``: ``b`` with noise, 1.5 % glitched samples and an unknown 7 ms delay.

Every tool gets the same model, the same fit log (commands and measured joint positions and velocities
at their physical times: :mod:`idkit.sim.timing`), the same bounds and, for each run, the same start:
the case's own, then ``starts - 1`` drawn log-uniformly in [0.2, 5] × the truth (delay 0). Rows:

* ``idkit rollout``: the estimator with its defaults (the robust scale is set by the data);
* ``sysid <optimizer>``: ``mujoco.sysid.optimize`` with ``optimizer="mujoco"`` (its default) or
  ``"scipy"``, least squares, the residual as documented (sensors ``jointpos``/``jointvel`` added to the
  model, the delay as its ``apply_resample_and_delay`` signal modifier);
* ``sysid scipy robust``: scipy's ``soft_l1`` loss with ``f_scale`` set by hand from the truth: the
  median absolute residual of the truth on the fit log (an oracle no user has: the best case for it);
* ``sysid ... shifted``: the same, the log's sensor times moved one step later — ``mujoco.sysid``
  labels the simulated sensor row of step ``k`` with the time after the step, while MuJoCo computes it
  before: a user who knows this relabels the log so.

Columns: success (every parameter within 5 % of the truth; the delay within 5 % or 0.1 ms), the median
and largest relative error, the held-out error (1.4826 × the median absolute position error, rad, over
the held-out log rolled out whole from its first logged state: the noise level when a model reproduces
it within the noise, unmoved by glitches; the truth's own is in the table's title), wall
time (median, and total), CPU seconds of the process (median: user + system, every thread)
and the simulated time in lengths of the fit log (median: a rollout of the whole
log counts 1, of a segment its share; a finite-difference column is a rollout).
Threads: ``--threads`` for both tools. Say the machine's load beside the numbers (``uptime``).
"""

# ruff: noqa: E402
from __future__ import annotations

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import argparse
import logging
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np

from idkit.estimators.rollout import RolloutEstimator
from idkit.sim.model import load_model
from idkit.sim.quantities import select_unknowns
from idkit.testing import rollout_cases as cases

SUCCESS = 0.05
COLUMNS = ("median err", "max err", "held-out", "wall med", "wall sum", "CPU med", "logs sim")
DELAY_SLACK = 1e-4


@dataclass
class Run:
    values: np.ndarray
    wall: float
    rollouts: int
    cpu: float = float("nan")


def relative_errors(case: cases.Case, values: np.ndarray) -> np.ndarray:
    truth = np.array(list(case.truth.values()))
    errors = np.abs(values - truth) / np.where(truth != 0, np.abs(truth), 1.0)
    for i, name in enumerate(case.truth):
        if name == "command_delay":
            errors[i] = min(errors[i], abs(values[i] - truth[i]) / DELAY_SLACK * SUCCESS)
    return errors


def held_out_error(case: cases.Case, values: dict[str, float]) -> float:
    """Robust position error (1.4826 × the median absolute error, which glitched samples do not move)
    over the held-out log, rolled out whole from its first state."""
    from mujoco import rollout

    sim = load_model(case.model)
    names = list(values)
    unknowns = select_unknowns(sim, case.fit.joint_names, case.params, start=values, bounds=case.bounds)
    model = sim.model
    unknowns.apply(model, np.array([values[n] for n in names]))
    mujoco.mj_setConst(model, mujoco.MjData(model))
    log = case.held_out
    from idkit.sim.drive import match_commands
    from idkit.sim.model import logged_state
    from idkit.sim.timing import held_averages

    drive = match_commands(sim, log)
    delay = values.get("command_delay", 0.0)
    controls = held_averages(
        log.command_t,
        log.commands[:, list(drive.columns)],
        np.array([log.t[0] - delay]),
        log.t.size - 1,
        sim.timestep,
    )
    state0 = logged_state(sim, log.joint_names, log.q[0], log.qd[0])
    state, _ = rollout.rollout(model, mujoco.MjData(model), state0, controls[0])
    ids = [sim.joint_id(j) for j in log.joint_names]
    q = state[0][:, 1 + np.array([model.jnt_qposadr[i] for i in ids])]
    return float(1.4826 * np.median(np.abs(q - log.q[1:])))


def run_idkit(case: cases.Case, start: dict[str, float], threads: int, **options: int) -> Run:
    problem = cases.problem_of(case, start, threads=threads)
    began, cpu = time.perf_counter(), time.process_time()
    estimate = RolloutEstimator(**options).fit(problem)
    wall, cpu = time.perf_counter() - began, time.process_time() - cpu
    duration = case.fit.t[-1] - case.fit.t[0]
    simulated = estimate.details.simulated_seconds / duration
    return Run(np.array(list(estimate.params.values())), wall, simulated, cpu)


# --- mujoco.sysid -------------------------------------------------------------------------------


def _modifier(name: str, kind: str) -> Callable | None:
    element = name.rpartition(".")[0]
    if kind in ("armature", "frictionloss"):
        return lambda spec, p: setattr(spec.joint(element), kind, p.value[0])
    if kind == "damping":

        def damping(spec, p):
            value = np.array(spec.joint(element).damping, dtype=float).reshape(-1)
            value[0] = p.value[0]
            spec.joint(element).damping = value

        return damping
    if kind in ("kp", "kv"):

        def gain(spec, p):
            actuator = spec.actuator(element)
            g, b = np.array(actuator.gainprm), np.array(actuator.biasprm)
            g[0] = p.value[0]
            b[1 if kind == "kp" else 2] = -p.value[0]
            actuator.gainprm, actuator.biasprm = g, b

        return gain
    return None


def run_sysid(
    case: cases.Case,
    start: dict[str, float],
    optimizer: str,
    shifted: bool,
    threads: int,
    f_scale: float | None,
) -> Run:
    from mujoco import sysid

    spec = mujoco.MjSpec.from_string(case.model)
    for joint in case.fit.joint_names:
        spec.add_sensor(
            name=f"{joint}_pos",
            type=mujoco.mjtSensor.mjSENS_JOINTPOS,
            objtype=mujoco.mjtObj.mjOBJ_JOINT,
            objname=joint,
        )
    for joint in case.fit.joint_names:
        spec.add_sensor(
            name=f"{joint}_vel",
            type=mujoco.mjtSensor.mjSENS_JOINTVEL,
            objtype=mujoco.mjtObj.mjOBJ_JOINT,
            objname=joint,
        )
    model = spec.compile()
    kinds = dict(zip(case.truth, _kinds(case), strict=True))
    params = sysid.ParameterDict()
    for name in case.truth:
        lower, upper = case.bounds[name]
        modifier = _modifier(name, kinds[name])
        parameter = sysid.Parameter(
            name, nominal=float(start[name]), min_value=lower, max_value=upper, modifier=modifier
        )
        params.add(parameter)
    log = case.fit
    sensor_times = log.t + (model.opt.timestep if shifted else 0.0)
    initial = sysid.create_initial_state(model, log.q[0], log.qd[0])
    from idkit.sim.drive import match_commands
    from idkit.sim.model import SimModel

    drive = match_commands(SimModel(spec, model, "bench", None), log)
    control = sysid.TimeSeries(log.command_t, log.commands[:, list(drive.columns)])
    sensors = sysid.TimeSeries.from_names(sensor_times, np.hstack([log.q, log.qd]), model)
    sequences = sysid.ModelSequences(case.name, spec, "fit", initial, control, sensors)
    options: dict = {}
    if "command_delay" in case.truth:
        largest = case.bounds["command_delay"][1]

        def delayed(params, predicted, measured, model, return_pred_all, state=None, **_):
            measured = sysid.apply_delayed_ts_window(measured, predicted, 0.0, largest)
            predicted = sysid.apply_resample_and_delay(
                predicted, measured.times, params["command_delay"].value[0]
            )
            residual = sysid.normalize_residual(
                sysid.weighted_diff(predicted.data, measured.data), measured.data
            )
            return residual, predicted, measured

        options["modify_residual"] = delayed
    counted = {"rollouts": 0}
    residual_fn = sysid.build_residual_fn(models_sequences=[sequences], n_threads=threads, **options)

    def counting(x, p, **kwargs):
        counted["rollouts"] += 1 if np.ndim(x) == 1 else np.shape(x)[1]
        return residual_fn(x, p, **kwargs)

    extra = {"loss": "soft_l1", "f_scale": f_scale} if f_scale is not None else {}
    began, cpu = time.perf_counter(), time.process_time()
    found, _ = sysid.optimize(params, counting, optimizer=optimizer, verbose=False, **extra)
    wall, cpu = time.perf_counter() - began, time.process_time() - cpu
    return Run(np.array([found[name].value[0] for name in case.truth]), wall, counted["rollouts"], cpu)


def _kinds(case: cases.Case) -> list[str]:
    sim = load_model(case.model)
    unknowns = select_unknowns(sim, case.fit.joint_names, case.params, start=case.start, bounds=case.bounds)
    return [u.kind for u in unknowns.items]


def truth_f_scale(case: cases.Case) -> float:
    """The oracle ``f_scale`` of ``sysid scipy robust``: the median absolute residual of the truth."""
    from mujoco import sysid

    spec = mujoco.MjSpec.from_string(case.model)
    for suffix, kind in (
        ("pos", mujoco.mjtSensor.mjSENS_JOINTPOS),
        ("vel", mujoco.mjtSensor.mjSENS_JOINTVEL),
    ):
        for joint in case.fit.joint_names:
            spec.add_sensor(
                name=f"{joint}_{suffix}", type=kind, objtype=mujoco.mjtObj.mjOBJ_JOINT, objname=joint
            )
    model = spec.compile()
    clean = cases.case_b(corrupted=False) if case.name == "c" else case
    measured = np.hstack([case.fit.q, case.fit.qd])
    exact = np.hstack([clean.fit.q, clean.fit.qd])
    if case.name == "c":
        from idkit.testing.rollout_cases import delayed

        q, qd = delayed(clean.fit.t, clean.fit.q, clean.fit.qd, case.truth["command_delay"])
        exact = np.hstack([q, qd])
    residual = sysid.normalize_residual(measured - exact, measured)
    del model
    return float(np.median(np.abs(residual)))


def table(rows: list[tuple[str, list[Run]]], case: cases.Case, reference: float) -> str:
    lines = [
        f"case {case.name}: {len(case.truth)} unknowns, {case.fit.n_samples} samples; "
        f"the truth's held-out error {reference:.3g} rad",
        f"{'tool':<28}{'success':>9}" + "".join(f"{h:>11}" for h in COLUMNS),
    ]
    for label, runs in rows:
        errors = [relative_errors(case, r.values) for r in runs]
        ok = sum(bool((e < SUCCESS).all()) for e in errors)
        held = [held_out_error(case, dict(zip(case.truth, r.values, strict=True))) for r in runs]
        lines.append(
            f"{label:<28}{f'{ok}/{len(runs)}':>9}"
            f"{statistics.median(float(np.median(e)) for e in errors):>11.2e}"
            f"{statistics.median(float(e.max()) for e in errors):>11.2e}{statistics.median(held):>11.2e}"
            f"{statistics.median(r.wall for r in runs):>10.1f}s{sum(r.wall for r in runs):>10.0f}s"
            f"{statistics.median(r.cpu for r in runs):>10.1f}s"
            f"{statistics.median(r.rollouts for r in runs):>11.0f}"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", default=["a", "b", "c"])
    parser.add_argument("--starts", type=int, default=20)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument(
        "--jacobian-every",
        type=int,
        nargs="+",
        default=[3],
        help="idkit rows, one per value of the estimator's jacobian_every (1: the polish before Broyden)",
    )
    parser.add_argument("--sysid", nargs="*", default=["mujoco", "scipy", "robust"])
    parser.add_argument(
        "--labels",
        choices=["physical", "shifted", "both"],
        default="both",
        help="the log's times as given to sysid: physical, moved one step later (its convention), or both",
    )
    args = parser.parse_args()
    logging.disable(logging.WARNING)
    from absl import logging as absl_logging

    absl_logging.set_verbosity(absl_logging.ERROR)
    for name in args.cases:
        case = cases.case_a() if name == "a" else cases.case_b(corrupted=name == "c")
        starts = [case.start, *case.starts(args.starts - 1, seed=1)]
        reference = held_out_error(case, case.truth)
        configurations = [(f"sysid {o}", o if o != "robust" else "scipy", o == "robust") for o in args.sysid]
        if "robust" in args.sysid and name != "c":
            configurations = [c for c in configurations if not c[2]]
        f_scale = truth_f_scale(case) if name == "c" else None
        conventions = {"physical": [False], "shifted": [True], "both": [False, True]}[args.labels]
        idkit_rows = {f"idkit rollout (jacobian_every={k})": k for k in args.jacobian_every}
        rows: dict[str, list[Run]] = {label: [] for label in idkit_rows}
        for shifted in conventions:
            for label, _, _ in configurations:
                rows[label + (" shifted" if shifted else "")] = []
        for i, start in enumerate(starts):
            for label, every in idkit_rows.items():
                rows[label].append(run_idkit(case, start, args.threads, jacobian_every=every))
            for shifted in conventions:
                for label, optimizer, robust in configurations:
                    run = run_sysid(
                        case, start, optimizer, shifted, args.threads, f_scale if robust else None
                    )
                    rows[label + (" shifted" if shifted else "")].append(run)
            print(f"  case {name}: start {i + 1}/{len(starts)} done", flush=True)
        print(table(list(rows.items()), case, reference), flush=True)


if __name__ == "__main__":
    main()
