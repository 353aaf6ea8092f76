"""The single task on measured files: data= lists, validate=, the preprocess group, identified.urdf,
and the one-line errors of bad input (in process through the config, and once as a subprocess)."""

from __future__ import annotations

import json
import re
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
from idkit.cli.tasks import arguments
from idkit.data.preprocess import PreprocessOptions
from idkit.estimators.linear.observation import IdentificationError
from idkit.reports import single as report
from idkit.robots.urdf import URDFRobot
from idkit.studies import single
from idkit.studies.recordings import preprocess_options

ASSET = Path(__file__).resolve().parents[2] / "idkit" / "robots" / "assets" / "cylindrical.urdf"
RATE = 200.0


def truth(robot: URDFRobot) -> torch.Tensor:
    """The CAD inertials with Coulomb 0.5, viscous 0.2 and offset 0.1 on every joint."""
    params = robot.nominal_params().clone()
    for k, name in enumerate(robot.param_names):
        params[k] = {"fc": 0.5, "fv": 0.2, "offset": 0.1}.get(name.rsplit(".", 1)[1], float(params[k]))
    return params


def motion(seconds: float, f0: float, seed: int) -> tuple[np.ndarray, ...]:
    """Two-harmonic sines per joint at ``RATE``: ``t[N], q, qd, qdd [N, 3]`` (exact derivatives)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / RATE)
    q, qd, qdd = (np.zeros((t.size, 3)) for _ in range(3))
    for j, (centre, amplitude) in enumerate(((0.0, 0.6), (0.4, 0.1), (0.5, 0.3))):
        q[:, j] = centre
        for k in (1, 2):
            w, phase = 2 * np.pi * f0 * k * (1 + 0.3 * j), rng.uniform(0, 2 * np.pi)
            q[:, j] += amplitude / k * np.sin(w * t + phase)
            qd[:, j] += amplitude / k * w * np.cos(w * t + phase)
            qdd[:, j] -= amplitude / k * w**2 * np.sin(w * t + phase)
    return t, q, qd, qdd


def raw_csv(path: Path, seconds: float, f0: float, seed: int, noise: float = 0.01) -> Path:
    """A raw recording ``t, q1..q3, tau1..tau3`` of the friction + offset cylindrical URDF robot."""
    robot = URDFRobot(str(ASSET), friction=True, offset=True)
    t, q, qd, qdd = motion(seconds, f0, seed)
    tau = robot.inverse_dynamics(truth(robot), *map(torch.from_numpy, (q, qd, qdd))).numpy()
    tau += np.random.default_rng(seed + 100).normal(0.0, noise, tau.shape)
    header = ["t", *(f"q{j}" for j in (1, 2, 3)), *(f"tau{j}" for j in (1, 2, 3))]
    np.savetxt(path, np.column_stack([t, q, tau]), delimiter=",", header=",".join(header), comments="")
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("recordings")
    return {
        "urdf": Path(ASSET),
        "train": raw_csv(folder / "train.csv", 12.0, 0.2, 1),
        "train2": raw_csv(folder / "train2.csv", 8.0, 0.25, 3),
        "test": raw_csv(folder / "test.csv", 10.0, 0.3, 2),
        "folder": folder,
    }


def command(*overrides: str, out: Path):
    """What ``idkit <overrides>`` runs, in process: compose, bind the config to the study, report."""
    setup()
    GlobalHydra.instance().clear()
    with initialize_config_module(config_module="idkit.conf", version_base="1.3"):
        cfg = compose("config", overrides=list(overrides))
    GlobalHydra.instance().clear()
    resolved = OmegaConf.to_container(cfg, resolve=True)
    kwargs = arguments("single", resolved, single.run)
    result = single.run(**kwargs)
    report.write(result, out, plots=bool(cfg.plots))
    return result, json.loads((out / "result.json").read_text())


def robot_args(files: dict[str, Path]) -> list[str]:
    return ["robot=urdf", f"robot.urdf={files['urdf']}", "robot.friction=true", "robot.offset=true"]


def test_the_issue_command_fits_validates_and_writes_identified_urdf(files, tmp_path):
    pin = pytest.importorskip("pinocchio")
    result, data = command(
        *robot_args(files),
        f"data={files['train']}",
        f"validate=[{files['test']}]",
        "estimator=pcls",
        "plots=true",
        out=tmp_path,
    )
    robot = URDFRobot(str(ASSET), friction=True, offset=True)
    validation = data["payload"]["validation"][str(files["test"])]
    # Noise 0.01 N·m on torques of ~1-80 N·m: a consistent model of the right structure predicts the
    # held-out file to well under 1 %.
    assert validation["rel_all"] < 0.01 and len(validation["rms"]) == 3
    assert data["data"]["file"] == str(files["train"]) and data["data"]["validate"] == [str(files["test"])]
    assert data["data"]["preprocess"]["cutoff"] == 10.0  # raw CSVs: preprocessed by default
    assert data["data"]["preprocess"]["files"] == [str(files["train"]), str(files["test"])]
    uncertainty = data["payload"]["estimate"]["details"]["uncertainty"]
    assert uncertainty["rank"] == len(robot.base_param_names)
    assert set(data["files"]) >= {"identified_urdf", "validation_plot_1", "result"}
    text = report.text(result)
    assert "held-out validation" in text and "condition number" in text and "unidentifiable" in text
    # pinocchio loads identified.urdf and its rigid-body torques are the identified model's
    model = pin.buildModelFromUrdf(data["files"]["identified_urdf"])
    back = URDFRobot(data["files"]["identified_urdf"])
    params = torch.tensor([result.estimate.params[n] for n in robot.param_names], dtype=torch.float64)
    q = torch.tensor([[0.3, 0.4, 0.5]], dtype=torch.float64)
    qd, qdd = torch.tensor([[0.2, -0.1, 0.3]]).double(), torch.tensor([[1.0, 0.5, -0.7]]).double()
    rigid = URDFRobot(str(ASSET)).inverse_dynamics(params[: 10 * len(robot.link_names)], q, qd, qdd)
    expected = pin.rnea(model, model.createData(), q[0].numpy(), qd[0].numpy(), qdd[0].numpy())
    np.testing.assert_allclose(rigid[0].numpy(), expected, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(back.nominal_params().numpy(), params[: back.n_params].numpy(), atol=1e-9)


def test_data_list_is_stacked_and_each_file_preprocessed_alone(files, tmp_path):
    result, data = command(
        *robot_args(files),
        f"data=[{files['train']},{files['train2']}]",
        "estimator=ls",
        "~cost",
        "plots=false",
        "identified_urdf=false",
        out=tmp_path,
    )
    options = PreprocessOptions()
    trim = int(np.ceil(3.0 / options.cutoff * RATE))
    expected = (12.0 * RATE - 2 * trim) + (8.0 * RATE - 2 * trim)
    assert data["payload"]["estimate"]["details"]["uncertainty"]["dof"] == 3 * expected - 14
    assert data["data"]["files"] == [str(files["train"]), str(files["train2"])]
    assert data["payload"]["validation"] == {} and result.validation == []


def test_samples_files_are_used_as_they_are_unless_preprocess_on(files, tmp_path):
    """auto: a file with qdd keeps its own derivatives; on: it is preprocessed from its timestamps."""
    robot = URDFRobot(str(ASSET), friction=True, offset=True)
    t, q, qd, qdd = motion(6.0, 0.2, 5)
    tau = robot.inverse_dynamics(truth(robot), *map(torch.from_numpy, (q, qd, qdd))).numpy()
    path = files["folder"] / "samples.npz"
    np.savez(path, t=t, q=q, qd=qd, qdd=qdd, tau=tau)
    quiet = ["estimator=ls", "~cost", "plots=false", "identified_urdf=false"]
    kept, _ = command(*robot_args(files), f"data={path}", *quiet, out=tmp_path / "a")
    assert "preprocess" not in kept.data
    np.testing.assert_allclose(
        [kept.estimate.params[n] for n in robot.param_names if n.endswith((".fc", ".fv", ".offset"))],
        [
            float(v)
            for n, v in zip(robot.param_names, truth(robot), strict=True)
            if n.endswith((".fc", ".fv", ".offset"))
        ],
        rtol=1e-6,
    )
    filtered, data = command(
        *robot_args(files),
        f"data={path}",
        "preprocess=on",
        "preprocess.cutoff=5",
        *quiet,
        out=tmp_path / "b",
    )
    assert data["data"]["preprocess"]["cutoff"] == 5.0
    assert data["payload"]["estimate"]["details"]["uncertainty"]["dof"] < 3 * t.size - 14


def test_the_preprocess_group_is_the_options_dataclass(files):
    setup()
    GlobalHydra.instance().clear()
    with initialize_config_module(config_module="idkit.conf", version_base="1.3"):
        groups = {
            name: OmegaConf.to_container(compose("config", overrides=[f"preprocess={name}"]).preprocess)
            for name in ("auto", "on", "off")
        }
    GlobalHydra.instance().clear()
    for name, node in groups.items():
        options, apply = preprocess_options(node)
        assert (options, apply) == (PreprocessOptions(), name)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (["preprocess.cutoff=150"], r"cutoff 150 Hz is not below the Nyquist frequency 100 Hz"),
        (["preprocess=off"], r"train\.csv: a raw recording \(no accelerations qdd\); preprocess it"),
        (["preprocess.cutof=5"], None),  # Hydra refuses the unknown key itself
    ],
)
def test_bad_preprocessing_is_one_clear_line(files, tmp_path, overrides, message):
    from hydra.errors import ConfigCompositionException

    args = [*robot_args(files), f"data={files['train']}", "estimator=ls", "~cost", *overrides]
    if message is None:
        with pytest.raises(ConfigCompositionException):
            command(*args, out=tmp_path)
        return
    with pytest.raises(ValueError, match=message) as caught:
        command(*args, out=tmp_path)
    assert "\n" not in str(caught.value)


def test_recording_with_other_joints_is_named(files, tmp_path):
    two = files["folder"] / "two_joints.csv"
    lines = files["train"].read_text().splitlines()
    keep = [0, 1, 2, 4, 5]  # t, q1, q2, tau1, tau2
    two.write_text("\n".join(",".join(line.split(",")[k] for k in keep) for line in lines) + "\n")
    for role, args in (
        ("data", [f"data={two}"]),
        ("validate", [f"data={files['train']}", f"validate=[{two}]"]),
    ):
        with pytest.raises(
            ValueError,
            match=rf"^{role} file .*two_joints\.csv has 2 joints but robot URDFRobot "
            r"\(.*cylindrical\.urdf\) has 3: theta1, d2, d3$",
        ):
            command(*robot_args(files), *args, "estimator=ls", "~cost", out=tmp_path)


def test_urdf_without_inertials_is_refused_by_pcls(files, tmp_path):
    bare = files["folder"] / "bare.urdf"
    bare.write_text(re.sub(r"<inertial>.*?</inertial>", "", ASSET.read_text(), flags=re.S))
    args = [
        "robot=urdf",
        f"robot.urdf={bare}",
        "robot.friction=true",
        f"data={files['train']}",
        "estimator=pcls",
    ]
    with pytest.raises(ValueError, match=r"^urdf: link\(s\) 'link1', 'link2', 'link3' have no <inertial>"):
        command(*args, out=tmp_path)


@pytest.mark.parametrize(
    ("status", "message"),
    [
        ("infeasible", r"^pcls: the constraints are infeasible"),
        ("solver_error", r"^pcls: the conic solver failed"),
    ],
)
def test_infeasible_program_and_solver_failure_are_one_line(files, tmp_path, monkeypatch, status, message):
    cp = pytest.importorskip("cvxpy")

    def broken(self, *args, **kwargs):
        self._status = status
        if status == "solver_error":
            raise cp.error.SolverError("numerical trouble")

    monkeypatch.setattr(cp.Problem, "solve", broken)
    with pytest.raises(IdentificationError, match=message) as caught:
        command(*robot_args(files), f"data={files['train']}", "estimator=pcls", out=tmp_path)
    assert "\n" not in str(caught.value)


def test_identified_urdf_can_be_turned_off_and_other_robots_write_none(files, tmp_path):
    _, data = command(
        *robot_args(files),
        f"data={files['train']}",
        "estimator=ls",
        "~cost",
        "identified_urdf=false",
        "plots=false",
        out=tmp_path / "a",
    )
    assert "identified_urdf" not in data["files"]
    result, data = command("estimator=ls", "~cost", "n_samples=30", "plots=false", out=tmp_path / "b")
    assert result.urdf is None and "identified_urdf" not in data["files"]


@pytest.mark.integration
def test_the_issue_command_as_a_subprocess(files, tmp_path):
    args = [*robot_args(files), f"data={files['train']}", f"validate=[{files['test']}]", "estimator=pcls"]
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            "from idkit.cli import main; main()",
            *args,
            f"hydra.run.dir={tmp_path / 'run'}",
        ],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
    )
    assert out.returncode == 0, out.stderr
    assert "held-out validation" in out.stdout and (tmp_path / "run" / "identified.urdf").is_file()
    data = json.loads((tmp_path / "run" / "result.json").read_text())
    assert data["payload"]["validation"][str(files["test"])]["rel_all"] < 0.01
    bad = subprocess.run(
        [
            sys.executable,
            "-c",
            "from idkit.cli import main; main()",
            *args,
            "preprocess.cutoff=150",
            f"hydra.run.dir={tmp_path / 'bad'}",
        ],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
    )
    assert bad.returncode == 1
    assert re.search(r"^idkit: preprocess \(.*train\.csv\): cutoff 150 Hz is not below", bad.stderr, re.M)
