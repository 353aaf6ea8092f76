"""Estimate labels from specs — registry names and options: ``PSO-f13``, ``PSO-huber(relative)``, ``LS-rel``.

A label is what tables, plots and ``result.json`` call an estimate, so it must say what ran and be
unique within a study. It comes from the spec alone, never from a class's own ``label`` or ``name``,
so a ready object and the config that builds it get one label:

* a name or mapping spec is a registry name and options; a ready object is read back into one:
  the name an installed distribution registers its class under, and its
  constructor's options as the object stores them (the plugin contract: every hyperparameter an
  attribute of the same name). An object of a class no distribution registers (a subclass in a
  script) has no registry name, and its class name stands in for one;
* the estimator's registry name, its first word upper-cased (``pso`` → ``PSO``, ``pso_f13_f14`` →
  ``PSO-f13-f14``; a class name as it is), then ``-rel`` when its ``relative`` option is on (the
  paper's ``LS-rel``);
* for an estimator that searches a cost (:class:`~idkit.interfaces.CostSearcher`): ``-`` and the
  cost's name, with the cost's options that differ from their defaults in brackets
  (``huber(relative)``, ``huber(delta=2.0)``).

Two specs that give the same label are told apart by the estimator's own non-default options
(``PSO(runs=4)-f1``); if they are still equal, :func:`unique_labels` raises.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from idkit import registry
from idkit.hyperparameters import get_params
from idkit.studies.build import Spec, constructor_options, name_and_options

#: Estimator options shown in the label itself (``-rel``), never in brackets.
_IN_NAME = ("relative",)


def registered_name(kind: registry.Kind, cls: type) -> str | None:
    """The name ``cls`` is registered under in ``kind``'s entry points, or ``None`` (imports nothing)."""
    target = f"{cls.__module__}:{cls.__qualname__}"
    found = [name for name in registry.available(kind) if registry.info(kind, name).value == target]
    return found[0] if found else None


def _read(kind: registry.Kind, spec: Spec) -> tuple[str | None, str, dict[str, Any], Any]:
    """``(registry name, name, options, factory)`` of a spec: a ready object is read back, and the
    name of an unregistered one is its class name (module docstring)."""
    name, options = name_and_options(kind, spec)
    if name is not None:
        return name, name, options, registry.load(kind, name)
    cls = type(spec)
    registered = registered_name(kind, cls)
    return registered, registered or cls.__name__, get_params(spec), cls


def _changed(kind: registry.Kind, spec: Spec) -> tuple[str | None, str, dict[str, Any]]:
    """The spec's registry name, name and options that differ from the constructor's defaults."""
    registered, name, options, factory = _read(kind, spec)
    defaults = constructor_options(factory)
    return registered, name, {k: v for k, v in options.items() if k not in defaults or defaults[k] != v}


def _brackets(options: Mapping[str, Any]) -> str:
    parts = [k if v is True else f"no-{k}" if v is False else f"{k}={v}" for k, v in options.items()]
    return f"({', '.join(parts)})" if parts else ""


def _display(name: str) -> str:
    head, *rest = name.split("_")
    return "-".join([head.upper(), *rest])


def cost_label(cost: Spec) -> str:
    """``f13``, ``huber(relative)``: the cost's name and its non-default options."""
    _, name, changed = _changed("cost", cost)
    return name + _brackets(changed)


def estimator_label(
    estimator: Spec, cost: Spec | None = None, *, with_cost: bool = False, all_options: bool = False
) -> str:
    """The label of ``estimator`` (fitted on ``cost`` when ``with_cost``), see the module docstring.

    Args:
        estimator, cost: specs (registry name, mapping or ready object).
        with_cost: append the cost (the estimator searches it).
        all_options: also bracket the estimator's other non-default options (to tell apart two
            specs of one estimator).
    """
    registered, name, changed = _changed("estimator", estimator)
    label = name if registered is None else _display(name)
    relative = bool(changed.pop("relative", False))
    if all_options:
        label += _brackets({k: v for k, v in changed.items() if k not in _IN_NAME})
    if relative:
        label += "-rel"
    if with_cost and cost is not None:
        label += "-" + cost_label(cost)
    return label


def unique_labels(specs: Sequence[tuple[Spec, Spec | None, bool]], where: str) -> list[str]:
    """Labels of ``(estimator, cost, with_cost)`` specs, made unique or refused.

    Raises:
        ValueError: two specs are the same estimator with the same options and cost.
    """
    short = [estimator_label(e, c, with_cost=w) for e, c, w in specs]
    labels = [
        estimator_label(e, c, with_cost=w, all_options=short.count(label) > 1)
        for (e, c, w), label in zip(specs, short, strict=True)
    ]
    seen: set[str] = set()
    for label in labels:
        if label in seen:
            raise ValueError(f"{where}: two estimators would both be labelled {label!r}; drop one of them")
        seen.add(label)
    return labels
