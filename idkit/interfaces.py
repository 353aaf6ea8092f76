"""The plugin contract: ``Robot``, ``Cost``, ``Estimator`` and ``Excitation``, and the optional
capabilities an estimator may add (``BatchedEstimator``, ``CostSearcher``).

Shapes are part of the contract. ``...`` is any batch of leading dimensions (swarm particles,
independent runs, several costs); ``N`` is the number of samples, ``n`` the number of joints, ``P``
the number of physical parameters and ``B`` the number of base parameters.

A plugin's hyperparameters are the keyword arguments of its constructor, stored unchanged, so a
config section maps one-to-one onto a constructor call.
"""

from __future__ import annotations

import math
import numbers
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Generic, Protocol, TypeVar, runtime_checkable

from idkit.hyperparameters import Hyperparameters
from idkit.problem import IdentificationProblem, Problem
from idkit.registry import create

if TYPE_CHECKING:
    from torch import Tensor

    from idkit.estimate import Estimate
    from idkit.limits import MotionLimits

#: The kind of problem an estimator fits (:class:`idkit.problem.IdentificationProblem`).
ProblemT = TypeVar("ProblemT", bound=IdentificationProblem)


class Robot(ABC):
    """Inverse dynamics of one robot, batched over parameter sets.

    Subclasses set ``joint_names`` and ``param_names`` and implement ``bounds`` and
    ``inverse_dynamics``. Robots whose dynamics are linear in (a recombination of) their
    parameters also implement ``regressor``, ``base_params`` and ``params_from_base`` and list
    ``base_param_names``; the least-squares family needs them.
    """

    joint_names: tuple[str, ...]
    param_names: tuple[str, ...]
    base_param_names: tuple[str, ...] = ()
    #: Where search-based estimators (PSO, Adam) look by default: the physical parameters within
    #: ``bounds()`` (the paper's way), or the base parameters within ``base_bounds()`` (robots
    #: with many unidentifiable physical parameters, e.g. a URDF arm).
    search_space: ClassVar[str] = "physical"
    #: Parameters the model carries but no data can separate (e.g. a rotor inertia that merges with
    #: a link inertia), one readable statement each; the uncertainty report lists them.
    unidentifiable: tuple[str, ...] = ()

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @property
    def n_params(self) -> int:
        return len(self.param_names)

    @abstractmethod
    def bounds(self) -> tuple[Tensor, Tensor]:
        """Search box ``(lower[P], upper[P])`` of the physical parameters, float64 on the CPU."""

    def base_bounds(self) -> tuple[Tensor, Tensor]:
        """Search box ``(lower[B], upper[B])`` of the base parameters (robots searched in base space)."""
        raise NotImplementedError(f"{type(self).__name__} has no base-parameter search box")

    def nominal_params(self) -> Tensor | None:
        """Known parameters ``[P]`` (simulation truth or a-priori CAD values), or ``None``."""
        return None

    def check_inputs(self, params: Tensor | None, *states: Tensor) -> None:
        """Raise ``ValueError`` unless ``params`` is ``[..., P]`` and every state is ``[N, n]``.

        Indexing ``params[..., i]`` or ``q[:, j]`` silently accepts too-wide inputs; call this at
        the top of ``inverse_dynamics``/``regressor`` so a mix-up fails where it happens.
        """
        name = type(self).__name__
        if params is not None and (params.ndim == 0 or params.shape[-1] != self.n_params):
            raise ValueError(
                f"{name}: params must be [..., {self.n_params}] ({', '.join(self.param_names)}), "
                f"got shape {tuple(params.shape)}"
            )
        for label, state in zip(("q", "qd", "qdd"), states, strict=False):
            if state.ndim != 2 or state.shape[1] != self.n_joints or state.shape != states[0].shape:
                raise ValueError(
                    f"{name}: {label} must be [N, {self.n_joints}] like q, got shape {tuple(state.shape)}"
                )

    def joint_torques(self, effort: Tensor) -> Tensor:
        """Joint torques ``[N, n]`` of a recording's efforts ``[N, n]`` (identity here; a robot whose
        drives record something else, e.g. a motor current, converts it)."""
        return effort

    @abstractmethod
    def inverse_dynamics(self, params: Tensor, q: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
        """Joint torques ``tau[..., N, n]`` for parameters ``params[..., P]`` and states ``[N, n]``."""

    def default_excitation(self) -> Excitation:
        """The motion ``excitation`` simulates: a registered ``idkit.excitations`` plugin.

        The default is the built-in ``fourier`` series with its default coefficients (five
        harmonics, golden-ratio phases), so any robot plugin can be simulated; robots with a
        planned trajectory or tight joint limits return another one.
        """
        return create("excitation", "fourier", n_joints=self.n_joints)

    def excitation(self, t: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """Joint trajectory ``(q, qd, qdd)``, each ``[N, n]``, at times ``t[N]`` for simulation."""
        return self.default_excitation()(t)

    def motion_limits(self) -> MotionLimits:
        """The box an excitation must stay in (joint positions, velocities, accelerations)."""
        raise NotImplementedError(f"{type(self).__name__} declares no joint motion limits")

    @property
    def has_regressor(self) -> bool:
        """Whether the linear-in-parameters part (``regressor`` and friends) is implemented."""
        return type(self).regressor is not Robot.regressor

    def regressor(self, q: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
        """Observation matrix ``Y[N, n, B]`` with ``tau = Y @ base_params(params)``."""
        raise NotImplementedError(f"{type(self).__name__} has no linear regressor")

    def base_params(self, params: Tensor) -> Tensor:
        """Base parameters ``alpha[..., B]`` of physical parameters ``params[..., P]``."""
        raise NotImplementedError(f"{type(self).__name__} has no base parameters")

    def params_from_base(self, alpha: Tensor) -> Tensor:
        """Physical parameters ``[..., P]`` consistent with base parameters ``alpha[..., B]``."""
        raise NotImplementedError(f"{type(self).__name__} cannot map base to physical parameters")


@dataclass(frozen=True)
class NormStructure:
    """What a cost computes, declared so that estimators can take a fused fast path.

    A cost whose value is a product of factors of the torque error ``E[..., n, N]`` — or, with
    ``relative``, of ``E`` divided by the denominator of
    ``idkit.relative.relative_denominator(measured, floor)`` — declares it through
    ``Cost.structure()``. A factor is a matrix norm (a name of ``idkit.costs.norms.NORMS``) or an
    entrywise reduction with a parameter (a name of ``idkit.costs.reductions.PARAMETRIC``:
    ``"huber"`` with its ``delta``, ``"trimmed"`` with its ``trim``). Estimators then evaluate many
    such costs with few tensor ops (or a compiled kernel) and never look at the cost's class; a
    cost without a structure, or naming a factor idkit does not know, is called as it is.

    Attributes:
        norms: the factors' names, one per factor (each a norm or an entrywise reduction; the
            field keeps its historical name).
        relative: whether the factors see ``E`` divided by the relative denominator (eq. 27).
        floor: the near-zero policy of that denominator (``idkit.relative``).
        parameters: one finite number per factor, aligned with ``norms`` (``0.0`` for a
            parameter-free norm), or empty when every factor is parameter-free.
    """

    norms: tuple[str, ...]
    relative: bool = False
    floor: float = 0.0
    parameters: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        norms, parameters = tuple(self.norms), tuple(self.parameters)
        if isinstance(self.norms, str):
            raise ValueError(
                f"NormStructure: norms must be a tuple of names, e.g. ({self.norms!r},), not a string"
            )
        if parameters and len(parameters) != len(norms):
            raise ValueError(
                f"NormStructure: parameters {parameters} must give one value per factor of norms "
                f"{norms} (or none, when every factor is parameter-free)"
            )
        for name, value in zip(norms, parameters, strict=False):
            if not (isinstance(value, numbers.Real) and math.isfinite(value)):
                raise ValueError(
                    f"NormStructure: the parameter of factor {name!r} must be a finite number, got {value!r}"
                )
        object.__setattr__(self, "norms", norms)  # a list would make the structure unhashable
        object.__setattr__(self, "parameters", tuple(float(value) for value in parameters))


class Cost(ABC):
    """A scalar cost of the torque error matrix, batched over leading dimensions.

    ``error = measured - predicted`` in the paper's joints × samples layout (eq. 6). ``measured``
    is passed so that relative costs (eq. 27) can divide by it.
    """

    #: Whether the cost divides by the measured torques (eq. 27); a class constant or an option.
    relative: bool = False
    #: Whether ``__call__`` also takes many trials' torques at once: ``measured[T, 1, ..., n, N]``
    #: broadcasting against ``error[T, ..., n, N]``. Estimators then evaluate a batch of trials
    #: in one call instead of one call per trial (a cost without a ``structure()`` is otherwise
    #: called once per trial and move).
    stacked_measured: ClassVar[bool] = False

    @abstractmethod
    def __call__(self, error: Tensor, measured: Tensor) -> Tensor:
        """Cost ``value[...]`` of ``error[..., n, N]`` given ``measured[n, N]``."""

    def structure(self) -> NormStructure | None:
        """The product of norms or entrywise reductions ``__call__`` computes, or ``None``.

        ``None`` (the default) sends the cost down the general path: it is called as it is. A
        cost that declares a structure must compute exactly it (``idkit.testing`` checks the two
        agree), and a subclass that changes ``__call__`` must stop declaring it.
        """
        return None


class Estimator(Hyperparameters, ABC, Generic[ProblemT]):
    """Identifies a robot's parameters from one identification problem of the kind it declares.

    ``problem_type`` is that kind: the torque :class:`~idkit.problem.Problem` (the default) or another
    implementation of :class:`~idkit.problem.IdentificationProblem` (``rollout``'s
    :class:`~idkit.sim.problem.RolloutProblem`, declared as ``Estimator[RolloutProblem]`` with
    ``problem_type = RolloutProblem``). The command line runs an estimator only in a task whose study
    builds that kind, and the conformance suite checks it on problems of that kind.

    Hyperparameters follow scikit-learn's contract (:mod:`idkit.hyperparameters`): every constructor
    keyword stored unchanged under its own name, checked by ``resolve()`` at construction and again
    at every ``fit`` (so that ``e.particles = 40`` after ``ParticleSwarm(particles=8)`` runs 40), read
    back by ``get_params()`` and changed by ``set_params(**values)``.

    ``fit`` starts with ``problem.check_identifiable()``: with fewer equations (samples × joints)
    than parameters any criterion has an arbitrary minimiser of near-zero cost, so the fit must fail
    instead. Options are checked against the constructor's annotations before it is called
    (``idkit.options``), so annotate them precisely (``int``, ``bool``, ``Literal[...]``).

    ``Estimate.details["history"]`` is optional; if kept it is the convergence record, one value per
    iteration (``None`` for a non-finite one), in one of three shapes:

    - a list of numbers ``[iterations]`` (one run);
    - a list of equal-length lists ``[runs][iterations]`` (e.g. PSO's best cost of each swarm);
    - a mapping of names to equal-length lists (named columns, e.g. ``{"cost": [...], "lr": [...]}``).

    ``idkit.estimate.history_table`` turns it into a table and names what breaks the format;
    ``idkit.testing.check_estimator`` checks it.
    """

    #: The kind of problem ``fit`` takes (class docstring).
    problem_type: ClassVar[type[IdentificationProblem]] = Problem

    @abstractmethod
    def fit(self, problem: ProblemT) -> Estimate:
        """Estimate the physical parameters (and base parameters where defined)."""

    def files_needed(self) -> dict[str, str]:
        """Data files besides the problem's samples that ``fit`` needs, by what they are in messages
        (``{"payload: reference": path}``). An estimator reads no file: a study reads each as it read
        the data and hands it over in ``Problem.recordings[path]``. Optional for a plugin that does not
        subclass ``Estimator``: without it, none."""
        return {}


def problem_type(estimator: Any) -> type[IdentificationProblem]:
    """The kind of problem an estimator (or estimator class) fits: its ``problem_type``, else the torque
    :class:`~idkit.problem.Problem` (a plugin that does not subclass :class:`Estimator`)."""
    cls = estimator if isinstance(estimator, type) else type(estimator)
    declared = getattr(cls, "problem_type", Problem)
    if not isinstance(declared, type):  # a protocol with attributes allows no issubclass: the class only
        raise TypeError(
            f"{cls.__name__}.problem_type must be a class implementing idkit.problem.IdentificationProblem "
            f"(e.g. idkit.problem.Problem), got {declared!r}"
        )
    return declared


@runtime_checkable
class BatchedEstimator(Protocol):
    """An estimator that fits many trials (a study's noise draws) in batched computations.

    ``idkit.estimators.trials.fit_trials`` calls ``fit_trials`` on an estimator that has it and
    falls back to one ``fit`` per trial (and cost) otherwise. Each trial's estimates must be the
    ones its own ``fit`` gives — whatever ``chunk`` and whatever the other trials — so batching
    changes the speed, never a number.
    """

    def fit_trials(
        self, problems: Sequence[Problem], costs: Sequence[Cost] | None = None, chunk: int | None = None
    ) -> list[list[Estimate]]:
        """``T`` lists of estimates, one per cost (``costs=None``: each problem's own cost, or the
        estimator's fixed criterion), fitting at most ``chunk`` trials per batch."""


@runtime_checkable
class CostSearcher(Protocol):
    """An estimator that minimises whichever cost it is given (PSO, Adam), so its estimates are
    labelled by the cost (``PSO-f13``) and a study fits all its costs in one call."""

    def fit_costs(self, problem: Problem, costs: Sequence[Cost]) -> list[Estimate]:
        """One estimate per cost, each minimising that cost on ``problem``'s samples."""


class Excitation(ABC):
    """A family of joint trajectories with exact derivatives, and one member of it.

    The constructor takes the family's structure (number of joints, harmonics, period, ...) and the
    member's coefficients as keyword arguments, stored unchanged: ``options()`` returns them as
    plain Python values, so a registry name and ``options()`` (a YAML file) rebuild the excitation.
    For optimisers the coefficients are also one flat vector ``[C]``, and ``evaluate`` computes the
    trajectories of a whole batch of coefficient vectors ``[..., C]`` in one tensor computation.

    Families an optimiser can tune also implement ``coefficient_joints`` and ``coefficient_box``;
    they must be an offset plus a motion linear in the other coefficients of the same joint
    (sums of sines, Fourier series, splines are), so scaling those coefficients scales the motion
    about the offset — that is how ``idkit.excitation.optimize`` keeps candidates within limits.
    """

    n_joints: int

    @abstractmethod
    def options(self) -> dict[str, Any]:
        """Constructor keyword arguments (ints, floats, nested lists) that rebuild this excitation."""

    @abstractmethod
    def to_vector(self) -> Tensor:
        """The coefficients as one vector ``[C]`` (float64, CPU)."""

    @abstractmethod
    def from_vector(self, vector: Tensor) -> Excitation:
        """The member of the same family whose coefficients are ``vector[C]``."""

    @abstractmethod
    def evaluate(self, coefficients: Tensor, t: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """``(q, qd, qdd)``, each ``[..., T, n]``, of coefficients ``[..., C]`` at times ``t[T]``.

        Computed on ``t``'s device and dtype, differentiable in ``coefficients`` and ``t``.
        """

    def __call__(self, t: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """``(q, qd, qdd)``, each ``[T, n]``, of this member at times ``t[T]``."""
        return self.evaluate(self.to_vector(), t)

    def check_joints(self, joint_names: Sequence[str], owner: str) -> None:
        """``ValueError`` unless this excitation moves one joint per name (``owner``: whose joints)."""
        if len(joint_names) != self.n_joints:
            raise ValueError(
                f"{type(self).__name__} moves {self.n_joints} joints, but {owner} has {len(joint_names)} "
                f"({', '.join(joint_names)})"
            )

    def coefficient_joints(self) -> tuple[Tensor, Tensor]:
        """``(joint[C], is_offset[C])``: the joint each coefficient moves, and whether it is its offset."""
        raise NotImplementedError(f"{type(self).__name__} does not declare its coefficients' joints")

    def coefficient_box(self, limits: MotionLimits) -> tuple[Tensor, Tensor]:
        """Search box ``(lower[C], upper[C])`` of the coefficients for motions within ``limits``."""
        raise NotImplementedError(f"{type(self).__name__} has no coefficient search box")
