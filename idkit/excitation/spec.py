"""An excitation from what a user writes: a registry name (``fourier``), a file, or an object.

``scenario.excitation=fourier`` and ``scenario.excitation=out/excitation.yaml`` both name a motion;
:func:`excitation_of` tells them apart (a registered name wins; anything else is a file) and checks
that the motion moves the robot's joints, so a wrong file fails once, naming the file.
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from idkit.data.presets import Scenario
from idkit.excitation.files import load_excitation
from idkit.interfaces import Excitation, Robot
from idkit.registry import available, create, load


def build_excitation(name: str, robot: Robot, options: Mapping[str, Any] | None = None) -> Excitation:
    """The registered family ``name`` with ``options``; ``n_joints`` is the robot's unless given."""
    options = dict(options or {})
    if "n_joints" in inspect.signature(load("excitation", name)).parameters:
        options.setdefault("n_joints", robot.n_joints)
    excitation = create("excitation", name, **options)
    excitation.check_joints(robot.joint_names, f"robot {type(robot).__name__}")
    return excitation


def excitation_of(spec: str | Path | Excitation, robot: Robot) -> Excitation:
    """The motion ``spec`` names, checked against ``robot``'s joints.

    Args:
        spec: an ``Excitation``; a registered family name (its default member, e.g. ``paper`` is
            eq. (39)); or the path of an excitation file (``excitation.yaml`` of an
            ``idkit +experiment=excitation`` run).

    Raises:
        ValueError: neither a family nor a readable excitation file, or the motion moves another
            number of joints than ``robot`` has; the message names the file.
    """
    if isinstance(spec, Excitation):
        spec.check_joints(robot.joint_names, f"robot {type(robot).__name__}")
        return spec
    families = available("excitation")
    if isinstance(spec, str) and spec in families:
        return build_excitation(spec, robot)
    path = Path(spec)
    if not path.is_file():
        raise ValueError(
            f"excitation {str(spec)!r}: no such file, and not an excitation family "
            f"({', '.join(sorted(families))})"
        )
    excitation = load_excitation(path)
    excitation.check_joints(robot.joint_names, f"robot {type(robot).__name__} (excitation file {path})")
    return excitation


def scenario_excitation(scenario: Scenario, robot: Robot) -> Excitation | None:
    """The motion ``scenario``'s ``excitation`` field names, for :func:`idkit.data.scenarios.simulate`
    (which takes the motion itself); ``None`` when it names none (the robot's own motion)."""
    return None if scenario.excitation is None else excitation_of(scenario.excitation, robot)


def family_name(excitation: Excitation) -> str | None:
    """The registry name of ``excitation``'s family (``None`` for an unregistered class)."""
    return next((n for n in available("excitation") if load("excitation", n) is type(excitation)), None)
