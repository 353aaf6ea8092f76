"""Check plugin options (and plain settings such as ``seed``) against their type annotations.

A plugin's options are its constructor's keyword arguments, so their annotations are the schema:
``registry.create`` checks every option here *before* the constructor runs, and a typo or a value
of the wrong type fails with one line naming the plugin, the option, the value and the expected
type — not mid-fit, and never silently (``relative="maybe"`` is truthy and would change the run).

The rule: **a value is accepted if it already has the annotated type, or if it is a string (what
a command line passes) that spells a value of that type exactly.** In detail:

========================  =====================================================================
annotation                accepted
========================  =====================================================================
``int``                   an integer (not a bool); a whole float (``40.0`` → 40); a string of a
                          whole number (``"40"``, ``"1e3"``). ``1.5``, ``"abc"``, ``True``: error.
``float``                 an int or float (not a bool); a string of a number (``"0.5"``,
                          ``"inf"``). NaN in any form: error.
``bool``                  ``True``/``False``; the ints 0 and 1; the strings true/false, yes/no,
                          1/0 (any case). ``"maybe"``, ``2``, ``0.5``: error.
``str``                   a string; an int or float is written as its string (a command line
                          reads ``label=2024`` as a number). A bool: error.
``Literal[a, b]``         one of the choices (after the conversions above for the choice's type).
``X | None``              ``None``, or a value accepted for ``X``.
``X | Y``                 the first member the value already has; else the first that converts.
``Sequence[X]``,          a list or tuple (not a string) whose items are accepted for ``X``;
``list[X]``,              a fixed ``tuple[X, Y]`` also needs the right length.
``tuple[X, ...]``
``Mapping[K, V]``         a mapping whose keys and values are accepted for ``K`` and ``V``.
an ``Enum``               a member, or a member's name or value.
any other class           an instance of it.
``Any``, none, or an      anything (the constructor has the last word).
unresolvable annotation
========================  =====================================================================

``None`` is also accepted where the default is ``None`` (a common ``x: float = None`` slip). Values
that pass are handed over converted (``"40"`` → ``40``); range checks (``particles >= 1``) stay
with the plugin, which knows its own limits.
"""

from __future__ import annotations

import collections.abc
import difflib
import enum
import functools
import inspect
import math
import numbers
import types
import typing
from collections.abc import Callable, Mapping
from typing import Any

_TRUE = frozenset({"true", "yes", "1"})
_FALSE = frozenset({"false", "no", "0"})


class OptionError(ValueError, TypeError):
    """An option or setting has an unknown name or a value of the wrong type.

    Both a ``ValueError`` and a ``TypeError`` (as scikit-learn's ``InvalidParameterError``), so
    callers that caught the constructor's ``TypeError`` for an unknown keyword still catch it.
    """


class _Rejected(Exception):
    """Internal: ``value`` does not fit one annotation; ``hint`` says why, for the message."""

    def __init__(self, hint: str = "") -> None:
        super().__init__(hint)
        self.hint = hint


# --- the public functions ----------------------------------------------------------------------


def check_options(
    kind: str, name: str, factory: Callable[..., Any], options: Mapping[str, Any]
) -> dict[str, Any]:
    """The options of plugin ``kind``/``name`` checked against ``factory``'s signature, converted.

    Args:
        kind: ``"robot"``, ``"estimator"`` or ``"cost"`` (for the message).
        name: the plugin's registry name (for the message).
        factory: the class or function the registry calls with ``**options``.
        options: keyword arguments for ``factory``.

    Raises:
        OptionError: an option the factory does not take (the message lists its options, the
            closest first), or a value its annotation rejects (see the module docstring).
    """
    where = f"{kind} {name!r}"
    parameters = _parameters(factory)
    if parameters is None:  # no readable signature: the factory has the last word
        return dict(options)
    takes_any = any(p.kind is p.VAR_KEYWORD for p in parameters.values())
    keywords = [k for k, p in parameters.items() if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    hints = _annotations(factory)
    checked: dict[str, Any] = {}
    for option, value in options.items():
        if option not in keywords:
            if takes_any:
                checked[option] = value
                continue
            close = difflib.get_close_matches(option, keywords, n=len(keywords), cutoff=0.0)
            listed = ", ".join(close) if close else "none"
            raise OptionError(f"{where} has no option {option!r}; its options (closest first): {listed}")
        default = parameters[option].default
        checked[option] = _check(f"{where} option {option!r}", value, hints.get(option, Any), default)
    return checked


def check_setting(name: str, value: Any, annotation: Any) -> Any:
    """A plain setting (``seed``, ``plots``) checked against ``annotation`` by the same rule, converted.

    Example: ``check_setting("seed", "7", int)`` returns ``7``; ``check_setting("plots", "maybe",
    bool)`` raises ``OptionError: setting 'plots' must be a bool (true/false, yes/no or 1/0), got
    'maybe' (str)``.
    """
    return _check(f"setting {name!r}", value, annotation, inspect.Parameter.empty)


def describe(annotation: Any, article: bool = True) -> str:
    """A short readable form of an annotation: ``an int or None``, ``a list of float``, ``'a' or 'b'``."""
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if annotation is Any or annotation is inspect.Parameter.empty:
        return "anything"
    if annotation is type(None) or annotation is None:
        return "None"
    if origin is typing.Annotated:
        return describe(args[0], article)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(describe(a, article) for a in args)
    if origin is typing.Literal:
        return " or ".join(repr(a) for a in args)
    if origin is tuple and args and args[-1] is not Ellipsis:
        return f"a list of {len(args)} ({', '.join(describe(a, False) for a in args)})"
    if origin in _SEQUENCES:
        return f"a list of {describe(args[0], False)}" if args else "a list"
    if origin in _MAPPINGS:
        return (
            f"a mapping of {describe(args[0], False)} to {describe(args[1], False)}" if args else "a mapping"
        )
    if annotation is bool and article:
        return "a bool (true/false, yes/no or 1/0)"
    if annotation in (int, float, str) and article:
        return {int: "an int", float: "a float", str: "a str"}[annotation]
    if isinstance(annotation, type):
        return annotation.__name__
    return str(annotation)


# --- reading a factory's signature -----------------------------------------------------------


def _parameters(factory: Callable[..., Any]) -> Mapping[str, inspect.Parameter] | None:
    try:
        return inspect.signature(factory).parameters
    except (TypeError, ValueError):  # builtins and C extensions without a signature
        return None


@functools.cache
def _annotations(factory: Callable[..., Any]) -> dict[str, Any]:
    """Each parameter's annotation, evaluated; one that cannot be evaluated is left out (unchecked).

    ``typing.get_type_hints`` fails as a whole when one annotation names a ``TYPE_CHECKING``-only
    import, so annotations are evaluated one by one in the function's module.
    """
    function = factory.__init__ if isinstance(factory, type) else factory
    function = inspect.unwrap(function)
    raw = getattr(function, "__annotations__", {})
    namespace = getattr(function, "__globals__", {})
    hints: dict[str, Any] = {}
    for key, annotation in raw.items():
        if key == "return":
            continue
        if isinstance(annotation, str):
            try:
                annotation = eval(annotation, namespace)  # noqa: S307  (the plugin's own source)
            except Exception:
                continue
        hints[key] = annotation
    return hints


# --- checking one value ----------------------------------------------------------------------

_SEQUENCES = (list, tuple, collections.abc.Sequence, collections.abc.MutableSequence)
_MAPPINGS = (dict, collections.abc.Mapping, collections.abc.MutableMapping)


def _check(where: str, value: Any, annotation: Any, default: Any) -> Any:
    if value is None and default is None:
        return None
    try:
        return _convert(value, annotation)
    except _Rejected as rejected:
        hint = f"; {rejected.hint}" if rejected.hint else ""
        raise OptionError(
            f"{where} must be {describe(annotation)}, got {value!r} ({type(value).__name__}){hint}"
        ) from None


def _convert(value: Any, annotation: Any) -> Any:
    """``value`` converted to fit ``annotation``, or ``_Rejected``."""
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if annotation is Any or annotation is inspect.Parameter.empty or isinstance(annotation, typing.TypeVar):
        return value
    if annotation is None or annotation is type(None):
        if value is None:
            return None
        raise _Rejected()
    if origin is typing.Annotated:
        return _convert(value, args[0])
    if origin in (typing.Union, types.UnionType):
        return _convert_union(value, args)
    if origin is typing.Literal:
        return _convert_literal(value, args)
    if origin in _SEQUENCES or annotation in _SEQUENCES:
        return _convert_sequence(value, origin or annotation, args)
    if origin in _MAPPINGS or annotation in _MAPPINGS:
        return _convert_mapping(value, args)
    if annotation in _SCALARS:
        return _SCALARS[annotation](value)
    if isinstance(annotation, type) and issubclass(annotation, enum.Enum):
        return _convert_enum(value, annotation)
    if isinstance(annotation, type):
        try:
            if isinstance(value, annotation):
                return value
        except TypeError:  # e.g. a Protocol that is not runtime-checkable
            return value
        raise _Rejected()
    return value  # Callable[...], type[...], forward references: not checked


def _is_instance(value: Any, annotation: Any) -> bool:
    """Whether ``value`` fits ``annotation`` as it is, without conversion (picks a union member)."""
    if annotation in _EXACT:
        return _EXACT[annotation](value)
    try:
        return _convert(value, annotation) is value
    except _Rejected:
        return False


def _convert_union(value: Any, members: tuple[Any, ...]) -> Any:
    for member in members:  # a member the value already is wins: "1" stays a str in `int | str`
        if _is_instance(value, member):
            return value
    hints = []
    for member in members:
        try:
            return _convert(value, member)
        except _Rejected as rejected:
            if rejected.hint:
                hints.append(rejected.hint)
    raise _Rejected("; ".join(hints))


def _convert_literal(value: Any, choices: tuple[Any, ...]) -> Any:
    for choice in choices:
        try:
            if _SCALARS.get(type(choice), lambda v: v)(value) == choice:
                return choice
        except _Rejected:
            continue
    if isinstance(value, str):
        names = [c for c in choices if isinstance(c, str)]
        close = difflib.get_close_matches(value, names, n=len(names), cutoff=0.0)
        if close:
            raise _Rejected(f"closest: {', '.join(repr(c) for c in close)}")
    raise _Rejected()


def _convert_sequence(value: Any, container: Any, args: tuple[Any, ...]) -> Any:
    if isinstance(value, (str, bytes)) or not isinstance(value, collections.abc.Sequence):
        raise _Rejected("give a list, e.g. [1, 2]")
    items = list(value)
    if container is tuple and args and args[-1] is not Ellipsis:
        if len(items) != len(args):
            raise _Rejected(f"needs {len(args)} items, got {len(items)}")
        kinds = list(args)
    else:
        kinds = [args[0] if args else Any] * len(items)
    converted = []
    for index, (item, kind) in enumerate(zip(items, kinds, strict=True)):
        try:
            converted.append(_convert(item, kind))
        except _Rejected as rejected:
            hint = f" ({rejected.hint})" if rejected.hint else ""
            raise _Rejected(f"item {index} = {item!r} is not {describe(kind, False)}{hint}") from None
    if all(a is b for a, b in zip(converted, items, strict=True)):
        return value
    return tuple(converted) if isinstance(value, tuple) else converted


def _convert_mapping(value: Any, args: tuple[Any, ...]) -> Any:
    if not isinstance(value, collections.abc.Mapping):
        raise _Rejected()
    key_type, value_type = args if args else (Any, Any)
    converted = {}
    for key, item in value.items():
        try:
            converted[_convert(key, key_type)] = _convert(item, value_type)
        except _Rejected as rejected:
            hint = f" ({rejected.hint})" if rejected.hint else ""
            raise _Rejected(f"entry {key!r}: {item!r} is not {describe(value_type, False)}{hint}") from None
    return value if all(converted.get(k) is v for k, v in value.items()) else converted


def _convert_enum(value: Any, annotation: type[enum.Enum]) -> Any:
    if isinstance(value, annotation):
        return value
    for member in annotation:
        if value in (member.name, member.value):
            return member
    names = [m.name for m in annotation]
    raise _Rejected(f"the choices are {', '.join(names)}")


def _to_int(value: Any) -> int:
    if isinstance(value, bool):
        raise _Rejected()
    if isinstance(value, numbers.Integral):
        return value  # type: ignore[return-value]
    if not isinstance(value, (str, numbers.Real)):
        raise _Rejected()
    if isinstance(value, str):
        try:
            return int(value.strip())  # exact for any size, where a float would round
        except ValueError:
            pass
    number = _to_float(value)
    if not (math.isfinite(number) and float(number).is_integer()):
        raise _Rejected("not a whole number")
    return int(number)


def _to_float(value: Any) -> float:
    if isinstance(value, bool):
        raise _Rejected()
    if isinstance(value, numbers.Real):
        number = value
    elif isinstance(value, str):
        try:
            number = float(value.strip())
        except ValueError:
            raise _Rejected("not a number") from None
    else:
        raise _Rejected()
    if math.isnan(number):
        raise _Rejected("NaN is never a valid option")
    return number  # type: ignore[return-value]


def _to_bool(value: Any) -> bool:
    if isinstance(value, bool):
        return value
    text = str(value).strip().lower() if isinstance(value, (str, numbers.Integral)) else None
    if text in _TRUE:
        return True
    if text in _FALSE:
        return False
    raise _Rejected("other strings would silently count as true")


def _to_str(value: Any) -> str:
    if isinstance(value, str):
        return value
    if isinstance(value, numbers.Real) and not isinstance(value, bool):
        return str(value)
    raise _Rejected()


_SCALARS: dict[Any, Callable[[Any], Any]] = {int: _to_int, float: _to_float, bool: _to_bool, str: _to_str}

#: Values a scalar annotation takes as they are (an int is a float, a bool is not an int).
_EXACT: dict[Any, Callable[[Any], bool]] = {
    int: lambda v: isinstance(v, numbers.Integral) and not isinstance(v, bool),
    float: lambda v: isinstance(v, numbers.Real) and not isinstance(v, bool) and not math.isnan(v),
    bool: lambda v: isinstance(v, bool),
    str: lambda v: isinstance(v, str),
}
