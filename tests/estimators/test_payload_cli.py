"""estimator=payload through the idkit command: the printed block, result.json, identified.urdf, and the
one-line refusals."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import torch
from urdf_cases import TREE_URDF

from idkit.data.io import save_samples
from idkit.problem import Samples
from idkit.robots.inertia import standard_parameters
from idkit.robots.urdf import URDFRobot

MASS, COM = 0.7, np.array([0.03, -0.02, 0.1])


@pytest.fixture
def files(tmp_path):
    """The test robot's URDF and a recording with a payload on link ``c`` (idkit's own torques: the
    pinocchio comparisons live in test_payload.py)."""
    (tmp_path / "arm.urdf").write_text(TREE_URDF)
    robot = URDFRobot(str(tmp_path / "arm.urdf"))
    truth = robot.nominal_params().clone()
    i = robot.link_names.index("c")
    truth[10 * i : 10 * i + 10] += torch.as_tensor(
        standard_parameters(MASS, COM, np.diag([2e-3, 2.5e-3, 1.5e-3]))
    )
    q, qd, qdd = robot.random_states(300, torch.Generator().manual_seed(0))
    save_samples(Samples(q, qd, qdd, robot.inverse_dynamics(truth, q, qd, qdd)), tmp_path / "with_tool.npz")
    return tmp_path


@pytest.mark.integration
def test_the_command_prints_and_writes_the_payload(files, run_idkit, capsys):
    run = files / "run"
    status, said = run_idkit(
        f"robot.urdf={files / 'arm.urdf'}",
        "robot=urdf",
        f"data={files / 'with_tool.npz'}",
        "estimator=payload",
        "estimator.link=c",
        "cost=f1",
        f"hydra.run.dir={run}",
    )
    assert status == 0, said
    # no reference given: the report says that the arm model's error is not in the stds
    page = (run / "report.html").read_text()
    assert "no reference: the arm model (its inertials, friction and offsets) is taken as exact" in page
    # its σ are in the payload's verdict: the page does not also say that the fit reports none
    assert "reports no uncertainty" not in page and "standard deviations and what it leaves free" in page
    result = json.loads((run / "result.json").read_text())
    block = result["payload"]["estimate"]["details"]["payload"]
    assert block["mass"] == pytest.approx(MASS, rel=1e-8)
    assert block["sdk"]["ur"]["cog"] == pytest.approx(COM, abs=1e-9)
    assert '<link name="payload">' in (run / "identified.urdf").read_text()
    used = result["plugins"]["robot"]["options"]  # the robot as the run built it (defaults included)
    back = URDFRobot(str(run / "identified.urdf"), friction=used["friction"], offset=used["offset"])
    assert back.nominal_params().tolist() == pytest.approx(
        list(result["payload"]["estimate"]["params"].values())
    )


def test_an_unknown_link_is_one_line_listing_the_links(files, run_idkit):
    status, said = run_idkit(
        "robot=urdf",
        f"robot.urdf={files / 'arm.urdf'}",
        f"data={files / 'with_tool.npz'}",
        "estimator=payload",
        "estimator.link=gripper",
        f"hydra.run.dir={files / 'run'}",
    )
    assert status == 1 and len(said) == 1
    assert said[0].startswith("idkit: payload: link 'gripper' is not a moving link of ")
    assert said[0].endswith("its links: a, b (welded: tool), c, d")


def test_a_robot_without_a_tree_is_one_line(files, run_idkit):
    status, said = run_idkit("estimator=payload", f"hydra.run.dir={files / 'run'}")
    assert status == 1
    assert said == [
        "idkit: payload: needs a robot with a kinematic tree and per-link parameters (robot=urdf or "
        "robot=mjcf), got CylindricalRobot"
    ]


RATE = 200.0


def _raw_recording(robot: URDFRobot, params: torch.Tensor, path, delay: float = 0.0):
    """Ten seconds of two-harmonic sines on every joint at ``RATE``, written as a raw recording
    (``t``, positions, torques: no accelerations, so idkit preprocesses it), its torques ``delay`` s late."""
    from idkit.data.recording import Recording, save_recording

    t = np.arange(0.0, 10.0, 1.0 / RATE)
    phase = np.arange(robot.n_joints)[None, :]
    w = 2 * np.pi * 0.3 * (1 + 0.3 * phase)

    def states(at: np.ndarray) -> tuple[torch.Tensor, ...]:
        at = at[:, None]
        q = 0.4 * np.sin(w * at + phase) + 0.1 * np.sin(2 * w * at + 2 * phase)
        qd = 0.4 * w * np.cos(w * at + phase) + 0.2 * w * np.cos(2 * w * at + 2 * phase)
        qdd = -0.4 * w**2 * np.sin(w * at + phase) - 0.4 * w**2 * np.sin(2 * w * at + 2 * phase)
        return tuple(map(torch.from_numpy, (q, qd, qdd)))

    q = states(t)[0].numpy()
    tau = robot.inverse_dynamics(params, *states(t - delay)).numpy()
    save_recording(Recording(t, q, tau, joint_names=tuple(robot.joint_names)), path)
    return path


@pytest.fixture
def raw(files):
    """The same motion recorded with the payload and without it, torques 20 ms late."""
    robot = URDFRobot(str(files / "arm.urdf"))
    truth = robot.nominal_params().clone()
    i = robot.link_names.index("c")
    truth[10 * i : 10 * i + 10] += torch.as_tensor(
        standard_parameters(MASS, COM, np.diag([2e-3, 2.5e-3, 1.5e-3]))
    )
    return (
        _raw_recording(robot, truth, files / "with_tool.csv", delay=0.02),
        _raw_recording(robot, robot.nominal_params(), files / "without_tool.csv", delay=0.02),
    )


@pytest.mark.parametrize("correction", ["model", "samples"])
def test_the_reference_is_preprocessed_as_the_data(files, raw, correction):
    """A cut-off and a torque delay of the study's apply to the reference too: its rows are filtered
    and aligned as the data's (before, it got the default 10 Hz and no delay: other samples, so
    correction=samples refused it and correction=model fitted rows filtered otherwise)."""
    from idkit.studies import single

    data, reference = raw
    result = single.run(
        robot={"_name_": "urdf", "urdf": str(files / "arm.urdf")},
        estimator={"_name_": "payload", "link": "c", "reference": str(reference), "correction": correction},
        cost=None,
        data=str(data),
        preprocess={"cutoff": 3.0},
        recording={"torque_lag": 0.02},
        identified_urdf=False,
    )
    details = result.estimate.details
    made = details["reference"]
    assert made["preprocess"] == "as data=" and made["delay"]["seconds"] == pytest.approx(0.02)
    trained = single.load_data(
        URDFRobot(str(files / "arm.urdf")),
        data=str(data),
        preprocess={"cutoff": 3.0},
        recording={"torque_lag": 0.02},
    )[0]
    assert made["samples"] == trained.n_samples  # the trim of 3 Hz (1 s at each end), not of 10 Hz
    assert details["payload"]["mass"] == pytest.approx(MASS, rel=2e-3)
    from idkit.reports.single import text

    said = text(result)
    assert f"reference {reference}" in said and "no reference:" not in said


def test_the_data_given_as_its_own_reference_is_refused_in_one_line(files, raw, run_idkit):
    """The data file as the reference (its path, a copy, or the same samples in a samples file) would
    show a payload of about 0 kg with exit status 0: refused naming both files."""
    from idkit.studies import single

    data, _ = raw
    copy = files / "copy.csv"
    copy.write_bytes(data.read_bytes())
    same = files / "same_samples.npz"
    # the robot the command fits, typed out (no default may change it): the same cut-off is chosen
    save_samples(single.load_data(URDFRobot(str(files / "arm.urdf")), data=str(data))[0], same)
    common = [
        "robot=urdf",
        f"robot.urdf={files / 'arm.urdf'}",
        "robot.friction=false",
        "robot.offset=false",
        "estimator=payload",
        "estimator.link=c",
    ]
    cases = {
        data: r"is the data file .*with_tool.csv \(same file\)",
        copy: r"is the data file .*with_tool.csv \(same content\)",
        same: r"holds the same samples as the data \(its rows 0–\d+\)",
    }
    for reference, how in cases.items():
        run = files / f"run_{reference.stem}"
        status, said = run_idkit(
            *common, f"data={data}", f"estimator.reference={reference}", f"hydra.run.dir={run}"
        )
        assert status == 1 and len(said) == 1, said
        assert re.fullmatch(
            f"idkit: payload: reference file {reference} {how}; compared with itself .*", said[0]
        )
