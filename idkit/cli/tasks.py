"""The command line's tasks: each is one study function, one report module and one config section.

The config maps onto the study's signature one to one: a task's arguments are the keys of its
section (``paper.costs`` → ``paper.run(costs=...)``) and the top-level keys its signature names
(``robot``, ``estimator``, ``cost``, ``scenario``, ``seed``, ``trials`` ...). A top-level key that is
set but not in the signature — ``idkit +experiment=kuka cost=f13`` — is an error, as is a section
key the study does not take, and every value is checked against the study's annotation
(:func:`idkit.options.check_setting`: ``seed=abc`` is refused before anything runs). Adding a
task = a study function, a report module (``text``, ``write``), a config section and one line in
:data:`TASKS`.
"""

from __future__ import annotations

import importlib
import inspect
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import ModuleType
from typing import Any

from idkit.options import check_setting, type_hints
from idkit.registry import NAME_KEY


@dataclass(frozen=True)
class Task:
    """Where a task's study and report live, its config section (``None``: top level only) and the kind
    of identification problem its study hands the estimator (``"module:Class"``)."""

    study: str
    report: str
    section: str | None = None
    problem: str = "idkit.problem:Problem"

    def problem_type(self) -> type:
        module, _, attr = self.problem.partition(":")
        return getattr(importlib.import_module(module), attr)

    def study_function(self) -> Callable[..., Any]:
        module, _, attr = self.study.partition(":")
        return getattr(importlib.import_module(module), attr)

    def report_module(self) -> ModuleType:
        return importlib.import_module(self.report)


TASKS: dict[str, Task] = {
    "single": Task("idkit.studies.single:run", "idkit.reports.single"),
    "paper": Task("idkit.studies.paper:run", "idkit.reports.paper", "paper"),
    "robustness": Task("idkit.studies.robustness:run", "idkit.reports.robustness", "robustness"),
    "kuka": Task("idkit.studies.kuka:run", "idkit.reports.kuka", "kuka"),
    "excitation": Task("idkit.studies.excitation:run", "idkit.reports.excitation", "excitation"),
    "rollout": Task(
        "idkit.studies.rollout:run", "idkit.reports.rollout", "rollout", "idkit.sim.problem:RolloutProblem"
    ),
}

#: Top-level keys read by the command line itself, not by a study.
COMMAND_KEYS = ("task", "plots")
#: Study arguments the command line supplies itself (never from the config).
SUPPLIED = ("progress", "checkpoint")
#: Config groups a user may delete (``'~cost'``): the study then gets ``None`` — for ``cost``, the
#: estimator's own criterion is reported — instead of the signature's default, which would bring back
#: what was deleted without a word.
REMOVABLE = ("cost",)


def get_task(name: str) -> Task:
    if name not in TASKS:
        raise ValueError(f"unknown task {name!r}; the tasks are {', '.join(TASKS)}")
    return TASKS[name]


def _describe(value: Any) -> str:
    if isinstance(value, Mapping) and "_name_" in value:
        return str(value["_name_"])
    if isinstance(value, Mapping) and "name" in value:
        return str(value["name"])
    return repr(value)


def arguments(name: str, config: Mapping[str, Any], study: Callable[..., Any]) -> dict[str, Any]:
    """The keyword arguments of task ``name``'s study from a resolved config (plain dict).

    Args:
        name: the task.
        config: the resolved config without ``hydra``.
        study: the task's study function; its signature says which keys it takes and its
            annotations what they must be.

    Raises:
        ValueError: a set top-level key the study does not take, or an unknown section key.
        idkit.options.OptionError: a value its annotation rejects (also a ``ValueError``).
    """
    task = get_task(name)
    takes = inspect.signature(study).parameters
    options = ", ".join(k for k in takes if k not in SUPPLIED)
    section = dict(config.get(task.section) or {}) if task.section else {}
    for key in section:
        if key not in takes or key in SUPPLIED:
            raise ValueError(f"{task.section}.{key} is not an option of the {name} task; it takes {options}")
    kwargs = dict(section)
    deleted = [key for key in REMOVABLE if key in takes and key not in config and key not in section]
    kwargs.update(dict.fromkeys(deleted))
    for key, value in config.items():
        if key in COMMAND_KEYS or key == task.section:
            continue
        if key in takes and key not in SUPPLIED:
            if key in section:
                raise ValueError(f"{key} is set both at the top level and as {task.section}.{key}; keep one")
            kwargs[key] = value
        elif value is not None:
            got = f"{key}={_describe(value)}"
            raise ValueError(f"the {name} task takes no {key} (got {got}); it takes {options}")
    _refuse_foreign_estimator(name, kwargs.get("estimator"))
    hints = type_hints(study)
    return {
        key: check_setting(_setting(task, key, section), value, hints.get(key, Any), takes[key].default)
        for key, value in kwargs.items()
    }


def _refuse_foreign_estimator(name: str, estimator: Any) -> None:
    """Refuse an estimator that fits another kind of problem (its ``problem_type``) than task ``name``'s
    study builds, naming the task that builds it.

    A plugin written before ``problem_type`` existed may still declare its task by name
    (``task = "rollout"``): that is honoured, with a ``DeprecationWarning``.
    """
    plugin = estimator.get(NAME_KEY) if isinstance(estimator, Mapping) else None
    if plugin is None:
        return
    from idkit import registry
    from idkit.interfaces import problem_type

    try:
        cls = registry.load("estimator", plugin)
    except registry.PluginError:
        return  # the study's build reports it
    legacy = getattr(cls, "task", None)
    if isinstance(legacy, str) and problem_type(cls) is get_task("single").problem_type():
        warnings.warn(
            f"estimator {plugin}: the class attribute task = {legacy!r} is deprecated; declare the kind of "
            "problem it fits instead (problem_type = ..., idkit.interfaces.Estimator)",
            DeprecationWarning,
            stacklevel=2,
        )
        own = [legacy] if legacy in TASKS else []
    else:
        accepts = problem_type(cls)
        if issubclass(get_task(name).problem_type(), accepts):
            return
        own = [task for task in TASKS if issubclass(get_task(task).problem_type(), accepts)]
    if name not in own:
        if not own:
            raise ValueError(f"estimator={plugin} fits problems that no task of the command line builds")
        raise ValueError(
            f"estimator={plugin} runs in the {own[0]} task, not the {name} task: idkit +experiment={own[0]} …"
        )


def _setting(task: Task, key: str, section: Mapping[str, Any]) -> str:
    """The key as the user wrote it: ``paper.costs`` for a section key, ``seed`` at the top."""
    return f"{task.section}.{key}" if key in section else key
