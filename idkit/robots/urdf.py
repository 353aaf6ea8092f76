"""Any fixed-base URDF robot: standard parameters, exact regressor, numerical base parameters.

Parameters ``p[P]`` (``P = 10 nb + D``), in this order:

* per moving body (link frame = joint frame; welded links merged), the 10 standard inertial
  parameters ``<link>.m, .mcx, .mcy, .mcz, .Ixx, .Ixy, .Ixz, .Iyy, .Iyz, .Izz`` with the inertia
  about the LINK-FRAME ORIGIN (not the centre of mass): the dynamics are linear in these;
* the ``D`` drive parameters of :mod:`idkit.robots.drives`, one group per term and joint: friction
  (``friction=True``: ``<joint>.fc`` then ``<joint>.fv``, the paper's eq. (1) ``F_c sign(qd) + F_v
  qd``, and with ``stribeck_velocity = v_s`` a low-speed ``<joint>.fs``: ``F_s > 0`` is the Stribeck
  excess of breakaway over Coulomb friction, ``-F_c ≤ F_s < 0`` friction that builds up over ``v_s``
  after a velocity reversal; ``friction="asymmetric"``: ``fc_pos, fc_neg, fv``;
  ``friction="sigmoid"``: ``phi1, fv`` and the shape ``phi2, phi3``), then ``<joint>.armature``
  (``armature=True``), then ``<joint>.offset`` (``offset=True``, a constant torque per joint).

``effort_scale`` does not add parameters: :meth:`URDFRobot.joint_torques` turns recorded efforts
into joint torques where a recording enters a study. An armature whose regressor column lies in the
span of the link-inertia columns (the first joints of most arms) is *merged*: it is named in
``unidentifiable`` (and warned about once), and every estimator keeps it at its a-priori value
(``a_priori_params``) while the link inertia carries the rest.

Base parameters (``alpha = K p``) come from :mod:`idkit.robots.base_params` on the regressor stacked
over ``n_states`` random states; ``base_param_names`` names each after the standard parameter it is
built on, with a trailing ``R`` when other parameters are regrouped into it (Khalil's convention);
``base_param_groups`` spells out every group.

Supported: fixed-base kinematic trees (serial chains and branches) of revolute, continuous and
prismatic joints; ``fixed`` joints are merged into their moving parent's inertial (dropped when
welded to the root). Refused with an error naming the joint: ``floating``/``planar`` joints (no
floating base), unknown types, ``<mimic>`` joints; closed loops are refused too.
"""

from __future__ import annotations

import inspect
import warnings
from collections.abc import Sequence
from typing import ClassVar

import numpy as np
import torch
from torch import Tensor

from idkit.interfaces import Robot
from idkit.limits import MotionLimits
from idkit.robots.base_params import BaseParameters, find_base_parameters
from idkit.robots.drives import (
    Boxes,
    DriveModel,
    Friction,
    check_effort_scale,
    float_array,
    per_joint,
    read_armatures,
)
from idkit.robots.meshes import checked_package_dirs
from idkit.robots.rnea import TreeTensors, rnea, rnea_regressor
from idkit.robots.urdf_model import INERTIAL_NAMES, KinematicTree, parse_urdf
from idkit.seeds import Seed, torch_generator


class URDFRobot(Robot):
    """Inverse dynamics of a fixed-base URDF robot by a batched torch Newton–Euler pass.

    Args:
        urdf: a URDF file path, URDF text, or the name of a URDF shipped in ``idkit/robots/assets``
            (default: the paper's cylindrical robot).
        friction: the friction model (:mod:`idkit.robots.drives`): ``False``, ``True`` (Coulomb ``fc``
            and viscous ``fv``), ``"asymmetric"`` (``fc_pos``, ``fc_neg``, ``fv``) or ``"sigmoid"``
            (Gaz et al.: ``phi1``, ``fv`` and the nonlinear shape ``phi2``, ``phi3``).
        stribeck_velocity: with ``friction=True``, also a per-joint Stribeck parameter ``fs`` with
            this velocity scale (rad/s or m/s; one value, or one per joint); ``None`` = no Stribeck term.
        coulomb_velocity: ``v_c`` (rad/s or m/s; one value or one per joint): the Coulomb terms use
            ``tanh(q̇ / v_c)`` instead of ``sign(q̇)``, so a joint at rest is not predicted at ``±fc``
            by the sign of its velocity noise (:mod:`idkit.robots.drives`); ``None`` or 0: the sign;
            ``"auto"``: the sign until a study chooses ``v_c`` from measured training data
            (:mod:`idkit.studies.coulomb`).
        offset: add a per-joint constant torque offset.
        armature: add a per-joint reflected rotor inertia ``armature`` (``tau += Ia qdd``); its
            a-priori value comes from the URDF's transmissions (:func:`~idkit.robots.drives.read_armatures`).
        effort_scale: ``k[n]`` with joint torque = ``k`` × recorded effort (e.g. gear ratio × torque
            constant for a motor current); ``None`` = the recordings hold joint torques.
        gravity: gravitational acceleration (m/s²) along −z of the root link.
        n_states: random states stacked to find the base parameters (``n_states * n >> P``).
        tolerance: relative rank tolerance of the base-parameter search.
        seed: seed of the random states (``q`` uniform within the joint limits, or ``[-π, π]`` /
            ``[-1, 1] m`` without limits; ``qd``, ``qdd`` standard normal).
        max_coulomb, max_viscous, max_offset, max_armature: search-box widths of the friction
            (N·m, N·m·s/rad), offset (N·m) and armature (kg·m²) parameters.
        sigmoid_steepness, sigmoid_shift: reference ``phi2`` (s/rad) and ``phi3`` (rad/s) of the
            sigmoid model (one value or one per joint): the a-priori shape linear estimators use.
        steepness_range, max_shift: search box of ``phi2`` and ``phi3`` (``±max_shift``).
        package_dirs: folders holding the ROS packages the URDF's ``package://`` mesh paths name
            (the geometry that plausibility bounds read: :mod:`idkit.robots.geometry`); each must be an
            existing folder.

    Search boxes (``bounds``), from the URDF's a-priori values ``m0, h0 = m0 c0, I0`` of a body
    (``L = max(|c0|, 0.1 m)``, ``m_hi`` the upper mass bound): mass ``[m0/2, 2 m0]`` (``[0, 1 kg]``
    when ``m0 = 0``); first moments ``h0 ± m_hi L``; diagonal inertia about the origin
    ``[I0/2, 2 I0]`` (``[0, m_hi L²]`` when 0); products ``I0_kl ± sqrt(I_hi,kk I_hi,ll) / 2``;
    ``fc, fc_pos, fc_neg, phi1 ∈ [0, max_coulomb]``, ``fv ∈ [0, max_viscous]``, ``fs ∈ ±max_coulomb``,
    ``armature ∈ [0, max_armature]``, ``offset ∈ ±max_offset``, ``phi2 ∈ steepness_range``,
    ``phi3 ∈ ±max_shift``.
    ``base_bounds`` is the smallest box holding ``K p`` for every ``p`` in that box (interval
    arithmetic: ``K mid ± |K| half_width``), so every physical point of the box is reachable.
    """

    search_space = "base"
    #: The model format: names it in error messages (a subclass reading another format sets it).
    source_format: ClassVar[str] = "urdf"

    def __init__(
        self,
        urdf: str = "cylindrical",
        friction: Friction = False,
        offset: bool = False,
        gravity: float = 9.81,
        n_states: int = 200,
        tolerance: float = 1e-8,
        seed: Seed = 0,
        max_coulomb: float = 10.0,
        max_viscous: float = 10.0,
        max_offset: float = 10.0,
        stribeck_velocity: float | Sequence[float] | None = None,
        armature: bool = False,
        effort_scale: Sequence[float] | None = None,
        max_armature: float = 10.0,
        sigmoid_steepness: float | Sequence[float] = 10.0,
        sigmoid_shift: float | Sequence[float] = 0.0,
        steepness_range: tuple[float, float] = (1.0, 100.0),
        max_shift: float = 0.2,
        package_dirs: Sequence[str] = (),
        coulomb_velocity: float | Sequence[float] | str | None = None,
    ) -> None:
        self.urdf = urdf
        self.friction = friction
        self.offset = offset
        self.gravity = gravity
        self.n_states = n_states
        self.tolerance = tolerance
        self.seed = seed
        self.max_coulomb = max_coulomb
        self.max_viscous = max_viscous
        self.max_offset = max_offset
        self.stribeck_velocity = stribeck_velocity
        self.armature = armature
        self.effort_scale = effort_scale
        self.max_armature = max_armature
        self.sigmoid_steepness = sigmoid_steepness
        self.sigmoid_shift = sigmoid_shift
        self.steepness_range = steepness_range
        self.max_shift = max_shift
        checked_package_dirs(package_dirs, self.source_format)  # a typo would drop every mesh silently
        self.package_dirs = package_dirs
        self.coulomb_velocity = coulomb_velocity
        self.tree: KinematicTree = self._read_tree()
        self.joint_names = self.tree.joint_names
        #: per joint, ``"revolute"`` or ``"prismatic"`` (reports give efforts in N·m or N)
        self.joint_kinds = self.tree.joint_kinds
        self.stribeck_scales = self._check_stribeck(stribeck_velocity)
        self.coulomb_scales = self._check_coulomb(coulomb_velocity)
        self.effort_scales = check_effort_scale(effort_scale, self.joint_names, self.source_format)
        self.link_names = self.tree.link_names
        self.drives = self._drive_model()
        names = [f"{link}.{p}" for link in self.link_names for p in INERTIAL_NAMES]
        self.param_names = tuple(names) + self.drives.names
        self._tensors: dict[tuple[torch.device, torch.dtype], TreeTensors] = {}
        self._regressor_cache: tuple[tuple[Tensor, ...], tuple[int, ...], Tensor] | None = None
        self.base = self._find_base()
        self.base_map = torch.as_tensor(self.base.matrix)
        self.base_param_groups = self.base.groups(self.param_names)
        self.base_param_names = tuple(
            self.param_names[i] + ("R" if np.count_nonzero(row) > 1 else "")
            for i, row in zip(self.base.indices, self.base.matrix, strict=True)
        )
        self.unidentifiable, merged = self._merged_armatures()
        #: Standard parameters every estimator keeps at ``nominal_params()``: merged armatures and
        #: the sigmoid shapes (zero regressor columns; :mod:`idkit.estimators.varpro` searches those).
        self.a_priori_params = merged + self.drives.names_where(lambda term: term.shape)
        free = self.base.matrix.copy()
        free[:, [self.param_names.index(name) for name in self.a_priori_params]] = 0.0
        self._pinv = torch.as_tensor(np.linalg.pinv(free))

    # ---------------------------------------------------------------- structure
    def _drive_model(self) -> DriveModel:
        """The friction, armature and offset terms (:mod:`idkit.robots.drives`) of this robot's joints."""
        joints = self.joint_names
        prior = None
        if self.armature:
            known = self._a_priori_armatures()
            prior = np.array([known.get(j, 0.0) for j in joints])
        shape = None
        if self.friction == "sigmoid":
            shape = (
                per_joint(self.sigmoid_steepness, joints, "sigmoid_steepness", self.source_format),
                per_joint(self.sigmoid_shift, joints, "sigmoid_shift", self.source_format),
            )
        low, high = self.steepness_range  # a config's list becomes the tuple Boxes holds
        boxes = Boxes(
            self.max_coulomb,
            self.max_viscous,
            self.max_offset,
            self.max_armature,
            (low, high),
            self.max_shift,
        )
        return DriveModel(
            joints,
            self.friction,
            self.armature,
            self.offset,
            self.stribeck_scales,
            prior,
            shape,
            boxes,
            self.source_format,
            self.coulomb_scales,
        )

    def with_options(self, **changes: object) -> URDFRobot:
        """The same robot built with some constructor options changed (e.g. the reference sigmoid
        shape a fit found): every option is stored unchanged under its own name."""
        keys = inspect.signature(type(self)).parameters
        return type(self)(**{**{key: getattr(self, key) for key in keys}, **changes})

    def _a_priori_armatures(self) -> dict[str, float]:
        """The model file's armature per joint (a URDF's transmissions); the MJCF reader overrides it."""
        return read_armatures(self.urdf)

    def _merged_armatures(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """``(statements, names)`` of the armatures whose column the link inertias already span.

        Such an armature is a dependent column of the base-parameter search, regrouped into a link's
        base parameter: no data can separate the two, so it is kept at its a-priori value and named.
        """
        statements, names = [], []
        base = set(self.base.indices)
        for name in self.drives.names_where(lambda term: term.suffix == "armature"):
            k = self.param_names.index(name)
            if k in base:
                continue
            rows = np.flatnonzero(self.base.matrix[:, k])
            into = ", ".join(self.base_param_names[r] for r in rows) or "no base parameter"
            prior = float(self.nominal_params()[k])
            statements.append(
                f"{name} merges with the link inertia ({into}): not identifiable, kept at its a-priori "
                f"value {prior:.6g}"
            )
            names.append(name)
        if statements:
            warnings.warn(f"{self.source_format}: {'; '.join(statements)}", stacklevel=3)
        return tuple(statements), tuple(names)

    def _read_tree(self) -> KinematicTree:
        """The tree the dynamics run on: the seam where another format plugs in (``mjcf``)."""
        return parse_urdf(self.urdf)

    def _tree_tensors(self, like: Tensor) -> TreeTensors:
        key = (like.device, like.dtype)
        if key not in self._tensors:
            self._tensors[key] = TreeTensors.build(self.tree, like.device, like.dtype)
        return self._tensors[key]

    def random_states(self, n_states: int, generator: torch.Generator) -> tuple[Tensor, Tensor, Tensor]:
        """Random ``(q, qd, qdd)`` each ``[n_states, n]``: ``q`` within limits, rates standard normal."""
        lower, upper = [], []
        for body in self.tree.bodies:
            default = (-np.pi, np.pi) if body.kind == "revolute" else (-1.0, 1.0)
            lo, hi = body.limits or default
            lower.append(lo)
            upper.append(hi)
        low, high = torch.tensor(lower, dtype=torch.float64), torch.tensor(upper, dtype=torch.float64)
        shape = (n_states, self.n_joints)
        q = low + (high - low) * torch.rand(shape, generator=generator, dtype=torch.float64)
        qd = torch.randn(shape, generator=generator, dtype=torch.float64)
        qdd = torch.randn(shape, generator=generator, dtype=torch.float64)
        return q, qd, qdd

    def _find_base(self) -> BaseParameters:
        if self.n_states * self.n_joints <= self.n_params:
            raise ValueError(
                f"{self.source_format}: n_states={self.n_states} gives {self.n_states * self.n_joints} "
                f"regressor rows for {self.n_params} parameters; use n_states > "
                f"{self.n_params // self.n_joints} (default 200)"
            )
        generator = torch_generator(self.seed)
        states = self.random_states(self.n_states, generator)
        stacked = self.standard_regressor(*states).reshape(-1, self.n_params)
        return find_base_parameters(stacked.numpy(), self.tolerance)

    def motion_limits(self) -> MotionLimits:
        """The URDF's ``<limit>``: position ``lower``/``upper``, velocity ``±velocity``.

        A URDF has no acceleration limits (they are ``±inf`` here: give them with
        ``MotionLimits.replace("acceleration", ...)``); a continuous joint has no position limit,
        a missing or zero ``velocity`` no velocity limit.
        """
        inf = float("inf")
        return MotionLimits.from_ranges(
            self.joint_names,
            [body.limits or (-inf, inf) for body in self.tree.bodies],
            [(-(body.max_velocity or inf), body.max_velocity or inf) for body in self.tree.bodies],
            [(-inf, inf)] * self.n_joints,
        )

    @property
    def effort_limits(self) -> np.ndarray | None:
        """``<limit effort>`` per joint ``[n]``, or ``None`` unless every joint declares one."""
        efforts = [b.effort for b in self.tree.bodies]
        return None if any(e is None for e in efforts) else np.array(efforts, dtype=np.float64)

    # ---------------------------------------------------------------- parameters
    def nominal_params(self) -> Tensor:
        """The URDF's CAD parameters ``[P]`` (friction and offset 0, the reference sigmoid shape, the
        transmissions' armature)."""
        inertial = np.concatenate([b.inertial for b in self.tree.bodies])
        return torch.as_tensor(np.concatenate([inertial, self.drives.nominal()]))

    def joint_torques(self, effort: Tensor) -> Tensor:
        """Joint torques ``[N, n]`` of recorded efforts ``[N, n]``: ``k × effort`` with ``effort_scale``."""
        if self.effort_scales is None:
            return effort
        return effort * torch.as_tensor(self.effort_scales, dtype=effort.dtype, device=effort.device)

    def bounds(self) -> tuple[Tensor, Tensor]:
        """Search box ``(lower[P], upper[P])`` from the a-priori values (rule in the class doc)."""
        lower, upper = [], []
        for body in self.tree.bodies:
            m0, h0 = body.inertial[0], body.inertial[1:4]
            inertia0 = body.inertial[[4, 7, 9]]  # xx, yy, zz
            m_lo, m_hi = (m0 / 2, 2 * m0) if m0 > 0 else (0.0, 1.0)
            length = max(np.linalg.norm(h0) / m0 if m0 > 0 else 0.0, 0.1)
            diag_lo = np.where(inertia0 > 0, inertia0 / 2, 0.0)
            diag_hi = np.where(inertia0 > 0, 2 * inertia0, m_hi * length**2)
            products0 = body.inertial[[5, 6, 8]]  # xy, xz, yz
            half = np.sqrt(diag_hi[[0, 0, 1]] * diag_hi[[1, 2, 2]]) / 2
            (xx_lo, yy_lo, zz_lo), (xx_hi, yy_hi, zz_hi) = diag_lo, diag_hi
            (xy_lo, xz_lo, yz_lo), (xy_hi, xz_hi, yz_hi) = products0 - half, products0 + half
            lower += [m_lo, *(h0 - m_hi * length), xx_lo, xy_lo, xz_lo, yy_lo, yz_lo, zz_lo]
            upper += [m_hi, *(h0 + m_hi * length), xx_hi, xy_hi, xz_hi, yy_hi, yz_hi, zz_hi]
        drive_lower, drive_upper = self.drives.bounds()
        return (
            torch.tensor(np.concatenate([lower, drive_lower]), dtype=torch.float64),
            torch.tensor(np.concatenate([upper, drive_upper]), dtype=torch.float64),
        )

    def base_bounds(self) -> tuple[Tensor, Tensor]:
        """Search box ``(lower[B], upper[B])``: the interval image ``K mid ± |K| half`` of ``bounds``."""
        lower, upper = self.bounds()
        mid, half = (upper + lower) / 2, (upper - lower) / 2
        centre, radius = self.base_map @ mid, self.base_map.abs() @ half
        return centre - radius, centre + radius

    def base_params(self, params: Tensor) -> Tensor:
        """``alpha[..., B] = K p`` for ``params[..., P]``."""
        self._check_params(params)
        return params @ self.base_map.to(params).T

    def params_from_base(self, alpha: Tensor) -> Tensor:
        """Physical parameters ``[..., P]`` closest (Euclidean) to the CAD values with ``K p = alpha``.

        ``p = p0 + pinv(K_free) (alpha - K p0)``: the base parameters fix ``B`` combinations; the other
        ``P - B`` directions (the null space of ``K``) stay at their a-priori value. ``K_free`` is ``K``
        without the columns of ``a_priori_params`` (a merged armature stays at its a-priori value and
        its link inertia takes the whole regrouped base parameter). Not unique and
        not guaranteed physical (e.g. a mass may become negative) when ``alpha`` is far from ``K p0``.
        """
        if alpha.shape[-1] != len(self.base_param_names):
            raise ValueError(
                f"{self.source_format}: base parameters need {len(self.base_param_names)} values in the "
                f"last dimension, got shape {tuple(alpha.shape)}"
            )
        base_map, pinv = self.base_map.to(alpha), self._pinv.to(alpha)
        nominal = self.nominal_params().to(alpha)
        return nominal + (alpha - nominal @ base_map.T) @ pinv.T

    # ---------------------------------------------------------------- dynamics
    def _check_params(self, params: Tensor) -> None:
        if params.shape[-1:] != (self.n_params,):
            raise ValueError(
                f"{self.source_format}: params need {self.n_params} values in the last dimension "
                f"({self.param_names[0]}, ...), got shape {tuple(params.shape)}"
            )

    def _check_states(self, q: Tensor, qd: Tensor, qdd: Tensor) -> None:
        for name, value in (("q", q), ("qd", qd), ("qdd", qdd)):
            if value.ndim != 2 or value.shape[1] != self.n_joints or value.shape != q.shape:
                raise ValueError(
                    f"{self.source_format}: {name} must be [N, {self.n_joints}] like q, got "
                    f"{tuple(value.shape)} (joints: {', '.join(self.joint_names)})"
                )

    def inverse_dynamics(self, params: Tensor, q: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
        """Torques ``tau[..., N, n]`` for ``params[..., P]``; exact on two paths.

        One parameter set on new states runs the Newton–Euler recursion (:func:`rnea`). A batch of
        parameter sets, or the states of the previous call again, uses the regressor form
        ``tau = Y(q, qd, qdd) @ params``: ``Y`` shares the kinematics and the wrench regressors of
        all sets, is built once per state batch and kept (one entry, keyed by tensor identity and
        version; ``N * n * P`` floats). Optimisers evaluate thousands of parameter sets on the
        same samples, so each of their evaluations is one matrix product.
        """
        self._check_params(params)
        self._check_states(q, qd, qdd)
        nb = len(self.tree.bodies)
        drive = self.drives.torque(params[..., 10 * nb :], qd, qdd)
        y = self._cached_regressor(q, qd, qdd, build=params.ndim > 1)
        if y is not None:
            return torch.einsum("snp,...p->...sn", y[..., : 10 * nb], params[..., : 10 * nb]) + drive
        inertials = params[..., : 10 * nb].unflatten(-1, (nb, 10))
        return rnea(self._tree_tensors(q), inertials, q, qd, qdd, self.gravity) + drive

    def _cached_regressor(self, q: Tensor, qd: Tensor, qdd: Tensor, build: bool) -> Tensor | None:
        """The standard regressor of these exact state tensors if kept, else built when ``build``.

        Not kept when a state tensor requires grad (the graph would be kept alive and reused).
        """
        states = (q, qd, qdd)
        versions = tuple(x._version for x in states)
        cache = self._regressor_cache
        if (
            cache is not None
            and all(a is b for a, b in zip(cache[0], states, strict=True))
            and cache[1] == versions
        ):
            return cache[2]
        if not build:
            return None
        y = self.standard_regressor(q, qd, qdd)
        if not any(x.requires_grad for x in states):
            self._regressor_cache = (states, versions, y)
        return y

    def _check_coulomb(self, value: float | Sequence[float] | str | None) -> np.ndarray | None:
        """``coulomb_velocity`` as ``[n]`` scales ``> 0``, or ``None`` (the sign: ``None``, 0, ``"auto"``)."""
        if value is None or (isinstance(value, str) and value == "auto"):
            return None
        try:
            scales = None if isinstance(value, str) else float_array(value)
        except (TypeError, ValueError):
            scales = None
        if scales is not None and scales.size == 1:
            scales = np.full(self.n_joints, scales[0])
        if (
            scales is None
            or scales.shape != (self.n_joints,)
            or not np.isfinite(scales).all()
            or (scales < 0).any()
        ):
            raise ValueError(
                f"{self.source_format}: coulomb_velocity={value!r} needs 'auto', 0 (the sign) or one "
                f"velocity scale >= 0 (rad/s) or {self.n_joints} of them "
                f"(joints: {', '.join(self.joint_names)})"
            )
        if (scales == 0).all():
            return None
        if (scales == 0).any():
            raise ValueError(
                f"{self.source_format}: coulomb_velocity={value!r} mixes 0 (the sign) with scales > 0; give "
                "every joint a scale > 0, or 0 for all"
            )
        return scales

    def _check_stribeck(self, value: float | Sequence[float] | None) -> np.ndarray | None:
        """``stribeck_velocity`` as ``[n]`` positive scales, or ``None``."""
        if value is None:
            return None
        scales = float_array(value)
        if scales.size == 1:
            scales = np.full(self.n_joints, scales[0])
        if self.friction is not True or scales.shape != (self.n_joints,) or not (scales > 0).all():
            raise ValueError(
                f"{self.source_format}: stribeck_velocity={value!r} needs friction=true and one value > 0 "
                f"(rad/s) or {self.n_joints} of them (joints: {', '.join(self.joint_names)})"
            )
        return scales

    def standard_regressor(self, q: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
        """Regressor ``Y[N, n, P]`` of all standard parameters: ``tau = Y @ params``."""
        self._check_states(q, qd, qdd)
        inertial = rnea_regressor(self._tree_tensors(q), q, qd, qdd, self.gravity).flatten(-2)
        return torch.cat([inertial, self.drives.columns(qd, qdd)], dim=-1)

    def regressor(self, q: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
        """Base regressor ``Y[N, n, B]``: the base columns of the standard one, ``tau = Y @ alpha``."""
        return self.standard_regressor(q, qd, qdd)[..., list(self.base.indices)]
