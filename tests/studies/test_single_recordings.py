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
from idkit.data.options import DataOptions, Preprocessing
from idkit.data.pipeline import DelayWarning
from idkit.data.preprocess import GapWarning
from idkit.estimators.linear.observation import IdentificationError
from idkit.reports import single as report
from idkit.robots.urdf import URDFRobot
from idkit.studies import single

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
    # raw CSVs: preprocessed by default, at the cut-off the training data chose (recorded with its scores)
    preprocessed = data["data"]["preprocess"]
    choice = preprocessed["cutoff_choice"]
    assert preprocessed["cutoff"] == choice["cutoff"] and f"{choice['cutoff']:g}" in choice["scores"]
    assert choice["reason"].startswith("auto: lowest 5-fold cross-validated torque error")
    assert validation["band_hz"] == 6.0 and "low-passed at 6 Hz" in validation["metric"]
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
    trim = int(np.ceil(3.0 / data["data"]["preprocess"]["cutoff"] * RATE))
    expected = (12.0 * RATE - 2 * trim) + (8.0 * RATE - 2 * trim)
    assert data["payload"]["estimate"]["details"]["uncertainty"]["dof"] == 3 * expected - 14
    assert data["data"]["files"] == [str(files["train"]), str(files["train2"])]
    assert data["payload"]["validation"] == {} and result.validation == []


def test_the_cutoff_changes_the_model_but_not_the_yardstick(files, tmp_path):
    """Held-out torques are compared in one fixed band whatever the training cut-off: the measured
    torques scored are the same samples' raw torques, the metric and band the same; the held-out
    states (and so the prediction) follow the cut-off."""
    runs = {}
    for cutoff in (4, 12):
        runs[cutoff], _ = command(
            *robot_args(files),
            f"data={files['train']}",
            f"validate=[{files['test']}]",
            "estimator=ls",
            "~cost",
            f"preprocess.cutoff={cutoff}",
            "plots=false",
            "identified_urdf=false",
            out=tmp_path / str(cutoff),
        )
    low, high = (runs[c].validation[0] for c in (4, 12))
    assert low.scores.metric == high.scores.metric and low.scores.band == high.scores.band == 6.0
    common, a, b = np.intersect1d(
        np.round(low.times * RATE), np.round(high.times * RATE), return_indices=True
    )
    assert common.size > 1500
    np.testing.assert_array_equal(low.scores.measured[a], high.scores.measured[b])
    assert not np.allclose(low.scores.predicted[a], high.scores.predicted[b], rtol=1e-6, atol=0)


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
        assert DataOptions.of(node).preprocess == Preprocessing(apply=name)
        checked = arguments("single", {"preprocess": node}, single.run)["preprocess"]
        assert checked == Preprocessing(apply=name)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (["preprocess.cutoff=150"], r"cutoff 150 Hz is not below the Nyquist frequency 100 Hz"),
        (["preprocess.cutoff=soon"], r"^setting 'preprocess\.cutoff' must be a float or 'auto', got 'soon'"),
        (["preprocess=off"], r"train\.csv: a raw recording \(no accelerations qdd\); preprocess it"),
        (["preprocess.cutof=5"], None),  # Hydra refuses the unknown key itself
        (
            ["+preprocess.velocitiez=measured"],
            r"^preprocess has no option 'velocitiez'; its options \(closest",
        ),
        (["preprocess.trim=-1"], r"^preprocess\.trim must be seconds >= 0, or null \(3 / cutoff\), got -1"),
        (["preprocess.decimate=0"], r"^preprocess\.decimate must be a whole number >= 1, got 0$"),
        (["preprocess.max_gap=0.5"], r"^preprocess\.max_gap must be a number of median steps > 1, got 0\.5$"),
        (["preprocess.apply=sometimes"], r"^setting 'preprocess\.apply' must be 'auto' or 'on' or 'off'"),
        (
            ["+recording.topics=/joint_states"],
            r"^recording has no option 'topics'; its options \(closest first\): topic",
        ),
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


def test_a_typo_in_a_section_from_python_is_named_as_that_key(files):
    """``idkit.run(preprocess={...})`` is checked as the command line checks it: a misspelt option is
    refused as that key, with the options closest first — not reported later as whatever it changed."""
    robot = {"_name_": "urdf", "urdf": str(files["urdf"])}
    with pytest.raises(
        ValueError, match=r"^preprocess has no option 'velocitiez'; its options \(closest first\): velocities"
    ):
        single.run(robot, "ls", None, data=str(files["train"]), preprocess={"velocitiez": "measured"})
    with pytest.raises(ValueError, match=r"^setting 'recording\.torque_lag' must be a float or 'auto'"):
        single.run(robot, "ls", None, data=str(files["train"]), recording={"torque_lag": "late"})


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


# --- recordings that cannot lie: refused or said in one line, through the command ---------------


def idkit_main(monkeypatch, capsys, *args: str, run_dir: Path) -> tuple[int, str, str]:
    """``idkit <args>`` in process (``idkit.cli.main``): exit status, stdout, stderr."""
    from idkit.cli import app

    monkeypatch.setattr(sys, "argv", ["idkit", *args, f"hydra.run.dir={run_dir}"])
    monkeypatch.delenv(app.FULL_ERROR, raising=False)
    GlobalHydra.instance().clear()
    code = 0
    try:
        app.main()
    except SystemExit as exit_:
        code = int(exit_.code or 0)
    finally:
        GlobalHydra.instance().clear()
    out = capsys.readouterr()
    return code, out.out, out.err


def ls_args(files: dict[str, Path], data: Path) -> list[str]:
    return [
        *robot_args(files),
        f"data={data}",
        "estimator=ls",
        "~cost",
        "plots=false",
        "identified_urdf=false",
    ]


def test_a_duplicated_column_is_one_line_and_exit_1(files, tmp_path, monkeypatch, capsys):
    lines = files["train"].read_text().splitlines()
    header = lines[0].split(",")
    duplicated = tmp_path / "dup.csv"  # tau1 twice: the last one used to win silently
    duplicated.write_text(
        "\n".join([",".join([*header, "tau1"])] + [f"{line},0" for line in lines[1:]]) + "\n"
    )
    code, out, err = idkit_main(monkeypatch, capsys, *ls_args(files, duplicated), run_dir=tmp_path / "run")
    assert code == 1 and out == ""
    assert err.splitlines() == [
        f"idkit: {duplicated}: column 'tau1' appears twice (columns 5 and 8); which one is meant? "
        "Name each column once"
    ]
    assert not (tmp_path / "run" / "result.json").exists()


def test_a_two_second_gap_is_split_said_and_recorded(files, tmp_path, monkeypatch, capsys):
    text = files["train"].read_text().splitlines()
    gapped = tmp_path / "gap.csv"
    rows = [line.split(",") for line in text[1:]]
    for row in rows[1200:]:
        row[0] = repr(float(row[0]) + 2.0)
    gapped.write_text("\n".join([text[0], *(",".join(r) for r in rows)]) + "\n")
    with pytest.warns(GapWarning) as said:
        code, out, _ = idkit_main(monkeypatch, capsys, *ls_args(files, gapped), run_dir=tmp_path / "run")
    gaps = [w for w in said if w.category is GapWarning]
    assert code == 0 and len(gaps) == 1
    note = str(gaps[0].message)
    assert note.startswith(f"{gapped}: 1 gap(s) in the timestamps longer than 5 median steps (25 ms) at t = ")
    assert "not interpolated across: 2 segments preprocessed separately and stacked" in note
    data = json.loads((tmp_path / "run" / "result.json").read_text())
    gaps = data["data"]["preprocess"]["gaps"][str(gapped)]
    assert gaps["note"] == note and [s["raw"] for s in gaps["segments"]] == [1200, 1200]
    trim = int(np.ceil(3.0 / data["data"]["preprocess"]["cutoff"] * RATE))
    assert data["payload"]["estimate"]["details"]["uncertainty"]["dof"] == 3 * 2 * (1200 - 2 * trim) - 14


def test_validating_on_the_training_file_is_refused(files, tmp_path, monkeypatch, capsys):
    copy = tmp_path / "copy.csv"
    copy.write_bytes(files["train"].read_bytes())
    for held, how in ((files["train"], "same file"), (copy, "same content")):
        args = [*ls_args(files, files["train"]), f"validate=[{files['test']},{held}]"]
        code, out, err = idkit_main(monkeypatch, capsys, *args, run_dir=tmp_path / how.replace(" ", "_"))
        assert code == 1 and out == ""
        assert err.splitlines() == [
            f"idkit: validate file {held} is the training file {files['train']} ({how}): a score on the "
            "data the model was fitted to is not held-out validation; validate on a recording the fit "
            "does not see"
        ]
    excel = tmp_path / "excel.csv"  # other bytes, same samples: a byte-order mark and upper-case names
    excel.write_bytes(b"\xef\xbb\xbf" + files["train"].read_text().upper().encode())
    args = [*ls_args(files, f"[{files['train2']},{files['train']}]"), f"validate=[{excel}]"]
    code, out, err = idkit_main(monkeypatch, capsys, *args, run_dir=tmp_path / "excel")
    assert code == 1 and out == ""
    assert re.fullmatch(
        rf"idkit: validate file {excel} holds the same samples as the training data \(its rows \d+–\d+\): "
        r"a score on the data the model was fitted to is not held-out validation; .*\n",
        err,
    )
    train = single.load_data(URDFRobot(str(ASSET)), data=files["train"])[0]
    with pytest.raises(
        ValueError, match=r"validate file <Samples> is the training file <Samples> \(the same"
    ):
        single.run("cylindrical", "ls", None, data=train, validate=[train])


def test_a_file_given_twice_is_refused(files, tmp_path, monkeypatch, capsys):
    """data=[train.csv, train.csv] used to stack the file twice, each sample counting double in the
    fit, with exit 0; a copy of it (same bytes) is the same recording, and so is a validate= file
    given twice."""
    copy = tmp_path / "copy.csv"
    copy.write_bytes(files["train"].read_bytes())
    train, test = files["train"], files["test"]
    cases = [
        (
            [f"[{train},{files['train2']},{train}]"],
            f"data= gives {train} twice (same file)",
            "data",
        ),
        ([f"[{train},{copy}]"], f"data= gives {copy} twice (same content as {train})", "data"),
        (
            [str(train), f"validate=[{test},{test}]"],
            f"validate= gives {test} twice (same file)",
            "",
        ),
    ]
    for k, ((data, *more), said, role) in enumerate(cases):
        args = [*ls_args(files, data), *more]
        code, out, err = idkit_main(monkeypatch, capsys, *args, run_dir=tmp_path / str(k))
        effect = "would be stacked twice and count double in the fit" if role else "would be scored twice"
        assert code == 1 and out == ""
        assert err.splitlines() == [f"idkit: {said}: its samples {effect}; give each recording once"]
        assert not (tmp_path / str(k) / "result.json").exists()
    samples = single.load_data(URDFRobot(str(ASSET)), data=train)[0]
    with pytest.raises(ValueError, match=r"^data= gives <Samples> twice \(the same samples\)"):
        single.run("cylindrical", "ls", None, data=[samples, samples])


@pytest.mark.integration
def test_the_judged_bad_recordings_as_a_subprocess(files, tmp_path):
    """A duplicated column: one line, exit 1. A 2-second gap: one warning line naming it, exit 0."""
    lines = files["train"].read_text().splitlines()
    duplicated = tmp_path / "dup.csv"
    duplicated.write_text("\n".join([lines[0] + ",tau1", *(f"{line},0" for line in lines[1:])]) + "\n")
    rows = [line.split(",") for line in lines[1:]]
    for row in rows[1200:]:
        row[0] = repr(float(row[0]) + 2.0)
    gapped = tmp_path / "gap.csv"
    gapped.write_text("\n".join([lines[0], *(",".join(r) for r in rows)]) + "\n")
    runs = {}
    for name, path in (("dup", duplicated), ("gap", gapped)):
        runs[name] = subprocess.run(
            [
                sys.executable,
                "-c",
                "from idkit.cli import main; main()",
                *ls_args(files, path),
                f"hydra.run.dir={tmp_path / name}",
            ],
            capture_output=True,
            text=True,
            timeout=300,
            cwd=tmp_path,
        )
    assert runs["dup"].returncode == 1 and "Traceback" not in runs["dup"].stderr
    assert runs["dup"].stderr.strip().splitlines() == [
        f"idkit: {duplicated}: column 'tau1' appears twice (columns 5 and 8); which one is meant? "
        "Name each column once"
    ]
    assert runs["gap"].returncode == 0, runs["gap"].stderr
    assert "1 gap(s) in the timestamps longer than 5 median steps" in runs["gap"].stderr


# --- ROS logs by name (issue 16 item 1) -----------------------------------------------------------


def bag_of(csv_path: Path, folder: Path, drop: str | None = None) -> Path:
    """A ROS 2 MCAP bag of the raw CSV's samples: JointState with the joints in another order (and
    reversed in every other message), an extra gripper joint and an unrelated /status topic."""
    from bag_cases import Stream, write_ros2

    table = np.loadtxt(csv_path, delimiter=",", skiprows=1)
    names = ["d3", "theta1", "d2"]  # the driver's order; the robot's is theta1, d2, d3
    columns = {"theta1": 0, "d2": 1, "d3": 2}
    keep = [n for n in names if n != drop]
    order = [columns[n] for n in keep]
    stamps = 1_700_000_000_000_000_000 + np.round(table[:, 0] * 1e9).astype(np.int64)
    stream = Stream("/joint_states", stamps, keep, table[:, 1:4][:, order], None, table[:, 4:7][:, order])
    return write_ros2(folder, [stream])


def test_a_bag_gives_the_estimate_of_the_csv_of_the_same_samples(files, tmp_path):
    pytest.importorskip("rosbags")
    from bag_cases import storage_file

    bag = bag_of(files["train"], tmp_path / "bag")
    quiet = ["estimator=ls", "~cost", "plots=false", "identified_urdf=false"]
    reference, _ = command(*robot_args(files), f"data={files['train']}", *quiet, out=tmp_path / "csv")
    for name, path in (("folder", bag), ("file", storage_file(bag))):
        result, data = command(*robot_args(files), f"data={path}", *quiet, out=tmp_path / name)
        for key, value in reference.estimate.params.items():
            assert result.estimate.params[key] == pytest.approx(value, rel=1e-6, abs=1e-9), key
        assert data["data"]["logs"][str(path)]["ignored_joints"] == ["gripper"]
        assert data["data"]["logs"][str(path)]["ignored_topics"] == ["/status"]


def test_epoch_stamps_of_a_bag_and_of_a_csv_give_one_estimate_to_1e_9(files, tmp_path):
    """Nanosecond stamps since the epoch, jittered by up to 0.2 ms (as a real logger's): as float64
    seconds they keep ~0.2 µs, which moved an estimate by ~1e-4. Subtracting the first stamp exactly
    (integers in the bag, decimal text in the CSV) leaves the bag, its storage file and the CSV of
    the same samples one estimate."""
    pytest.importorskip("rosbags")
    from bag_cases import Stream, storage_file, write_ros2

    table = np.loadtxt(files["train"], delimiter=",", skiprows=1)
    jitter = np.random.default_rng(5).integers(0, 200_000, table.shape[0])
    stamps = 1_700_000_000_123_456_789 + np.round(table[:, 0] * 1e9).astype(np.int64) + jitter
    stream = Stream("/joint_states", stamps, ["theta1", "d2", "d3"], table[:, 1:4], None, table[:, 4:7])
    bag = write_ros2(tmp_path / "bag", [stream])
    csv = tmp_path / "epoch.csv"
    lines = ["t,q1,q2,q3,tau1,tau2,tau3"] + [
        f"{s // 10**9}.{s % 10**9:09d}," + ",".join(f"{v:.17g}" for v in row[1:])
        for s, row in zip(stamps.tolist(), table, strict=True)
    ]
    csv.write_text("\n".join(lines) + "\n")
    quiet = ["estimator=ls", "~cost", "plots=false", "identified_urdf=false", "preprocess.cutoff=5"]
    reference, _ = command(*robot_args(files), f"data={csv}", *quiet, out=tmp_path / "csv")
    for name, path in (("folder", bag), ("file", storage_file(bag))):
        result, _ = command(*robot_args(files), f"data={path}", *quiet, out=tmp_path / name)
        for key, value in reference.estimate.params.items():
            assert result.estimate.params[key] == pytest.approx(value, rel=1e-9, abs=1e-12), (name, key)


def test_a_bag_without_a_robot_joint_is_one_line_naming_it(files, tmp_path, monkeypatch, capsys):
    pytest.importorskip("rosbags")
    bag = bag_of(files["train"], tmp_path / "bag", drop="d2")
    code, out, err = idkit_main(monkeypatch, capsys, *ls_args(files, bag), run_dir=tmp_path / "run")
    assert code == 1 and out == ""
    assert err.splitlines() == [
        f"idkit: {bag}: /joint_states: the log has no joint 'd2' (the robot needs it); the log's joints: "
        "d3, theta1, gripper"
    ]
    code, _, err = idkit_main(
        monkeypatch, capsys, *ls_args(files, bag), "recording.topic=/tf", run_dir=tmp_path / "run2"
    )
    assert code == 1 and err.splitlines() == [
        f"idkit: {bag}: no topic '/tf' (recording.topic); the log's topics: /joint_states "
        "(sensor_msgs/msg/JointState), /status (std_msgs/msg/String)"
    ]


def test_a_torque_delay_on_samples_used_as_they_are_is_refused(files, tmp_path, monkeypatch, capsys):
    """delay=auto on a samples file (its torques are not shifted: there is no recording to estimate a
    delay on) used to end with exit 0 as if no delay had been asked for; so did any delay given for
    ``Samples`` in memory. A samples file in a data= list is refused before a cut-off is chosen."""
    robot = URDFRobot(str(ASSET), friction=True, offset=True)
    t, q, qd, qdd = motion(6.0, 0.2, 5)
    tau = robot.inverse_dynamics(truth(robot), *map(torch.from_numpy, (q, qd, qdd))).numpy()
    samples = tmp_path / "samples.npz"
    np.savez(samples, q=q, qd=qd, qdd=qdd, tau=tau)
    cases = (("auto", samples), ("auto", f"[{files['train']},{samples}]"), ("0.02", samples))
    for k, (delay, data) in enumerate(cases):
        args = [*ls_args(files, data), f"recording.torque_lag={delay}"]
        code, out, err = idkit_main(monkeypatch, capsys, *args, run_dir=tmp_path / str(k))
        assert code == 1 and out == "", err
        assert err.splitlines() == [
            f"idkit: {samples}: recording.torque_lag={delay} shifts a raw recording's torques, but this file "
            "holds samples used as they are (preprocess=on reads a samples file with timestamps as a "
            "recording)"
        ]
        assert not (tmp_path / str(k) / "result.json").exists()
    in_memory = single.load_data(robot, data=samples)[0]
    with pytest.raises(ValueError, match=r"^<Samples>: recording\.torque_lag=0\.01 shifts a raw recording's"):
        single.run(robot, "ls", None, data=in_memory, recording={"torque_lag": 0.01})
    assert single.run(robot, "ls", None, data=in_memory, recording={"torque_lag": 0}).estimate is not None


def test_a_torque_delay_is_estimated_applied_and_recorded(files, tmp_path):
    """Torques logged 4 samples (20 ms) after their states: delay=auto finds it (the lag where the
    robot's regressor explains the torques best), and the fit is as good as with the delay given, or
    without any delay in the log; ignoring the delay is worse."""
    robot = URDFRobot(str(ASSET), friction=True, offset=True)
    t, q, qd, qdd = motion(12.0, 0.2, 1)
    tau = robot.inverse_dynamics(truth(robot), *map(torch.from_numpy, (q, qd, qdd))).numpy()
    header = ["t", *(f"q{j}" for j in (1, 2, 3)), *(f"tau{j}" for j in (1, 2, 3))]
    late = tmp_path / "late.csv"  # tau logged at t belongs to the state at t - 20 ms
    table = np.column_stack([t[4:], q[4:], tau[:-4]])
    np.savetxt(late, table, delimiter=",", header=",".join(header), comments="", fmt="%.17g")
    quiet = ["estimator=ls", "~cost", "plots=false", "identified_urdf=false"]
    with pytest.warns(
        DelayWarning, match=r"late\.csv: the torques trail the states by (19\.[5-9]|20(\.[0-5])?) ms"
    ):
        found, data = command(
            *robot_args(files), f"data={late}", "recording.torque_lag=auto", *quiet, out=tmp_path / "a"
        )
    delay = data["data"]["delays"][str(late)]
    assert delay["seconds"] == pytest.approx(0.02, abs=5e-4) and delay["estimated"] is True
    given, _ = command(
        *robot_args(files), f"data={late}", "recording.torque_lag=0.02", *quiet, out=tmp_path / "b"
    )
    ignored, _ = command(*robot_args(files), f"data={late}", *quiet, out=tmp_path / "c")
    true = dict(zip(robot.base_param_names, robot.base_params(truth(robot)).tolist(), strict=True))

    def error(result):  # the largest base-parameter error relative to the largest base parameter
        scale = max(abs(v) for v in true.values())
        return max(abs(result.estimate.base_params[n] - v) for n, v in true.items()) / scale

    # the floor: the same samples logged without delay (the filtered states' own small error); the
    # estimated delay is within 0.5 ms of 20, which leaves at most 1/40 of the ignored delay's error
    aligned = tmp_path / "aligned.csv"
    np.savetxt(aligned, np.column_stack([t, q, tau]), delimiter=",", header=",".join(header), comments="")
    floor = error(command(*robot_args(files), f"data={aligned}", *quiet, out=tmp_path / "e")[0])
    assert error(given) < 1.1 * floor and error(ignored) > 5 * floor
    assert error(found) < 1.1 * floor + error(ignored) / 40
    with pytest.raises(
        ValueError, match=r"setting 'recording\.torque_lag' must be a float or 'auto', got 'soon'"
    ):
        command(*robot_args(files), f"data={late}", "recording.torque_lag=soon", *quiet, out=tmp_path / "d")


def test_a_current_recording_with_its_effort_scale_is_the_recording_in_newton_metres(files, tmp_path):
    """``robot.effort_scale`` applies to every torque idkit reads — the training file, the held-out one
    (their measured torques, scored and plotted), the automatic cut-off's choice: motor currents with
    their scale give the model and the held-out figures of the same recordings converted to N·m first
    (held-out ‖E‖/‖T‖ was ~900 % when the held-out currents went unscaled)."""
    scale = np.array([20.0, 50.0, 35.0])  # joint torque (N·m, N) per ampere

    def in_amperes(path: Path) -> Path:
        header = path.read_text().splitlines()[0]
        table = np.loadtxt(path, delimiter=",", skiprows=1)
        table[:, 4:7] /= scale
        out = tmp_path / f"amperes_{path.name}"
        np.savetxt(out, table, delimiter=",", header=header, comments="", fmt="%.17g")
        return out

    quiet = ["estimator=ls", "~cost", "plots=false", "identified_urdf=false"]
    newton, newton_json = command(
        *robot_args(files),
        f"data={files['train']}",
        f"validate=[{files['test']}]",
        *quiet,
        out=tmp_path / "nm",
    )
    amperes, amperes_json = command(
        *robot_args(files),
        "robot.effort_scale=[20,50,35]",
        f"data={in_amperes(files['train'])}",
        f"validate=[{in_amperes(files['test'])}]",
        *quiet,
        out=tmp_path / "a",
    )
    robot = URDFRobot(str(ASSET), friction=True, offset=True)
    _, q, qd, qdd = (torch.from_numpy(x) for x in motion(10.0, 0.3, 2))
    predicted = [
        robot.inverse_dynamics(
            torch.tensor([r.estimate.params[p] for p in robot.param_names], dtype=torch.float64), q, qd, qdd
        )
        for r in (newton, amperes)
    ]
    torch.testing.assert_close(
        predicted[1], predicted[0], rtol=1e-6, atol=1e-6 * float(predicted[0].abs().max())
    )
    held = [r.validation[0].scores for r in (newton, amperes)]
    np.testing.assert_allclose(held[1].measured, held[0].measured, rtol=1e-12)  # what the plot shows
    scores = [
        j["payload"]["validation"][str(p)]
        for j, p in ((newton_json, files["test"]), (amperes_json, tmp_path / "amperes_test.csv"))
    ]
    for key in ("rel_all", "rel_all_raw", "rms", "relative"):
        np.testing.assert_allclose(scores[1][key], scores[0][key], rtol=1e-6, err_msg=key)
    assert scores[0]["rel_all"] < 0.01
    assert (
        "torques: efforts as logged (e.g. motor currents), times robot.effort_scale per joint [20, 50, 35] → "
        "fitted and scored in joint torque (N·m; N on a prismatic joint)"
    ) in report.text(amperes).splitlines()
    assert "torques:" not in report.text(newton)
    torques = amperes_json["data"]["torques"]
    assert torques["effort_scale"] == [20.0, 50.0, 35.0] and torques["fitted"].startswith("joint torque (N·m")
    assert (
        "effort_scale" in torques["recorded"]
        and newton_json["data"]["torques"]["recorded"] == torques["fitted"]
    )
