"""Which logged command drives which actuator.

Every actuator of the model needs one command column of the log (:mod:`idkit.data.commands`), found
in this order:

1. ``<actuator>.ctrl`` (or an ``.npz``'s ``ctrl`` column of that actuator);
2. by the joint the actuator drives: ``<joint>.ctrl`` when it is that joint's only actuator, else the
   servo's reference — ``<joint>.q_ref`` for a position servo, ``<joint>.qd_ref`` for a velocity
   servo, ``<joint>.ctrl`` for any other actuator.

Columns no actuator takes are reported, not used.
"""

from __future__ import annotations

from dataclasses import dataclass

from idkit.data.commands import RobotLog
from idkit.sim.model import SimModel
from idkit.sim.quantities import servo_kind

REFERENCE = {"position": "q_ref", "velocity": "qd_ref", "other": "ctrl"}


@dataclass(frozen=True)
class Drive:
    """``columns[a]``: the log column driving actuator ``a``; ``unused``: the columns nothing takes."""

    columns: tuple[int, ...]
    unused: tuple[str, ...]

    def describe(self, sim: SimModel, log: RobotLog) -> dict[str, str]:
        return {sim.model.actuator(a).name: log.command_names[c] for a, c in enumerate(self.columns)}


def match_commands(sim: SimModel, log: RobotLog) -> Drive:
    """The column of ``log`` driving each actuator of ``sim`` (module docstring).

    Raises:
        ValueError: an actuator without a command, naming it and the columns it could take.
    """
    index = {name: i for i, name in enumerate(log.command_names)}
    per_joint: dict[int, int] = {}
    for a in range(sim.model.nu):
        joint = sim.actuated_joint(a)
        if joint is not None:
            per_joint[joint] = per_joint.get(joint, 0) + 1
    columns = []
    for a in range(sim.model.nu):
        name = sim.model.actuator(a).name
        wanted = [f"{name}.ctrl", f"#{a}.ctrl"] if name else [f"#{a}.ctrl"]
        joint = sim.actuated_joint(a)
        if joint is not None:
            joint_name = sim.model.joint(joint).name
            if per_joint[joint] == 1:
                wanted.append(f"{joint_name}.ctrl")
            wanted.append(f"{joint_name}.{REFERENCE[servo_kind(sim.model, a)]}")
        found = next((index[w] for w in wanted if w in index), None)
        if found is None:
            label = f"actuator {name!r}" if name else f"actuator #{a} (unnamed)"
            shown = ", ".join(w for w in wanted if not w.startswith("#"))
            raise ValueError(
                f"{log.source}: no command for {label}: expected a column {shown}; the log's commands: "
                f"{', '.join(log.command_names)}"
            )
        columns.append(found)
    unused = tuple(name for i, name in enumerate(log.command_names) if i not in columns)
    return Drive(tuple(columns), unused)
