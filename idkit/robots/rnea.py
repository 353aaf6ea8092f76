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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from idkit.robots.urdf_model import KinematicTree


def cross(u: Tensor, v: Tensor) -> Tensor:
    """``u × v`` over the last dimension, broadcasting the leading ones (``[..., 3]``)."""
    u, v = torch.broadcast_tensors(u, v)
    return torch.linalg.cross(u, v)


@dataclass(frozen=True)
class TreeTensors:
    """The constant geometry of a :class:`KinematicTree` as tensors on one device and dtype.

    Attributes:
        rotation: ``[nb, 3, 3]`` joint-frame orientation in the parent body at ``q = 0``.
        translation: ``[nb, 3]`` joint-frame origin in the parent body.
        axis: ``[nb, 3]`` unit joint axes in the body frames.
        revolute: ``[nb]`` bool, ``False`` for prismatic joints.
        subtree: ``[nb, nb]`` with ``subtree[j, i] = 1`` when body ``i`` is ``j`` or a descendant.
        parents: parent body indices (``-1`` = the fixed root).
    """

    rotation: Tensor
    translation: Tensor
    axis: Tensor
    revolute: Tensor
    subtree: Tensor
    parents: tuple[int, ...]

    @classmethod
    def build(cls, tree: KinematicTree, device: torch.device | str, dtype: torch.dtype) -> TreeTensors:
        nb = len(tree.bodies)
        subtree = np.eye(nb)
        for i in range(nb):  # walk up from every body, marking its ancestors
            j = tree.bodies[i].parent
            while j >= 0:
                subtree[j, i] = 1.0
                j = tree.bodies[j].parent

        def tensor(array: np.ndarray) -> Tensor:
            return torch.as_tensor(np.asarray(array), dtype=dtype, device=device)

        return cls(
            rotation=tensor(np.stack([b.rotation for b in tree.bodies])),
            translation=tensor(np.stack([b.translation for b in tree.bodies])),
            axis=tensor(np.stack([b.axis for b in tree.bodies])),
            revolute=torch.tensor([b.kind == "revolute" for b in tree.bodies], device=device),
            subtree=tensor(subtree),
            parents=tree.parents,
        )


@dataclass(frozen=True)
class Kinematics:
    """Per-body motion for ``N`` states; lists indexed by body, each entry ``[N, 3]`` or ``[N, 3, 3]``.

    ``rotation[k]``/``translation[k]``: pose of body ``k`` in its parent body at the current ``q``;
    ``w``, ``dw``, ``a``: angular velocity, angular acceleration and classical linear acceleration of
    the origin (gravity included) in body ``k``'s coordinates.
    """

    rotation: list[Tensor]
    translation: list[Tensor]
    w: list[Tensor]
    dw: list[Tensor]
    a: list[Tensor]


def _axis_rotation(axis: Tensor, angle: Tensor) -> Tensor:
    """Rodrigues: rotation ``[N, 3, 3]`` by ``angle[N]`` about the unit ``axis[3]``."""
    x, y, z = axis.unbind(-1)
    zero = torch.zeros((), dtype=axis.dtype, device=axis.device)
    skew = torch.stack([torch.stack([zero, -z, y]), torch.stack([z, zero, -x]), torch.stack([-y, x, zero])])
    s, c = torch.sin(angle)[:, None, None], torch.cos(angle)[:, None, None]
    eye = torch.eye(3, dtype=axis.dtype, device=axis.device)
    return eye + s * skew + (1.0 - c) * (skew @ skew)


def _rotate_t(rotation: Tensor, vector: Tensor) -> Tensor:
    """``R^T v`` for ``R[N, 3, 3]`` and ``v[N, 3]``."""
    return (vector[:, None, :] @ rotation)[:, 0, :]


def forward_kinematics(tree: TreeTensors, q: Tensor, qd: Tensor, qdd: Tensor, gravity: float) -> Kinematics:
    """Forward Newton–Euler pass for states ``q, qd, qdd`` each ``[N, nb]``."""
    n_samples = q.shape[0]
    root_a = q.new_zeros(n_samples, 3)
    root_a[:, 2] = gravity
    root_w = q.new_zeros(n_samples, 3)
    kin = Kinematics([], [], [], [], [])
    for k, parent in enumerate(tree.parents):
        axis = tree.axis[k]
        w_p, dw_p, a_p = (
            (root_w, root_w, root_a) if parent < 0 else (kin.w[parent], kin.dw[parent], kin.a[parent])
        )
        if bool(tree.revolute[k]):
            rotation = tree.rotation[k] @ _axis_rotation(axis, q[:, k])
            translation = tree.translation[k].expand(n_samples, 3)
        else:
            rotation = tree.rotation[k].expand(n_samples, 3, 3)
            translation = tree.translation[k] + q[:, k, None] * (tree.rotation[k] @ axis)
        # Acceleration of the new origin as a point of the parent body, then into body k.
        a = a_p + cross(dw_p, translation) + cross(w_p, cross(w_p, translation))
        a = _rotate_t(rotation, a)
        w_in = _rotate_t(rotation, w_p)  # parent's angular velocity in body k
        dw = _rotate_t(rotation, dw_p)
        joint_rate = qd[:, k, None] * axis
        if bool(tree.revolute[k]):
            w = w_in + joint_rate
            dw = dw + qdd[:, k, None] * axis + cross(w_in, joint_rate)
        else:
            w = w_in
            a = a + qdd[:, k, None] * axis + 2.0 * cross(w_in, joint_rate)
        kin.rotation.append(rotation)
        kin.translation.append(translation)
        kin.w.append(w)
        kin.dw.append(dw)
        kin.a.append(a)
    return kin


def _inertia_matrix(params: Tensor) -> Tensor:
    """``I_O[..., 3, 3]`` from standard parameters ``[..., 10]``."""
    xx, xy, xz, yy, yz, zz = params[..., 4:].unbind(-1)
    return torch.stack(
        [torch.stack([xx, xy, xz], -1), torch.stack([xy, yy, yz], -1), torch.stack([xz, yz, zz], -1)], -2
    )


def rnea(tree: TreeTensors, inertials: Tensor, q: Tensor, qd: Tensor, qdd: Tensor, gravity: float) -> Tensor:
    """Joint torques ``tau[..., N, nb]`` for standard parameters ``inertials[..., nb, 10]``.

    The kinematics run once for the ``N`` states; the wrenches and the backward pass broadcast over
    the parameter batch ``...``.
    """
    kin = forward_kinematics(tree, q, qd, qdd, gravity)
    nb = len(tree.parents)
    mass = inertials[..., :, 0, None, None]  # [..., nb, 1, 1]
    first = inertials[..., :, None, 1:4]  # [..., nb, 1, 3]
    inertia = _inertia_matrix(inertials)[..., :, None, :, :]  # [..., nb, 1, 3, 3]
    force: list[Tensor] = []
    moment: list[Tensor] = []
    for k in range(nb):
        w, dw, a = kin.w[k], kin.dw[k], kin.a[k]
        h = first[..., k, :, :]
        inertia_k = inertia[..., k, :, :, :]
        force.append(mass[..., k, :, :] * a + cross(dw, h) + cross(w, cross(w, h)))
        i_w = (inertia_k @ w[..., None])[..., 0]
        i_dw = (inertia_k @ dw[..., None])[..., 0]
        moment.append(i_dw + cross(w, i_w) + cross(h, a))
    torques: list[Tensor] = [q.new_zeros(())] * nb
    for k in reversed(range(nb)):
        axis = tree.axis[k]
        torques[k] = (moment[k] if bool(tree.revolute[k]) else force[k]) @ axis
        parent = tree.parents[k]
        if parent >= 0:
            f_p = (kin.rotation[k] @ force[k][..., None])[..., 0]  # child's force in the parent frame
            force[parent] = force[parent] + f_p
            m_p = (kin.rotation[k] @ moment[k][..., None])[..., 0] + cross(kin.translation[k], f_p)
            moment[parent] = moment[parent] + m_p
    return torch.stack(torques, dim=-1)


def _skew(v: Tensor) -> Tensor:
    """``[v]×[..., 3, 3]`` for ``v[..., 3]``."""
    x, y, z = v.unbind(-1)
    zero = torch.zeros_like(x)
    return torch.stack(
        [torch.stack([zero, -z, y], -1), torch.stack([z, zero, -x], -1), torch.stack([-y, x, zero], -1)], -2
    )


def _inertia_operator(w: Tensor) -> Tensor:
    """``L(w)[..., 3, 6]`` with ``I w = L(w) (I_xx, I_xy, I_xz, I_yy, I_yz, I_zz)``."""
    x, y, z = w.unbind(-1)
    zero = torch.zeros_like(x)
    return torch.stack(
        [
            torch.stack([x, y, z, zero, zero, zero], -1),
            torch.stack([zero, x, zero, y, z, zero], -1),
            torch.stack([zero, zero, x, zero, y, z], -1),
        ],
        -2,
    )


def rnea_regressor(tree: TreeTensors, q: Tensor, qd: Tensor, qdd: Tensor, gravity: float) -> Tensor:
    """Regressor ``Y[N, nb, nb, 10]``: ``tau[:, j] = sum_i Y[:, j, i] @ inertials[i]`` exactly.

    Regressor-form Newton–Euler: each body's wrench is ``A_i(w, dw, a) pi_i`` with ``A_i[N, 6, 10]``;
    the wrench blocks are carried to the root frame (moments about the root origin) in one batched
    product, and joint ``j`` sees the blocks of the bodies in its subtree projected on its axis
    (a Plücker line in the root frame).
    """
    kin = forward_kinematics(tree, q, qd, qdd, gravity)
    w, dw, a = (torch.stack(x, dim=1) for x in (kin.w, kin.dw, kin.a))  # [N, nb, 3]
    zeros3 = torch.zeros_like(a)
    force = torch.cat(
        [a[..., None], _skew(dw) + _skew(w) @ _skew(w), zeros3[..., None].expand(-1, -1, -1, 6)], -1
    )
    moment = torch.cat(
        [zeros3[..., None], -_skew(a), _inertia_operator(dw) + _skew(w) @ _inertia_operator(w)], -1
    )  # [N, nb, 3, 10] each: body-frame wrench blocks
    # Poses of the bodies in the root frame.
    rot_world: list[Tensor] = []
    pos_world: list[Tensor] = []
    for k, parent in enumerate(tree.parents):
        if parent < 0:
            rot_world.append(kin.rotation[k])
            pos_world.append(kin.translation[k])
        else:
            rot_world.append(rot_world[parent] @ kin.rotation[k])
            pos_world.append(pos_world[parent] + (rot_world[parent] @ kin.translation[k][..., None])[..., 0])
    rot, pos = torch.stack(rot_world, 1), torch.stack(pos_world, 1)  # [N, nb, 3, 3], [N, nb, 3]
    force_w = rot @ force
    moment_w = rot @ moment + _skew(pos) @ force_w  # about the root origin
    axis_w = (rot @ tree.axis[:, :, None])[..., 0]  # [N, nb, 3]
    revolute = tree.revolute[:, None]
    # Plücker coordinates of each joint's axis: torque = line · (moment, force) wrench.
    line_moment = torch.where(revolute, axis_w, torch.zeros_like(axis_w))
    line_force = torch.where(revolute, cross(pos, axis_w), axis_w)
    y = torch.einsum("njs,nisp->njip", line_moment, moment_w) + torch.einsum(
        "njs,nisp->njip", line_force, force_w
    )
    return y * tree.subtree[None, :, :, None]
