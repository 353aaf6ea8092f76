"""Every registered plugin — built-in or installed from another distribution — passes idkit.testing.

Plugins are built with their class's ``conformance_options`` (cheap settings, e.g. few PSO
iterations) when they declare them. Estimators are checked on ``idkit.testing.make_problem()``
(the cylindrical robot, 20 samples, 2 % torque noise, cost ``f1``).
"""

from __future__ import annotations

import pytest

from idkit import registry
from idkit.registry import PluginLoadError
from idkit.testing import build_for_checks, checks_for, problem_factory_for


def _cases() -> list[pytest.param]:
    cases = []
    for kind in ("robot", "cost", "estimator", "excitation"):
        for name in registry.available(kind):  # reads metadata only; nothing is imported here
            for check in checks_for(kind):
                cases.append(pytest.param(kind, name, check, id=f"{kind}-{name}-{check.__name__}"))
    return cases


@pytest.fixture(scope="module")
def plugins() -> dict[tuple[str, str], object]:
    return {}


@pytest.mark.parametrize(("kind", "name", "check"), _cases())
def test_registered_plugin_conforms(kind, name, check, plugins):
    key = (kind, name)
    if key not in plugins:
        try:
            plugins[key] = build_for_checks(kind, name)
        except PluginLoadError as err:  # every registered name must load: a real failure
            pytest.fail(str(err), pytrace=False)
    extra = [problem_factory_for(plugins[key])] if kind == "estimator" else []
    check(plugins[key], *extra)
