"""Check plugin options (and plain settings such as ``seed``) against their type annotations.

A plugin's options are its constructor's keyword arguments, so their annotations are the schema:
``registry.create`` checks every option here *before* the constructor runs, and a typo or a value
of the wrong type fails with one line naming the plugin, the option, the value and the expected
type — not mid-fit, and never silently (``relative="maybe"`` is truthy and would change the run).

The rule is pydantic's **lax mode** (``pydantic.TypeAdapter(annotation).validate_python``): a
value is accepted if it has the annotated type or converts to it by pydantic's conversion table
(https://docs.pydantic.dev/latest/concepts/conversion_table/), which is what a command line needs —
it passes strings and YAML scalars. The cases that matter here:

========================  =====================================================================
annotation                accepted
========================  =====================================================================
``int``                   an int; a whole float (``40.0`` → 40); a string of a whole number
                          (``"40"``, ``" 40 "``, ``"40.0"``); a bool (``True`` → 1).
                          ``1.5``, ``"abc"``, ``"1e3"``: error.
``float``                 an int or float; a string of a number (``"0.5"``, ``"inf"``).
                          NaN in any form: error (idkit's rule on top of pydantic's).
``bool``                  ``True``/``False``; 0 and 1; the strings true/false, yes/no, on/off,
                          y/n, t/f, 1/0 (any case). ``"maybe"``, ``2``: error.
``str``                   a string; an int or float is written as its string (a command line
                          reads ``label=2024`` as a number; pydantic's ``coerce_numbers_to_str``).
                          A bool: error.
``idkit.seeds.Seed``      an integer in [0, 2**64) (numpy integers too); a string of digits.
                          A bool, any float (``1e3`` is not rounded), ``-1``, ``2**64``: error.
``Literal[a, b]``         one of the choices, exactly (the message lists them closest first).
``X | None``, ``X | Y``   a value already of a member's type wins (``"1"`` stays a str in
                          ``int | str``); else the first member it converts to.
``Sequence[X]``,          a list or tuple (not a string) whose items are accepted for ``X``;
``list[X]``, ``tuple``    a fixed ``tuple[X, Y]`` needs the right length and becomes a tuple.
``Mapping[K, V]``         a mapping whose keys and values are accepted for ``K`` and ``V``.
an ``Enum``               a member or a member's value.
any other class           an instance of it.
``Any``, none, or an      anything (the constructor has the last word): so is an annotation
unresolvable annotation   pydantic cannot build a validator for (a non-runtime Protocol).
========================  =====================================================================

``None`` is also accepted where the default is ``None`` (a common ``x: float = None`` slip). Values
that pass are handed over converted (``"40"`` → ``40``). Range checks stay with the plugin, or in
its annotation: ``particles: Annotated[int, annotated_types.Ge(1)]`` is enforced here too.
"""

from __future__ import annotations

import collections.abc
import dataclasses
import difflib
import functools
import inspect
import math
import types
import typing
from collections.abc import Callable, Mapping
from typing import Any

if typing.TYPE_CHECKING:
    from pydantic import TypeAdapter
    from pydantic_core import ErrorDetails


class OptionError(ValueError, TypeError):
    """An option or setting has an unknown name or a value of the wrong type.

    Both a ``ValueError`` and a ``TypeError`` (as scikit-learn's ``InvalidParameterError``), so
    callers that caught the constructor's ``TypeError`` for an unknown keyword still catch it.
    """


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
    hints = type_hints(factory)
    checked: dict[str, Any] = {}
    for option, value in options.items():
        if option not in keywords:
            if takes_any:
                checked[option] = value
                continue
            listed = ", ".join(closest_first(option, keywords)) or "none"
            raise OptionError(f"{where} has no option {option!r}; its options (closest first): {listed}")
        default = parameters[option].default
        checked[option] = _check(f"{where} option {option!r}", value, hints.get(option, Any), default)
    return checked


def check_setting(name: str, value: Any, annotation: Any, default: Any = inspect.Parameter.empty) -> Any:
    """A plain setting (``seed``, ``plots``) checked against ``annotation`` by the same rule, converted.

    Example: ``check_setting("seed", "7", int)`` returns ``7``; ``check_setting("plots", "maybe",
    bool)`` raises ``OptionError: setting 'plots' must be a bool (true/false, yes/no, on/off or
    1/0), got 'maybe' (str); input should be a valid boolean, unable to interpret input``.
    ``default``: a ``None`` default also accepts ``None``. A setting annotated with a dataclass (a
    config section such as ``preprocess``) given as a mapping is checked field by field
    (:func:`check_section`).
    """
    section = _dataclass_in(annotation)
    if section is not None and isinstance(value, Mapping):
        return check_section(name, section, value)
    return _check(f"setting {name!r}", value, annotation, default)


def check_section(name: str, cls: type, values: Mapping[str, Any]) -> Any:
    """The dataclass ``cls`` (a config section: ``preprocess``, ``recording``) from a mapping.

    Each key must be a field — a typo is named as ``name.key`` with the fields closest first, not
    reported later as whatever the misspelt value would have changed — and each value is checked
    against its field's annotation by the rule of the module docstring; the class's own
    ``__post_init__`` then checks ranges.

    Raises:
        OptionError: an unknown key or a value its annotation rejects.
        ValueError: what the class refuses.
    """
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    hints = typing.get_type_hints(cls)
    checked = {}
    for key, value in values.items():
        if key not in fields:
            listed = ", ".join(closest_first(str(key), fields))
            raise OptionError(f"{name} has no option {key!r}; its options (closest first): {listed}")
        default = fields[key].default
        checked[key] = _check(f"setting '{name}.{key}'", value, hints.get(key, Any), default)
    return cls(**checked)


def _dataclass_in(annotation: Any) -> type | None:
    """The dataclass ``annotation`` is, or the one member of a union (``Section | None``) that is one."""
    members = (
        typing.get_args(annotation)
        if typing.get_origin(annotation) in (typing.Union, types.UnionType)
        else (annotation,)
    )
    found = [m for m in members if isinstance(m, type) and dataclasses.is_dataclass(m)]
    return found[0] if len(found) == 1 else None


def positive_number(value: Any) -> bool:
    """Whether ``value`` is a finite number > 0 (a bool is not a number): a duration, period, rate or
    step of 0 divides by zero, a negative one runs backwards, an infinite one never ends."""
    return not isinstance(value, bool) and isinstance(value, (int, float)) and 0 < value < math.inf


def closest_first(word: str, names: typing.Iterable[str]) -> list[str]:
    """``names`` ordered by similarity to ``word`` (``difflib``), the closest first."""
    names = list(names)
    return difflib.get_close_matches(word, names, n=len(names), cutoff=0.0) if names else []


@functools.cache
def type_hints(function: Callable[..., Any]) -> dict[str, Any]:
    """Each parameter's annotation, evaluated; one that cannot be evaluated is left out (unchecked).

    ``typing.get_type_hints`` fails as a whole when one annotation names a ``TYPE_CHECKING``-only
    import, so annotations are evaluated one by one in the function's module. A class stands for
    its ``__init__``.
    """
    if isinstance(function, type):
        cls: type[Any] = function
        function = cls.__init__
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
        if Any in args:  # e.g. a plugin spec: a name, a mapping or a ready object
            return "anything"
        return " or ".join(describe(a, article) for a in args)
    if origin is typing.Literal:
        return " or ".join(repr(a) for a in args)
    if origin in _SEQUENCES or origin in _MAPPINGS:
        return _describe_container(origin, args)
    if annotation is bool and article:
        return "a bool (true/false, yes/no, on/off or 1/0)"
    if annotation in (int, float, str) and article:
        return {int: "an int", float: "a float", str: "a str"}[annotation]
    if isinstance(annotation, type):
        return annotation.__name__
    return str(annotation)


def _describe_container(origin: Any, args: tuple[Any, ...]) -> str:
    """:func:`describe` of a sequence or mapping type (``origin``) with its arguments."""
    if origin is tuple and args and args[-1] is not Ellipsis:
        return f"a list of {len(args)} ({', '.join(describe(a, False) for a in args)})"
    if origin in _SEQUENCES:
        return f"a list of {describe(args[0], False)}" if args else "a list"
    return f"a mapping of {describe(args[0], False)} to {describe(args[1], False)}" if args else "a mapping"


# --- checking one value ------------------------------------------------------------------------

_SEQUENCES = (list, tuple, collections.abc.Sequence, collections.abc.MutableSequence)
_MAPPINGS = (dict, collections.abc.Mapping, collections.abc.MutableMapping)
#: pydantic error types that only restate the expected type, which the message already names.
_RESTATED = {"literal_error", "enum", "is_instance_of", "none_required", "callable_type"}


def _parameters(factory: Callable[..., Any]) -> Mapping[str, inspect.Parameter] | None:
    try:
        return inspect.signature(factory).parameters
    except (TypeError, ValueError):  # builtins and C extensions without a signature
        return None


@functools.lru_cache(maxsize=512)
def _adapter(annotation: Any) -> TypeAdapter | None:
    """pydantic's lax-mode validator for ``annotation``; ``None`` if pydantic cannot build one.

    pydantic is imported here, on the first option checked, so ``idkit --help`` never pays for it.
    """
    from pydantic import ConfigDict, PydanticSchemaGenerationError, TypeAdapter
    from pydantic_core import SchemaError

    config = ConfigDict(coerce_numbers_to_str=True, arbitrary_types_allowed=True)
    try:
        return TypeAdapter(annotation, config=config)
    except (PydanticSchemaGenerationError, SchemaError, TypeError, NameError):
        return None


def _check(where: str, value: Any, annotation: Any, default: Any) -> Any:
    if value is None and default is None:
        return None
    if annotation is Any or annotation is inspect.Parameter.empty:
        return value
    try:
        adapter = _adapter(annotation)
    except TypeError:  # an unhashable annotation: not cached, not checked
        adapter = None
    if adapter is None:
        return value
    from pydantic import ValidationError

    got = f"got {value!r} ({type(value).__name__})"
    try:
        converted = adapter.validate_python(value)
    except ValidationError as error:
        hint = _hint(error.errors(include_url=False), value, annotation)
        raise OptionError(f"{where} must be {describe(annotation)}, {got}{hint}") from None
    nan = _nan_at(converted)
    if nan == "":
        raise OptionError(f"{where} must be {describe(annotation)}, {got}; NaN is never a valid option")
    if nan is not None:  # inside a list or mapping (a plugin spec): name the item, not the whole value
        raise OptionError(f"{where}: {nan} is NaN; NaN is never a valid option")
    return converted


def _hint(errors: collections.abc.Sequence[ErrorDetails], value: Any, annotation: Any) -> str:
    """``"; <why>"`` from pydantic's most specific error, or closest choices for a literal."""
    error = max(errors, key=lambda e: len(e["loc"]))
    if error["type"] in ("literal_error", "enum") and isinstance(value, str):
        choices = [c for c in _literal_choices(annotation) if isinstance(c, str)]
        close = closest_first(value, choices)
        return f"; closest: {', '.join(repr(c) for c in close)}" if close else ""
    if error["type"] in _RESTATED or (error["type"].endswith("_type") and len(error["loc"]) <= 1):
        return ""
    message = error["msg"][:1].lower() + error["msg"][1:]
    if error["loc"] and isinstance(error["loc"][-1], int):
        index = error["loc"][-1]
        sequence = value if isinstance(value, collections.abc.Sequence) else None
        item = f" = {sequence[index]!r}" if sequence is not None and index < len(sequence) else ""
        return f"; item {index}{item}: {message}"
    return f"; {message}"


def _literal_choices(annotation: Any) -> list[Any]:
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is typing.Literal:
        return list(args)
    if origin in (typing.Union, types.UnionType, typing.Annotated):
        return [c for a in args for c in _literal_choices(a)]
    return []


def _nan_at(value: Any) -> str | None:
    """Where ``value`` holds a NaN: ``""`` (it is one), ``"particles"``, ``"item 2"``, ``"betas item 0"``
    (nested), or ``None`` (nowhere)."""
    if isinstance(value, float):
        return "" if math.isnan(value) else None
    items: collections.abc.Iterable[tuple[Any, Any]]
    if isinstance(value, (list, tuple)):
        items = enumerate(value)
    elif isinstance(value, dict):
        items = value.items()
    else:
        return None
    for key, item in items:
        inner = _nan_at(item)
        if inner is not None:
            here = f"item {key}" if isinstance(value, (list, tuple)) else str(key)
            return f"{here} {inner}".strip()
    return None
