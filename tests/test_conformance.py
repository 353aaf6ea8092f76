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

#: (kind, name, check) -> why it fails today. Strict xfail: once fixed, the XPASS says "remove me".
_CALL_CHECK = "fit does not call problem.check_identifiable() yet (estimators are edited in another branch)"
KNOWN_FAILURES: dict[tuple[str, str, str], str] = {
    ("estimator", name, "check_estimator_too_few_equations"): _CALL_CHECK
    for name in ("pso", "adam", "pso_f13_f14")
}


def _cases() -> list[pytest.param]:
    cases = []
    for kind in ("robot", "cost", "estimator", "excitation"):
        for name in registry.available(kind):  # reads metadata only; nothing is imported here
            for check in checks_for(kind):
                marks = []
                reason = KNOWN_FAILURES.get((kind, name, check.__name__))
                if reason:
                    marks.append(pytest.mark.xfail(reason=reason, strict=True))
                cases.append(
                    pytest.param(kind, name, check, id=f"{kind}-{name}-{check.__name__}", marks=marks)
                )
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
