"""The ``excitation`` task: the study, its report's files, and the files loaded back into scenarios.

One small optimisation (module fixture) serves the in-process tests; the command line runs as a
subprocess in the ``integration`` tests.
"""

from __future__ import annotations

import inspect
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_module
from hydra.core.global_hydra import GlobalHydra
from omegaconf import OmegaConf

from idkit.cli.app import setup
from idkit.cli.tasks import TASKS, arguments
from idkit.data.scenarios import get_scenario, simulate, simulate_batch
from idkit.excitation.criterion import NoiseModel, excitation_criterion
from idkit.excitation.effort import default_acceleration_limits
from idkit.excitation.export import controller_times, read_trajectory
from idkit.excitation.files import load_excitation
from idkit.excitation.spec import scenario_excitation
from idkit.problem import Problem
from idkit.registry import create
from idkit.reports import excitation as report
from idkit.robots.cylindrical import CylindricalRobot
from idkit.robots.urdf import URDFRobot
from idkit.studies import excitation as study
from idkit.studies import paper, robustness

SMALL = {"swarms": 2, "particles": 16, "iterations": 15, "adam_steps": 10}

#: Eq. (38) typed from the paper, rows q, qd, qdd; columns theta1, d2, d3 as (lower, upper).
EQ38 = np.array(
    [
        [(-np.pi, np.pi), (0, 1), (0, 1)],
        [(-4, 4), (-2, 2), (-1.5, 1.5)],
        [(-3, 3), (-2, 2), (-1, 1)],
    ]
)


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> tuple[study.ExcitationStudy, dict[str, str]]:
    result = study.run("cylindrical", seed=2, **SMALL)
    return result, report.write(result, tmp_path_factory.mktemp("excitation"))


def test_report_writes_the_documented_files(written):
    result, files = written
    assert set(files) == {"excitation", "csv", "npz", "plot", "report", "result"}
    data = json.loads(Path(files["result"]).read_text())
    assert data["task"] == "excitation" and data["status"] == "complete" and data["seed"] == 2
    assert (
        data["plugins"]["excitation"]["name"] == "fourier"
        and data["plugins"]["robot"]["name"] == "cylindrical"
    )
    payload = data["payload"]
    assert payload["before"] == pytest.approx(result.result.before) and payload["after"] < payload["before"]
    assert payload["baseline"] == "paper" and payload["n_samples"] == 10 and payload["t_end"] == 10.0
    assert payload["excess_before"]["d2"]["position"] > 0.08  # eq. (39) leaves eq. (38)
    assert all(v == 0 for joint in payload["excess_after"].values() for v in joint.values())
    assert (
        payload["rate"] == 1000.0
        and payload["check"]["violations"] == []
        and payload["check"]["rate"] == pytest.approx(1000)
    )
    assert payload["check"]["effort"] == "not checked (the robot declares no effort limits)"
    assert payload["check"]["self_collision"] == "not checked (CylindricalRobot is not a URDF robot)"
    assert set(payload["check"]["margins"]["d3"]) == {"position", "velocity", "acceleration"}
    assert payload["options"]["rest"] is True and payload["options"]["period"] == 10.0
    assert Path(files["plot"]).stat().st_size > 0
    text = report.text(result)
    assert f"cond = {result.result.before:.6g}" in text and f"cond = {result.result.after:.6g}" in text
    assert "| theta1 | " in text and "all checks passed" in text and "exported at 1000 Hz" in text


def test_every_sample_keeps_the_configured_margin_and_the_report_says_against_what(written):
    result, files = written
    found = read_trajectory(files["csv"], ("theta1", "d2", "d3"))
    for row, name in enumerate(("q", "qd", "qdd")):
        low, high = EQ38[row, :, 0], EQ38[row, :, 1]
        half = (high - low) / 2
        values = getattr(found, name)
        assert (np.minimum(values - low, high - values) >= 0.05 * half).all(), name
    payload = json.loads(Path(files["result"]).read_text())["payload"]
    assert payload["margins"] == dict.fromkeys(("position", "velocity", "acceleration", "effort"), 0.05)
    assert payload["improved"] is True and payload["after"] < payload["start"]
    text = report.text(result)
    assert f"cond = {result.result.start:.6g}" in text and "than the start" in text
    assert "all checks passed (every margin at least the required 5 % of each limit's half-range)" in text


def test_a_search_that_does_not_beat_its_start_keeps_the_start_and_says_so(written):
    """The start is an optimised motion; a one-candidate search cannot beat it."""
    good = written[0].result.excitation.options()
    kept = study.run("cylindrical", options=good, method="pso", swarms=1, particles=2, iterations=1, seed=0)
    r = kept.result
    assert not r.improved and r.after == r.start and r.details["search_result"] > r.start
    assert torch.allclose(r.excitation.to_vector(), written[0].result.excitation.to_vector(), rtol=1e-9)
    text = report.text(kept)
    assert "no improvement found" in text and "optimised" not in text
    assert f"the start is kept (cond = {r.after:.6g})" in text and kept.check.ok


def test_yaml_loads_back_as_the_same_motion(written):
    result, files = written
    loaded = load_excitation(files["excitation"])
    assert torch.equal(loaded.to_vector(), result.result.excitation.to_vector())


@pytest.mark.parametrize("kind", ["csv", "npz"])
def test_the_exported_samples_are_the_motion_at_1khz_at_rest_within_eq38(written, kind):
    result, files = written
    found = read_trajectory(files[kind], ("theta1", "d2", "d3"))
    t = controller_times(10.0, 1000.0)
    np.testing.assert_array_equal(found.t, t.numpy())
    for name, value in zip(("q", "qd", "qdd"), result.result.excitation(t), strict=True):
        np.testing.assert_array_equal(getattr(found, name), value.numpy())
    for row, name in enumerate(("q", "qd", "qdd")):
        values = getattr(found, name)
        assert (values >= EQ38[row, :, 0]).all() and (values <= EQ38[row, :, 1]).all()
    for end in (0, -1):
        assert np.abs(found.qd[end]).max() <= 1e-12 and np.abs(found.qdd[end]).max() <= 1e-12


@pytest.mark.parametrize("name", ["outliers", "all_noise"])
def test_a_scenario_on_the_file_equals_the_scenario_on_the_object(written, name):
    result, files = written
    robot = CylindricalRobot()
    scenario = get_scenario({"name": name, "excitation": files["excitation"]})
    from_file = simulate(robot, scenario, seed=4, excitation=scenario_excitation(scenario, robot))
    from_object = simulate(robot, name, seed=4, excitation=result.result.excitation)
    for key in ("q", "qd", "qdd", "tau"):
        assert torch.equal(getattr(from_file, key), getattr(from_object, key))
    with pytest.raises(
        ValueError, match=f"^scenario '{name}' names the excitation '.*excitation.yaml': give the"
    ):
        simulate(robot, scenario, seed=4)  # data reads no excitation file: the motion is given


def test_robustness_and_paper_run_every_scenario_on_the_file(written):
    result, files = written
    robot = CylindricalRobot()
    common = {"excitation": files["excitation"]}
    found = robustness.run(
        "cylindrical",
        None,
        trials=2,
        scenarios=["torque_noise"],
        estimators=["ls"],
        pso_costs=[],
        average_of=[],
        baseline="LS",
        optional=[],
        scenario=common,
        progress=False,
    )
    assert found.provenance.data == {"scenarios": ["torque_noise"], "scenario": common}
    batch = simulate_batch(robot, "torque_noise", trials=2, excitation=result.result.excitation)
    for trial in range(2):
        expected = create("estimator", "ls").fit(Problem(robot, batch[trial], None, seed=trial)).params
        np.testing.assert_allclose(
            found.params["torque_noise"]["LS"][trial], list(expected.values()), rtol=1e-12
        )
    tables = paper.run(
        "cylindrical",
        {"_name_": "pso", "particles": 8, "iterations": 5},
        scenarios=["clean"],
        linear=["ls"],
        costs=["f1"],
        average_of=[],
        scenario=common,
        reference="",
        progress=False,
    )
    ls = next(e for e in tables.tables[0].estimates if e.estimator == "LS")
    np.testing.assert_allclose(list(ls.params.values()), robot.nominal_params().numpy(), rtol=1e-9)
    assert tables.provenance.data["scenario"] == common


def test_a_urdf_without_acceleration_limits_gets_them_from_its_effort_limits():
    with pytest.raises(ValueError, match="one positive number or one per joint \\(3: "):
        study.run({"_name_": "urdf", "urdf": "cylindrical"}, acceleration_limit=[1.0, 2.0], **SMALL)
    found = study.run({"_name_": "urdf", "urdf": "cylindrical"}, seed=1, **SMALL)
    assert found.acceleration_source == "effort"
    torch.testing.assert_close(
        found.result.limits.upper[2], default_acceleration_limits(URDFRobot("cylindrical"))
    )
    given = study.run({"_name_": "urdf", "urdf": "cylindrical"}, acceleration_limit=2.0, seed=1, **SMALL)
    assert given.acceleration_source == "given" and torch.count_nonzero(given.result.excess_after) == 0
    assert (given.result.excitation(given.result.grid)[2].abs() <= 2.0).all()
    margins = given.check.margins["d2"]
    assert given.check.ok and margins["effort"]["upper"] == 1000.0 and margins["acceleration"]["upper"] == 2.0
    assert given.payload()["acceleration_limits"].startswith("given")


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"family": "paper"}, "excitation family 'paper' cannot start and end at rest"),
        (
            {"options": {"period": 3.0}},
            "t_end to be a whole number of periods, but t_end=10 s and period=3 s",
        ),
        ({"rate": 333.33}, r"excitation.t_end=10 s is not a whole number of .* steps at rate 333.33 Hz"),
        # t_end=0 and a period of 0 used to divide by zero (a traceback); a negative t_end was offered
        # "choose t_end = 0.001 or -5 s"
        ({"t_end": 0.0}, r"^excitation\.t_end must be a finite number of seconds > 0, got 0\.0$"),
        ({"t_end": -5.0}, r"^excitation\.t_end must be a finite number of seconds > 0, got -5\.0$"),
        ({"t_end": math.inf}, r"^excitation\.t_end must be a finite number of seconds > 0, got inf$"),
        ({"t_end": 0.0, "rest": False}, r"^excitation\.t_end must be a finite number of seconds > 0"),
        (
            {"t_end": 0.0, "rest": False, "rate": None},
            r"^optimize_excitation: t_end must be a finite number > 0",
        ),
        ({"options": {"period": 0}}, r"^excitation\.options\.period must be a finite number of seconds > 0"),
        ({"learning_rate": -0.01}, r"^optimize_excitation: learning_rate must be a finite number > 0"),
    ],
)
def test_motions_that_cannot_rest_or_be_sampled_are_refused(options, match):
    with pytest.raises(ValueError, match=match):
        study.run("cylindrical", **options, **SMALL)


def test_without_rest_and_rate_the_old_motion_and_no_export(tmp_path):
    found = study.run("cylindrical", rest=False, rate=None, seed=2, **SMALL)
    assert found.trajectory is None and found.check.samples == 10001
    assert found.result.excitation.options()["rest"] is False and found.result.excitation.period == 10.0
    files = report.write(found, tmp_path)
    assert set(files) == {"excitation", "plot", "report", "result"}


def test_the_ls_error_criterion_through_the_study():
    found = study.run("cylindrical", criterion="ls_error", noise={"state": 0.1, "draws": 4}, seed=3, **SMALL)
    r = found.result
    noise = NoiseModel(state=0.1, draws=4, seed=3)
    expected = excitation_criterion(CylindricalRobot(), "ls_error", *r.excitation(r.t), noise=noise)
    assert r.after == pytest.approx(float(expected), rel=1e-12) and r.after < r.before
    assert "ls_error" in report.text(found) and "smaller is better" in report.text(found)


def test_other_dtypes_are_refused():
    with pytest.raises(ValueError, match="float64"):
        study.run("cylindrical", dtype="float32", **SMALL)


@pytest.fixture
def hydra_compose():
    setup()
    GlobalHydra.instance().clear()
    with initialize_config_module(config_module="idkit.conf", version_base="1.3"):
        yield lambda *overrides: compose("config", overrides=list(overrides))
    GlobalHydra.instance().clear()


@pytest.mark.parametrize(
    "overrides",
    [
        ("+experiment=excitation", "robot=cylindrical", "excitation.criterion=logdet"),
        (
            "+experiment=excitation",
            "robot=urdf",
            "robot.urdf=cylindrical",
            "excitation.acceleration_limit=[1,2,3]",
        ),
        ("+experiment=excitation", "excitation.criterion=ls_error", "excitation.noise.state=0.1"),
        ("+experiment=excitation", "excitation.margin={effort: 0.2, position: 0.1}"),
        ("+experiment=robustness", "scenario.excitation=excitation.yaml"),
        ("+experiment=paper", "scenario.excitation=fourier"),
        ("+scenario=outliers", "scenario.excitation=fourier", "estimator=ls"),
    ],
)
def test_the_config_is_the_study_signature(hydra_compose, overrides):
    cfg = OmegaConf.to_container(hydra_compose(*overrides), resolve=True)
    function = TASKS[cfg["task"]].study_function()
    kwargs = arguments(cfg["task"], cfg, function)
    inspect.signature(function).bind(**kwargs)
    excitation = overrides[-1].partition("=")[2] if "scenario.excitation" in overrides[-1] else None
    if "scenario" in kwargs and excitation:
        assert kwargs["scenario"]["excitation"] == excitation


IDKIT = [sys.executable, "-c", "from idkit.cli import main; main()"]
TINY = ["excitation.swarms=1", "excitation.particles=8", "excitation.iterations=5", "excitation.adam_steps=3"]


def _idkit(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([*IDKIT, *args], cwd=cwd, capture_output=True, text=True, timeout=300)


@pytest.mark.integration
def test_the_command_writes_a_file_a_scenario_loads(tmp_path):
    out = _idkit("+experiment=excitation", "robot=cylindrical", *TINY, "hydra.run.dir=opt", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "robot's default motion (paper): cond = 36.1141" in out.stdout
    assert "after  (fourier, optimised): cond = " in out.stdout or "no improvement found" in out.stdout
    assert "all checks passed (every margin at least the required 5 %" in out.stdout
    run = tmp_path / "opt"
    assert {p.name for p in run.iterdir()} >= {
        "excitation.yaml",
        "excitation.csv",
        "excitation.npz",
        "excitation.png",
        "report.html",
        "result.json",
    }
    out = _idkit(
        "+scenario=outliers",
        "scenario.excitation=opt/excitation.yaml",
        "estimator=ls",
        "hydra.run.dir=fit",
        cwd=tmp_path,
    )
    assert out.returncode == 0, out.stderr
    data = json.loads((tmp_path / "fit" / "result.json").read_text())
    assert data["data"]["scenario"]["excitation"] == "opt/excitation.yaml"


@pytest.mark.integration
@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ("+scenario=clean", "scenario.excitation=missing.yaml"),
            "excitation 'missing.yaml': no such file, and not an excitation family (fourier, paper)",
        ),
        (("+scenario=clean", "scenario.excitation=fourrier"), "excitation 'fourrier': no such file"),
        (
            ("+experiment=excitation", "excitation.t_end=10.0005", *TINY),
            "excitation.t_end=10.0005 s is not a whole number of 0.001 s steps",
        ),
        (("+experiment=excitation", "excitation.family=fourrier", *TINY), "unknown excitation 'fourrier'"),
        (
            ("+experiment=excitation", "excitation.margin=1.5", *TINY),
            "excitation.margin must be a share of each limit's half-range in [0, 1)",
        ),
        (
            ("+experiment=excitation", "excitation.margin={torque: 0.1}", *TINY),
            "excitation.margin.torque is not a limit with a margin",
        ),
    ],
)
def test_bad_inputs_give_one_line(tmp_path, args, message):
    out = (
        _idkit(*args, "estimator=ls", cwd=tmp_path)
        if args[0].startswith("+scenario")
        else _idkit(*args, cwd=tmp_path)
    )
    assert out.returncode == 1 and message in out.stderr and "Traceback" not in out.stderr, out.stderr
