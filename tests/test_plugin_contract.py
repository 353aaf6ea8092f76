"""Plugins by contract: a plugin package whose classes do not subclass ``idkit.interfaces``.

``tests/plugin_package`` is a real distribution (pyproject with entry points), pip-installed into a
temporary folder that is put on ``sys.path`` — what a user's ``pip install`` does, without touching
the environment. Complete plugins get every optional member's default and fit end to end; a
plugin missing a required member is refused in one line naming it.
"""

from __future__ import annotations

import functools
import json
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import torch

from idkit import interfaces, registry
from idkit.cli import errors
from idkit.testing import check_cost, check_estimator, check_robot, make_problem

PACKAGE = Path(__file__).resolve().parent / "plugin_package"
DEMO = "idkit-contract-demo 0.1.0"


def install(target: Path, scratch: Path) -> None:
    """``pip install`` the demo package into ``target`` (built from a copy: the build writes files)."""
    source = scratch / "source"
    shutil.copytree(PACKAGE, source, ignore=shutil.ignore_patterns("__pycache__", "build", "*.egg-info"))
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--no-index"]
        + ["--disable-pip-version-check", "--target", str(target), str(source)],
        check=True,
    )


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Iterator[Path]:
    """The demo package installed and on ``sys.path``; the registry forgets it afterwards."""
    target = tmp_path_factory.mktemp("site")
    install(target, tmp_path_factory.mktemp("build"))
    with pytest.MonkeyPatch.context() as patch:
        patch.syspath_prepend(str(target))
        registry.refresh()
        yield target
    sys.modules.pop("idkit_contract_demo", None)
    registry.refresh()


def test_the_demo_classes_do_not_subclass_the_interfaces(site):
    import idkit_contract_demo as demo

    for cls in (demo.Pendulum, demo.MeanAbsoluteError, demo.RandomSearch, demo.Swing):
        assert not issubclass(
            cls, (interfaces.Robot, interfaces.Cost, interfaces.Estimator, interfaces.Excitation)
        )


def test_complete_plugins_get_the_optional_members_defaults(site):
    import idkit_contract_demo as demo

    robot = registry.create("robot", "demo_pendulum")
    cost = registry.create("cost", "demo_mae", relative=True)
    assert isinstance(robot, demo.Pendulum) and isinstance(robot, interfaces.Robot)
    assert type(robot).__name__ == "Pendulum" and type(robot).__module__ == "idkit_contract_demo"
    assert (robot.n_joints, robot.n_params, robot.base_param_names, robot.search_space) == (
        1,
        3,
        (),
        "physical",
    )
    assert cost.structure() is None and cost.stacked_measured is False and cost.relative is True
    made = registry.create("cost", "demo_made", power=1.0)  # a factory function's non-subclass instance
    assert isinstance(made, interfaces.Cost) and made.structure() is None
    swing = registry.create("excitation", "demo_swing")
    q, qd, qdd = swing(torch.linspace(0, 1, 5, dtype=torch.float64))  # __call__ is the interface's
    assert q.shape == qd.shape == qdd.shape == (5, 1)
    swing.check_joints(("q",), "robot Pendulum")


def test_complete_plugins_pass_the_conformance_suite(site):
    robot = registry.create("robot", "demo_pendulum")
    check_robot(robot)
    check_cost(registry.create("cost", "demo_mae", relative=True))
    check_estimator(
        registry.create("estimator", "demo_search", samples=200), functools.partial(make_problem, robot)
    )


@pytest.mark.parametrize(
    ("kind", "name", "missing", "interface"),
    [
        ("robot", "demo_stiff", "inverse_dynamics", "Robot"),
        ("robot", "demo_nameless", "joint_names", "Robot"),
        ("cost", "demo_nocall", "__call__", "Cost"),
    ],
)
def test_a_missing_required_member_is_refused_in_one_line(site, kind, name, missing, interface):
    with pytest.raises(registry.PluginContractError) as error:
        registry.create(kind, name)
    message = str(error.value)
    assert f"{kind} plugin {name!r}" in message and DEMO in message and "\n" not in message
    assert message.endswith(
        f"does not define {missing}, required by idkit.interfaces.{interface} (see the plugin contract)"
    )


def test_ready_objects_passed_to_idkit_run_are_held_to_the_same_contract(site):
    """``idkit.run(cost=obj)`` with an object of a class that does not subclass the interface: it
    gets the interface's defaults (before, a cost without ``structure`` failed with AttributeError
    deep in the objective), and one lacking a required member is refused naming it."""
    import idkit_contract_demo as demo

    import idkit

    pso = {"_name_": "pso", "runs": 2, "iterations": 20}
    result = idkit.run(cost=demo.MeanAbsoluteError(), estimator=pso, scenario="outliers")
    reference = idkit.run(cost=registry.create("cost", "demo_mae"), estimator=pso, scenario="outliers")
    assert result.estimate.params == reference.estimate.params
    with pytest.raises(registry.PluginContractError) as error:
        idkit.run(robot=demo.Nameless(), estimator="ls", cost=None)
    assert str(error.value) == (
        "robot object Nameless (idkit_contract_demo) does not define joint_names, required by "
        "idkit.interfaces.Robot (see the plugin contract)"
    )


def test_required_members_come_from_the_interfaces():
    assert registry.required_members("robot") == (
        ("bounds", "inverse_dynamics"),
        ("joint_names", "param_names"),
    )
    assert registry.required_members("cost") == (("__call__",), ())
    assert registry.required_members("estimator") == (("fit",), ())
    assert registry.required_members("excitation") == (
        ("evaluate", "from_vector", "options", "to_vector"),
        ("n_joints",),
    )


FIT = ("robot=demo_pendulum", "estimator=demo_search", "cost=demo_mae", "+scenario=outliers")


def test_a_complete_plugin_fits_through_the_command_line(site, tmp_path, run_idkit):
    run = tmp_path / "run"
    code, _ = run_idkit(*FIT, "scenario.excitation=demo_swing", f"hydra.run.dir={run}")
    assert code == 0
    result = json.loads((run / "result.json").read_text())
    assert set(result["payload"]["estimate"]["params"]) == {"J", "h", "fv"}
    assert result["data"]["scenario"]["excitation"] == "demo_swing"
    assert result["plugins"]["cost"]["distribution"] == "idkit-contract-demo"


def test_an_incomplete_plugin_is_one_line_on_the_command_line(site, tmp_path, run_idkit):
    code, said = run_idkit("robot=demo_stiff", "estimator=demo_search", f"hydra.run.dir={tmp_path}")
    assert code == errors.USAGE
    assert len(said) == 1 and said[0].startswith("idkit: robot plugin 'demo_stiff' (entry point")
    assert said[0].endswith(
        "does not define inverse_dynamics, required by idkit.interfaces.Robot (see the plugin contract)"
    )


@pytest.mark.integration
def test_installed_package_in_a_fresh_process(tmp_path):
    """As a user runs it: the package installed, ``idkit`` started in a new process."""
    target = tmp_path / "site"
    install(target, tmp_path)
    env = {**os.environ, "PYTHONPATH": str(target)}
    idkit = str(Path(sys.executable).with_name("idkit"))  # the console script of this environment
    command = [idkit, *FIT, f"hydra.run.dir={tmp_path / 'run'}"]
    done = subprocess.run(command, env=env, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "run" / "result.json").is_file()
    refused = subprocess.run(
        [idkit, "robot=demo_pendulum", "cost=demo_nocall", f"hydra.run.dir={tmp_path / 'refused'}"],
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    assert refused.returncode == errors.USAGE
    assert refused.stderr.strip().splitlines() == [
        "idkit: cost plugin 'demo_nocall' (entry point 'idkit_contract_demo:NoCall' in group "
        f"'idkit.costs', distribution {DEMO}) does not define __call__, required by "
        "idkit.interfaces.Cost (see the plugin contract)"
    ]
