"""Plugin options and plain settings are checked against annotations before anything is built."""

from __future__ import annotations

import enum
import inspect
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Annotated, Literal, Protocol

import pytest
from annotated_types import Ge
from hypothesis import given
from hypothesis import strategies as st

from idkit import registry
from idkit.options import OptionError, check_options, check_setting

if TYPE_CHECKING:
    from idkit.interfaces import Cost


def test_wrong_types_name_plugin_option_value_and_type():
    cases = [
        (
            "estimator",
            "pso",
            "particles",
            "abc",
            "must be an int or None, got 'abc' (str); input should be "
            "a valid integer, unable to parse string as an integer",
        ),
        (
            "estimator",
            "pso",
            "particles",
            1.5,
            "must be an int or None, got 1.5 (float); input should be "
            "a valid integer, got a number with a fractional part",
        ),
        (
            "robot",
            "cylindrical",
            "g",
            "abc",
            "must be a float, got 'abc' (str); input should be a valid number",
        ),
        (
            "estimator",
            "ls",
            "relative",
            "maybe",
            "must be a bool (true/false, yes/no, on/off or 1/0), got 'maybe'",
        ),
        ("estimator", "adam", "betas", "0.9", "must be a list of 2 (float, float), got '0.9' (str)"),
        (
            "estimator",
            "pso",
            "inertia",
            [0.7, "x", 3],
            "must be a list of 3 (float, float, int) or None, got [0.7, 'x', 3]",
        ),
    ]
    for kind, name, option, value, expected in cases:
        with pytest.raises(OptionError) as err:
            registry.create(kind, name, **{option: value})
        assert str(err.value).startswith(f"{kind} {name!r} option {option!r} {expected}"), str(err.value)


def test_unambiguous_strings_are_converted():
    pso = registry.create("estimator", "pso", particles="40", iterations=30.0, inertia=["0.7", "0.5", 3])
    assert (pso.particles, type(pso.particles)) == (40, int)
    assert (pso.iterations, type(pso.iterations)) == (30, int)
    assert pso.inertia == (0.7, 0.5, 3)
    with pytest.raises(OptionError, match=r"; item 1 = 'x': input should be a valid number, unable to parse"):
        registry.create("estimator", "pso", inertia=[0.7, "x", 3])
    assert registry.create("robot", "cylindrical", g="9.5").g == 9.5
    for text, value in (
        ("yes", True),
        ("No", False),
        ("1", True),
        ("0", False),
        ("TRUE", True),
        ("off", False),
    ):
        assert registry.create("estimator", "ls", relative=text).relative is value


def test_literal_choices_are_listed_closest_first():
    with pytest.raises(OptionError) as err:
        registry.create("estimator", "rls", solver="cvx")
    assert str(err.value) == (
        "estimator 'rls' option 'solver' must be 'closed_form' or 'cvxpy', got 'cvx' (str); "
        "closest: 'cvxpy', 'closed_form'"
    )


def test_unknown_option_lists_valid_keys_closest_first_on_one_line():
    with pytest.raises(OptionError) as err:
        registry.create("estimator", "pso", particle=40)
    message = str(err.value)
    assert message.startswith(
        "estimator 'pso' has no option 'particle'; its options (closest first): particles, "
    )
    assert "\n" not in message
    listed = message.split("(closest first): ")[1].split(", ")
    assert set(listed) == set(inspect.signature(registry.load("estimator", "pso")).parameters)
    assert isinstance(err.value, TypeError)  # callers that caught the constructor's TypeError still do


def test_unknown_plugin_name_is_one_line_closest_first():
    with pytest.raises(registry.UnknownPluginError) as err:
        registry.create("estimator", "psoo")
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith("unknown estimator 'psoo'; available estimators (closest first): pso, ")


def test_plain_settings():
    assert check_setting("seed", "7", int) == 7
    assert check_setting("plots", "no", bool) is False
    with pytest.raises(
        OptionError,
        match=r"^setting 'seed' must be an int, got 'abc' \(str\); input should be a valid integer",
    ):
        check_setting("seed", "abc", int)
    with pytest.raises(OptionError, match=r"^setting 'plots' must be a bool .*got 'maybe' \(str\)"):
        check_setting("plots", "maybe", bool)
    with pytest.raises(OptionError, match="got 2 \\(int\\)"):
        check_setting("plots", 2, bool)


def test_nan_is_never_an_option():
    with pytest.raises(OptionError, match="NaN is never a valid option"):
        check_setting("g", "nan", float)
    with pytest.raises(OptionError, match="NaN"):
        check_setting("g", math.nan, float)
    assert check_setting("max_cond", "inf", float) == math.inf


def test_nan_inside_a_plugin_spec_is_named_not_the_whole_spec():
    """``estimator.particles=nan`` reaches the top-level setting as a mapping: the line names the
    option holding the NaN instead of printing the whole mapping as "must be anything"."""
    from idkit.studies.build import Spec

    spec = {"_name_": "pso", "runs": 10, "particles": math.nan, "iterations": None}
    with pytest.raises(OptionError) as caught:
        check_setting("estimator", spec, Spec)
    assert str(caught.value) == "setting 'estimator': particles is NaN; NaN is never a valid option"
    with pytest.raises(OptionError, match=r"^setting 'estimator': betas item 1 is NaN;"):
        check_setting("estimator", {"_name_": "adam", "betas": [0.9, math.nan]}, Spec)


class Color(enum.Enum):
    RED = "r"
    BLUE = "b"


def toy(
    count: int = 1,
    name: str = "x",
    either: int | str = 0,
    optional: float | None = None,
    pair: tuple[int, float] = (1, 2.0),
    table: dict[str, int] | None = None,
    mode: Literal["a", "b"] = "a",
    color: Color = Color.RED,
    sloppy: float = None,  # type: ignore[assignment]  # the common slip: None default, no Optional
    costs: Sequence[Cost] = (),  # names a TYPE_CHECKING-only import: left unchecked
):
    return locals()


def check(**options):
    return check_options("estimator", "toy", toy, options)


def test_unions_keep_a_value_that_already_fits():
    assert check(either="1") == {"either": "1"}  # a str member: no conversion to int
    assert check(either=1) == {"either": 1}
    assert check(optional=None, sloppy=None) == {"optional": None, "sloppy": None}
    assert check(name=2024) == {"name": "2024"}  # a command line reads label=2024 as a number


def test_containers_enums_and_unresolvable_annotations():
    assert check(pair=["3", "0.5"]) == {"pair": (3, 0.5)}  # pydantic: a fixed tuple becomes a tuple
    with pytest.raises(OptionError, match=r"; tuple should have at most 2 items after validation, not 3$"):
        check(pair=[1, 2, 3])
    with pytest.raises(
        OptionError, match=r"option 'table' .*got \{'k': 'v'\} \(dict\); input should be a valid int"
    ):
        check(table={"k": "v"})
    assert check(color="r") == {"color": Color.RED}  # pydantic: an enum by value (not by name)
    with pytest.raises(OptionError, match="must be Color, got 'BLUE'"):
        check(color="BLUE")
    with pytest.raises(OptionError, match="must be 'a' or 'b', got 'c'"):
        check(mode="c")
    assert check(costs="anything") == {"costs": "anything"}


def test_keyword_catch_all_accepts_unknown_keys():
    def open_factory(alpha: float = 1.0, **rest):
        return rest

    assert check_options("cost", "open", open_factory, {"alpha": "2", "beta": "x"}) == {
        "alpha": 2.0,
        "beta": "x",
    }


@given(st.integers())
def test_int_round_trips_through_its_string(n):
    assert check_setting("n", str(n), int) == n


@given(st.floats(allow_nan=False))
def test_float_round_trips_through_its_repr(x):
    assert check_setting("x", repr(x), float) == x


@given(st.one_of(st.integers(), st.text(max_size=5), st.floats(allow_nan=False), st.booleans()))
def test_conversion_is_idempotent(value):
    for annotation in (int, float, bool, str, int | None):
        try:
            once = check_setting("v", value, annotation)
        except OptionError:
            continue
        assert check_setting("v", once, annotation) == once


def test_annotated_constraints_are_enforced_with_the_type():
    def swarm(particles: Annotated[int, Ge(1)] | None = None):
        return particles

    assert check_options("estimator", "swarm", swarm, {"particles": "3"}) == {"particles": 3}
    with pytest.raises(OptionError) as err:
        check_options("estimator", "swarm", swarm, {"particles": 0})
    assert str(err.value) == (
        "estimator 'swarm' option 'particles' must be an int or None, got 0 (int); "
        "input should be greater than or equal to 1"
    )


class Shaped(Protocol):
    def shape(self) -> tuple[int, ...]: ...


def test_a_protocol_pydantic_cannot_validate_is_left_to_the_constructor():
    def factory(thing: Shaped | None = None):
        return thing

    assert check_options("robot", "toy", factory, {"thing": 3}) == {"thing": 3}
