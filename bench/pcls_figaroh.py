"""idkit's ``pcls`` beside FIGAROH's physically consistent fit on the KUKA LWR4+, measured in one run.

Run: ``python bench/pcls_figaroh.py [--repeats 3]`` (needs the ``bench`` extra: FIGAROH, QICS, pinocchio,
and the KUKA files in ``../shared/data/kuka-lwr4``). Prints one Markdown table.

Every method fits the same training samples — ``measurements_1`` loaded and preprocessed by idkit
exactly as the short command ``idkit robot=urdf robot.urdf=kuka_lwr4.urdf data=measurements_1.npz
'validate=[measurements_3.npz,measurements_2.npz]'`` loads it (:func:`idkit.data.pipeline.read_training`)
— with Coulomb + viscous friction and an offset per joint:

* idkit ``pcls`` with ``prior_weight=auto`` (the command's default), at the fixed weight 300, and with
  ``plausible=true`` (every link mass within [0.5, 2] × CAD and inside its geometry's bounding
  ellipsoid; the alternative the command also fits when a link is flagged);
* FIGAROH 1.0.2's direct LMI effort fit (``figaroh.identification.physical_fit``) as its
  ``select_stage: physical_fit`` runs it (:func:`figaroh.identification.selection.run_physical_fit`:
  ``build_problem`` on the standard regressor, the CAD vector as prior, cvxopt, then the configured
  ``second_solver`` — here QICS — when cvxopt does not return ``optimal``), given idkit's standard
  regressor of the same samples with its columns named as FIGAROH names them (``m_<joint>``,
  ``mx_<joint>`` …, ``fs_``/``fv_``/``off_<joint>``). Once with FIGAROH's default ``prior_weight``
  (1e-6), once with the weight matched to idkit's: FIGAROH minimises ``‖Y θ − τ‖² + λ ‖z‖²`` with
  ``z`` the deviation from the prior in per-link relative units (mass, first moment and inertia each
  over their CAD norm), idkit ``‖Y θ − τ‖² / s² + w Σ D(J ‖ J0)``; scaling a link by ``1 + ε`` costs
  ``3 λ ε²`` in the one and ``2 w ε² s²`` (entropic divergence ≈ ``2 ε²``) in the other, so
  ``λ = (2/3) w s²`` with ``w`` the weight ``auto`` chose and ``s²`` idkit's data scale;
  and once more with FIGAROH's own ``mass_ratio_bounds`` (0.5, 2) — a ``PhysicalPolicy`` field its
  config does not expose — at the weight matched to the one ``plausible=true`` chose, beside it.

Each fit is scored by the figure the command prints (:func:`idkit.studies.validation.validate_file` on
``measurements_3`` and ``measurements_2``) and independently: the model written as ``identified.urdf``,
read back by pinocchio, its RNEA plus friction and offsets on the held-out files' own states
(:mod:`idkit.verify.rescore`, the npz read with numpy). "PSD" is checked on pinocchio's inertias of that
file. Times: wall and CPU (this process) of the fit, median of ``repeats`` calls after one warm-up,
everything on one thread; the load average is printed before and after. ``--sweep`` adds a table of
both priors at matched weights (idkit's ``w`` of :data:`SWEEP`), held-out figures only: the shapes of
the two priors differ (entropic divergence of the pseudo-inertias vs a per-coordinate quadratic).
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from idkit import registry  # noqa: E402
from idkit.data.load import DataFile  # noqa: E402
from idkit.data.options import DataOptions  # noqa: E402
from idkit.data.pipeline import read_held_out, read_training  # noqa: E402
from idkit.estimate import Estimate  # noqa: E402
from idkit.estimators.physical import PhysicallyConsistentLS  # noqa: E402
from idkit.model import IdentifiedModel  # noqa: E402
from idkit.problem import Problem  # noqa: E402
from idkit.robots.urdf import URDFRobot  # noqa: E402
from idkit.robots.urdf_export import write_identified_urdf  # noqa: E402
from idkit.studies.validation import validate_file  # noqa: E402
from idkit.verify.rescore import documented_score, predicted_torques, read_identified  # noqa: E402

KUKA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "kuka-lwr4"
HELD_OUT = ("measurements_3.npz", "measurements_2.npz")
FIXED_WEIGHT = 300.0
#: idkit prior weights of ``--sweep`` (FIGAROH's matched by :func:`figaroh_weight`).
SWEEP = (100.0, 300.0, 1000.0, 3000.0)
#: idkit's parameter key → FIGAROH's (``<key>_<joint>``); inertia keys are the same.
FIGAROH_KEYS = {"mcx": "mx", "mcy": "my", "mcz": "mz", "fc": "fs", "offset": "off"}
#: FIGAROH's ``physical_fit`` defaults (``figaroh.identification.config.PHYSICAL_FIT_DEFAULTS``) with the
#: second solver its CAD prior needs.
FIGAROH_DEFAULT_WEIGHT = 1e-6
SECOND_SOLVER = "qics"


@dataclass
class Fit:
    """One method's parameters (idkit's order) and its fit times (s)."""

    label: str
    params: np.ndarray
    wall: list[float]
    cpu: list[float]
    note: str = ""


def timed(label: str, fit: Callable[[], tuple[np.ndarray, str]], repeats: int) -> Fit:
    """``fit`` once to warm up (its result is the one scored), then ``repeats`` timed calls."""
    params, note = fit()
    wall, cpu = [], []
    for _ in range(repeats):
        w0, c0 = time.perf_counter(), time.process_time()
        fit()
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
    return Fit(label, params, wall, cpu, note)


def figaroh_names(robot: URDFRobot) -> list[str]:
    """idkit's parameter names as FIGAROH names them (a link's parameters carry its joint's name)."""
    joint_of = dict(zip(robot.link_names, robot.joint_names, strict=True))
    out = []
    for name in robot.param_names:
        owner, key = name.rsplit(".", 1)
        out.append(f"{FIGAROH_KEYS.get(key, key)}_{joint_of.get(owner, owner)}")
    return out


def figaroh_weight(weight: float, scale2: float) -> float:
    """FIGAROH's ``prior_weight`` that pulls a uniformly scaled link as hard as idkit's ``weight`` with
    data scale ``scale2`` (module doc)."""
    return 2.0 / 3.0 * weight * scale2


def figaroh_fit(
    robot: URDFRobot, Y: np.ndarray, tau: np.ndarray, weight: float, mass_ratio: tuple[float, float] | None
) -> Callable[[], tuple[np.ndarray, str]]:
    """FIGAROH's direct effort fit with a CAD prior, solver then second solver as ``run_physical_fit`` does;
    ``mass_ratio``: its ``PhysicalPolicy.mass_ratio_bounds`` (not reachable from its config)."""
    from figaroh.identification import physical_fit, selection

    names = figaroh_names(robot)
    prior = robot.nominal_params().numpy()

    def configured() -> tuple[np.ndarray, str]:
        identif = SimpleNamespace(
            identif_config={
                "physical_fit": {"enabled": True, "second_solver": SECOND_SOLVER, "prior_weight": weight}
            },
            standard_parameter=dict(zip(names, prior, strict=True)),
            _solve_W=Y,
            _solve_tau=tau,
            _idx_eliminated=[],
            model=SimpleNamespace(names=["universe", *robot.joint_names]),
            _wls_row_weight=None,
        )
        outcome = selection.run_physical_fit(identif)
        if not outcome["accepted"]:
            raise RuntimeError(f"FIGAROH physical_fit rejected: {outcome['reason']}")
        return outcome["record"].theta, outcome["reason"]

    def bounded() -> tuple[np.ndarray, str]:
        policy = physical_fit.PhysicalPolicy(mass_min=1e-6, prior_weight=weight, mass_ratio_bounds=mass_ratio)
        problem = physical_fit.build_problem(Y, tau, names, robot.joint_names, prior=prior, policy=policy)
        steps = []
        for solver in ("cvxopt", SECOND_SOLVER):
            record = physical_fit.solve_direct_effort_fit(problem, solver=solver)
            steps.append(f"{solver}: {record.solver_status}")
            if record.solver_status == "optimal":
                break
        if not record.accepted:
            raise RuntimeError(f"FIGAROH physical_fit rejected: {'; '.join(steps)}")
        return record.theta, "; ".join(steps)

    return configured if mass_ratio is None else bounded


def pcls_fit(
    problem: Problem, details: dict | None = None, **options: object
) -> Callable[[], tuple[np.ndarray, str]]:
    """``pcls`` with ``options`` on ``problem``; ``details`` receives the last estimate's details."""
    estimator = PhysicallyConsistentLS(**options)  # type: ignore[arg-type]
    robot = problem.robot

    def fit() -> tuple[np.ndarray, str]:
        estimate = estimator.fit(problem)
        if details is not None:
            details.update(estimate.details)
        vector = np.array([estimate.params[name] for name in robot.param_names])
        return vector, f"prior weight {estimate.details['prior_weight']:g}"

    return fit


def rescored(robot: URDFRobot, params: np.ndarray, folder: Path) -> tuple[list[float], float]:
    """Pinocchio's held-out ``‖E‖/‖T‖`` of the written model on each held-out npz, and the smallest
    pseudo-inertia eigenvalue over its bodies (both from ``identified.urdf`` as pinocchio reads it)."""
    urdf = write_identified_urdf(robot, torch.from_numpy(params), folder / "identified.urdf")
    identified = read_identified(urdf)
    scores = []
    for name in HELD_OUT:
        data = np.load(KUKA / name)
        times = data["times"] - data["times"][0]
        predicted = predicted_torques(
            identified, robot.joint_names, data["positions"], data["velocities"], data["accelerations"]
        )
        scores.append(documented_score(times, data["torques"], predicted, 6.0))
    eigen = []
    for inertia in identified.model.inertias[1:]:
        m, c, inertia_c = inertia.mass, np.asarray(inertia.lever), np.asarray(inertia.inertia)
        inertia_o = inertia_c + m * (c @ c * np.eye(3) - np.outer(c, c))
        sigma = 0.5 * np.trace(inertia_o) * np.eye(3) - inertia_o
        pseudo = np.block([[sigma, m * c[:, None]], [m * c[None, :], np.array([[m]])]])
        eigen.append(np.linalg.eigvalsh(pseudo)[0])
    return scores, float(min(eigen))


def held_out(robot: URDFRobot, params: np.ndarray, held: list[DataFile]) -> list[float]:
    """The command's held-out ``‖E‖/‖T‖`` (%) of standard ``params`` on each held-out file."""
    estimate = Estimate("bench", dict(zip(robot.param_names, params.tolist(), strict=True)), None, 0.0)
    model = IdentifiedModel(robot, estimate)
    return [100 * validate_file(model, h).rel_all for h in held]


def mass_ratios(robot: URDFRobot, params: np.ndarray) -> str:
    """The smallest and largest link mass over its CAD mass."""
    masses = [robot.param_names.index(f"{link}.m") for link in robot.link_names]
    ratio = params[masses] / robot.nominal_params().numpy()[masses]
    return f"{ratio.min():.2f}–{ratio.max():.2f}"


def row(fit: Fit, robot: URDFRobot, held: list[DataFile], folder: Path) -> str:
    again, eigen = rescored(robot, fit.params, folder)
    ours = held_out(robot, fit.params, held)
    cells = [
        fit.label,
        f"{statistics.median(fit.wall):.2f} ({min(fit.wall):.2f})",
        f"{statistics.median(fit.cpu):.2f}",
        *(f"{a:.2f} % / {100 * b:.2f} %" for a, b in zip(ours, again, strict=True)),
        f"{'yes' if eigen >= 0 else 'no'} ({eigen:.1e})",
        mass_ratios(robot, fit.params),
        fit.note,
    ]
    return "| " + " | ".join(cells) + " |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="timed fits per method (median)")
    parser.add_argument(
        "--sweep", action="store_true", help="also both priors at matched weights 100–3000 (held-out only)"
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    load_before = os.getloadavg()
    robot = registry.create("robot", "urdf", urdf=str(KUKA / "kuka_lwr4.urdf"), friction=True, offset=True)
    training = read_training(robot, str(KUKA / "measurements_1.npz"), DataOptions.of())
    samples = training.samples()
    held = read_held_out(robot, [str(KUKA / name) for name in HELD_OUT], training)
    problem = Problem(robot, samples, None)

    started = time.perf_counter()
    Y = robot.standard_regressor(samples.q, samples.qd, samples.qdd)  # [N, n, P]
    regressor_s = time.perf_counter() - started
    Y_rows = Y.reshape(-1, Y.shape[-1]).numpy()
    tau_rows = samples.tau.reshape(-1).numpy()

    auto: dict = {}
    fits = [timed("idkit pcls, prior_weight=auto", pcls_fit(problem, auto, plausible=False), args.repeats)]
    weight, scale2 = auto["prior_weight"], auto["data_scale"]["used"] ** 2
    matched = figaroh_weight(weight, scale2)
    plausible_auto: dict = {}
    fits += [
        timed(
            f"idkit pcls, prior_weight={FIXED_WEIGHT:g}",
            pcls_fit(problem, prior_weight=FIXED_WEIGHT, plausible=False),
            args.repeats,
        ),
        timed(
            "idkit pcls, plausible=true (auto)",
            pcls_fit(problem, plausible_auto, plausible=True),
            args.repeats,
        ),
        timed(
            f"FIGAROH physical_fit, default prior_weight {FIGAROH_DEFAULT_WEIGHT:g}",
            figaroh_fit(robot, Y_rows, tau_rows, FIGAROH_DEFAULT_WEIGHT, None),
            args.repeats,
        ),
        timed(
            f"FIGAROH physical_fit, prior_weight {matched:.3g} (= idkit's {weight:g})",
            figaroh_fit(robot, Y_rows, tau_rows, matched, None),
            args.repeats,
        ),
    ]
    bounded_weight = plausible_auto["prior_weight"]
    bounded = figaroh_weight(bounded_weight, scale2)
    fits.append(
        timed(
            f"FIGAROH physical_fit, prior_weight {bounded:.3g} (= idkit's {bounded_weight:g}), "
            "mass_ratio_bounds (0.5, 2)",
            figaroh_fit(robot, Y_rows, tau_rows, bounded, (0.5, 2.0)),
            args.repeats,
        )
    )
    print(
        f"KUKA LWR4+: trained on measurements_1 ({samples.q.shape[0]} samples, {Y.shape[-1]} standard "
        f"parameters incl. friction and offsets); idkit's s² = {scale2:.4g} N²m², auto weight {weight:g}; "
        f"the standard regressor given to FIGAROH took {regressor_s:.2f} s (not in its fit times; idkit's "
        "fits build their own)"
    )
    print(
        "\n| method | fit wall s, median (min) | fit CPU s | held-out m3: command / re-score | held-out m2: "
        "command / re-score | all links PSD (min eig) | mass / CAD | notes |"
    )
    print("|---|---:|---:|---:|---:|---|---:|---|")
    with tempfile.TemporaryDirectory() as folder:
        for fit in fits:
            print(row(fit, robot, held, Path(folder)), flush=True)
        if args.sweep:
            print(
                "\n| prior weight (idkit w / FIGAROH λ) | idkit pcls: m3 / m2 | mass / CAD "
                "| FIGAROH physical_fit: m3 / m2 | mass / CAD |"
            )
            print("|---|---:|---:|---:|---:|")
            for w in SWEEP:
                cells = [f"{w:g} / {figaroh_weight(w, scale2):.3g}"]
                for fit in (
                    pcls_fit(problem, prior_weight=w, plausible=False),
                    figaroh_fit(robot, Y_rows, tau_rows, figaroh_weight(w, scale2), None),
                ):
                    params = fit()[0]
                    cells += [" / ".join(f"{x:.2f} %" for x in held_out(robot, params, held))]
                    cells += [mass_ratios(robot, params)]
                print("| " + " | ".join(cells) + " |", flush=True)
    load_after = os.getloadavg()
    shown = [" ".join(f"{x:.2f}" for x in load) for load in (load_before, load_after)]
    print(
        f"\n{args.repeats} timed fits per method after one warm-up, one thread. Load average (1, 5, 15 min): "
        f"{shown[0]} before, {shown[1]} after."
    )


if __name__ == "__main__":
    main()
