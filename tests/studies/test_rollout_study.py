"""The ``rollout`` task: files in, identified.xml out; a bag gives the CSV's estimate; the command line."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest
from bag_cases import Stream, write_ros2
from mujoco import rollout

from idkit.data.commands import save_robot_log
from idkit.estimators.rollout import RolloutEstimator
from idkit.notes import Note
from idkit.reports import rollout as report
from idkit.sim.export import identified_xml, start_state
from idkit.sim.model import load_model
from idkit.studies.rollout import run
from idkit.testing import rollout_cases as cases

PARAMS = ["armature", "damping"]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rollout")
    case = cases.case_a()
    (folder / "arm.xml").write_text(case.model.replace('damping="1.0"', 'damping="0.7"'))
    save_robot_log(case.fit, folder / "fit.csv")
    save_robot_log(case.held_out, folder / "held_out.csv")
    return folder, case


def test_the_study_fits_writes_and_the_written_model_reproduces_a_held_out_log(files, tmp_path):
    folder, case = files
    result = run(
        str(folder / "arm.xml"),
        str(folder / "fit.csv"),
        params=PARAMS,
        validate=[str(folder / "held_out.csv")],
    )
    truth = {**case.truth, "joint1.damping": 1.0, "joint2.damping": 0.8, "joint3.damping": 0.6}
    truth |= {"joint4.damping": 0.4, "joint5.damping": 0.2}
    for name, value in truth.items():
        assert result.estimate.params[name] == pytest.approx(value, rel=1e-6)
    fitted, start = result.validation  # torque motors: segments only, at the fitted and start values
    assert (fitted.mode, fitted.values, fitted.default) == ("segments", "fitted", True)
    assert fitted.rms.max() < 1e-6 and fitted.verdict == "within noise"
    assert start.values == "start" and start.rms.max() > 1e-3  # damping 0.7 where the truth is 1.0
    written = report.write(result, tmp_path / "run")
    assert {"identified_mjcf", "fit_plot", "validation_plot_1", "result"} <= set(written)
    assert "joint1.armature" in report.text(result)
    # identified.xml, loaded by MuJoCo and rolled out under the held-out commands from its first state
    sim = load_model(str(tmp_path / "run" / "identified.xml"))
    log = case.held_out
    state = start_state(sim, log.joint_names, log.q[0], log.qd[0], log.commands[0])
    rows, _ = rollout.rollout(sim.model, mujoco.MjData(sim.model), state, log.commands[:-1])
    assert np.abs(rows[0, :, 1:6] - log.q[1:]).max() < 1e-4  # MJCF keeps 6 digits
    document = json.loads((tmp_path / "run" / "result.json").read_text())
    assert document["task"] == "rollout" and document["payload"]["identified_xml"] == "identified.xml"


def test_a_bag_gives_the_csvs_estimate(files, tmp_path):
    folder, case = files
    log = case.fit
    stamps = 1_700_000_000_123_000_000 + np.round(log.t * 1e9).astype(np.int64)
    joints = list(log.joint_names)
    streams = [
        Stream("/joint_states", stamps, joints, position=log.q, velocity=log.qd),
        Stream("/effort_commands", stamps, [f"act{i}" for i in range(1, 6)], effort=log.commands, extra={}),
    ]
    bag = write_ros2(tmp_path / "fit_bag", streams)
    from_csv = run(str(folder / "arm.xml"), str(folder / "fit.csv"), params=PARAMS)
    from_bag = run(str(folder / "arm.xml"), str(bag), params=PARAMS, command_topic="/effort_commands")
    for name, value in from_csv.estimate.params.items():
        assert from_bag.estimate.params[name] == pytest.approx(value, rel=1e-9, abs=1e-12)


def test_logs_without_the_models_joints_are_refused(files, tmp_path):
    folder, case = files
    text = case.model.replace('"joint', '"axis')
    (tmp_path / "other.xml").write_text(text)
    with pytest.raises(ValueError, match="none of the model's joints"):
        run(str(tmp_path / "other.xml"), str(folder / "fit.csv"), params=PARAMS)


@pytest.mark.integration
def test_the_command_line(files, tmp_path):
    folder, _ = files
    out = tmp_path / "cli"
    command = [
        sys.executable, "-c", "from idkit.cli import main; main()", "+experiment=rollout",
        f"rollout.model={folder / 'arm.xml'}", f"data={folder / 'fit.csv'}",
        f"validate=[{folder / 'held_out.csv'}]", "rollout.params=[armature,damping]",
        "rollout.bounds={joint1.damping:[0.1,5]}", f"hydra.run.dir={out}",
    ]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert (out / "identified.xml").is_file()
    payload = json.loads((out / "result.json").read_text())["payload"]
    assert payload["estimate"]["params"]["joint1.damping"] == pytest.approx(1.0, rel=1e-6)


def test_the_single_task_refuses_the_rollout_estimator_naming_the_experiment(files):
    from idkit.cli.tasks import arguments, get_task

    study = get_task("single").study_function()
    config = {"task": "single", "estimator": {"_name_": "rollout"}, "robot": {"_name_": "mjcf"}}
    with pytest.raises(ValueError, match=r"runs in the rollout task.*\+experiment=rollout"):
        arguments("single", config, study)


def _held_out_error(text: str, log) -> float:
    """1.4826 × the median absolute position error of ``text`` rolled out by MuJoCo under the log's
    commands from its first logged state (robust: glitched samples do not move it)."""
    sim = load_model(text)
    state = start_state(sim, log.joint_names, log.q[0], log.qd[0], log.commands[0])
    rows, _ = rollout.rollout(sim.model, mujoco.MjData(sim.model), state, log.commands[:-1])
    ids = [sim.joint_id(j) for j in log.joint_names]
    q = rows[0][:, 1 + np.array([sim.model.jnt_qposadr[i] for i in ids])]
    return float(1.4826 * np.median(np.abs(q - log.q[1:])))


@pytest.mark.slow
def test_identified_xml_of_a_corrupted_log_reproduces_the_held_out_log_within_the_noise():
    """Case c (noise, glitches, a 7 ms delay), defaults, the case's far start: the written model, rolled
    out by MuJoCo alone (its actuator delay) under the held-out commands, is as close to the held-out
    log as the truth is; the start is far off (the measure can tell)."""
    case = cases.case_b(corrupted=True)
    problem = cases.problem_of(case)
    estimate = RolloutEstimator().fit(problem)
    sim, unknowns = problem.robot.sim, problem.robot.unknowns
    names = [u.name for u in unknowns.items]
    fitted = identified_xml(sim, unknowns, np.array([estimate.params[n] for n in names]))
    truth = identified_xml(sim, unknowns, np.array([case.truth[n] for n in names]))
    start = identified_xml(sim, unknowns, np.array([case.start[n] for n in names]))
    log = case.held_out
    best = _held_out_error(truth, log)
    assert best < 5 * cases.NOISE[0]  # the truth reproduces it within the noise (and the first sample's)
    assert _held_out_error(fitted, log) < 1.1 * best
    assert _held_out_error(start, log) > 10 * best


def test_a_stalled_driver_is_left_out_noted_and_counted_and_the_fit_stays_exact(files, tmp_path):
    """Case a's noiseless log with three 20 ms stalls: the repeats left out, so the fit stays exact,
    said in one note and counted in the result."""
    folder, case = files
    save_robot_log(cases.stalled(case.fit, seconds=0.02), tmp_path / "stalled.csv")
    with pytest.warns(Note, match=r"stalled.csv: 30 stalled rows \(3 stretches repeating the last row\)"):
        result = run(str(folder / "arm.xml"), str(tmp_path / "stalled.csv"), params=PARAMS)
    assert result.details.outliers == {"stalled": 30, "stalls": 3, "dropped": 0}
    assert result.estimate.params["joint1.damping"] == pytest.approx(1.0, rel=1e-6)
    assert "left out as the driver's: 30 stalled rows in 3 stretches" in report.text(result)
    written = report.write(result, tmp_path / "run", plots=False)
    payload = json.loads(Path(written["result"]).read_text())["payload"]
    assert payload["estimate"]["details"]["outliers"]["stalled"] == 30
