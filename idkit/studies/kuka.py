"""Identify a real KUKA LWR4+ on one recording, predict the held-out ones (the ``kuka`` task).

``idkit +experiment=kuka [kuka.stride=5] [kuka.data_dir=/path/to/kuka-lwr4]``.

The recordings (``measurements_{1,2,3}.npz`` and the CAD URDF ``kuka_lwr4.urdf``, from FloBaRoID)
are not part of this repository: pass the folder that holds them. There are no true parameters for a
real robot, so the only honest score is prediction: identify on ``measurements_1`` and report, on
``measurements_2`` and ``measurements_3``, the RMS torque error per joint (N·m) and relative to the
RMS of the measured torque, for the a-priori CAD model and for every estimator and model variant.

Model variants (``models``: ``(friction, offset)`` or ``(friction, offset, stribeck_velocity)`` of
``URDFRobot``): the rigid body alone, plus Coulomb + viscous friction per joint (the paper's eq. (1)
terms), plus a constant torque offset per joint (torque-sensor bias), plus the low-speed friction
term ``fs exp(-(qd/v_s)²) sign(qd)``. The CAD rows use the URDF's inertial values; with friction, also
the URDF's ``<dynamics friction= damping=>`` values as Coulomb and viscous coefficients. Every row
carries the smallest pseudo-inertia eigenvalue over the links (``min_eig``, ``< 0``: not physically
consistent) and how many links are negative.

The recordings are read by :func:`idkit.data.pipeline.read_training` (the files' own derivatives
by default; ``preprocess={apply: on, ...}`` recomputes them with idkit's filter, its ``cutoff=auto``
chosen on the training recording) and scored by :func:`idkit.studies.validation.validate_file`: the
measured and predicted torques compared in the fixed scoring band (6 Hz, on the files' timestamps).
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

import time
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from torch import Tensor

from idkit.data.load import DataFile
from idkit.data.options import DataOptions, Preprocessing
from idkit.data.pipeline import describe as describe_data
from idkit.data.pipeline import read_held_out, read_training
from idkit.interfaces import CostSearcher
from idkit.model import IdentifiedModel
from idkit.problem import Problem, Samples
from idkit.robots.inertia import min_pseudo_inertia_eigenvalues
from idkit.robots.urdf import URDFRobot
from idkit.seeds import Seed
from idkit.studies.build import Spec, build, describe
from idkit.studies.labels import unique_labels
from idkit.studies.result import Provenance, StudyInterrupted
from idkit.studies.validation import Validation, score, validate_file

URDF_NAME = "kuka_lwr4.urdf"
#: The estimators run by default: the linear family (RLS in closed form; the cvxpy SOCP has the
#: same minimiser and is slower on 35k equations), and the searches (PSO, Adam) on ``search_cost``
#: in the robot's base-parameter box, which is derived from the CAD values (``URDFRobot.base_bounds``)
#: and so acts as a prior. The relative variants are left out: they divide by measured torques that
#: cross zero on every joint (joints 1, 5, 6, 7 hover near it), so they weight the residual by noise.
DEFAULT_ESTIMATORS: tuple[Spec, ...] = (
    "ls",
    "tls",
    {"_name_": "rls", "solver": "closed_form"},
    {"_name_": "pso", "runs": 4, "history": False},
    {"_name_": "adam", "starts": 4, "history": False},
    {"_name_": "pcls", "prior_weight": 0.0},
    "pcls",
    {"_name_": "pcls", "prior_weight": 300.0},
)
DEFAULT_MODELS: tuple[tuple[Any, ...], ...] = (
    (False, False),
    (True, False),
    (True, True),
    (True, True, 0.05),
)
#: Two recordings "follow the same trajectory" when their positions agree sample by sample to this (rad).
REPEAT_TOLERANCE = 0.01
CAD = "CAD"


def urdf_joint_data(urdf: Path, joint_names: Sequence[str]) -> dict[str, np.ndarray]:
    """Per joint (in ``joint_names`` order): CAD ``coulomb`` and ``viscous`` friction."""
    joints = {j.get("name"): j for j in ET.parse(urdf).getroot().findall("joint")}
    out: dict[str, list[float]] = {"coulomb": [], "viscous": []}
    for name in joint_names:
        dynamics = joints[name].find("dynamics")
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


def scores(validation: Validation) -> dict[str, float | None]:
    """A row's metrics: ``rms_j*`` (N·m), ``rel_j*``, ``rel_all``, ``nrms_limit`` (module doc)."""
    out: dict[str, float | None] = {f"rms_j{j + 1}": float(v) for j, v in enumerate(validation.rms)}
    out.update({f"rel_j{j + 1}": float(v) for j, v in enumerate(validation.relative)})
    out["rel_all"] = validation.rel_all
    out["nrms_limit"] = validation.nrms_limit
    return out


def consistency(robot: URDFRobot, params: Tensor) -> dict[str, float | int]:
    """``min_eig``: the smallest pseudo-inertia eigenvalue over the links; ``links_negative``: how many
    links have a negative one (``-1e-10`` allows the solver's zero where an LMI is active)."""
    eigenvalues = min_pseudo_inertia_eigenvalues(robot, params)
    return {"min_eig": float(eigenvalues.min()), "links_negative": int((eigenvalues < -1e-10).sum())}


def data_check(samples: Samples, times: np.ndarray | None) -> dict[str, float]:
    """How clean the accelerations are: content above 10 Hz, and agreement with ``d(qd)/dt``.

    Returns the worst joint's share of the RMS acceleration above 10 Hz, and the RMS of
    ``qdd − gradient(qd, t)`` relative to the RMS of ``qdd`` (a lag or noise in ``qdd`` shows here).

    Raises:
        ValueError: no ``times`` (a recording without timestamps).
    """
    if times is None:
        raise ValueError("kuka: a recording without timestamps; the data check needs its sampling times")
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


def variant(label: str, friction: bool, offset: bool, stribeck: float | None = None) -> str:
    """``"LS + friction + offset"``: an estimator label with its model variant."""
    low_speed = f" + low-speed friction ({stribeck:g} rad/s)" if stribeck else ""
    return label + (" + friction" if friction else "") + low_speed + (" + offset" if offset else "")


@dataclass
class Traces:
    """Measured and predicted torques ``[N, n]`` of one held-out recording, for the plot (joints
    named by ``joint_names``)."""

    recording: str
    times: np.ndarray
    measured: np.ndarray
    predicted: dict[str, np.ndarray]
    joint_names: tuple[str, ...] = ()


@dataclass
class KukaStudy:
    """Scores of every (model variant, estimator) on the training and held-out recordings.

    Attributes:
        rows: one per (model, variant, recording): ``model`` (``"CAD"`` or the estimator label),
            ``friction``, ``offset``, ``stribeck`` (velocity scale or ``None``), ``recording``,
            ``split`` (``"train"``/``"test"``), ``fit_time_s``, the metrics of :func:`scores` and
            :func:`consistency`.
        estimates: per fit, the model variant and the ``Estimate`` as a dict.
        data_check: per recording, :func:`data_check`.
        traces: the first held-out recording's torques (``None`` without a test recording).
    """

    provenance: Provenance
    train: str
    test: list[str]
    stride: int
    rows: list[dict[str, Any]]
    estimates: list[dict[str, Any]]
    data_check: dict[str, dict[str, float]]
    traces: Traces | None
    plot_window: tuple[float, float] = (10.0, 25.0)

    def payload(self) -> dict[str, Any]:
        return {
            "train": self.train,
            "test": self.test,
            "stride": self.stride,
            "scores": self.rows,
            "estimates": self.estimates,
            "data_check": self.data_check,
        }


def _repeat_rows(
    recordings: dict[str, DataFile], train: str, test: Sequence[str], robot: URDFRobot
) -> list[dict[str, Any]]:
    """Rows scoring a test recording's torques against the training torques where both follow the
    same trajectory (same length, positions within ``REPEAT_TOLERANCE``): the repeatability floor
    that no model of the joint states alone can be expected to beat."""
    reference = recordings[train].samples
    rows = []
    for name in test:
        samples = recordings[name].samples
        same_shape = samples.q.shape == reference.q.shape
        if same_shape and float((samples.q - reference.q).abs().max()) < REPEAT_TOLERANCE:
            rows.append(
                {
                    "model": f"{train} torques (same trajectory)",
                    "friction": False,
                    "offset": False,
                    "stribeck": None,
                    "recording": name,
                    "split": "test",
                    "fit_time_s": 0.0,
                    **scores(
                        score(
                            recordings[name].measured_tau,
                            recordings[train].measured_tau,
                            robot.effort_limits,
                            recordings[name].times,
                        )
                    ),
                    "min_eig": None,
                    "links_negative": None,
                }
            )
    return rows


def _model(spec: Sequence[Any]) -> tuple[bool, bool, float | None]:
    """``(friction, offset, stribeck_velocity)`` of a ``models`` entry (two or three values)."""
    if len(spec) not in (2, 3):
        raise ValueError(
            f"kuka.models: each entry is [friction, offset] or [friction, offset, v_s], got {spec}"
        )
    stribeck = float(spec[2]) if len(spec) == 3 and spec[2] is not None else None
    if stribeck is not None and not spec[0]:
        raise ValueError(f"kuka.models: the low-speed friction term ({spec}) needs friction=true")
    return bool(spec[0]), bool(spec[1]), stribeck


def run(
    data_dir: str | Path,
    *,
    estimators: Sequence[Spec] = DEFAULT_ESTIMATORS,
    models: Sequence[Sequence[Any]] = DEFAULT_MODELS,
    train: str = "measurements_1",
    test: Sequence[str] = ("measurements_2", "measurements_3"),
    stride: int = 1,
    search_cost: Spec = "f1",
    plot_window: Sequence[float] = (10.0, 25.0),
    preprocess: Preprocessing | None = None,
    seed: Seed = 0,
    device: str = "cpu",
    dtype: str = "float64",
) -> KukaStudy:
    """Identify on ``train``, score on ``train`` and ``test``.

    Args:
        data_dir: folder with ``measurements_*.npz`` and ``kuka_lwr4.urdf``.
        estimators: estimator specs (``"ls"``, ``{"_name_": "pso", "runs": 4}``, ...).
        models: ``(friction, offset)`` or ``(friction, offset, stribeck_velocity)`` of ``URDFRobot``.
        train, test: recording names (without ``.npz``).
        stride: keep every ``stride``-th sample of every recording, for identification and scores
            (1 = all 5,027; the data check always reads every sample).
        search_cost: the cost PSO and Adam minimise (the linear family minimises its own criterion
            and reports this cost at its estimate).
        plot_window: seconds of the first test recording kept for the plot.
        preprocess: the ``preprocess`` options (:class:`idkit.data.options.Preprocessing`); the default
            (``auto``) keeps the files' own velocities and accelerations, ``apply: on`` recomputes
            them from the positions with idkit's filter.
        seed, device, dtype: of the identification ``Problem``.

    Raises:
        StudyInterrupted: on Ctrl-C, carrying the model variants finished so far.
    """
    data_dir = Path(data_dir)
    urdf = data_dir / URDF_NAME
    if not urdf.is_file():
        raise FileNotFoundError(
            f"KUKA URDF not found: {urdf.resolve()}; set kuka.data_dir=... or IDKIT_KUKA_DIR to the folder "
            "with the FloBaRoID recordings"
        )
    variants = [_model(spec) for spec in models]
    est_objs = [build("estimator", spec) for spec in estimators]  # refused before the data load
    searches = [isinstance(obj, CostSearcher) for obj in est_objs]
    labels = unique_labels(
        [(spec, search_cost, s) for spec, s in zip(estimators, searches, strict=True)], where="kuka"
    )
    cost = build("cost", search_cost)
    names = (train, *test)
    rigid = URDFRobot(str(urdf))
    # an automatic cut-off is chosen with the richest model variant's regressor
    richest = URDFRobot(str(urdf), friction=any(v[0] for v in variants), offset=any(v[1] for v in variants))
    training = read_training(richest, data_dir / f"{train}.npz", DataOptions.of(preprocess), stride=stride)
    held = read_held_out(rigid, [data_dir / f"{name}.npz" for name in test], training, stride) if test else []
    loaded = [*training.files, *held]
    recordings = dict(zip(names, loaded, strict=True))
    files = [data_dir / f"{name}.npz" for name in names]
    as_recorded = read_training(rigid, files, DataOptions.of({"apply": "off"})).files
    checks = {name: data_check(f.samples, f.times) for name, f in zip(names, as_recorded, strict=True)}
    data = {"dir": str(data_dir), "train": train, "test": list(test), "stride": stride}
    if any(f.preprocessed for f in loaded):
        data["preprocess"] = describe_data(loaded, training)["preprocess"]
    provenance = Provenance(
        task="kuka",
        label="kuka held-out torques",
        seed=seed,
        data=data,
        plugins={
            "robot": describe("robot", {"_name_": "urdf", "urdf": str(urdf)}),
            "cost": describe("cost", search_cost),
        },
        requested=len(variants),
        done=0,
        unit="model variant",
    )
    rows: list[dict[str, Any]] = []
    estimates: list[dict[str, Any]] = []
    shown = recordings[test[0]] if test else None
    traces, keep = None, None
    if shown is not None and shown.times is not None:
        keep = (shown.times >= plot_window[0]) & (shown.times <= plot_window[1])
        traces = Traces(test[0], shown.times[keep], shown.measured_tau[keep], {}, tuple(rigid.joint_names))

    def result() -> KukaStudy:
        repeats = _repeat_rows(recordings, train, test, rigid) if rows else []
        return KukaStudy(
            provenance,
            train,
            list(test),
            stride,
            rows + repeats,
            estimates,
            checks,
            traces,
            (float(plot_window[0]), float(plot_window[1])),
        )

    try:
        for friction, offset, stribeck in variants:
            robot = URDFRobot(str(urdf), friction=friction, offset=offset, stribeck_velocity=stribeck)
            model = {"friction": friction, "offset": offset, "stribeck": stribeck}
            fits: list[tuple[str, IdentifiedModel, float]] = []
            if not offset and stribeck is None:  # the CAD model has no offset; its friction is the URDF's
                cad = cad_params(robot, urdf_joint_data(urdf, robot.joint_names))
                fits.append((CAD, IdentifiedModel.from_params(robot, cad, CAD), 0.0))
            problem = Problem(robot, recordings[train].samples, cost, seed=seed, device=device, dtype=dtype)
            for label, estimator in zip(labels, est_objs, strict=True):
                started = time.perf_counter()
                estimate = replace(estimator.fit(problem), estimator=label)
                elapsed = time.perf_counter() - started
                fits.append((label, IdentifiedModel(robot, estimate), elapsed))
                estimates.append({"model": label, **model, "estimate": estimate.to_dict()})
            for label, identified, elapsed in fits:
                physical = consistency(robot, identified.vector)
                for name, recording in recordings.items():
                    scored = validate_file(identified, recording)
                    rows.append(
                        {
                            "model": label,
                            **model,
                            "recording": name,
                            "split": "train" if name == train else "test",
                            "fit_time_s": elapsed,
                            **scores(scored),
                            **physical,
                        }
                    )
                    if traces is not None and name == traces.recording:
                        traces.predicted[variant(label, friction, offset, stribeck)] = scored.predicted[keep]
            provenance.done += 1
    except KeyboardInterrupt:
        raise StudyInterrupted(result()) from None
    return result()
