"""A reference inverse dynamics built on pytorch-kinematics: the Lagrangian from centre-of-mass Jacobians.

pytorch-kinematics (pk) gives batched forward kinematics and geometric Jacobians of any URDF but no
dynamics. This module adds them the textbook way, independent of any recursive Newton–Euler code
(``idkit.robots.urdf``, pinocchio), so that it can serve as an oracle for both:

* ``M(q) = sum_l m_l J_v,lᵀ J_v,l + J_ω,lᵀ R_l I_l R_lᵀ J_ω,l`` from pk's Jacobian of every moving
  link at its centre of mass (``SerialChain.jacobian(th, locations=com)``);
* ``V(q) = -sum_l m_l gᵀ p_l(q)`` from the same pk poses;
* ``tau = M q̈ + Ṁ q̇ - ∂/∂q (½ q̇ᵀ M q̇) + ∂V/∂q`` (Euler–Lagrange), the derivatives by autograd
  (``Ṁ q̇ = sum_k ∂(M q̇)/∂q_k q̇_k``: one backward pass per joint; the rest: one more pass).

Traps of pk 0.10 handled here:

* it parses the URDF's joint origins and axes in **float32** (``torch.tensor(rpy, dtype=float32)``;
  ``Chain.to(float64)`` only casts the rounded values), which puts ~1e-6 N·m errors into a real arm's
  torques. The joint origins and axes are therefore re-read from the XML in float64 and written back
  into pk's frames before the chain's flat tensors are built;
* its joint order is its tree traversal, not necessarily the order wanted by the caller: columns of
  ``q`` follow ``joint_names`` and are mapped to pk's order by name;
* its XML parser (lxml) rejects *text* with an encoding declaration: the URDF is always passed as bytes;
* it takes an absent ``<axis>`` as ``z``; the URDF specification (and pinocchio) as ``x`` — the
  axes re-read from the XML follow the specification.

Inertial parameters are read from the XML in float64 too (pk ignores them).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import pytorch_kinematics as pk
import torch
from pytorch_kinematics.transforms import Transform3d
from torch import Tensor

_MOVABLE = ("revolute", "continuous", "prismatic")


def _floats(text: str | None, default: Sequence[float], where: str) -> list[float]:
    if text is None:
        return list(default)
    values = [float(v) for v in text.split()]
    if len(values) != len(default):
        raise ValueError(f"URDF {where}: expected {len(default)} numbers, got {text!r}")
    return values


def rpy_matrix(rpy: Sequence[float]) -> Tensor:
    """URDF ``rpy`` (fixed-axis roll, pitch, yaw) as a float64 rotation ``R[3, 3] = Rz(y) Ry(p) Rx(r)``."""
    r, p, y = (torch.tensor(float(a), dtype=torch.float64) for a in rpy)
    cr, sr, cp, sp, cy, sy = r.cos(), r.sin(), p.cos(), p.sin(), y.cos(), y.sin()
    return torch.stack(
        (
            torch.stack((cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr)),
            torch.stack((sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr)),
            torch.stack((-sp, cp * sr, cp * cr)),
        )
    )


def _origin(element: ET.Element | None, where: str) -> Tensor:
    """Homogeneous float64 transform ``[4, 4]`` of an ``<origin>`` (identity when absent)."""
    out = torch.eye(4, dtype=torch.float64)
    if element is not None:
        out[:3, :3] = rpy_matrix(_floats(element.get("rpy"), (0.0, 0.0, 0.0), f"{where} origin rpy"))
        xyz = _floats(element.get("xyz"), (0.0, 0.0, 0.0), f"{where} origin xyz")
        out[:3, 3] = torch.tensor(xyz, dtype=torch.float64)
    return out


@dataclass(frozen=True)
class LinkInertia:
    """A link's inertial element in float64: mass, centre of mass and inertia ``[3, 3]`` in link axes."""

    mass: float
    com: Tensor  # [3]
    inertia: Tensor  # [3, 3] about the centre of mass, in the link frame's axes


def _read_urdf(urdf: str | bytes | Path) -> bytes:
    if isinstance(urdf, Path) or (isinstance(urdf, str) and not urdf.lstrip().startswith("<")):
        path = Path(urdf)
        if not path.is_file():
            raise FileNotFoundError(f"URDF file not found: {path}")
        return path.read_bytes()
    return urdf.encode("utf-8") if isinstance(urdf, str) else bytes(urdf)


def _parse(xml: bytes) -> tuple[dict[str, ET.Element], dict[str, LinkInertia]]:
    root = ET.fromstring(xml)
    joints = {j.get("name", ""): j for j in root.findall("joint")}
    inertias = {}
    for link in root.findall("link"):
        inertial = link.find("inertial")
        if inertial is None:
            continue
        name = link.get("name", "")
        mass_el, inertia_el = inertial.find("mass"), inertial.find("inertia")
        mass = float(mass_el.get("value", 0.0)) if mass_el is not None else 0.0
        frame = _origin(inertial.find("origin"), f"link {name!r} inertial")
        inertia = torch.zeros(3, 3, dtype=torch.float64)
        if inertia_el is not None:
            keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
            ixx, ixy, ixz, iyy, iyz, izz = (float(inertia_el.get(k, 0.0)) for k in keys)
            inertia = torch.tensor([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]], dtype=torch.float64)
        rot = frame[:3, :3]
        inertias[name] = LinkInertia(mass, frame[:3, 3].clone(), rot @ inertia @ rot.T)
    return joints, inertias


def _walk(frame: pk.frame.Frame):
    yield frame
    for child in frame.children:
        yield from _walk(child)


class PKDynamics:
    """Inverse dynamics, mass matrix and gravity torques of a fixed-base URDF, built on pytorch-kinematics.

    Args:
        urdf: a path, or the URDF text (``str`` starting with ``<``, or ``bytes``).
        joint_names: the order of the columns of ``q``, ``qd``, ``qdd`` and of the torques; by default
            the movable joints in document order of the URDF. Names are checked against the URDF.
        gravity: gravitational acceleration vector ``[3]`` in the root frame (m/s²).

    All computations are float64 on the CPU: this is a reference, not a fast path.
    """

    def __init__(
        self,
        urdf: str | bytes | Path,
        joint_names: Sequence[str] | None = None,
        gravity: Sequence[float] = (0.0, 0.0, -9.81),
    ) -> None:
        xml = _read_urdf(urdf)
        joints, inertias = _parse(xml)
        movable = [name for name, j in joints.items() if j.get("type") in _MOVABLE]
        self.joint_names = tuple(movable if joint_names is None else joint_names)
        if sorted(self.joint_names) != sorted(movable):
            raise ValueError(
                f"joint_names {self.joint_names} must be a permutation of the URDF's movable joints {movable}"
            )
        self.gravity = torch.tensor(gravity, dtype=torch.float64)
        self.chain = self._float64_chain(xml, joints)
        # One serial chain per moving link with mass: its Jacobian at the centre of mass.
        self._links: list[tuple[pk.SerialChain, Tensor, LinkInertia]] = []
        for name, inertia in inertias.items():
            if name not in self.chain.frame_to_idx or (inertia.mass == 0 and not inertia.inertia.any()):
                continue
            serial = pk.SerialChain(self.chain, name, dtype=torch.float64)
            names = serial.get_joint_parameter_names()
            if names:
                columns = torch.tensor([self.joint_names.index(n) for n in names])
                self._links.append((serial, columns, inertia))

    @staticmethod
    def _float64_chain(xml: bytes, joints: dict[str, ET.Element]) -> pk.Chain:
        """pk's chain with every joint origin and axis replaced by its float64 value from the XML."""
        chain = pk.build_chain_from_urdf(xml)
        for frame in _walk(chain._root):
            frame.link.offset = None  # URDF links have no origin of their own; pk stores an identity
            element = joints.get(frame.joint.name)
            if element is None:
                continue
            where = f"joint {frame.joint.name!r}"
            frame.joint.offset = Transform3d(
                matrix=_origin(element.find("origin"), where), dtype=torch.float64
            )
            axis_el = element.find("axis")
            axis = torch.tensor(
                _floats(None if axis_el is None else axis_el.get("xyz"), (1.0, 0.0, 0.0), f"{where} axis"),
                dtype=torch.float64,
            )
            if frame.joint.joint_type != "fixed" and not axis.any():
                raise ValueError(f"URDF {where}: zero axis")
            frame.joint.axis = axis / axis.norm() if axis.any() else axis
        return pk.Chain(chain._root, dtype=torch.float64)  # rebuild the flat tensors from the fixed frames

    def _check(self, name: str, x: Tensor) -> Tensor:
        if x.ndim != 2 or x.shape[1] != len(self.joint_names):
            raise ValueError(f"PKDynamics: {name} must be [N, {len(self.joint_names)}], got {tuple(x.shape)}")
        return x.to(torch.float64)

    def _mass_and_potential(self, q: Tensor) -> tuple[Tensor, Tensor]:
        """``M[N, n, n]`` and the potential energy ``V[N]`` at positions ``q[N, n]`` (differentiable)."""
        n_samples, n = q.shape
        mass = q.new_zeros(n_samples, n, n)
        potential = q.new_zeros(n_samples)
        for serial, columns, link in self._links:
            jac, pose = serial.jacobian(
                q[:, columns], locations=link.com, ret_eef_pose=True
            )  # [N,6,k], [N,4,4]
            full = q.new_zeros(n_samples, 6, n).index_copy(2, columns, jac)
            jv, jw = full[:, :3], full[:, 3:]
            rot = pose[:, :3, :3]
            inertia_world = rot @ link.inertia @ rot.transpose(1, 2)
            mass = mass + link.mass * jv.transpose(1, 2) @ jv + jw.transpose(1, 2) @ inertia_world @ jw
            potential = potential - link.mass * pose[:, :3, 3] @ self.gravity
        return mass, potential

    def mass_matrix(self, q: Tensor) -> Tensor:
        """Joint-space inertia ``M[N, n, n]`` at ``q[N, n]``."""
        return self._mass_and_potential(self._check("q", q))[0].detach()

    def inverse_dynamics(self, q: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
        """Joint torques/forces ``tau[N, n]`` (columns in ``joint_names`` order) for states ``[N, n]``."""
        q = self._check("q", q).detach().requires_grad_(True)
        qd, qdd = self._check("qd", qd).detach(), self._check("qdd", qdd).detach()
        with torch.enable_grad():
            mass, potential = self._mass_and_potential(q)
            momentum = (mass @ qd.unsqueeze(-1)).squeeze(-1)  # [N, n] = ∂T/∂q̇
            kinetic = 0.5 * (momentum * qd).sum(-1)
            # Samples are independent, so the gradient of a sum over samples is the per-sample gradient.
            (dv_minus_dt,) = torch.autograd.grad((potential - kinetic).sum(), q, retain_graph=True)
            mdot_qd = torch.stack(
                [
                    (torch.autograd.grad(momentum[:, j].sum(), q, retain_graph=True)[0] * qd).sum(-1)
                    for j in range(q.shape[1])
                ],
                dim=-1,
            )
        return (mass.detach() @ qdd.unsqueeze(-1)).squeeze(-1) + mdot_qd + dv_minus_dt
