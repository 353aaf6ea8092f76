"""Re-score a written ``identified.urdf`` without idkit's models: pinocchio's inverse dynamics plus the
friction and offsets the file carries, under idkit's documented validation metric or an expert's.

Why: a figure a program reports about its own model is only as good as the program. This module
recomputes it from the file idkit wrote, with independent code — pinocchio's recursive Newton–Euler
(``pin.rnea``) for the rigid body, and the resampling, Butterworth filter and central differences
written out here with numpy/scipy, not idkit's preprocessing — so a test can hold idkit's reported
held-out figure to it (:mod:`idkit.studies.validation` documents the metric).

The identified torque of joint ``j`` is ``rnea_j(q, qd, qdd) + fc_j sign(qd_j) + fv_j qd_j + offset_j``
with ``fc``, ``fv`` from ``<dynamics friction= damping=>`` and ``offset`` from the ``<!-- idkit:
offset=… -->`` comment :mod:`idkit.robots.urdf_export` writes into the joint (URDF has no field for it).

Two scorings of a held-out recording:

* :func:`documented_score`: idkit's metric — ``‖F(τ − τ̂)‖ / ‖F(τ)‖`` with ``F`` the zero-phase
  Butterworth low-pass (order 4 per pass) at the scoring band on the samples' own timestamps; ``τ̂``
  from the states as the training states were made (:func:`filtered_states` at the training cut-off
  for a raw recording, a samples file's own ``q, qd, qdd``);
* :func:`expert_score`: a classic pipeline — positions and torques resampled to the median rate,
  both low-passed at one cut-off, central differences, ``‖τ_f − τ̂‖ / ‖τ_f‖`` after trimming
  ``3 / cutoff`` s at each end.

Needs pinocchio (``pip install pin``).
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

#: ``<!-- idkit: offset=0.12 fs=… -->`` in a joint of identified.urdf.
COMMENT_TERM = re.compile(r"(\w+)=([-+0-9.eE]+)")


@dataclass(frozen=True)
class IdentifiedFile:
    """An identified URDF as pinocchio reads it, with the joint terms pinocchio does not model (read
    from the file alone, not through :class:`idkit.model.IdentifiedModel`).

    Attributes:
        model: the ``pinocchio.Model``.
        joints: the moving joints in pinocchio's order.
        coulomb, viscous, offset: per joint in that order (0 where the file has none).
    """

    model: Any  # pinocchio.Model: pinocchio ships no types
    joints: tuple[str, ...]
    coulomb: np.ndarray
    viscous: np.ndarray
    offset: np.ndarray


def read_identified(path: str | Path) -> IdentifiedFile:
    """Load ``identified.urdf`` with pinocchio and read its ``<dynamics>`` and idkit comment terms."""
    import pinocchio as pin

    text = Path(path).read_text(encoding="utf-8")
    model = pin.buildModelFromXML(text)
    joints = tuple(model.names[1:])
    root = ET.fromstring(text, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    terms: dict[str, dict[str, float]] = {}
    for joint in root.findall("joint"):  # not the <joint> references inside <transmission>
        found: dict[str, float] = {}
        dynamics = joint.find("dynamics")
        if dynamics is not None:
            found["fc"] = float(dynamics.get("friction", 0.0))
            found["fv"] = float(dynamics.get("damping", 0.0))
        for child in joint:
            comment = _comment(child)
            if comment is not None and "idkit:" in comment:
                found.update({k: float(v) for k, v in COMMENT_TERM.findall(comment)})
        terms[joint.get("name", "")] = found

    def column(key: str) -> np.ndarray:
        return np.array([terms.get(name, {}).get(key, 0.0) for name in joints])

    return IdentifiedFile(model, joints, column("fc"), column("fv"), column("offset"))


def _comment(element: ET.Element[Any]) -> str | None:
    """The text of an XML comment (parsed with comments kept), ``None`` for any other element."""
    return (element.text or "") if element.tag is ET.Comment else None


def predicted_torques(
    identified: IdentifiedFile, joints: Sequence[str], q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
) -> np.ndarray:
    """``τ̂[N, n]`` at the states ``q, qd, qdd[N, n]`` whose columns are ``joints`` (any order)."""
    import pinocchio as pin

    order = [list(joints).index(name) for name in identified.joints]
    q, qd, qdd = (np.asarray(a, dtype=np.float64)[:, order] for a in (q, qd, qdd))
    data = identified.model.createData()
    rigid = np.stack(
        [pin.rnea(identified.model, data, a, b, c).copy() for a, b, c in zip(q, qd, qdd, strict=True)]
    )
    tau = rigid + identified.coulomb * np.sign(qd) + identified.viscous * qd + identified.offset
    back = np.empty_like(tau)
    back[:, order] = tau
    return back


def _stretches(t: np.ndarray, max_gap: float = 5.0) -> tuple[list[np.ndarray], float]:
    """Index arrays of the stretches of ``t`` between steps longer than ``max_gap`` median steps."""
    step = float(np.median(np.diff(t)))
    cuts = np.flatnonzero(np.diff(t) > max_gap * step) + 1
    return np.split(np.arange(t.size), cuts), step


def lowpass(t: np.ndarray, x: np.ndarray, cutoff: float, order: int = 4) -> np.ndarray:
    """``x[N, k]`` at times ``t[N]``, zero-phase Butterworth low-passed at ``cutoff`` Hz: per stretch
    between gaps, linear resampling to the median step, ``sosfiltfilt``, and back to ``t``."""
    from scipy import signal

    out = np.empty_like(x, dtype=np.float64)
    stretches, step = _stretches(t)
    sos = signal.butter(order, cutoff, fs=1.0 / step, output="sos")
    for rows in stretches:
        local = t[rows] - t[rows][0]
        grid = np.arange(0.0, local[-1] + 0.5 * step, step)
        grid = grid[grid <= local[-1]]
        uniform = np.stack([np.interp(grid, local, c) for c in x[rows].T], 1)
        pad = min(int(np.ceil(3.0 / (cutoff * step) - 1e-9)), grid.size - 1)  # 3 / cutoff s of odd extension
        filtered = signal.sosfiltfilt(sos, uniform, axis=0, padlen=pad)
        out[rows] = np.stack([np.interp(local, grid, c) for c in filtered.T], 1)
    return out


def filtered_states(
    t: np.ndarray, q: np.ndarray, tau: np.ndarray, cutoff: float, order: int = 4
) -> tuple[np.ndarray, ...]:
    """A raw recording's states the classic way: ``(times, q, qd, qdd, tau_raw, tau_filtered)`` on the
    uniform grid of the median step (from ``t[0]``), positions low-passed at ``cutoff``, central
    differences, ``ceil(3 / cutoff × rate)`` samples trimmed at each end; no gap handling."""
    from scipy import signal

    t = np.asarray(t, dtype=np.float64) - t[0]
    step = float(np.median(np.diff(t)))
    grid = np.arange(0.0, t[-1] + 0.5 * step, step)
    grid = grid[grid <= t[-1]]
    sos = signal.butter(order, cutoff, fs=1.0 / step, output="sos")

    def resample(values: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(grid, t, c) for c in values.T], 1)

    qf = signal.sosfiltfilt(sos, resample(q), axis=0)
    raw = resample(tau)
    tf = signal.sosfiltfilt(sos, raw, axis=0)
    qd = np.gradient(qf, step, axis=0)
    qdd = np.zeros_like(qf)
    qdd[1:-1] = (qf[2:] - 2 * qf[1:-1] + qf[:-2]) / step**2
    keep = slice(
        int(np.ceil(3.0 / cutoff / step - 1e-9)), grid.size - int(np.ceil(3.0 / cutoff / step - 1e-9))
    )
    return grid[keep], qf[keep], qd[keep], qdd[keep], raw[keep], tf[keep]


def documented_score(times: np.ndarray, measured: np.ndarray, predicted: np.ndarray, band: float) -> float:
    """idkit's held-out ``‖E‖/‖T‖``: error and measured torques both low-passed at ``band`` Hz."""
    return float(
        np.linalg.norm(lowpass(times, measured - predicted, band))
        / np.linalg.norm(lowpass(times, measured, band))
    )


def expert_score(
    identified: IdentifiedFile,
    joints: Sequence[str],
    t: np.ndarray,
    q: np.ndarray,
    tau: np.ndarray,
    cutoff: float,
) -> float:
    """The classic pipeline's ``‖τ_f − τ̂‖ / ‖τ_f‖`` of a raw recording (module doc)."""
    _, qf, qd, qdd, _, tf = filtered_states(t, q, tau, cutoff)
    error = tf - predicted_torques(identified, joints, qf, qd, qdd)
    return float(np.linalg.norm(error) / np.linalg.norm(tf))
