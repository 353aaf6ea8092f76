"""Shared pieces of the conformance suite: the failure type, how checks report, plugin options.

Every check is a plain function ``check_*(plugin, ...) -> None`` that raises ``ConformanceError``
(an ``AssertionError``, so pytest shows it as a test failure) whose message starts with the check's
name and the plugin's class and says what broke, what was expected and what came back.
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable, Sequence
from typing import Any, NoReturn, TypeVar

import torch
from torch import Tensor

from idkit.hyperparameters import get_params
from idkit.options import OptionError, check_options

#: Leading batch shapes every batched method must accept (BoTorch's mix-ins use the same three).
BATCH_SHAPES: tuple[tuple[int, ...], ...] = ((), (2,), (2, 3))

#: Dtypes every tensor method must accept and preserve.
DTYPES: tuple[torch.dtype, ...] = (torch.float64, torch.float32)

#: Relative tolerance of "equal up to round-off" per dtype.
RTOL = {torch.float64: 1e-9, torch.float32: 1e-4}

F = TypeVar("F", bound=Callable[..., None])


class ConformanceError(AssertionError):
    """A plugin breaks the idkit plugin contract; the message names the check and what broke."""


def label(plugin: Any) -> str:
    """``module.Class`` of a plugin instance, the name a plugin author searches for."""
    cls = type(plugin)
    return f"{cls.__module__}.{cls.__qualname__}"


def fail(message: str) -> NoReturn:
    __tracebackhide__ = True
    raise ConformanceError(message)


def conformance_check(func: F) -> F:
    """Prefix a check's failures with its name and the plugin's class."""

    @functools.wraps(func)
    def wrapper(plugin: Any, *args: Any, **kwargs: Any) -> None:
        __tracebackhide__ = True  # pytest: show the failing check, not this wrapper
        try:
            func(plugin, *args, **kwargs)
        except ConformanceError as err:
            message = f"{func.__name__} failed for {label(plugin)}: {err}"
            raise ConformanceError(message).with_traceback(err.__traceback__) from err.__cause__

    return wrapper  # type: ignore[return-value]  # wraps() keeps func's signature; F cannot say so


def call(description: str, function: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """Call plugin code on VALID input; any exception becomes a failure that names the call."""
    try:
        return function(*args, **kwargs)
    except ConformanceError:
        raise
    except Exception as exc:
        raise ConformanceError(f"{description} raised {type(exc).__name__} on valid input: {exc}") from exc


def shape_str(name: str, shape: Sequence[int]) -> str:
    return f"{name}[{', '.join(str(s) for s in shape)}]"


def expect_tensor(value: Any, what: str, shape: Sequence[int], dtype: torch.dtype) -> Tensor:
    """Fail unless ``value`` is a finite tensor of exactly ``shape`` and ``dtype``."""
    if not isinstance(value, Tensor):
        fail(f"{what} must return a torch.Tensor, got {type(value).__name__}")
    if tuple(value.shape) != tuple(shape):
        fail(f"{what} returned shape {tuple(value.shape)}, expected {tuple(shape)}")
    if value.dtype != dtype:
        fail(f"{what} returned dtype {value.dtype}, expected {dtype} (the input dtype must be preserved)")
    bad = ~torch.isfinite(value)
    if bad.any():
        index = tuple(int(i) for i in bad.nonzero()[0])
        fail(f"{what} returned a non-finite value {value[index].item()} at index {index} on valid input")
    return value


def expect_close(actual: Tensor, expected: Tensor, what: str, rtol: float) -> None:
    """Fail unless ``|actual - expected| <= rtol * (|expected| + max|expected|)`` everywhere."""
    if actual.shape != expected.shape:
        fail(f"{what}: shapes differ, {tuple(actual.shape)} vs {tuple(expected.shape)}")
    actual, expected = actual.detach().double(), expected.detach().double()
    scale = expected.abs().max().clamp_min(1e-300)
    gap = (actual - expected).abs()
    limit = rtol * (expected.abs() + scale)
    if (gap > limit).any():
        worst = int((gap - limit).flatten().argmax())
        index = tuple(int(i) for i in torch.unravel_index(torch.tensor(worst), gap.shape))
        fail(
            f"{what}: worst mismatch at index {index}: {actual[index].item()!r} vs "
            f"{expected[index].item()!r} "
            f"(largest difference {gap.max().item():.3g}, relative tolerance {rtol:g})"
        )


def expect_raises(what: str, function: Callable[..., Any], *args: Any, fix: str) -> None:
    """Fail if ``function(*args)`` returns instead of raising ValueError/RuntimeError/IndexError."""
    try:
        result = function(*args)
    except (ValueError, RuntimeError, IndexError):
        return
    except Exception as exc:
        fail(f"{what} raised {type(exc).__name__} ({exc}); expected ValueError. {fix}")
    shape = tuple(result.shape) if isinstance(result, Tensor) else type(result).__name__
    fail(f"{what} returned {shape} instead of raising an error. {fix}")


# --- hyperparameters (scikit-learn's contract) -------------------------------------------------


def same(a: Any, b: Any) -> bool:
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    try:
        return bool(a == b) or (a is b)
    except Exception:  # e.g. tensors of different shapes
        return a is b


@conformance_check
def check_hyperparameters(plugin: Any, *_: Any) -> None:
    """Constructor options are explicit keyword arguments with defaults, stored unchanged.

    This is what lets a config section (and the command line, ``estimator.weight=tukey``) map
    one-to-one onto a constructor call, and what lets a run be rebuilt from its record. Defaults
    and the plugin's values must fit the options' annotations, which the registry enforces.
    (Further arguments, such as an estimator check's problem factory, are ignored.)
    """
    cls = type(plugin)
    signature = inspect.signature(cls)
    for p in signature.parameters.values():
        if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            fail(
                f"__init__ takes {'*' if p.kind is p.VAR_POSITIONAL else '**'}{p.name}; every option "
                "must be an explicit keyword argument so that configs can list and override it"
            )
        if p.kind is p.POSITIONAL_ONLY:
            fail(f"__init__ option {p.name!r} is positional-only; it must be passable by keyword")
        if p.default is p.empty:
            fail(f"__init__ option {p.name!r} has no default; every option needs one")
        if not hasattr(plugin, p.name):
            fail(
                f"__init__ option {p.name!r} is not stored as attribute self.{p.name}; store every "
                "option unchanged under its own name (scikit-learn style)"
            )
    fresh = call(f"{cls.__name__}() with default options", cls)
    for name, p in signature.parameters.items():
        if not same(getattr(fresh, name), p.default):
            fail(
                f"{cls.__name__}() stores self.{name} = {getattr(fresh, name)!r} but the default is "
                f"{p.default!r}; store options unchanged (derive other values in other attributes)"
            )
    params = get_params(plugin)
    defaults = {name: p.default for name, p in signature.parameters.items()}
    for what, values in (("default", defaults), ("configured value", params)):
        try:
            check_options("plugin", cls.__name__, cls, values)
        except OptionError as exc:
            fail(
                f"a {what} does not fit its own annotation, so the registry would refuse it: {exc}; "
                "annotate options with the types they take (idkit.options)"
            )
    clone = call(f"{cls.__name__}(**get_params(plugin))", cls, **params)
    for name, value in get_params(clone).items():
        if not same(value, params[name]):
            fail(f"rebuilding from its own options changed self.{name}: {params[name]!r} -> {value!r}")


def options_for_checks(factory: Any) -> dict[str, Any]:
    """Options the conformance suite builds a plugin with: its ``conformance_options`` or none.

    A plugin class may declare ``conformance_options: ClassVar[dict] = {...}`` — cheap settings
    (few iterations, few particles) under which the suite's fits take milliseconds. It is used
    only by ``check_plugin`` / ``build_for_checks``, never by the command line or experiments.
    """
    options = getattr(factory, "conformance_options", None) or {}
    if not isinstance(options, dict):
        raise TypeError(f"{factory!r}.conformance_options must be a dict, got {type(options).__name__}")
    return dict(options)
