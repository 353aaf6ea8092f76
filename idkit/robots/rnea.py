"""Batched recursive Newton–Euler inverse dynamics and its regressor form, in torch.

Everything is vectorised over samples ``N``; :func:`rnea` is also vectorised over any leading
batch ``...`` of parameter sets. The kinematic pass does not depend on the inertial parameters, so
it runs once per state batch, whatever the number of parameter sets.

Conventions (Craig/Khalil, body frames): each body ``k`` carries its frame at the joint; the forward
pass propagates its angular velocity ``w``, angular acceleration ``dw`` and the classical linear
acceleration ``a`` of its origin, all in body ``k``'s coordinates; gravity enters as an upward
acceleration ``+g z`` of the fixed root (the usual trick). A body's wrench about its origin is
linear in its standard parameters ``pi = (m, h = m c, I_O)``::

    f = m a + dw × h + w × (w × h)
    n = I_O dw + w × (I_O w) + h × a

The backward pass sums child wrenches into parents; the joint torque is the wrench projected on the
joint axis (moment for revolute, force for prismatic joints).

Speed (CPU): vectors are stored component-major, ``[3, N]`` (``[..., 3, N]`` with a parameter
batch), so every elementwise kernel runs over contiguous samples; rotations are never formed per
sample: ``R(q) = F Rot(axis, q)`` is applied as ``(A0 + sin q A1 + (1 - cos q) A2) v`` with the three
constant 3×3 matrices stacked into one ``[9, 3]`` matrix product (Rodrigues), and crosses with
constant vectors are constant-matrix products. Per sample and joint this is a few dozen flops
spread over long vector kernels, instead of many tiny 3×3 batched products.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from idkit.robots.urdf_model import KinematicTree


def cross(u: Tensor, v: Tensor) -> Tensor:
    """``u × v`` for component-major vectors ``[..., 3, N]`` (leading dimensions broadcast).

    Written out by components: ``torch.linalg.cross`` on broadcast (expanded) inputs is several
    times slower on a CPU.
    """
    (ux, uy, uz), (vx, vy, vz) = u.unbind(-2), v.unbind(-2)
    return torch.stack([uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx], -2)


def _skew(v: np.ndarray) -> np.ndarray:
    """``[v]×`` with ``[v]× x = v × x``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@dataclass(frozen=True)
class Joint:
    """Constants of one body's joint, on one device and dtype (vectors as ``[3, 1]`` columns).

    Attributes:
        revolute: ``False`` for a prismatic joint.
        to_child: ``[9, 3]`` (revolute) ``[F^T; -K F^T; K² F^T]`` so that
            ``R^T v = A0 v + sin q A1 v + (1 - cos q) A2 v``, or ``[3, 3]`` ``F^T`` (prismatic), with
            ``F`` the joint frame's orientation in the parent at ``q = 0`` and ``K = [axis]×``.
        to_parent: ``[9, 3]`` ``[F; F K; F K²]`` (``R v``), or ``[3, 3]`` ``F``.
        axis: ``[3, 1]`` unit axis in the body frame; ``skew_axis``: ``K``.
        origin: ``[3, 1]`` joint origin in the parent at ``q = 0``; ``skew_origin``: its ``[·]×``.
        slide: ``[3, 1]`` prismatic direction in the parent frame (``F axis``).
    """

    revolute: bool
    to_child: Tensor
    to_parent: Tensor
    axis: Tensor
    skew_axis: Tensor
    origin: Tensor
    skew_origin: Tensor
    slide: Tensor


@dataclass(frozen=True)
class TreeTensors:
    """The constant geometry of a :class:`KinematicTree` on one device and dtype."""

    joints: tuple[Joint, ...]
    parents: tuple[int, ...]

    @classmethod
    def build(cls, tree: KinematicTree, device: torch.device | str, dtype: torch.dtype) -> TreeTensors:
        def tensor(array: np.ndarray) -> Tensor:
            return torch.as_tensor(np.ascontiguousarray(array), dtype=dtype, device=device)

        joints = []
        for body in tree.bodies:
            rot, axis, origin = body.rotation, body.axis, body.translation
            k = _skew(axis)
            revolute = body.kind == "revolute"
            if revolute:
                to_child = np.concatenate([rot.T, -k @ rot.T, k @ k @ rot.T])
                to_parent = np.concatenate([rot, rot @ k, rot @ k @ k])
            else:
                to_child, to_parent = rot.T, rot
            joints.append(
                Joint(
                    revolute=revolute,
                    to_child=tensor(to_child),
                    to_parent=tensor(to_parent),
                    axis=tensor(axis[:, None]),
                    skew_axis=tensor(k),
                    origin=tensor(origin[:, None]),
                    skew_origin=tensor(_skew(origin)),
                    slide=tensor((rot @ axis)[:, None]),
                )
            )
        return cls(tuple(joints), tree.parents)


@dataclass(frozen=True)
class Kinematics:
    """Per-body motion for ``N`` states (lists indexed by body).

    ``w``, ``dw``, ``a`` (each ``[3, N]``): angular velocity, angular acceleration and classical
    linear acceleration of the body origin (gravity included), in the body's coordinates.
    ``sin``, ``versine = 1 - cos`` (``[N]``, revolute joints) or ``offset`` (``[3, N]``, prismatic: the joint
    origin in the parent frame) describe the body's pose in its parent.
    """

    w: list[Tensor]
    dw: list[Tensor]
    a: list[Tensor]
    sin: list[Tensor | None]
    versine: list[Tensor | None]
    offset: list[Tensor | None]


def _rotate(matrix: Tensor, sin: Tensor | None, versine: Tensor | None, vectors: Tensor) -> Tensor:
    """Apply a joint rotation (``to_child`` or ``to_parent``) to ``vectors[..., 3, N]`` (or ``[3, 1]``)."""
    if sin is None:
        return matrix @ vectors
    y0, y1, y2 = (matrix @ vectors).split(3, dim=-2)
    return y0 + sin * y1 + versine * y2


def _origin_cross(joint: Joint, offset: Tensor | None, vectors: Tensor) -> Tensor:
    """``p × v`` with ``p`` the joint origin in the parent frame (a constant-matrix product if fixed)."""
    if offset is None:
        return joint.skew_origin @ vectors
    return cross(offset, vectors)


def forward_kinematics(tree: TreeTensors, q: Tensor, qd: Tensor, qdd: Tensor, gravity: float) -> Kinematics:
    """Forward Newton–Euler pass for states ``q, qd, qdd`` each ``[N, nb]``."""
    q, qd, qdd = q.T.contiguous(), qd.T.contiguous(), qdd.T.contiguous()  # [nb, N]: a row per joint
    zero = q.new_zeros(3, q.shape[1])
    up = q.new_tensor([[0.0], [0.0], [gravity]])  # the root's acceleration: gravity, as a column
    kin = Kinematics([], [], [], [], [], [])
    for k, (joint, parent) in enumerate(zip(tree.joints, tree.parents, strict=True)):
        sin = versine = offset = None
        if joint.revolute:
            sin, versine = torch.sin(q[k]), 1.0 - torch.cos(q[k])
        else:
            offset = joint.origin + joint.slide * q[k]
        if parent < 0:  # on the fixed root: no parent motion, only gravity
            w_in, dw, a = zero, zero, _rotate(joint.to_child, sin, versine, up)
            coriolis = zero
        else:
            w_p, dw_p, a_p = kin.w[parent], kin.dw[parent], kin.a[parent]
            # Acceleration of the joint origin as a point of the parent: a + dw × p + w × (w × p).
            p = joint.origin if offset is None else offset
            a_origin = (
                a_p - _origin_cross(joint, offset, dw_p) + w_p * (w_p * p).sum(0) - p * (w_p * w_p).sum(0)
            )
            w_in, dw, a = _rotate(joint.to_child, sin, versine, torch.stack([w_p, dw_p, a_origin])).unbind(0)
            coriolis = -(joint.skew_axis @ w_in) * qd[k]  # w_in × (axis qd)
        if joint.revolute:
            w = w_in + joint.axis * qd[k]
            dw = dw + joint.axis * qdd[k] + coriolis
        else:
            w = w_in
            a = a + joint.axis * qdd[k] + 2.0 * coriolis
        kin.w.append(w)
        kin.dw.append(dw)
        kin.a.append(a)
        kin.sin.append(sin)
        kin.versine.append(versine)
        kin.offset.append(offset)
    return kin


def _skew_batch(h: Tensor) -> Tensor:
    """``[h]×[..., 3, 3]`` for ``h[..., 3]``."""
    x, y, z = h.unbind(-1)
    zero = torch.zeros_like(x)
    return torch.stack(
        [torch.stack([zero, -z, y], -1), torch.stack([z, zero, -x], -1), torch.stack([-y, x, zero], -1)], -2
    )


def rnea(tree: TreeTensors, inertials: Tensor, q: Tensor, qd: Tensor, qdd: Tensor, gravity: float) -> Tensor:
    """Joint torques ``tau[..., N, nb]`` for standard parameters ``inertials[..., nb, 10]``.

    The kinematics run once for the ``N`` states; the wrenches and the backward pass broadcast over
    the parameter batch ``...`` (each body's inertia acts as a ``[..., 3, 3]`` matrix on ``[3, N]``).
    """
    kin = forward_kinematics(tree, q, qd, qdd, gravity)
    nb = len(tree.parents)
    xx, xy, xz, yy, yz, zz = inertials[..., 4:].unbind(-1)
    inertia = torch.stack(
        [torch.stack([xx, xy, xz], -1), torch.stack([xy, yy, yz], -1), torch.stack([xz, yz, zz], -1)], -2
    )  # [..., nb, 3, 3]
    first = inertials[..., 1:4]  # [..., nb, 3]
    skew_first = _skew_batch(first)
    force: list[Tensor] = []
    moment: list[Tensor] = []
    for k in range(nb):
        w, dw, a = kin.w[k], kin.dw[k], kin.a[k]
        mass, h = inertials[..., k, 0, None, None], first[..., k, :, None]  # [..., 1, 1], [..., 3, 1]
        i_dw, i_w = (inertia[..., k, None, :, :] @ torch.stack([dw, w])).unbind(-3)
        h_dw, h_a = (skew_first[..., k, None, :, :] @ torch.stack([dw, a])).unbind(-3)
        # f = m a + dw × h + w × (w × h);  n = I dw + w × (I w) + h × a
        force.append(mass * a - h_dw + w * (h * w).sum(-2, keepdim=True) - h * (w * w).sum(0))
        moment.append(i_dw + cross(w, i_w) + h_a)
    torques: list[Tensor] = [q.new_zeros(())] * nb
    for k in reversed(range(nb)):
        joint = tree.joints[k]
        torques[k] = ((moment[k] if joint.revolute else force[k]) * joint.axis).sum(-2)
        parent = tree.parents[k]
        if parent >= 0:
            f_p, n_p = _rotate(
                joint.to_parent, kin.sin[k], kin.versine[k], torch.stack([force[k], moment[k]], -3)
            ).unbind(-3)
            force[parent] = force[parent] + f_p
            moment[parent] = moment[parent] + n_p + _origin_cross(joint, kin.offset[k], f_p)
    return torch.stack(torques, dim=-1)


def _symmetric_products(u: Tensor, v: Tensor) -> Tensor:
    """``s[..., 6, N]`` with ``u · (I v) = s · (I_xx, I_xy, I_xz, I_yy, I_yz, I_zz)`` for symmetric ``I``."""
    (ux, uy, uz), (vx, vy, vz) = u.unbind(-2), v.unbind(-2)
    return torch.stack(
        [ux * vx, ux * vy + uy * vx, ux * vz + uz * vx, uy * vy, uy * vz + uz * vy, uz * vz], -2
    )


def rnea_regressor(tree: TreeTensors, q: Tensor, qd: Tensor, qdd: Tensor, gravity: float) -> Tensor:
    """Regressor ``Y[N, nb, nb, 10]``: ``tau[:, j] = sum_i Y[:, j, i] @ inertials[i]`` exactly.

    Regressor-form Newton–Euler. Joint ``j`` feels body ``i`` (in its subtree) through the wrench
    ``(f_i, n_i)`` projected on ``j``'s unit motion (its twist at unit rate) written in body ``i``'s
    frame, ``l = (l_m, l_f)``: ``tau_j = l_m · n_i + l_f · f_i``. These motions are carried from
    body to body like velocities. Expanding the wrench with triple products gives the coefficient of
    each parameter::

        m:   l_f · a
        h:   l_f × dw + (l_f × w) × w + a × l_m
        I_O: sym(l_m, dw) + sym(l_m × w, w)          (see _symmetric_products)
    """
    kin = forward_kinematics(tree, q, qd, qdd, gravity)
    nb = len(tree.parents)
    y = q.new_zeros(nb, nb, 10, q.shape[0])  # component-major while filling: contiguous writes
    ancestors: list[list[int]] = []
    lines: list[tuple[Tensor, Tensor]] = []  # per body: (l_m, l_f), each [c, 3, N]
    for k, (joint, parent) in enumerate(zip(tree.joints, tree.parents, strict=True)):
        zero = torch.zeros_like(joint.axis)
        own_m, own_f = (joint.axis, zero) if joint.revolute else (zero, joint.axis)
        own_m, own_f = own_m.expand(1, 3, q.shape[0]), own_f.expand(1, 3, q.shape[0])
        if parent < 0:
            ancestors.append([k])
            line_m, line_f = own_m, own_f
        else:
            ancestors.append([*ancestors[parent], k])
            m_p, f_p = lines[parent]
            stacked = torch.stack([m_p, f_p - _origin_cross(joint, kin.offset[k], m_p)])  # f + m × p
            m_k, f_k = _rotate(joint.to_child, kin.sin[k], kin.versine[k], stacked).unbind(0)
            line_m, line_f = torch.cat([m_k, own_m]), torch.cat([f_k, own_f])
        lines.append((line_m, line_f))
        w, dw, a = kin.w[k], kin.dw[k], kin.a[k]
        rows = (
            slice(ancestors[k][0], k + 1)
            if ancestors[k] == list(range(ancestors[k][0], k + 1))
            else ancestors[k]
        )
        block = y[rows, k]  # [c, 10, N]; a view when the ancestors are consecutive (chains)
        block[:, 0] = (line_f * a).sum(-2)
        block[:, 1:4] = cross(line_f, dw) + cross(cross(line_f, w), w) + cross(a, line_m)
        block[:, 4:] = _symmetric_products(line_m, dw) + _symmetric_products(cross(line_m, w), w)
        if not isinstance(rows, slice):
            y[rows, k] = block
    return y.permute(3, 0, 1, 2)
