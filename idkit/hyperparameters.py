"""scikit-learn's estimator contract, for idkit's plugins: hyperparameters stored unchanged, checked by one
function at construction and again at every fit, read back with ``get_params``, changed with
``set_params`` (or by assigning the attribute).

The pattern, which every built-in estimator follows (``idkit.interfaces.Estimator`` inherits
:class:`Hyperparameters`)::

    class MyEstimator(Estimator):
        def __init__(self, iterations: int = 100, tol: float = 1e-8) -> None:
            self.iterations = iterations  # every keyword stored unchanged, under its own name
            self.tol = tol
            self.resolve()  # a bad value is refused now, before any data are loaded

        def resolve(self) -> MySettings:
            \"\"\"The hyperparameters checked and derived: everything a fit reads.\"\"\"
            if self.iterations < 1:
                raise ValueError(f"my_estimator: iterations must be >= 1, got {self.iterations!r}")
            return MySettings(self.iterations, float(self.tol))

        def fit(self, problem):
            settings = self.resolve()  # from the attributes as they are now
            ...

So ``e = MyEstimator(iterations=8); e.iterations = 40`` runs 40 (a derived value computed in
``__init__`` would silently keep 8), a bad assignment is refused by the next ``fit`` (or at once by
``set_params``), and ``MyEstimator(**e.get_params())`` rebuilds ``e``. The conformance suite
(``idkit.testing``) checks all three.
"""

from __future__ import annotations

import inspect
from typing import Any, TypeVar

P = TypeVar("P", bound="Hyperparameters")


def hyperparameter_names(cls: type) -> list[str]:
    """The keyword arguments of ``cls``'s constructor (``*args``/``**kwargs`` and positional-only ones
    are not hyperparameters); none for a class whose signature cannot be read."""
    try:
        parameters = inspect.signature(cls).parameters.values()
    except (TypeError, ValueError):  # builtins without a signature
        return []
    keyword = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    return [p.name for p in parameters if p.kind in keyword]


def get_params(plugin: Any) -> dict[str, Any]:
    """A plugin's hyperparameters ``{name: value}``, read from the attributes they are stored in.

    Raises:
        AttributeError: an option the plugin does not store under its own name (the contract).
    """
    values = {}
    for name in hyperparameter_names(type(plugin)):
        try:
            values[name] = getattr(plugin, name)
        except AttributeError:
            raise AttributeError(
                f"{type(plugin).__name__} does not store its option {name!r} as self.{name}; the plugin "
                "contract stores every constructor keyword unchanged under its own name"
            ) from None
    return values


def set_params(plugin: P, **values: Any) -> P:
    """Change hyperparameters of ``plugin`` as its constructor would take them; returns ``plugin``.

    Each value is checked against the option's annotation (and converted, as the registry does:
    :mod:`idkit.options`), then the plugin's ``resolve()`` checks the whole set. A refused call
    leaves the plugin as it was.

    Raises:
        idkit.options.OptionError: an unknown option (the message lists them, closest first) or a value
            its annotation rejects.
        ValueError: a value ``resolve()`` refuses (its message).
    """
    from idkit.options import check_options

    cls = type(plugin)
    checked = check_options("estimator" if hasattr(plugin, "fit") else "plugin", cls.__name__, cls, values)
    before = {name: getattr(plugin, name) for name in checked}
    changed = []
    try:
        for name, value in checked.items():
            setattr(plugin, name, value)  # a frozen plugin refuses here
            changed.append(name)
        plugin.resolve()
    except BaseException:
        for name in changed:
            setattr(plugin, name, before[name])
        raise
    return plugin


class Hyperparameters:
    """``get_params``, ``set_params`` and the ``resolve`` hook (module docstring)."""

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The hyperparameters ``{name: value}``: ``type(self)(**self.get_params())`` rebuilds this
        object. ``deep`` is accepted for scikit-learn's ``clone``; idkit's estimators nest none."""
        return get_params(self)

    def set_params(self: P, **values: Any) -> P:
        """Change hyperparameters, checked at once; returns ``self`` (:func:`set_params`)."""
        return set_params(self, **values)

    def resolve(self) -> Any:
        """The hyperparameters checked and resolved into what a fit reads, or ``ValueError`` naming the
        option at fault. Called by ``__init__`` (an early refusal) and by every ``fit`` (so that a
        changed attribute counts). The default checks nothing and resolves to ``None``."""
        return None
