"""Parameters an estimate did not fit: the sigmoid friction shapes every estimator but ``varpro`` holds.

A robot with ``friction=sigmoid`` has shape parameters (``phi2``, ``phi3``) that enter the torque
nonlinearly; the linear estimators and the base-space searches keep them at the robot's reference
(``sigmoid_steepness``, ``sigmoid_shift``). The estimate still lists them beside the fitted
parameters, and ``phi1``, ``fv`` and their standard deviations are right only if that shape is: so
the command says so in one ``warning:`` line and the table marks them ``held``.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

from idkit.estimate import Estimate
from idkit.interfaces import Robot

#: An estimate within this relative distance of the reference value held it (``held_shapes``).
HOLD_TOLERANCE = 1e-6


class HeldWarning(UserWarning):
    """An estimate lists parameters it held at the robot's reference instead of fitting them."""


def held_shapes(robot: Robot, fitted: Estimate) -> list[str]:
    """The robot's sigmoid shape parameters whose estimate is their reference value (to 1e-6 relative:
    a conic solver holds an equality constraint to its tolerance)."""
    drives = getattr(robot, "drives", None)
    nominal = robot.nominal_params()
    if drives is None or nominal is None:
        return []
    reference = dict(zip(robot.param_names, nominal.tolist(), strict=True))
    shapes = drives.names_where(lambda term: term.shape)
    return [
        name
        for name in shapes
        if name in fitted.params
        and abs(fitted.params[name] - reference[name]) <= HOLD_TOLERANCE * max(1.0, abs(reference[name]))
    ]


def say_held(robot: Robot, fitted: Estimate, label: str) -> Estimate:
    """``fitted`` with ``details["held"]`` listing the shapes it held, said in one line (a
    :class:`HeldWarning`); unchanged when it held none."""
    held = held_shapes(robot, fitted)
    if not held:
        return fitted
    values = ", ".join(f"{name} = {fitted.params[name]:g}" for name in held[:6]) + (", …" * (len(held) > 6))
    warnings.warn(
        f"{label}: the sigmoid friction shape is held at the robot's reference (robot.sigmoid_steepness, "
        f"robot.sigmoid_shift), not fitted: {values}; phi1, fv and their std assume that shape is right "
        "(estimator=varpro fits it)",
        HeldWarning,
        stacklevel=2,
    )
    return replace(fitted, details={**fitted.details, "held": held})
