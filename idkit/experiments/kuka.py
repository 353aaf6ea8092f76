"""Identify a real KUKA LWR4+ on one recording and predict the measured torques of the held-out ones.

The recordings (``measurements_{1,2,3}.npz`` and the CAD URDF ``kuka_lwr4.urdf``, from FloBaRoID)
are not part of this repository: pass the folder that holds them. There are no true parameters for a
real robot, so the only honest score is prediction: identify on ``measurements_1`` and report, on
``measurements_2`` and ``measurements_3``, the RMS torque error per joint (N·m) and relative to the
RMS of the measured torque, for the a-priori CAD model and for every estimator and model variant.

Model variants (``models``: ``(friction, offset)`` pairs of ``URDFRobot``): the rigid body alone, plus
Coulomb + viscous friction per joint (the paper's eq. (1) terms), plus a constant torque offset per
joint (torque-sensor bias). The CAD rows use the URDF's inertial values; with friction, also the
URDF's ``<dynamics friction= damping=>`` values as Coulomb and viscous coefficients.

Metrics (per recording; ``E = measured − predicted`` over ``N`` samples and ``n = 7`` joints):

* ``rms_j`` = ``sqrt(mean_t E_tj²)`` (N·m) and ``rel_j = rms_j / sqrt(mean_t τ_tj²)``;
* ``rel_all = ‖E‖_F / ‖T‖_F``, dominated by the big joints 2 and 4 (≈ 25 and 11 N·m RMS);
* ``nrms_limit = sqrt(mean_tj (E_tj / τmax_j)²)`` with ``τmax`` the URDF effort limits — an error
  normalised by the joint torque range, our reading of the "limit-normalised NRMS" FloBaRoID
  reports (0.18–0.21 % on ``measurements_2``); its exact normalisation was not verified, so compare
  orders of magnitude only.

Unmodelled (they stay in the residual whatever the estimator): friction beyond Coulomb + viscous
(Stribeck, stiction at velocity reversals, load- and position-dependent friction), temperature drift,
joint elasticity of the LWR's harmonic drives and torque sensors, cable forces, sensor bias drift
between recordings. Motor/gear inertia is *not* added: the LWR measures torque on the link side of
the gear, where the rotor inertia does not appear (the URDF's ``rotor_inertia`` values are ignored).
"""

from __future__ import annotations

import csv
import json
import time
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor

from idkit import registry
from idkit.estimate import jsonable
from idkit.problem import Problem, Samples
from idkit.robots.urdf import URDFRobot

URDF_NAME = "kuka_lwr4.urdf"
#: ``(name, constructor options)`` of the estimators run by default: the linear family (RLS in closed
#: form; the cvxpy SOCP has the same minimiser and is slower on 35k equations), and the searches
#: (PSO, Adam) on ``cost`` in the robot's base-parameter box, which is derived from the CAD values
#: (``URDFRobot.base_bounds``) and so acts as a prior. The relative variants are left out: they
#: divide by measured torques that cross zero on every joint (joints 1, 5, 6, 7 hover near it), so
#: they weight the residual by noise, not by signal.
DEFAULT_ESTIMATORS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("ls", {}),
    ("tls", {}),
    ("rls", {"solver": "closed_form"}),
    ("pso", {"runs": 4, "history": False}),
    ("adam", {"starts": 4, "history": False}),
)
DEFAULT_MODELS: tuple[tuple[bool, bool], ...] = ((False, False), (True, False), (True, True))
#: Two recordings "follow the same trajectory" when their positions agree sample by sample to this (rad).
REPEAT_TOLERANCE = 0.01


def load_recording(path: Path, stride: int = 1) -> tuple[Samples, np.ndarray]:
    """One recording as ``Samples`` (``q, qd, qdd, tau`` each ``[N, 7]``) and its ``times[N]`` (s).

    ``stride`` keeps every ``stride``-th sample (the recordings are ~200 Hz and low-pass filtered, so
    neighbouring samples carry little new information).
    """
    if not path.is_file():
        raise FileNotFoundError(f"KUKA recording not found: {path}")
    with np.load(path) as data:
        missing = {"times", "positions", "velocities", "accelerations", "torques"} - set(data.files)
        if missing:
            raise ValueError(f"{path}: missing arrays {sorted(missing)} (has {sorted(data.files)})")
        arrays = [
            np.asarray(data[k][::stride], dtype=np.float64)
            for k in ("positions", "velocities", "accelerations", "torques")
        ]
        times = np.asarray(data["times"][::stride], dtype=np.float64)
    return Samples(*(torch.from_numpy(a) for a in arrays)), times - times[0]


def urdf_joint_data(urdf: Path, joint_names: Sequence[str]) -> dict[str, np.ndarray]:
    """Per joint (in ``joint_names`` order): ``effort`` limit, CAD ``coulomb`` and ``viscous`` friction."""
    joints = {j.get("name"): j for j in ET.parse(urdf).getroot().findall("joint")}
    out: dict[str, list[float]] = {"effort": [], "coulomb": [], "viscous": []}
    for name in joint_names:
        limit, dynamics = joints[name].find("limit"), joints[name].find("dynamics")
        out["effort"].append(float(limit.get("effort", "nan")) if limit is not None else float("nan"))
        out["coulomb"].append(float(dynamics.get("friction", 0.0)) if dynamics is not None else 0.0)
        out["viscous"].append(float(dynamics.get("damping", 0.0)) if dynamics is not None else 0.0)
    return {k: np.array(v) for k, v in out.items()}


def cad_params(robot: URDFRobot, joint_data: dict[str, np.ndarray]) -> Tensor:
    """The a-priori parameters ``[P]``: URDF inertials, and the URDF friction where the robot has it."""
    params = robot.nominal_params().clone()
    if robot.friction:
        index = {name: i for i, name in enumerate(robot.param_names)}
        for j, joint in enumerate(robot.joint_names):
            params[index[f"{joint}.fc"]] = float(joint_data["coulomb"][j])
            params[index[f"{joint}.fv"]] = float(joint_data["viscous"][j])
    return params


def torque_metrics(measured: Tensor, predicted: Tensor, effort: np.ndarray) -> dict[str, float]:
    """RMS error per joint (N·m), relative per joint, ``rel_all`` and ``nrms_limit`` (module doc)."""
    error = (measured - predicted).double()
    rms = error.square().mean(0).sqrt()
    scale = measured.double().square().mean(0).sqrt()
    out = {f"rms_j{j + 1}": float(v) for j, v in enumerate(rms)}
    out.update({f"rel_j{j + 1}": float(v) for j, v in enumerate(rms / scale)})
    out["rel_all"] = float(error.norm() / measured.double().norm())
    out["nrms_limit"] = float((error / torch.as_tensor(effort, dtype=error.dtype)).square().mean().sqrt())
    return out


def data_check(samples: Samples, times: np.ndarray) -> dict[str, float]:
    """How clean the accelerations are: content above 10 Hz, and agreement with ``d(qd)/dt``.

    Returns the worst joint's share of the RMS acceleration above 10 Hz, and the RMS of
    ``qdd − gradient(qd, t)`` relative to the RMS of ``qdd`` (a lag or noise in ``qdd`` shows here).
    """
    qdd, qd = samples.qdd.numpy(), samples.qd.numpy()
    spectrum = np.abs(np.fft.rfft(qdd - qdd.mean(0), axis=0)) ** 2
    freq = np.fft.rfftfreq(len(times), d=float(np.median(np.diff(times))))
    high = np.sqrt(spectrum[freq > 10.0].sum(0) / spectrum.sum(0))
    derivative = np.gradient(qd, times, axis=0)
    mismatch = np.sqrt(((qdd - derivative) ** 2).mean(0)) / np.sqrt((qdd**2).mean(0))
    return {
        "sample_rate_hz": float(1.0 / np.median(np.diff(times))),
        "qdd_share_above_10hz_max": float(high.max()),
        "qdd_vs_gradient_qd_rel_rms_max": float(mismatch.max()),
    }


def run_kuka(
    data_dir: str | Path,
    out_dir: str | Path,
    estimators: Sequence[tuple[str, dict[str, Any]]] = DEFAULT_ESTIMATORS,
    models: Sequence[tuple[bool, bool]] = DEFAULT_MODELS,
    train: str = "measurements_1",
    test: Sequence[str] = ("measurements_2", "measurements_3"),
    stride: int = 1,
    plot_window: tuple[float, float] = (10.0, 25.0),
    device: str = "cpu",
    dtype: str = "float64",
    cost: str = "f1",
    seed: int = 0,
    plot: bool = True,
) -> list[dict[str, Any]]:
    """Identify on ``train``, score on ``train`` and ``test``; write the table, CSV, estimates and plot.

    Args:
        data_dir: folder with ``measurements_*.npz`` and ``kuka_lwr4.urdf``.
        out_dir: where ``kuka_heldout.csv``, ``kuka_heldout.md``, ``kuka_estimates.json`` and
            ``kuka_heldout_torques.png`` go (created if needed).
        estimators: ``(registry name, options)`` of each estimator (``idkit.registry``).
        models: ``(friction, offset)`` variants of ``URDFRobot``.
        train, test: recording names (without ``.npz``).
        stride: keep every ``stride``-th sample of every recording, for identification and scores
            (1 = all 5,027; the data check always reads every sample).
        plot_window: seconds of the first test recording shown in the plot.
        cost: registry name of the ``Problem`` cost (what PSO and Adam minimise; the linear family
            minimises its own criterion and reports this cost at its estimate).
        device, dtype, seed: of the identification ``Problem``.
        plot: draw ``kuka_heldout_torques.png`` (matplotlib takes seconds on a loaded machine).

    Returns:
        One row per (model, variant, recording): ``model`` (``"CAD"`` or the estimator label),
        ``friction``, ``offset``, ``recording``, ``split`` (``"train"``/``"test"``), ``fit_time_s``
        and the metrics of ``torque_metrics``.
    """
    data_dir, out_dir = Path(data_dir), Path(out_dir)
    urdf = data_dir / URDF_NAME
    if not urdf.is_file():
        raise FileNotFoundError(f"KUKA URDF not found: {urdf}")
    out_dir.mkdir(parents=True, exist_ok=True)
    recordings = {name: load_recording(data_dir / f"{name}.npz", stride) for name in (train, *test)}
    rows: list[dict[str, Any]] = []
    estimates: list[dict[str, Any]] = []
    predictions: dict[str, Tensor] = {}  # label -> predicted torques of the first test recording
    joint_data: dict[str, np.ndarray] = {}
    for friction, offset in models:
        robot = URDFRobot(str(urdf), friction=friction, offset=offset)
        joint_data = urdf_joint_data(urdf, robot.joint_names)
        fits: list[tuple[str, Tensor, float]] = []
        if not offset:  # the CAD model has no offset; its friction is the URDF's
            fits.append(("CAD", cad_params(robot, joint_data), 0.0))
        problem = Problem(
            robot,
            recordings[train][0],
            cost=registry.create("cost", cost),
            seed=seed,
            device=device,
            dtype=dtype,
        )
        for name, options in estimators:
            estimator = registry.create("estimator", name, **options)
            started = time.perf_counter()
            estimate = estimator.fit(problem)
            elapsed = time.perf_counter() - started
            label = estimate.estimator
            params = torch.tensor([estimate.params[p] for p in robot.param_names], dtype=torch.float64)
            fits.append((label, params, elapsed))
            estimates.append({"model": label, "friction": friction, "offset": offset, **estimate.to_dict()})
        for label, params, elapsed in fits:
            for rec_name, (samples, _) in recordings.items():
                with torch.no_grad():
                    predicted = robot.inverse_dynamics(params, samples.q, samples.qd, samples.qdd)
                rows.append(
                    {
                        "model": label,
                        "friction": friction,
                        "offset": offset,
                        "recording": rec_name,
                        "split": "train" if rec_name == train else "test",
                        "fit_time_s": elapsed,
                        **torque_metrics(samples.tau, predicted, joint_data["effort"]),
                    }
                )
                if test and rec_name == test[0]:
                    predictions[_variant(label, friction, offset)] = predicted
    rows += _repeat_rows(recordings, train, test, joint_data["effort"])
    checks = {name: data_check(*load_recording(data_dir / f"{name}.npz")) for name in recordings}
    _write_csv(rows, out_dir / "kuka_heldout.csv")
    (out_dir / "kuka_heldout.md").write_text(markdown_table(rows, train, test, stride))
    payload = {
        "data_check": checks,
        "stride": stride,
        "train": train,
        "test": list(test),
        "estimates": estimates,
    }
    (out_dir / "kuka_estimates.json").write_text(json.dumps(jsonable(payload), indent=1))
    if plot and test:
        _plot(
            rows, predictions, recordings[test[0]], test[0], plot_window, out_dir / "kuka_heldout_torques.png"
        )
    return rows


def _repeat_rows(
    recordings: dict[str, tuple[Samples, np.ndarray]], train: str, test: Sequence[str], effort: np.ndarray
) -> list[dict[str, Any]]:
    """Rows scoring a test recording's torques against the training torques where both follow the
    same trajectory (same length, positions within ``REPEAT_TOLERANCE``): the repeatability floor
    that no model of the joint states alone can be expected to beat."""
    reference = recordings[train][0]
    rows = []
    for name in test:
        samples = recordings[name][0]
        same_shape = samples.q.shape == reference.q.shape
        if same_shape and float((samples.q - reference.q).abs().max()) < REPEAT_TOLERANCE:
            metrics = torque_metrics(samples.tau, reference.tau, effort)
            label = f"{train} torques (same trajectory)"
            rows.append(
                {
                    "model": label,
                    "friction": False,
                    "offset": False,
                    "recording": name,
                    "split": "test",
                    "fit_time_s": 0.0,
                    **metrics,
                }
            )
    return rows


def _variant(label: str, friction: bool, offset: bool) -> str:
    return label + (" + friction" if friction else "") + (" + offset" if offset else "")


def _write_csv(rows: list[dict[str, Any]], path: Path) -> None:
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def markdown_table(rows: list[dict[str, Any]], train: str, test: Sequence[str], stride: int) -> str:
    """One Markdown table per test recording: per joint ``RMS N·m (rel %)``, ``rel_all``, ``nrms_limit``."""
    n = sum(1 for k in rows[0] if k.startswith("rms_j"))
    every = "every sample" if stride == 1 else f"every {stride}th sample"
    lines = [
        f"Identified on `{train}` ({every}); RMS torque error per joint, N·m (in brackets: relative to "
        "the measured torque RMS of that joint); ‖E‖/‖T‖ over all joints; NRMS/limit normalised by "
        "the URDF effort limits.",
        "",
    ]
    for rec in (*test, train):
        lines += [f"### {rec}" + (" (training data)" if rec == train else " (held out)"), ""]
        header = ["model", "friction", "offset", *(f"j{j + 1}" for j in range(n)), "‖E‖/‖T‖", "NRMS/limit"]
        lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        for r in (r for r in rows if r["recording"] == rec):
            cells = [r["model"], "yes" if r["friction"] else "no", "yes" if r["offset"] else "no"]
            cells += [f"{r[f'rms_j{j + 1}']:.3f} ({100 * r[f'rel_j{j + 1}']:.0f} %)" for j in range(n)]
            cells += [f"{100 * r['rel_all']:.2f} %", f"{100 * r['nrms_limit']:.3f} %"]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def _plot(
    rows: list[dict[str, Any]],
    predictions: dict[str, Tensor],
    recording: tuple[Samples, np.ndarray],
    name: str,
    window: tuple[float, float],
    path: Path,
) -> None:
    """Measured vs predicted torques on a window of the first test recording: CAD and the best fits."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    samples, times = recording
    test_rows = [
        r
        for r in rows
        if r["recording"] == name and _variant(r["model"], r["friction"], r["offset"]) in predictions
    ]
    cad = min((r for r in test_rows if r["model"] == "CAD"), key=lambda r: r["rel_all"])
    fitted = sorted((r for r in test_rows if r["model"] != "CAD"), key=lambda r: r["rel_all"])
    best_rigid = next((r for r in fitted if not r["friction"]), None)
    shown = [cad, *([best_rigid] if best_rigid else []), *fitted[:1]]
    keep = (times >= window[0]) & (times <= window[1])
    n = samples.tau.shape[1]
    fig, axes = plt.subplots(n, 1, figsize=(10, 2.0 * n), sharex=True)
    for j, ax in enumerate(axes):
        ax.plot(times[keep], samples.tau[keep, j].numpy(), "k", lw=2.0, label="measured")
        for r in shown:
            key = _variant(r["model"], r["friction"], r["offset"])
            ax.plot(
                times[keep],
                predictions[key][keep, j].numpy(),
                lw=1.0,
                label=f"{key}: rel {100 * r[f'rel_j{j + 1}']:.0f} %",
            )
        ax.set_ylabel(f"joint {j + 1} (N·m)")
        ax.legend(fontsize=7, loc="upper right")
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(f"KUKA LWR4+ held-out torques, {name}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
