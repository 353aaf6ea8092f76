"""Estimate labels from registry names and options: ``PSO-f13``, ``PSO-huber(relative)``, ``LS-rel``.

A label is what tables, plots and ``result.json`` call an estimate, so it must say what ran and be
unique within a study. It is derived from the specs, not from class names:

* the estimator's registry name, its first word upper-cased (``pso`` → ``PSO``, ``pso_f13_f14`` →
  ``PSO-f13-f14``), then ``-rel`` when its ``relative`` option is on (the paper's ``LS-rel``);
* for an estimator that searches a cost (it has ``fit_costs``): ``-`` and the cost's registry name,
  with the cost's options that differ from their defaults in brackets (``huber(relative)``,
  ``huber(delta=2.0)``).

Two specs that give the same label are told apart by the estimator's own non-default options
(``PSO(runs=4)-f1``); if they are still equal, :func:`unique_labels` raises.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from idkit import registry
from idkit.studies.build import Spec, constructor_options, name_and_options

#: Estimator options shown in the label itself (``-rel``), never in brackets.
_IN_NAME = ("relative",)


def _defaults(kind: registry.Kind, name: str | None) -> dict[str, Any]:
    return {} if name is None else constructor_options(registry.load(kind, name))


def _changed(kind: registry.Kind, name: str | None, options: Mapping[str, Any]) -> dict[str, Any]:
    """Options that differ from the constructor's defaults."""
    defaults = _defaults(kind, name)
    return {k: v for k, v in options.items() if k not in defaults or defaults[k] != v}


def _brackets(options: Mapping[str, Any]) -> str:
    parts = [k if v is True else f"no-{k}" if v is False else f"{k}={v}" for k, v in options.items()]
    return f"({', '.join(parts)})" if parts else ""


def _display(name: str) -> str:
    head, *rest = name.split("_")
    return "-".join([head.upper(), *rest])


def searches_cost(estimator: Any) -> bool:
    """Whether an estimator minimises the problem's cost (so the cost belongs in its label)."""
    return callable(getattr(estimator, "fit_costs", None))


def cost_label(cost: Spec) -> str:
    """``f13``, ``huber(relative)``: the cost's registry name and its non-default options."""
    name, options = name_and_options("cost", cost)
    if name is None:
        return type(cost).__name__
    return name + _brackets(_changed("cost", name, options))


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
    name, options = name_and_options("estimator", estimator)
    if name is None:  # a ready object: its own short name if it declares one
        own = getattr(estimator, "label", None)
        label = own if isinstance(own, str) and "{" not in own else type(estimator).__name__
        relative = bool(getattr(estimator, "relative", False))
    else:
        label = _display(name)
        changed = _changed("estimator", name, options)
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
