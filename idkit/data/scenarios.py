"""Simulated measurement scenarios reproducing the paper's Tables II–V.

A scenario samples ``robot.excitation`` (eq. (39) for the cylindrical robot), or any other
``Excitation`` given as ``excitation=`` — the motion the scenario's ``excitation`` field names (a
family name or an excitation file, e.g. an optimised one from ``idkit +experiment=excitation``) is
built by :func:`idkit.excitation.spec.scenario_excitation` and given so (data reads no excitation
file: that is the excitation package's), at
``sample_times(n_samples, t_end)``, computes the true torques from the *clean* states with
``robot.inverse_dynamics(params or robot.nominal_params(), ...)`` — so state noise never leaks
into the torques — and then corrupts the four arrays.

Noise model. The paper says "a random error of up to X %" without naming a distribution. We read
it as a multiplicative, uniform, independent error on every sample component::

    noisy = clean · (1 + u),   u ~ U(−X, X)

Relative ("%") errors are multiplicative by definition, "up to" gives a hard bound, and uniform is
the maximum-entropy law with only that bound known. Consequences: an exactly zero component stays
zero, and the error scales with the signal (small torques get small absolute errors).

Outliers (Table V): ``n_outliers`` of the ``N · 4 · n`` sample components (q, qd, qdd, tau of every
joint of every sample: 10 × 12 = 120 for the paper) are chosen uniformly without replacement and
get ``u ~ U(−outlier_noise, outlier_noise)`` instead of the base level. "Up to 70 %" allows a
drawn outlier to be small; ``SampleBatch.outliers`` records which components were chosen.

Randomness: one CPU ``torch.Generator`` seeded with ``seed`` draws ``U(0, 1)`` numbers
``[T, 2, M]`` (``M = 4·N·n``): per trial, M for the errors and M whose ranking chooses the
outliers. Same seed → identical samples, and trial ``i`` depends only on ``(seed, i)``: trial 0
of ``simulate_batch(trials=T, seed=s)`` is ``simulate(seed=s)`` for any ``T``. The draw does not
depend on the noise levels, so scenarios with the same ``N`` and seed share their random numbers
(common random numbers: a comparison of two scenarios is not blurred by different draws).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor

from idkit.data.presets import SCENARIOS, Scenario, UnknownScenarioError
from idkit.data.trajectory import sample_times
from idkit.interfaces import Excitation, Robot
from idkit.memory import check_memory
from idkit.problem import SAMPLE_ARRAYS, Samples
from idkit.seeds import torch_generator


def get_scenario(scenario: str | Scenario | Mapping[str, Any], **overrides: Any) -> Scenario:
    """Resolve a scenario by name, instance or mapping, then apply ``overrides``.

    A mapping (e.g. a Hydra config node) whose ``name`` is a preset starts from that preset and
    overrides the fields it lists; any other mapping builds ``Scenario(**mapping)``. ``None``
    values in ``overrides`` are ignored, so optional config keys can stay unset.
    """
    if isinstance(scenario, str):
        if scenario not in SCENARIOS:
            raise UnknownScenarioError(f"unknown scenario {scenario!r}; available: {', '.join(SCENARIOS)}")
        base = SCENARIOS[scenario]
    elif isinstance(scenario, Scenario):
        base = scenario
    elif isinstance(scenario, Mapping):
        values = dict(scenario)
        name = values.get("name")
        preset = SCENARIOS[name] if isinstance(name, str) and name in SCENARIOS else Scenario()
        base = preset.replace(**values)
    else:
        raise TypeError(f"scenario must be a name, a Scenario or a mapping, got {type(scenario).__name__}")
    return base.replace(**{k: v for k, v in overrides.items() if v is not None})


def shared_fields(scenario: Mapping[str, Any] | None, where: str) -> dict[str, Any]:
    """Scenario fields a study sets on every one of its named scenarios (``None`` values dropped).

    ``idkit +experiment=robustness scenario.excitation=out/excitation.yaml`` runs every scenario of
    the study on that motion. ``name`` is refused (the study's own list names the scenarios), as
    is any key that is not a ``Scenario`` field.
    """
    fields = {k: v for k, v in dict(scenario or {}).items() if v is not None}
    if "name" in fields:
        raise ValueError(
            f"{where}: scenario.name={fields['name']!r} is not for this study: it runs its own list of "
            "scenarios; scenario.<field>=... sets a field of every one of them"
        )
    Scenario().replace(**fields)  # unknown fields or bad values: an error naming them
    return fields


@dataclass(frozen=True)
class SampleBatch:
    """``T`` independently corrupted copies of the same clean samples, stacked.

    Indexing gives one trial as ``Samples``; the stacked tensors serve batched estimators.

    Attributes:
        scenario: the resolved scenario.
        seed: the seed of the generator that drew the noise.
        t: sampling instants ``[N]``.
        clean: the uncorrupted samples (each ``[N, n]``); ``tau`` from the clean states.
        q, qd, qdd, tau: noisy samples ``[T, N, n]``.
        relative_error: the drawn ``u`` ``[T, 4, N, n]`` (arrays in ``SAMPLE_ARRAYS`` order):
            ``noisy = clean · (1 + u)``.
        outliers: ``[T, 4, N, n]`` bool, the components that got ``outlier_noise``.
    """

    scenario: Scenario
    seed: int
    t: Tensor
    clean: Samples
    q: Tensor
    qd: Tensor
    qdd: Tensor
    tau: Tensor
    relative_error: Tensor
    outliers: Tensor

    def __len__(self) -> int:
        return self.q.shape[0]

    def __getitem__(self, trial: int) -> Samples:
        return Samples(self.q[trial], self.qd[trial], self.qdd[trial], self.tau[trial])

    def __iter__(self) -> Iterator[Samples]:
        return (self[i] for i in range(len(self)))


def clean_samples(
    robot: Robot,
    n_samples: int = 10,
    params: Tensor | None = None,
    t_end: float = 10.0,
    excitation: Excitation | None = None,
) -> tuple[Tensor, Samples]:
    """Sampling instants ``t[N]`` and uncorrupted samples of a motion (CPU, float64).

    The motion is ``excitation`` (default ``robot.excitation``). Torques are
    ``robot.inverse_dynamics(params, q, qd, qdd)``; ``params[P]`` defaults to ``robot.nominal_params()``.
    """
    if params is None:
        params = robot.nominal_params()
        if params is None:
            raise ValueError(
                f"{type(robot).__name__} has no nominal parameters to simulate with; pass params=[P] "
                f"({', '.join(robot.param_names)})"
            )
    params = torch.as_tensor(params, dtype=torch.float64)
    if params.shape != (robot.n_params,):
        raise ValueError(
            f"params must have shape ({robot.n_params},) for {', '.join(robot.param_names)}, "
            f"got {tuple(params.shape)}"
        )
    if excitation is not None:
        excitation.check_joints(robot.joint_names, f"robot {type(robot).__name__}")
    t = sample_times(n_samples, t_end)
    q, qd, qdd = robot.excitation(t) if excitation is None else excitation(t)
    tau = robot.inverse_dynamics(params, q, qd, qdd)
    if not isinstance(tau, Tensor) or tuple(tau.shape) != tuple(q.shape):
        got = tuple(tau.shape) if isinstance(tau, Tensor) else type(tau).__name__
        raise ValueError(
            f"robot {type(robot).__name__}: inverse_dynamics(params[{robot.n_params}], q, qd, qdd "
            f"[{q.shape[0]}, {q.shape[1]}]) returned {got}, not tau [{q.shape[0]}, {q.shape[1]}] "
            "(samples x joints; see the plugin contract)"
        )
    return t, Samples(q, qd, qdd, tau)


def simulation_bytes(n_samples: int, n_joints: int, trials: int) -> int:
    """A lower bound on the bytes :func:`simulate_batch` holds at once: times and clean arrays
    (``[N]``, ``4 × [N, n]``), the uniform draws ``[T, 2, 4·N·n]`` and four float64 arrays
    ``[T, 4, N, n]`` (errors, levels, products, noisy samples). The robot's own work is extra."""
    components = 4 * n_samples * n_joints
    return 8 * (n_samples + components + trials * components * (2 + 4))


def simulate_batch(
    robot: Robot,
    scenario: str | Scenario | Mapping[str, Any] = "clean",
    trials: int = 1,
    seed: int = 0,
    n_samples: int | None = None,
    params: Tensor | None = None,
    excitation: Excitation | None = None,
    **overrides: Any,
) -> SampleBatch:
    """``trials`` independent noisy copies of one scenario, drawn in one vectorised call.

    Args:
        robot: any ``Robot``; its ``excitation`` gives the states unless ``excitation`` is given.
        scenario: preset name (see ``SCENARIOS``), ``Scenario`` or mapping (see ``get_scenario``).
        trials: number of independent noise draws ``T``.
        seed: seeds the ``torch.Generator`` that draws every random number.
        n_samples: overrides ``scenario.n_samples``.
        params: true physical parameters ``[P]`` (default ``robot.nominal_params()``).
        excitation: the motion to sample instead of the robot's default one; required when the
            scenario's ``excitation`` field names one (build it with
            :func:`idkit.excitation.spec.scenario_excitation`).
        **overrides: any other ``Scenario`` field, e.g. ``torque_noise=0.1``.

    Returns:
        A ``SampleBatch`` with noisy arrays ``[T, N, n]`` (CPU, float64).
    """
    sc = get_scenario(scenario, n_samples=n_samples, **overrides)
    if excitation is not None and not isinstance(excitation, Excitation):
        raise ValueError(
            f"simulate: excitation={excitation!r} is not an Excitation; build the motion a name or file "
            "means with idkit.excitation.spec.excitation_of(name_or_file, robot)"
        )
    if isinstance(trials, bool) or not isinstance(trials, int) or trials < 1:
        raise ValueError(f"simulate_batch: trials must be an integer >= 1, got {trials!r}")
    check_memory(
        f"scenario {sc.name!r}: n_samples={sc.n_samples} ({robot.n_joints} joints, {trials} trial(s))",
        simulation_bytes(sc.n_samples, robot.n_joints, trials),
        "fewer n_samples need less",
    )
    if excitation is None and sc.excitation is not None:
        raise ValueError(
            f"scenario {sc.name!r} names the excitation {sc.excitation!r}: give the motion as well, "
            "excitation=idkit.excitation.spec.scenario_excitation(scenario, robot)"
        )
    t, clean = clean_samples(robot, sc.n_samples, params, sc.t_end, excitation)
    n = clean.n_joints
    shape = (trials, len(SAMPLE_ARRAYS), sc.n_samples, n)
    n_components = math.prod(shape[1:])
    if sc.n_outliers > n_components:
        raise ValueError(
            f"scenario {sc.name!r}: n_outliers={sc.n_outliers} exceeds the {n_components} sample components "
            f"({sc.n_samples} samples x 4 arrays x {n} joints)"
        )
    gen = torch_generator(seed)
    # Per trial, 2·M consecutive numbers: M for the errors, M to choose the outliers — so trial i
    # depends only on (seed, i), whatever the number of trials.
    draws = torch.rand(trials, 2, n_components, generator=gen, dtype=torch.float64)
    unit = (2.0 * draws[:, 0] - 1.0).view(shape)  # U(-1, 1)
    outliers = torch.zeros(trials, n_components, dtype=torch.bool)
    if sc.n_outliers:
        outliers.scatter_(1, draws[:, 1].argsort(dim=1)[:, : sc.n_outliers], True)
    outliers = outliers.view(shape)
    base = torch.tensor([sc.state_noise] * 3 + [sc.torque_noise], dtype=torch.float64)[:, None, None]
    level = torch.where(outliers, torch.tensor(sc.outlier_noise, dtype=torch.float64), base)
    u = unit * level
    clean_stack = torch.stack([getattr(clean, k) for k in SAMPLE_ARRAYS])  # [4, N, n]
    noisy = clean_stack * (1.0 + u)  # [T, 4, N, n]
    q, qd, qdd, tau = noisy.unbind(1)
    return SampleBatch(sc, int(seed), t, clean, q, qd, qdd, tau, relative_error=u, outliers=outliers)


def simulate(
    robot: Robot,
    scenario: str | Scenario | Mapping[str, Any] = "clean",
    seed: int = 0,
    n_samples: int | None = None,
    params: Tensor | None = None,
    excitation: Excitation | None = None,
    **overrides: Any,
) -> Samples:
    """One noisy sample set of a scenario: trial 0 of ``simulate_batch`` with the same arguments.

    Example: ``simulate(CylindricalRobot(), "outliers", seed=3)`` → ``Samples`` with ``[10, 3]`` arrays.
    """
    return simulate_batch(robot, scenario, 1, seed, n_samples, params, excitation, **overrides)[0]
