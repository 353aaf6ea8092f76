"""The plugin example in docs/plugins.md is real code: it passes the conformance suite."""

from __future__ import annotations

import functools
import re
import sys
import types
from collections.abc import Iterator
from pathlib import Path

import pytest

from idkit.problem import IdentificationError
from idkit.testing import check_cost, check_estimator, check_robot, make_problem

PAGE = Path(__file__).resolve().parents[1] / "docs" / "plugins.md"


@pytest.fixture(scope="module")
def example() -> Iterator[types.ModuleType]:
    code = re.findall(r"```python\n(.*?)```", PAGE.read_text(), re.S)[0]
    module = types.ModuleType("idkit_pendulum_plugins")
    sys.modules[module.__name__] = module  # so that classes defined in it have a home module
    try:
        exec(compile(code, f"{PAGE}:example", "exec"), module.__dict__)
        yield module
    finally:
        del sys.modules[module.__name__]


def test_example_plugins_conform(example):
    check_robot(example.Pendulum())
    check_cost(example.MeanAbsoluteError(relative=True))
    check_estimator(example.RandomSearch(samples=200), functools.partial(make_problem, example.Pendulum()))


def test_example_estimator_refuses_too_few_samples(example):
    problem = make_problem(example.Pendulum(), n_samples=2)
    with pytest.raises(IdentificationError, match="2 samples × 1 joint = 2 equations < 3 base parameters"):
        example.RandomSearch().fit(problem)
