"""One identification run: data → problem → estimate (the ``single`` task).

``run``'s signature is the command line's config: ``idkit estimator=pso cost=f13 +scenario=outliers
seed=1 n_samples=40`` calls ``run(robot=..., estimator=..., cost=..., scenario=..., seed=1,
n_samples=40, ...)``. From Python, ``idkit.run(...)`` (:mod:`idkit.api`) calls it and adds the
report's ``table()`` and ``save()``; a study never imports a report::

    import idkit
    result = idkit.run(estimator="pso", cost="f13", scenario="outliers", seed=0)
    print(result.table())
    result.estimate.params            # {"m2": ..., "m3": ..., "s3z": ..., "I": ...}

Measured data: ``data=`` is one file or a list (stacked for training), ``validate=`` lists held-out
files the identified model is scored on (:mod:`idkit.studies.validation`), ``preprocess`` and
``recording`` say how files become samples (:mod:`idkit.data.options`); the data pipeline
(:mod:`idkit.data.pipeline`) reads them, and the other recordings an estimator names (a payload's
reference), which it gets as samples. A fit of a ``urdf`` robot also carries
its ``identified.urdf`` text (``identified_urdf=False`` to skip), a fit of an ``mjcf`` robot its
``identified.xml`` (MJCF; ``identified_mjcf=True`` for a ``urdf`` robot too), which the report writes.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from idkit.data.files import as_paths, refuse_seen_samples, refuse_training_files
from idkit.data.options import DataOptions, Preprocessing, RecordingOptions
from idkit.data.pipeline import (
    Training,
    read_held_out,
    read_other,
    read_training,
    recorded,
    simulated,
)
from idkit.data.pipeline import describe as describe_data
from idkit.estimate import Estimate
from idkit.interfaces import CostSearcher
from idkit.model import IdentifiedModel
from idkit.notes import Note
from idkit.progress import reporting
from idkit.seeds import Seed
from idkit.studies.build import Spec, build, describe, plain
from idkit.studies.coulomb import CoulombVelocityNote, choose_coulomb_velocity, wants_choice
from idkit.studies.held import say_held
from idkit.studies.labels import cost_label, estimator_label
from idkit.studies.metrics import mean_abs_relative_error, relative_errors
from idkit.studies.plausibility import PlausibleAlternative, judged, plausible_alternative
from idkit.studies.result import Provenance
from idkit.studies.validation import Validation, validate_files


@dataclass(frozen=True)
class HeldOut:
    """The identified model's scores on one ``validate=`` file, with its ``times[N]`` for the plot."""

    file: str
    scores: Validation
    times: np.ndarray | None


@dataclass
class RunResult:
    """An estimate with everything needed to judge and reproduce it.

    Attributes:
        estimate: what the estimator returned, labelled from the specs (``PSO-f13``).
        truth: the parameters the data were simulated with (``None`` for measured data).
        cost_name: which cost ``estimate.cost`` is: the problem's cost (``f13``) or, without one,
            the estimator's own criterion (``LS criterion``).
        provenance: the envelope (task, seed, data, plugins, config, run id).
        validation: scores on the ``validate=`` files, in their order.
        urdf: the ``identified.urdf`` text of a ``urdf`` robot's fit (``None``: other robots, turned
            off, or not writable, e.g. a link mass <= 0).
        mjcf: the ``identified.xml`` (MJCF) text of an ``mjcf`` robot's fit, or of a ``urdf`` robot's
            with ``identified_mjcf=True`` (``None``: not asked, or not writable: non-physical inertia).
        plausible: the fit the other ``plausible`` option gives, scored on the same files
            (:mod:`idkit.studies.plausibility`).
        robot: the robot object the estimator fitted (``model`` puts the estimate back on it).
        cost_ignored: ``cost`` was given to an estimator with its own criterion (a
            :class:`CostIgnoredNote` said so): a sweep over costs repeats the same fit.
    """

    estimate: Estimate
    truth: dict[str, float] | None
    cost_name: str
    provenance: Provenance
    validation: list[HeldOut] = field(default_factory=list)
    urdf: str | None = None
    mjcf: str | None = None
    plausible: PlausibleAlternative | None = None
    robot: Any = field(default=None, repr=False, compare=False)
    #: the cost was given but the estimator minimises its own criterion (LS, TLS, RLS, pcls …): the
    #: estimate is the same for any cost, which is only evaluated at it
    cost_ignored: bool = False

    @functools.cached_property
    def model(self) -> IdentifiedModel:
        """The identified model (``predict``, ``params`` with σ, ``save``), with this run's held-out
        scores as its ``validation`` and this result as its ``result``.

        Raises:
            ValueError: the result was made without its robot object (e.g. read back from a file).
        """
        if self.robot is None:
            raise ValueError("this RunResult holds no robot object, so it has no model")
        return IdentifiedModel(self.robot, self.estimate, validation=self.validation, result=self)

    @property
    def joint_kinds(self) -> list[str] | None:
        """The robot's ``joint_kinds`` where it has them (a plugin need not)."""
        kinds = getattr(self.robot, "joint_kinds", None)
        return None if kinds is None else [str(kind) for kind in kinds]

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The robot's joints, in the order of every per-joint figure (``()`` without the robot)."""
        return () if self.robot is None else tuple(self.robot.joint_names)

    @property
    def nominal(self) -> dict[str, float] | None:
        """The robot's a-priori parameters (a URDF's CAD inertials) by name, for the report to set the
        estimate beside (``None``: no robot object, or a robot without them)."""
        nominal = None if self.robot is None else self.robot.nominal_params()
        return None if nominal is None else dict(zip(self.robot.param_names, nominal.tolist(), strict=True))

    @property
    def seed(self) -> int:
        return self.provenance.seed

    @property
    def data(self) -> dict[str, Any] | None:
        return self.provenance.data

    @property
    def plugins(self) -> dict[str, Any]:
        return self.provenance.plugins

    @property
    def relative_error(self) -> dict[str, float | None] | None:
        """Signed ``(estimate − truth) / |truth|`` per parameter (see ``idkit.studies.metrics``)."""
        return None if self.truth is None else relative_errors(self.estimate.params, self.truth)

    @property
    def parameter_error(self) -> float | None:
        """Mean absolute relative error over the parameters."""
        rel = self.relative_error
        return None if rel is None else mean_abs_relative_error(rel)

    def payload(self) -> dict[str, Any]:
        """The task's part of ``result.json``: the estimate, the truth and the errors."""
        return {
            "estimate": self.estimate.to_dict(),
            "truth": self.truth,
            "relative_error": self.relative_error,
            "parameter_error": self.parameter_error,
            "cost": {
                "name": self.cost_name,
                "value": self.estimate.cost,
                "used_by_fit": not self.cost_ignored,
            },
            "joint_names": list(self.joint_names),
            # per joint "revolute" (torque, N·m) or "prismatic" (force, N); null where the robot says not
            "joint_kinds": self.joint_kinds,
            "nominal": self.nominal,
            "validation": {held.file: held.scores.to_dict() for held in self.validation},
            **(
                {"plausible_alternative": self.plausible.to_dict([h.file for h in self.validation])}
                if self.plausible is not None
                else {}
            ),
        }


def _scenario_spec(scenario: Any) -> Any:
    """Config nodes may list a Scenario field as ``null``, meaning "the preset's value"."""
    scenario = plain(scenario)
    if isinstance(scenario, Mapping):
        return {k: v for k, v in scenario.items() if v is not None}
    return scenario


def load_data(
    robot: Any,
    scenario: Any = None,
    *,
    seed: Seed = 0,
    data: Any = None,
    n_samples: int | None = None,
    params: Any = None,
    preprocess: Preprocessing | None = None,
    recording: RecordingOptions | None = None,
) -> tuple[Any, dict[str, float] | None, dict[str, Any]]:
    """``(samples, truth, description)``: measured ``data`` (path(s) or ``Samples``) or a simulation.

    For measured data, ``description["preprocess"]`` holds the options the files were preprocessed
    with, a resolved ``cutoff=auto`` included (``cutoff_choice``: how it was chosen).

    Raises:
        ValueError: both ``scenario`` and ``data`` given (which one was meant?), ``n_samples``
            with ``data`` (a file has the samples it has), or a file the robot cannot use.
    """
    options = DataOptions.of(preprocess, recording)
    samples, truth, description, _ = _load(robot, scenario, seed, data, n_samples, params, options)
    return samples, truth, description


def _load(
    robot: Any,
    scenario: Any,
    seed: Seed,
    data: Any,
    n_samples: int | None,
    params: Any,
    options: DataOptions,
) -> tuple[Any, dict[str, float] | None, dict[str, Any], Training]:
    """:func:`load_data`, and the training files read (none for a simulation): the held-out files and
    an estimator's other recordings are read with the options they resolved."""
    if data is not None:
        if scenario is not None:
            shown = [p if isinstance(p, (str, Path)) else type(p).__name__ for p in as_paths(data)]
            raise ValueError(
                f"give either data= (measured samples) or scenario= (a simulation), not both: "
                f"data={shown[0] if len(shown) == 1 else shown}, scenario={_scenario_spec(scenario)}"
            )
        if n_samples is not None:
            raise ValueError(f"n_samples={n_samples} applies to a simulated scenario, not to data=")
        training = read_training(robot, data, options)
        return training.samples(), None, describe_data(training.files, training), training
    import torch

    from idkit.data.scenarios import get_scenario, simulate
    from idkit.excitation.spec import scenario_excitation

    sc = get_scenario(_scenario_spec(scenario if scenario is not None else "clean"), n_samples=n_samples)
    samples = simulate(robot, sc, seed=seed, params=params, excitation=scenario_excitation(sc, robot))
    true = torch.as_tensor(params, dtype=torch.float64) if params is not None else robot.nominal_params()
    truth = dict(zip(robot.param_names, true.tolist(), strict=True))
    return samples, truth, {"scenario": sc.as_dict()}, simulated(robot, options)


def _identified_urdf(model: IdentifiedModel) -> str | None:
    """The ``identified.urdf`` text of a ``urdf`` robot's fit (with the payload a ``payload`` fit found
    as its own link); ``None`` (with a warning) if unwritable."""
    from idkit.robots.urdf import URDFRobot

    if not isinstance(model.robot, URDFRobot) or model.robot.source_format != "urdf":
        return None
    try:
        return model.to_urdf()
    except ValueError as exc:
        warnings.warn(f"identified.urdf not written: {exc}", stacklevel=3)
        return None


def _identified_mjcf(model: IdentifiedModel, wanted: bool | None) -> str | None:
    """The ``identified.xml`` text of an ``mjcf`` robot's fit (``wanted=None`` or ``True``) or of a
    ``urdf`` robot's (``wanted=True``); ``None`` (with a one-line warning) if MuJoCo would refuse it."""
    from idkit.registry import PluginLoadError
    from idkit.robots.urdf import URDFRobot

    if not isinstance(model.robot, URDFRobot) or wanted is False:
        return None
    if wanted is None and model.robot.source_format != "mjcf":
        return None
    try:
        return model.to_mjcf()
    except (ValueError, PluginLoadError) as exc:
        warnings.warn(f"identified.xml not written: {exc}", stacklevel=3)
        return None


def refuse_meaningless(fitted: Estimate, names: tuple[str, ...], label: str) -> None:
    """Refuse an estimate that is no answer: a parameter missing or not finite (a third-party
    estimator that failed quietly), which a report would otherwise print and save with exit status 0.

    Raises:
        IdentificationError: naming the estimator and the parameters.
    """
    from idkit.problem import IdentificationError

    missing = [name for name in names if name not in fitted.params]
    if missing:
        raise IdentificationError(
            f"estimator {label} returned no value for {len(missing)} of the robot's {len(names)} "
            f"parameters ({', '.join(missing[:4])}{', …' * (len(missing) > 4)}); nothing is reported"
        )
    bad = [f"{name} = {fitted.params[name]}" for name in names if not np.isfinite(fitted.params[name])]
    if bad:
        raise IdentificationError(
            f"estimator {label} returned {len(bad)} non-finite parameter(s) of {len(names)} "
            f"({', '.join(bad[:4])}{', …' * (len(bad) > 4)}); nothing is reported"
        )


def run(
    robot: Spec = "cylindrical",
    estimator: Spec = "pso",
    cost: Spec | None = "f13",
    scenario: Any = None,
    *,
    seed: Seed = 0,
    data: Any = None,
    n_samples: int | None = None,
    params: Any = None,
    validate: Any = None,
    preprocess: Preprocessing | None = None,
    recording: RecordingOptions | None = None,
    identified_urdf: bool = True,
    identified_mjcf: bool | None = None,
    device: str = "cpu",
    dtype: str = "float64",
    progress: bool = False,
) -> RunResult:
    """Identify a robot's parameters once.

    Args:
        robot, estimator, cost: a registry name (``"pso"``), a config mapping
            (``{"_name_": "pso", "particles": 40}``) or a ready object. ``cost=None`` for
            estimators with a fixed criterion (LS, TLS, RLS).
        scenario: noise scenario name, ``Scenario`` or mapping (``idkit.data.scenarios``);
            ``None`` means ``"clean"`` unless ``data`` is given. Not together with ``data``.
        seed: seeds the noise draw and the estimator.
        data: measured samples instead of a simulation: a ``.npz``/``.csv`` path, ``Samples``, or a
            list of them (stacked for training; each must have the robot's joints).
        n_samples: the scenario's number of samples (``None``: the scenario's own).
        params: true parameters ``[P]`` to simulate with (default ``robot.nominal_params()``).
        validate: held-out files (or ``Samples``) the identified model is scored on; a training file
            (same path, same bytes, or the same samples in another file) is refused.
        preprocess: how raw recordings become samples (:class:`idkit.data.options.Preprocessing`, or a
            mapping of its fields): ``PreprocessOptions`` fields plus ``apply`` (``auto``: raw
            recordings only; ``on``; ``off``), applied to every data and validate file.
        recording: how raw recordings are read: ``RecordingOptions`` fields (a ROS log's ``topic``
            and ``effort_topic``, :mod:`idkit.data.logs`; the torque ``delay`` in s or ``"auto"``,
            :mod:`idkit.data.delay`), for every data and validate file.
        identified_urdf: for a ``urdf`` robot, also produce ``identified.urdf`` (the report writes it).
        identified_mjcf: produce ``identified.xml`` (MJCF, :mod:`idkit.robots.mjcf_export`): ``None``
            for an ``mjcf`` robot only, ``True`` for a ``urdf`` robot too, ``False`` never.
        device, dtype: where and in which precision the estimator computes.
        progress: lines every few seconds from the fit's long steps (pcls' prior-weight choice, a
            search's iterations: :mod:`idkit.progress`); the command sets it on a terminal.
    """
    from idkit.problem import Problem

    robot_obj = build("robot", robot)
    cost_obj = build("cost", cost)  # a bad option is refused before the data are loaded
    estimator_obj = build("estimator", estimator)
    if validate is not None and data is not None:
        refuse_training_files(data, validate)
    options = DataOptions.of(preprocess, recording)
    samples, truth, source, training = _load(robot_obj, scenario, seed, data, n_samples, params, options)
    if data is not None and wants_choice(robot_obj):  # robot.coulomb_velocity=auto on measured data
        robot_obj, choice = choose_coulomb_velocity(robot_obj, samples)
        warnings.warn(f"robot.coulomb_velocity=auto: {choice.reason}", CoulombVelocityNote, stacklevel=2)
        source = {**source, "coulomb_velocity": choice.to_dict()}
    held_out = [] if validate is None else read_held_out(robot_obj, validate, training)
    if data is not None:
        refuse_seen_samples(samples, held_out)
    if held_out:
        source = describe_data(held_out, training, source)
    recordings = {
        path: recorded(read_other(robot_obj, path, role, training, data))
        for role, path in getattr(estimator_obj, "files_needed", dict)().items()  # a duck-typed plugin: none
    }
    problem = Problem(
        robot_obj, samples, cost_obj, seed=seed, device=device, dtype=dtype, recordings=recordings
    )
    problem.check_identifiable()  # for every estimator, a third party's included, before its fit
    with reporting("fit", progress):
        fitted = estimator_obj.fit(problem)
    searches = isinstance(estimator_obj, CostSearcher)
    label = estimator_label(estimator, cost, with_cost=searches)
    cost_ignored = cost_obj is not None and not searches
    if cost_ignored:
        say_cost_ignored(label)
    refuse_meaningless(fitted, robot_obj.param_names, label)
    fitted = judged(robot_obj, say_held(robot_obj, fitted, label))  # one plausibility verdict, any estimator
    cost_name = cost_label(cost) if cost is not None else f"{label} criterion"
    provenance = Provenance(
        task="single",
        label=label,
        seed=seed,
        data=source,
        plugins={
            "robot": describe("robot", robot),
            "estimator": describe("estimator", estimator),
            "cost": describe("cost", cost),
        },
    )
    model = IdentifiedModel(robot_obj, replace(fitted, estimator=label))
    scores = validate_files(model, held_out)
    with warnings.catch_warnings():  # the alternative's own choices (its prior weight) are not the run's
        warnings.simplefilter("ignore", Note)
        alternative = plausible_alternative(estimator_obj, fitted, problem, held_out)
    return RunResult(
        model.estimate,
        truth,
        cost_name,
        provenance,
        [HeldOut(f.path, s, f.times) for f, s in zip(held_out, scores, strict=True)],
        _identified_urdf(model) if identified_urdf else None,
        _identified_mjcf(model, identified_mjcf),
        alternative,
        robot_obj,
        cost_ignored,
    )


class CostIgnoredNote(Note):
    """An estimator with its own criterion was given a cost, which cannot change its estimate."""


def say_cost_ignored(label: str) -> None:
    """One note per estimator (the message names no cost, so a sweep over costs prints it once)."""
    warnings.warn(
        CostIgnoredNote(
            f"{label} minimises its own criterion and ignores cost=: every cost gives the same estimate "
            "(the cost is only evaluated at it, for the report), so a sweep over costs repeats this fit"
        ),
        stacklevel=3,
    )
