"""Payload identification (``payload``): one rigid body fixed to a link, the rest of the robot known.

After an arm is identified (``identified.urdf``) its owner mounts a tool and needs the tool's mass,
centre of mass and inertia. The torques are linear in the payload's 10 standard parameters
``phi = (m, m c, I_O)`` (about the origin of the link frame ``F`` it is reported in, the order of
:mod:`idkit.robots.urdf_model`), so with the arm's model ``p_arm`` fixed::

    tau_measured − Y(q, q̇, q̈) p_arm = Y_body T phi + e

where ``Y`` is the robot's standard regressor, ``Y_body`` its 10 columns of the moving body that
carries ``F`` and ``T`` the frame change from ``F`` to that body's frame
(:func:`idkit.robots.inertia.frame_change`; the identity when ``F`` is the body's own link). This is
``pcls`` on one body with the rest fixed: the same QR-compressed data term in χ² units, the same
pseudo-inertia LMI ``J(phi) ⪰ 0`` (here the payload's own, so that it is a real body), ``m ≥
min_mass``, solved by the same cvxpy/Clarabel machinery (:func:`~idkit.conic.program.solve_program`).
When the unconstrained least-squares solution already satisfies the constraints it is the program's
minimiser and is taken as it is (``status`` says so): no solver tolerance on the common case.

**Weights.** Joints differ in noise (a torque sensor's noise grows with its range), and one variance
for all rows makes the fit inefficient and its standard deviations wrong (on the KUKA test with 1 %
of each joint's RMS torque as noise, the unweighted mass and inertia were off by 3.5–4 of their
standard deviations; weighted, the mass and centre-of-mass errors of 12 noise draws were 1.1–1.4
standard deviations RMS). Rows are weighted per joint (and recording) by the inverse residual
standard deviation of an unweighted fit (:func:`group_weights`; Gautier's weighted least squares),
so ``s² ≈ 1``.

**The arm model** is the robot as configured: its URDF inertials (every body, welded links merged)
and, for the friction and offset parameters the robot holds (``robot.friction=true``,
``robot.offset=true``), the values its file records (:mod:`idkit.robots.joint_terms`: an
``identified.urdf`` keeps friction in ``<dynamics>`` and offsets in an ``idkit:`` comment, which
``robot=urdf`` itself reads as 0). Recorded terms the robot does not hold are not used, and listed.

**With a reference recording** (``reference=<file>``, the same arm without the payload) the arm's
own errors cancel instead of leaking into the payload. Two ways (``correction``):

* ``model`` (default, any trajectory): a correction ``delta`` of every base parameter of the robot
  (the identifiable combinations of the links' inertials and the robot's friction and offsets) is
  fitted together with the payload::

      reference rows:   tau_ref − W_ref alpha_arm  = W_ref delta
      payload rows:     tau − W alpha_arm          = W delta + Y_body T phi

  The reference rows fix ``delta``; the payload rows then see the arm as the reference recording
  showed it, and only the difference is left for ``phi``. Any error of the arm model that is linear
  in its parameters (wrong masses, inertias, friction, offsets) cancels. When both recordings run
  the same trajectory, every repeatable error cancels, in the model or not: the payload's columns
  lie in the span of the arm's (``Y_body = W K_body``), so ``delta`` absorbs the recordings' common
  part and only their difference determines ``phi``.
* ``samples`` (the same trajectory replayed with and without the payload, sample for sample): the
  reference's residual ``r_ref(t) = tau_ref(t) − Y(t_ref) p_arm`` is subtracted from the payload
  rows, ``tau(t) − Y(t) p_arm − r_ref(t) = Y_body T phi``. Unweighted this equals ``model`` on the
  same trajectory; it needs no base regressor (10 unknowns instead of ``10 + B``), and its weights
  come from how well the two recordings repeat each other, which is what limits the payload (on
  the KUKA's repeated recordings with a simulated tool added to one, the centre of mass came out
  1.8 mm off against 4.0 mm with ``model``: docs/payload.md). Refused when the positions differ by
  more than ``MAX_MISMATCH``.

Either way the reference's noise enters the covariance below. The identified model (``params``,
``identified.urdf``) keeps the arm as given: the correction is a nuisance, reported in ``details``.

**Unidentified directions.** Columns are scaled to unit norm (``z = x / u``). A tie-break
``TIE_BREAK ‖z − z_LS‖²`` towards the unconstrained minimum-norm least-squares solution makes the
program's solution unique where the data leave a direction free; where the LMI is not active it
changes nothing. Free directions get infinite standard deviations and are listed.

**Uncertainty.** The sandwich of :mod:`idkit.estimators.linear.uncertainty` on the weighted rows and
their unconstrained least-squares residuals (HAC: residuals correlated in time and between joints,
leverage-adjusted; the data and the reference are independent recordings), plus ``pull pullᵀ`` with
``pull = x − x_LS`` where the constraints moved the estimate: a mean squared error. The textbook
``s² (AᵀA)⁺`` it replaces assumed independent residuals; an arm model without its friction leaves
residuals correlated over the motion, and its 95 % intervals held the truth in far fewer draws
(``tests/estimators/test_payload_coverage.py``). Like every σ of idkit it is model-conditional
(:mod:`idkit.std_source`): an arm-model error the payload's columns absorb (a wrong mass of the link
that carries it) moves the estimate without widening σ; a reference recording cancels it. Mass,
centre of mass ``c = h / m`` and the inertia about it ``I_c = I_O − (|h|² 1 − h hᵀ) / m`` get theirs
by the delta method (:func:`centroidal_jacobian`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Literal, get_args

import numpy as np
import torch
from torch import Tensor

from idkit.conic.program import (
    NOISE_FLOOR,
    ConsistentSettings,
    Solver,
    compress,
    cone_violations,
    pseudo_inertia_expression,
    solve_program,
)
from idkit.estimate import Estimate, to_python
from idkit.estimators.linear.observation import IdentificationError, _null_directions
from idkit.estimators.linear.uncertainty import sandwich
from idkit.estimators.payload_verdict import (
    equilibrated_cond,
    motion_share,
    recording_notes,
    sdk_calls,
    verdict,
)
from idkit.interfaces import Estimator, Robot
from idkit.problem import Problem, Samples
from idkit.robots.inertia import centroidal, frame_change, pseudo_inertia
from idkit.robots.joint_terms import recorded_joint_terms
from idkit.robots.urdf_model import INERTIAL_NAMES
from idkit.std_source import describe

#: Weight of the pull towards the unconstrained LS solution, relative to the data term of a
#: unit-norm column (module doc): negligible wherever the data determine a direction.
TIE_BREAK = 1e-6
#: Physical scale of a body's 10 standard parameters (kg, kg·m, kg·m²): a tool of about 1 kg and
#: 10 cm. Only sets which columns count as numerically zero and how those are scaled (``_compressed``).
PHYSICAL_UNITS = np.array([1.0, *[0.1] * 3, *[0.01] * 6])
#: A column below this fraction of the largest (both in physical units) is round-off, not data.
ZERO_COLUMN = 1e-10
#: The status of a fit whose unconstrained least-squares solution already satisfies the constraints:
#: it is then the program's minimiser (the tie-break pulls towards it), so no conic solve is needed.
INSIDE = "least squares inside the constraints"
#: ``correction=samples``: the largest position difference (rad or m) between the data and the
#: reference recording that still counts as the same trajectory (the KUKA's repeated recordings
#: differ by up to 0.0062 rad).
MAX_MISMATCH = 0.05
#: Suffix of the recorded low-speed friction scale (a shape of the model, not a parameter).
STRIBECK = "stribeck_velocity"


#: How a reference recording enters (``PayloadIdentification``'s ``correction``).
Correction = Literal["model", "samples"]


@dataclass(frozen=True)
class PayloadSettings:
    """The payload fit's options, checked once.

    Attributes:
        link: the link the payload is fixed to and reported in (``None``: the tree's end link).
        reference: a recording of the arm without the payload (a path or ``Samples``), or ``None``.
        correction: how the reference is used (``"model"`` or ``"samples"``).
        min_mass: lower bound on the payload mass (kg, ``>= 0``).
        conic_solvers: the cvxpy solvers ``solver`` stands for, tried in order.
    """

    link: str | None
    reference: str | Samples | None
    correction: Correction
    min_mass: float
    conic_solvers: tuple[str, ...]

    @classmethod
    def checked(
        cls,
        link: str | None,
        reference: str | Samples | None,
        correction: Correction,
        min_mass: float,
        solver: Solver,
    ) -> PayloadSettings:
        """The settings; ``min_mass`` and ``solver`` checked as ``pcls`` checks them (``ValueError``)."""
        conic = ConsistentSettings.checked("payload", min_mass=min_mass, solver=solver)
        if correction not in get_args(Correction):
            choices = ", ".join(map(repr, get_args(Correction)))
            raise ValueError(f"payload: correction must be one of {choices}, got {correction!r}")
        if isinstance(reference, str) and not reference.strip():
            reference = None  # estimator.reference= on a command line: none
        return cls(link or None, reference, correction, float(min_mass), conic.conic_solvers)


@dataclass(frozen=True)
class Attachment:
    """Where the payload sits: the link whose frame it is reported in, and the body carrying it.

    Attributes:
        link: the link (frame ``F``).
        body: index of the moving body in ``robot.tree.bodies``.
        transform: ``T[10, 10]``: payload parameters in ``F`` → in the body frame.
    """

    link: str
    body: int
    transform: np.ndarray


def tree_of(robot: Robot) -> Any:
    """The robot's kinematic tree, or a one-line ``ValueError`` for a robot without one."""
    tree = getattr(robot, "tree", None)
    if tree is None or not hasattr(robot, "standard_regressor"):
        raise ValueError(
            f"payload: needs a robot with a kinematic tree and per-link parameters (robot=urdf or "
            f"robot=mjcf), got {type(robot).__name__}"
        )
    return tree


def attachment(robot: Any, link: str | None) -> Attachment:
    """The payload's link (``None``: the tree's single end link) and its frame change.

    Raises:
        ValueError: an unknown link (the message lists the moving links and those welded to
            them), a link welded to the fixed root, several end links and no ``link`` given, a
            welded link of a model that is not a URDF.
    """
    tree = tree_of(robot)
    bodies = {body.link: i for i, body in enumerate(tree.bodies)}
    if link is None:
        parents = {body.parent for body in tree.bodies}
        ends = [body.link for i, body in enumerate(tree.bodies) if i not in parents]
        if len(ends) > 1:
            raise ValueError(
                f"payload: the tree has {len(ends)} end links ({', '.join(ends)}); choose one with "
                "estimator.link=<name>"
            )
        link = ends[0]
    if link in bodies:
        return Attachment(link, bodies[link], np.eye(10))
    welded = {name: body.link for body in tree.bodies for name in body.welded}
    if link not in welded and link in {own.name for own in tree.links}:
        raise ValueError(
            f"payload: link {link!r} of {tree.source} never moves (it is the root or welded to it)"
        )
    if link not in welded:
        listed = ", ".join(
            body.link + (f" (welded: {', '.join(body.welded)})" if body.welded else "")
            for body in tree.bodies
        )
        raise ValueError(f"payload: link {link!r} is not a moving link of {tree.source}; its links: {listed}")
    if getattr(robot, "source_format", "urdf") != "urdf":
        raise ValueError(
            f"payload: link {link!r} is welded to {welded[link]!r}; frames of welded bodies are read from "
            f"URDF only: use estimator.link={welded[link]}"
        )
    from idkit.robots.urdf_frames import link_placement

    placed = link_placement(tree, robot.urdf, link)
    return Attachment(link, placed.body, frame_change(placed.rotation, placed.translation))


@dataclass(frozen=True)
class ArmModel:
    """The fixed part of the model: the robot's parameters with its recorded joint terms.

    Attributes:
        params: ``[P]`` float64: the file's inertials and the recorded values of the joint terms
            the robot holds (0 where the file records none).
        used: the recorded joint terms put into ``params``.
        not_recorded: joint parameters the robot holds but the file does not record (left at 0).
        not_used: non-zero recorded joint terms the robot does not hold (left out).
    """

    params: np.ndarray
    used: dict[str, float]
    not_recorded: tuple[str, ...]
    not_used: tuple[str, ...]

    def to_details(self, source: str) -> dict[str, Any]:
        return {
            "source": source,
            "joint_terms": self.used,
            "not_recorded": list(self.not_recorded),
            "not_used": list(self.not_used),
        }


def arm_model(robot: Any) -> ArmModel:
    """The robot's a-priori parameters with the joint terms its file records (module doc).

    Raises:
        ValueError: the file's ``stribeck_velocity`` or ``coulomb_velocity`` of a joint differs from
            the robot's, whose friction would then not be the one the file's values were fitted with.
    """
    params = robot.nominal_params().double().numpy().copy()
    recorded = recorded_joint_terms(robot)
    nb = len(robot.tree.bodies)
    joint_params = robot.param_names[10 * nb :]
    for key, attribute in ((STRIBECK, "stribeck_scales"), ("coulomb_velocity", "coulomb_scales")):
        scales = getattr(robot, attribute, None)
        for j, joint in enumerate(robot.joint_names):
            written = recorded.get(f"{joint}.{key}")
            current = 0.0 if scales is None else float(scales[j])  # coulomb_velocity 0: the sign
            if (
                written is not None
                and (scales is not None or key != STRIBECK)
                and not math.isclose(written, current, rel_tol=1e-9)
            ):
                raise ValueError(
                    f"payload: {robot.tree.source} records {key}={written:g} for {joint} but the robot "
                    f"uses {current:g}; set robot.{key} to the recorded value"
                )
    used = {name: recorded[name] for name in joint_params if name in recorded}
    for name, value in used.items():
        params[robot.param_names.index(name)] = value
    not_recorded = tuple(name for name in joint_params if name not in recorded)
    not_used = tuple(
        name
        for name, value in recorded.items()
        if name not in robot.param_names and not name.endswith(STRIBECK) and value != 0.0
    )
    return ArmModel(params, used, not_recorded, not_used)


def centroidal_jacobian(phi: np.ndarray) -> np.ndarray:
    """``∂(m, c[3], I_c[xx, xy, xz, yy, yz, zz]) / ∂phi``, ``[10, 10]``, of standard parameters ``phi``.

    ``c = h / m`` and ``I_c = I_O − (|h|² 1 − h hᵀ) / m``; ``I_O``'s six entries enter ``I_c`` one
    to one. The delta method turns ``Cov(phi)`` into ``D Cov(phi) Dᵀ``.
    """
    m, h = float(phi[0]), np.asarray(phi[1:4], dtype=np.float64)
    out = np.zeros((10, 10))
    out[0, 0] = 1.0
    out[1:4, 0] = -h / m**2
    out[1:4, 1:4] = np.eye(3) / m
    pairs = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]
    shift = h @ h * np.eye(3) - np.outer(h, h)  # m (|c|² 1 − c cᵀ) · m
    for row, (a, b) in enumerate(pairs):
        out[4 + row, 4 + row] = 1.0
        out[4 + row, 0] = shift[a, b] / m**2
        for k in range(3):  # ∂(|h|² δ_ab − h_a h_b)/∂h_k = 2 h_k δ_ab − δ_ak h_b − h_a δ_bk
            d = 2 * h[k] * (a == b) - (a == k) * h[b] - h[a] * (b == k)
            out[4 + row, 1 + k] = -d / m
    return out


def sdk_conventions(mass: float, com: np.ndarray, inertia: np.ndarray) -> dict[str, Any]:
    """The payload in the arguments robot SDKs take (all in the frame idkit reports it in).

    * libfranka ``Robot::setLoad(load_mass, F_x_Cload, load_inertia)``: ``F_x_Cload`` the centre of
      mass in the flange frame ``F`` (m), ``load_inertia`` the 3×3 inertia about the centre of mass
      (kg·m²) as 9 numbers, column-major;
    * Universal Robots: URScript ``set_payload(m, cog)`` / ``set_target_payload(m, cog, inertia)``
      and ur_rtde ``setPayload(mass, cog)``: ``cog`` from the tool mount (tool flange frame, m),
      ``inertia = [Ixx, Iyy, Izz, Ixy, Ixz, Iyz]`` about the centre of mass, flange axes.
    """
    (xx, xy, xz), (_, yy, yz), (_, _, zz) = inertia
    return {
        "libfranka": {
            "load_mass": mass,
            "F_x_Cload": list(com),
            "load_inertia": list(np.asarray(inertia).flatten(order="F")),
        },
        "ur": {"mass": mass, "cog": list(com), "inertia": [xx, yy, zz, xy, xz, yz]},
    }


def payload_block(
    phi: np.ndarray,
    covariance: np.ndarray,
    link: str,
    body: str,
    min_eigenvalue: float,
    unusable: str | None = None,
) -> dict[str, Any]:
    """``result.json``'s ``payload``: mass, centre of mass, inertia about it, their standard
    deviations, the standard parameters, the verdict of each quantity
    (:func:`idkit.estimators.payload_verdict.verdict`; ``unusable``: why nothing counts as identified)
    and the SDK calls it allows (``None`` where the mass is 0)."""
    variance = np.where(np.isfinite(np.diag(covariance)), np.diag(covariance), np.inf)
    block: dict[str, Any] = {
        "link": link,
        "body": body,
        "frame": link,
        "standard": dict(zip(INERTIAL_NAMES, phi.tolist(), strict=True)),
        "standard_std": dict(zip(INERTIAL_NAMES, np.sqrt(variance).tolist(), strict=True)),
        "min_eigenvalue": min_eigenvalue,
        "mass": float(phi[0]),
        "mass_std": float(np.sqrt(variance[0])),
    }
    if not phi[0] > 0:
        block.update(com=None, com_std=None, inertia=None, inertia_std=None, sdk=None, verdict=None)
        return block
    mass, com, inertia = centroidal(phi)
    finite = np.isfinite(np.diag(covariance))
    jac = centroidal_jacobian(phi)
    safe = np.where(np.outer(finite, finite), covariance, 0.0)
    std = np.sqrt(np.maximum(np.diag(jac @ safe @ jac.T), 0.0))
    std[(np.abs(jac[:, ~finite]) > 0).any(1)] = np.inf  # touched by an unidentified direction
    rows = [(0, 1, 2), (1, 3, 4), (2, 4, 5)]
    inertia_std = [[float(std[4 + k]) for k in row] for row in rows]
    judged = verdict(
        mass, float(std[0]), com.tolist(), std[1:4].tolist(), inertia.tolist(), inertia_std, unusable
    )
    block.update(
        mass=mass,
        com=com.tolist(),
        com_std=std[1:4].tolist(),
        inertia=inertia.tolist(),
        inertia_std=inertia_std,
        verdict=judged,
        sdk=sdk_calls(sdk_conventions(mass, com, inertia), judged),
    )
    return block


@dataclass(frozen=True)
class Rows:
    """One recording's equations: ``Y`` standard regressor ``[M, P]``, the torques ``tau[M]``, and the
    base regressor ``W[M, B]`` when a reference correction is fitted (float64, CPU)."""

    Y: Tensor
    tau: Tensor
    W: Tensor | None


def _rows(robot: Any, samples: Samples, base: bool) -> Rows:
    Y = robot.standard_regressor(samples.q, samples.qd, samples.qdd)
    W = robot.regressor(samples.q, samples.qd, samples.qdd) if base else None
    flat = [x.reshape(-1, x.shape[-1]).to("cpu", torch.float64) for x in (Y, *([W] if base else []))]
    return Rows(flat[0], samples.tau.reshape(-1).to("cpu", torch.float64), flat[1] if base else None)


def base_units(robot: Any) -> np.ndarray:
    """Physical scale ``[B]`` of each base parameter: ``|K| u`` with ``u`` = ``PHYSICAL_UNITS`` per
    body and 1 for the joint terms (N·m, N·m·s/rad)."""
    nb = len(robot.tree.bodies)
    standard = np.concatenate([np.tile(PHYSICAL_UNITS, nb), np.ones(robot.n_params - 10 * nb)])
    return np.abs(robot.base_map.double().numpy()) @ standard


def reference_samples(
    robot: Any, reference: str | Samples, problem: Problem
) -> tuple[Samples, str, dict[str, Any]]:
    """The reference recording as samples on the problem's device and dtype, what to call it in
    messages, and how it was made (``preprocessed``, ``preprocess``, ``delay`` if any).

    A path is read by the study as the ``data=`` files were — the same cut-off, torque delay and
    effort scale — and handed over in ``problem.recordings`` (an estimator reads no file); samples are
    taken as they are (joint torques).

    Raises:
        ValueError: a path the problem holds no recording for (a ``Problem`` built by hand), another
            number of joints than the robot's.
    """
    if isinstance(reference, Samples):
        samples, name, about = reference, "<Samples>", {"preprocessed": False, "preprocess": "none"}
    else:
        read = problem.recordings.get(reference)
        if read is None:
            raise ValueError(
                f"payload: the reference file {reference} was not read: an estimator reads no file. Run "
                "the fit through idkit.run or the idkit command (they read it as the data), or give the "
                "samples: reference=Samples(...) (joint torques), or Problem(..., recordings={path: "
                "Recorded(samples)})"
            )
        samples, name, about = read.samples, reference, dict(read.about)
    if samples.n_joints != robot.n_joints:
        raise ValueError(
            f"payload: reference file {name} has {samples.n_joints} joints but the robot has "
            f"{robot.n_joints}: {', '.join(robot.joint_names)}"
        )
    like = problem.tensors().q
    return samples.to(device=like.device, dtype=like.dtype), name, about


@dataclass(frozen=True)
class System:
    """The equations of one fit, ``A x ≈ b`` (float64, CPU), and how to read them.

    Attributes:
        A: ``[M, k]``: the payload's columns ``Y_body T`` (then the correction's, ``correction=model``).
        b: ``[M]``: measured torques minus the arm model's (minus the reference's residual,
            ``correction=samples``).
        measured: ``[M]``: the measured torques of each row (the floor of noise-free data).
        groups: ``[M]``: the weight group of each row (a joint of a recording).
        names, units: ``[k]`` the unknowns' names and physical scales.
        fitted_rows: the first rows, those of the data (not the reference).
        reference: what the reference did, for ``details["reference"]`` (``None``: no reference).
        joints: rows per sample (sample-major: a sample's joints are consecutive rows).
    """

    A: Tensor
    b: Tensor
    measured: Tensor
    groups: Tensor
    names: tuple[str, ...]
    units: np.ndarray
    fitted_rows: int
    reference: dict[str, Any] | None
    joints: int = 1


def same_trajectory(data: Samples, reference: Samples, path: str, joints: Sequence[str]) -> float:
    """The largest position difference (rad or m) between two recordings of one trajectory.

    Raises:
        ValueError: other sample counts, or positions further apart than ``MAX_MISMATCH`` (naming the
            sample and joint): ``correction=samples`` subtracts the reference sample by sample.
    """
    if reference.n_samples != data.n_samples:
        raise ValueError(
            f"payload: correction=samples needs a reference of the same trajectory, sample for sample; "
            f"{path} has {reference.n_samples} samples, the data {data.n_samples} (use correction=model)"
        )
    gap = (reference.q - data.q).abs().to("cpu", torch.float64)
    worst = int(gap.argmax())
    sample, joint = divmod(worst, data.n_joints)
    if float(gap.max()) > MAX_MISMATCH:
        raise ValueError(
            f"payload: correction=samples needs the same trajectory, but {path} differs from the data by "
            f"{float(gap.max()):.3g} at sample {sample}, joint {joints[joint]} (more than {MAX_MISMATCH:g}); "
            "use correction=model"
        )
    return float(gap.max())


class PayloadIdentification(Estimator):
    """``payload``: the mass, centre of mass and inertia of a body fixed to a link (module doc).

    Args:
        link: the link the payload is fixed to; its frame is the one the payload is reported in
            and written to ``identified.urdf`` on. A moving link or a link welded to one (e.g. a
            flange, URDF only). ``None``: the tree's end link (refused if it has several).
        reference: a recording of the arm without the payload (same joints), so that the arm's model
            errors cancel: a data file, which the study reads as it reads ``data=`` (the estimator
            reads no file: :meth:`files_needed`), or ``Samples`` (joint torques).
        correction: how the reference is used (module doc): ``"model"`` fits a correction of the
            arm's base parameters together with the payload (any trajectory); ``"samples"``
            subtracts the reference's residual sample by sample (the same trajectory, time-aligned).
        min_mass: lower bound on the payload mass (kg).
        solver: ``"auto"`` (Clarabel, then SCS), ``"clarabel"`` or ``"scs"``.

    ``details["payload"]``: :func:`payload_block` with the fit's numbers; ``details["arm_model"]``:
    which joint terms came from the file; ``details["reference"]``: what the reference did.
    """

    conformance_robot: ClassVar[tuple[str, dict[str, Any]]] = ("urdf", {"urdf": "cylindrical"})

    def __init__(
        self,
        link: str | None = None,
        reference: str | Samples | None = None,
        correction: Correction = "model",
        min_mass: float = 0.0,
        solver: Solver = "auto",
    ) -> None:
        self.link = link
        self.reference = reference
        self.correction = correction
        self.min_mass = min_mass
        self.solver = solver
        self.resolve()  # refused now, not after loading the data

    def resolve(self) -> PayloadSettings:
        """The options checked; at construction and at every fit, so an assigned option counts."""
        return PayloadSettings.checked(self.link, self.reference, self.correction, self.min_mass, self.solver)

    @property
    def name(self) -> str:
        settings = self.resolve()
        return "payload" + (f"+reference-{settings.correction}" if settings.reference is not None else "")

    def files_needed(self) -> dict[str, str]:
        """The reference, when it is a file: the study reads it as the data (``Problem.recordings``)."""
        reference = self.resolve().reference
        return {"payload: reference": reference} if isinstance(reference, str) else {}

    def system(self, problem: Problem, arm: ArmModel, where: Attachment) -> System:
        """The equations of the fit on the problem's samples, with the reference if any
        (:func:`reference_samples`)."""
        robot, samples = problem.robot, problem.tensors()
        settings = self.resolve()
        model = settings.reference is not None and settings.correction == "model"
        rows = _rows(robot, samples, base=model)
        arm_params = torch.as_tensor(arm.params)
        body = slice(10 * where.body, 10 * where.body + 10)
        A = rows.Y[:, body] @ torch.as_tensor(where.transform)  # [M, 10]: Y_body T
        b = rows.tau - rows.Y @ arm_params
        n = robot.n_joints
        groups = torch.arange(len(b)) % n  # rows are sample-major: one weight per joint
        names, units = tuple(f"payload.{k}" for k in INERTIAL_NAMES), PHYSICAL_UNITS
        plain = System(A, b, rows.tau, groups, names, units, len(b), None, n)
        if settings.reference is None:
            return plain
        ref_samples, ref_name, made = reference_samples(robot, settings.reference, problem)
        ref = _rows(robot, ref_samples, base=model)
        ref_residual = ref.tau - ref.Y @ arm_params
        inertials = slice(0, 10 * len(tree_of(robot).bodies))
        about = {
            "file": ref_name,
            "samples": ref_samples.n_samples,
            **made,
            "correction": settings.correction,
            "rel_error_arm": float(ref_residual.norm() / ref.tau.norm()),
            "motion_share": motion_share(robot, ref_samples.q, ref_samples.qd, ref_samples.qdd, inertials),
            **({"cond": equilibrated_cond(ref.W)} if ref.W is not None else {}),
        }
        if settings.correction == "samples":
            about["max_mismatch"] = same_trajectory(samples, ref_samples, ref_name, robot.joint_names)
            return System(A, b - ref_residual, rows.tau, groups, names, units, len(b), about, n)
        assert rows.W is not None and ref.W is not None  # correction=model: _rows was asked for them
        top = torch.cat([A, rows.W], 1)
        bottom = torch.cat([torch.zeros(ref.W.shape[0], 10, dtype=torch.float64), ref.W], 1)
        return System(
            torch.cat([top, bottom]),
            torch.cat([b, ref_residual]),
            torch.cat([rows.tau, ref.tau]),
            torch.cat([groups, n + torch.arange(len(ref_residual)) % n]),
            names + tuple(f"correction.{k}" for k in robot.base_param_names),
            np.concatenate([units, base_units(robot)]),
            len(b),
            {**about, "rows": (ref.W, ref_residual, ref.tau)},
            n,
        )

    def fit(self, problem: Problem) -> Estimate:
        start = time.perf_counter()
        problem.check_identifiable()
        robot = problem.robot
        tree = tree_of(robot)
        settings = self.resolve()
        where = attachment(robot, settings.link)
        arm = arm_model(robot)
        system = self.system(problem, arm, where)
        solution = _solve(system, settings)
        phi = solution.x[:10]
        lowest, outside = cone_violations(["payload"], pseudo_inertia(torch.as_tensor(phi)[None]).numpy())
        if outside:
            raise IdentificationError(
                f"payload: {solution.solver} ended with status {solution.status!r} outside the constraints: "
                f"pseudo-inertia not positive semidefinite for {outside[0]}; try solver=clarabel or scs"
            )
        params = arm.params.copy()
        params[10 * where.body : 10 * where.body + 10] += where.transform @ phi
        rows = slice(0, system.fitted_rows)
        before = system.b[rows]
        after = before - system.A[rows] @ torch.as_tensor(solution.x)
        norm = float(system.measured[rows].norm())
        details: dict[str, Any] = {}
        if system.reference is not None:
            details["reference"] = _reference_details(
                system.reference, solution.x[10:], robot.base_param_names
            )
        body = slice(10 * where.body, 10 * where.body + 10)
        s = problem.tensors()
        recordings: dict[str, float | None] = {
            "data_motion_share": motion_share(robot, s.q, s.qd, s.qdd, body)
        }
        reference = details.get("reference") or {}
        recordings.update(
            reference_motion_share=reference.get("motion_share"), reference_cond=reference.get("cond")
        )
        notes, unusable = recording_notes(recordings, reference.get("file"))  # its path, or <Samples>
        block = payload_block(
            phi, solution.covariance[:10, :10], where.link, tree.bodies[where.body].link, lowest[0], unusable
        )
        block.update(
            equations=int(system.A.shape[0]),
            rank=solution.rank,
            unknowns=len(system.names),
            cond=solution.cond,
            sigma2=solution.sigma2,
            std_method="weighted-hac",
            std_source=describe("weighted-hac"),
            unidentifiable=list(solution.unidentifiable),
            free=list(solution.free),
            recordings={**recordings, "notes": notes},
            rel_error_arm_only=float(before.norm()) / norm,
            rel_error=float(after.norm()) / norm,
        )
        p = torch.as_tensor(params, dtype=s.q.dtype, device=s.q.device)
        cost = float(after.norm()) if problem.cost is None else float(problem.evaluate(p))
        details.update(
            payload=block,
            arm_model=arm.to_details(tree.source),
            criterion="||tau - Y p_arm - Y_link T phi||_2 s.t. J(phi) PSD",
            criterion_value=float(after.norm()),
            rel_error_train=block["rel_error"],
            solver=solution.solver,
            status=solution.status,
            solve_time_s=solution.solve_time_s,
        )
        return Estimate(
            estimator=self.name,
            params=dict(zip(robot.param_names, params.tolist(), strict=True)),
            cost=cost,
            wall_time_s=time.perf_counter() - start,
            base_params=dict(
                zip(robot.base_param_names, robot.base_params(torch.as_tensor(params)).tolist(), strict=True)
            ),
            details=to_python(details),
        )


def _reference_details(about: dict[str, Any], delta: np.ndarray, base_names: Sequence[str]) -> dict[str, Any]:
    """``details["reference"]``: the file and, for ``correction=model``, the fitted correction of each
    base parameter and the reference's ‖E‖/‖T‖ with it."""
    out = {key: value for key, value in about.items() if key != "rows"}
    if "rows" in about:
        W, residual, tau = about["rows"]
        corrected = residual - W @ torch.as_tensor(delta)
        out["correction_values"] = dict(zip(base_names, delta.tolist(), strict=True))
        out["rel_error_corrected"] = float(corrected.norm() / tau.norm())
    return out


@dataclass(frozen=True)
class Solution:
    """The solved payload program.

    Attributes:
        x: ``[k]`` the unknowns (payload ``phi[10]``, then the correction, if any).
        covariance: ``[k, k]`` the HAC sandwich plus the pull of the constraints (module doc; ``inf``
            rows and columns on unidentified directions).
        sigma2: ``s²``; rank, cond: of the column-equilibrated ``A``.
        unidentifiable: readable free directions.
        free: the unknowns a free direction touches (their standard deviations are infinite).
        solver, status, solve_time_s: of the conic solve.
    """

    x: np.ndarray
    covariance: np.ndarray
    sigma2: float
    rank: int
    cond: float
    unidentifiable: tuple[str, ...]
    free: tuple[str, ...]
    solver: str
    status: str
    solve_time_s: float


@dataclass(frozen=True)
class _Compressed:
    """``A x ≈ b`` with unit-norm columns (``x = unit · z``), QR-compressed to ``R z ≈ rhs`` (``rest``
    the part of ``‖b‖²`` no ``z`` reaches), ``R = U diag(S) Vh``, and the minimum-norm LS ``z_ls``."""

    unit: np.ndarray
    R: np.ndarray
    rhs: np.ndarray
    rest: float
    S: np.ndarray
    Vh: np.ndarray
    kept: np.ndarray
    tol: float
    z_ls: np.ndarray


def _compressed(A: Tensor, b: Tensor, units: np.ndarray) -> _Compressed:
    """Compress ``A x ≈ b`` (``units[k]``: each unknown's physical scale, see ``PHYSICAL_UNITS``).

    Columns are scaled to unit norm, except those below ``ZERO_COLUMN`` of the largest once put in
    physical units: such a column is round-off of a parameter the motion cannot excite, and
    scaling it up would make round-off look like data (its unknown stays on the tie-break).
    """
    M, k = A.shape
    norms = torch.linalg.vector_norm(A * torch.as_tensor(units), dim=0).numpy()
    big = norms.max() if norms.max() > 0 else 1.0
    unit = units / np.where(norms > ZERO_COLUMN * big, norms, big)
    R, rhs, rest = compress(A * torch.as_tensor(unit), b)
    U, S, Vh = np.linalg.svd(R)
    tol = max(M, k) * np.finfo(np.float64).eps * S[0] if S[0] > 0 else 0.0
    kept = tol < S
    z_ls = Vh[kept].T @ ((U[:, kept].T @ rhs) / S[kept])
    return _Compressed(unit, R, rhs, rest, S, Vh, kept, tol, z_ls)


def group_weights(residual: Tensor, measured: Tensor, groups: Tensor, unknowns: int) -> Tensor:
    """Row weights ``1 / σ_g`` ``[M]``: ``σ_g²`` the residual variance of each group of rows (a joint
    of a recording) after an unweighted fit, floored at ``NOISE_FLOOR`` times its mean squared torque.

    Joints differ in noise (a torque sensor's noise grows with its range; 1 % of each joint's RMS
    torque is ten times more on the KUKA's second joint than on its last), and the covariance
    ``s² (AᵀA)⁻¹`` assumes one variance: weighting each joint by its own (Gautier's weighted least
    squares) makes the fit efficient and its standard deviations right.
    """
    count = torch.bincount(groups).to(residual)
    dof = max(len(residual) - unknowns, 1) / len(residual)  # share of the rows' degrees of freedom
    variance = torch.bincount(groups, residual.square()) / (count * dof)
    floor = NOISE_FLOOR * torch.bincount(groups, measured.square()) / count
    return torch.maximum(variance, floor).clamp_min(torch.finfo(torch.float64).tiny).rsqrt()[groups]


def _sandwich(
    system: System, weights: Tensor, unit: np.ndarray, z_ls: np.ndarray, bread: np.ndarray
) -> np.ndarray:
    """``[k, k]`` covariance of the scaled unknowns ``z``: the HAC sandwich of
    :func:`idkit.estimators.linear.uncertainty.sandwich` on the weighted rows and their
    least-squares residuals, the data and the reference each a recording of their own."""
    X = (system.A * weights[:, None]) * torch.as_tensor(unit)
    residual = system.b * weights - X @ torch.as_tensor(z_ls)
    starts = (0, system.fitted_rows) if len(system.b) > system.fitted_rows else (0,)
    covariance, _ = sandwich(X[None], residual[None], torch.as_tensor(bread)[None], system.joints, starts)
    return covariance[0].numpy()


def _solve(system: System, settings: PayloadSettings) -> Solution:
    """Weighted least squares ``A x ≈ b`` under the payload's LMI on ``x[:10]`` (module doc).

    Raises:
        IdentificationError: no more equations than unknowns, no torque, a failed solver.
    """
    import cvxpy as cp

    A, b, measured, groups, names, units = (
        system.A,
        system.b,
        system.measured,
        system.groups,
        system.names,
        system.units,
    )
    M, k = A.shape
    if k >= M:
        raise IdentificationError(
            f"payload: {M} equations for {k} unknowns ({', '.join(names[:3])}, ...); record more samples"
        )
    if float(measured.square().sum()) == 0.0:
        raise IdentificationError("payload: the measured torques are all zero; nothing to fit")
    plain = _compressed(A, b, units)
    weights = group_weights(b - A @ torch.as_tensor(plain.unit * plain.z_ls), measured, groups, k)
    c = _compressed(A * weights[:, None], b * weights, units)
    sigma2 = max(c.rest, NOISE_FLOOR * float((measured * weights).square().sum())) / (M - k)
    unit, kept, Vh, S = c.unit, c.kept, c.Vh, c.S
    x_ls = unit * c.z_ls
    lowest = float(np.linalg.eigvalsh(pseudo_inertia(torch.as_tensor(x_ls[:10]))).min())
    if lowest >= 0 and x_ls[0] >= settings.min_mass:  # the program's minimiser, exactly
        x, used, status, elapsed = x_ls, "none", INSIDE, 0.0
    else:
        z = cp.Variable(k)
        phi = cp.multiply(unit[:10], z[:10])
        objective = (cp.sum_squares(c.R @ z - c.rhs) + TIE_BREAK * cp.sum_squares(z - c.z_ls)) / sigma2
        constraints = [pseudo_inertia_expression(phi, cp) >> 0, phi[0] >= settings.min_mass]
        infeasible = f"no payload mass >= min_mass={settings.min_mass:g} kg with a PSD pseudo-inertia"
        started = time.perf_counter()
        program = cp.Problem(cp.Minimize(objective), constraints)
        failures: list[str] = []
        for used in settings.conic_solvers:  # the first solution inside the cone (the fit refuses others)
            found = solve_program(program, (used,), "payload", infeasible, failures=failures)
            if found is None:
                continue
            status = found
            x = unit * np.asarray(z.value)
            _, outside = cone_violations(["payload"], pseudo_inertia(torch.as_tensor(x[:10])[None]).numpy())
            if not outside:
                break
            failures.append(f"{used}: status {found!r} but {outside[0]} outside the cone")
        else:
            raise IdentificationError(f"payload: the conic solver failed ({'; '.join(failures)})")
        elapsed = time.perf_counter() - started
    bread = (Vh[kept].T / S[kept] ** 2) @ Vh[kept]  # (AᵀA)⁺ of the weighted, scaled rows
    covariance_z = _sandwich(system, weights, unit, c.z_ls, bread)
    floor = NOISE_FLOOR * float((measured * weights).square().sum()) / (M - k)  # noise-free data
    covariance_z = covariance_z + floor * bread
    touched = (np.abs(Vh[~kept]) > 1e-8).any(0)
    pull = x - x_ls  # the constraints' pull, a bias the scatter does not show (module doc)
    covariance = covariance_z * np.outer(unit, unit) + np.outer(pull, pull)
    covariance[touched, :] = np.inf
    covariance[:, touched] = np.inf
    free = tuple(_null_directions(torch.as_tensor(Vh), torch.as_tensor(S), float(c.tol), tuple(names)))
    return Solution(
        x=x,
        covariance=covariance,
        sigma2=sigma2,
        rank=int(kept.sum()),
        cond=float(S[0] / S[-1]) if kept.all() else math.inf,
        unidentifiable=free,
        free=tuple(name for name, out in zip(names, touched, strict=True) if out),
        solver=used,
        status=status,
        solve_time_s=elapsed,
    )
