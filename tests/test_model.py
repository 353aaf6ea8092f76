"""``IdentifiedModel`` and ``idkit.identify``: predictions against pinocchio and MuJoCo (the KUKA
recordings where present, the cylindrical URDF always), numpy/torch in and out, batch shapes, σ,
saving, and the one-line entry running the command's study."""

from __future__ import annotations

import inspect
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

import idkit
from idkit.data import simulate
from idkit.model import IdentifiedModel
from idkit.robots.urdf import URDFRobot
from idkit.studies import single

KUKA = Path(__file__).resolve().parents[2] / "shared" / "data" / "kuka-lwr4"
BATCHES = ((), (7,), (2, 7))


@pytest.fixture(scope="module")
def arm() -> URDFRobot:
    """The paper's robot as a URDF, with every joint term the model writes: friction, offset, armature."""
    with warnings.catch_warnings():  # the first joint's armature merges with the link: said, and kept
        warnings.simplefilter("ignore", UserWarning)
        return URDFRobot("cylindrical", friction=True, offset=True, armature=True)


@pytest.fixture(scope="module")
def arm_model(arm) -> IdentifiedModel:
    """The arm with each body's CAD inertials scaled (so still physical: 1.1, 1.2, 1.3), and friction,
    offsets and armatures > 0."""
    values = arm.nominal_params().clone()
    for body in range(len(arm.tree.bodies)):
        values[10 * body : 10 * body + 10] *= 1.1 + 0.1 * body
    for k, name in enumerate(arm.param_names):
        if name.endswith((".fc", ".fv", ".armature")):
            values[k] = 0.3 + 0.1 * k
        elif name.endswith(".offset"):
            values[k] = (-1) ** k * 0.2
    return IdentifiedModel.from_params(arm, values)


def states(shape: tuple[int, ...], n: int, seed: int = 0) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    return tuple(rng.standard_normal((*shape, n)) for _ in range(3))


@pytest.mark.parametrize("batch", BATCHES, ids=str)
def test_predict_gives_numpy_for_numpy_and_torch_for_torch_over_any_batch(arm_model, batch):
    q, qd, qdd = states(batch, arm_model.robot.n_joints)
    flat = [torch.from_numpy(x.reshape(-1, x.shape[-1])) for x in (q, qd, qdd)]
    expected = arm_model.robot.inverse_dynamics(arm_model.vector, *flat).reshape(*batch, -1).numpy()
    from_numpy = arm_model.predict(q, qd, qdd)
    from_torch = arm_model.predict(*(torch.from_numpy(x) for x in (q, qd, qdd)))
    assert isinstance(from_numpy, np.ndarray) and from_numpy.dtype == np.float64
    assert isinstance(from_torch, torch.Tensor) and from_torch.dtype == torch.float64
    assert from_numpy.shape == from_torch.shape == (*batch, arm_model.robot.n_joints)
    np.testing.assert_allclose(from_numpy, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(from_torch.numpy(), expected, rtol=0, atol=1e-12)


def test_predict_keeps_a_tensors_dtype_and_gradient(arm_model):
    q, qd, qdd = (torch.from_numpy(x).float() for x in states((5,), arm_model.robot.n_joints))
    qdd.requires_grad_(True)
    tau = arm_model.predict(q, qd, qdd)
    assert tau.dtype == torch.float32 and tau.shape == (5, 3)
    tau.sum().backward()
    assert qdd.grad is not None and torch.isfinite(qdd.grad).all() and qdd.grad.abs().sum() > 0


def test_predict_refuses_mixed_types_and_shapes_that_do_not_fit(arm_model):
    q, qd, qdd = states((4,), 3)
    with pytest.raises(TypeError, match="all torch tensors or all numpy arrays"):
        arm_model.predict(torch.from_numpy(q), qd, qdd)
    with pytest.raises(ValueError, match=r"one shape \[\.\.\., 3\].*qd \(4, 2\)"):
        arm_model.predict(q, qd[:, :2], qdd)
    with pytest.raises(ValueError, match=r"one shape \[\.\.\., 3\]"):
        arm_model.predict(q[:, :2], qd[:, :2], qdd[:, :2])
    with pytest.raises(TypeError, match="real numbers"):
        arm_model.predict(q.astype(str), qd, qdd)


def test_to_pinocchio_plus_the_joint_terms_is_predict(arm_model):
    """pinocchio's RNEA on the identified URDF (with the armature to_pinocchio sets) plus Coulomb,
    viscous friction and offsets: the same torques as idkit's own dynamics."""
    pin = pytest.importorskip("pinocchio")
    model = arm_model.to_pinocchio()
    data = model.createData()
    q, qd, qdd = states((50,), 3, seed=1)
    rigid = np.stack([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd, strict=True)])
    order = [model.getJointId(name) - 1 for name in arm_model.joint_names]
    assert order == [0, 1, 2]  # one degree of freedom per joint, in the robot's order
    assert (model.armature > 0).all()
    term = {
        key: np.array([arm_model.params[f"{j}.{key}"] for j in arm_model.joint_names])
        for key in ("fc", "fv", "offset")
    }
    pinocchio = rigid + term["fc"] * np.sign(qd) + term["fv"] * qd + term["offset"]
    np.testing.assert_allclose(arm_model.predict(q, qd, qdd), pinocchio, rtol=0, atol=1e-9)


def test_a_missing_extra_is_named(arm_model, monkeypatch):
    monkeypatch.setitem(sys.modules, "pinocchio", None)  # "import pinocchio" now fails
    with pytest.raises(ImportError, match=r"pip install 'robot-idkit\[pinocchio\]'"):
        arm_model.to_pinocchio()
    monkeypatch.setitem(sys.modules, "mujoco", None)
    with pytest.raises(ImportError, match=r"pip install 'robot-idkit\[mjcf\]'"):
        arm_model.to_mujoco()


def test_save_writes_a_urdf_that_reads_back_to_the_same_parameters(arm_model, tmp_path):
    path = arm_model.save(tmp_path / "identified.urdf")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the merged armature, as for the arm
        again = URDFRobot(str(path), friction=True, offset=True, armature=True)
    inertial = [k for k, name in enumerate(again.param_names) if not name.endswith((".fc", ".fv", ".offset"))]
    np.testing.assert_allclose(
        again.nominal_params()[inertial], arm_model.vector[inertial], rtol=1e-12, atol=1e-12
    )


def test_save_refuses_an_unknown_suffix_and_never_truncates_a_file(arm, arm_model, tmp_path):
    with pytest.raises(ValueError, match=r"suffix '\.json'; use \.urdf .* or \.xml"):
        arm_model.save(tmp_path / "model.json")
    target = tmp_path / "identified.urdf"
    arm_model.save(target)
    before = target.read_bytes()
    massless = dict(arm_model.estimate.params, **{f"{arm.tree.bodies[0].link}.m": -1.0})
    with pytest.raises(ValueError, match="mass"):
        IdentifiedModel.from_params(arm, massless).save(target)
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["identified.urdf"]  # no temporary file left


def test_a_robot_without_a_file_cannot_be_saved():
    robot = idkit.registry.create("robot", "cylindrical")
    model = IdentifiedModel.from_params(robot, robot.nominal_params())
    with pytest.raises(ValueError, match="CylindricalRobot is not read from a URDF or MJCF file"):
        model.save("identified.urdf")


def test_the_estimate_must_name_the_robots_parameters(arm):
    with pytest.raises(ValueError, match=r"missing link1\.m, .* \(41 in all\), unknown none"):
        IdentifiedModel(arm, idkit.Estimate("x", {"link3.m": 1.0}, None, 0.0))
    with pytest.raises(ValueError, match=r"missing none, unknown tool\.m"):
        IdentifiedModel(
            arm, idkit.Estimate("x", {**dict.fromkeys(arm.param_names, 1.0), "tool.m": 1.0}, None, 0.0)
        )
    with pytest.raises(ValueError, match=r"params must be \[\d+\]"):
        IdentifiedModel.from_params(arm, [1.0, 2.0])


def test_sigma_is_the_estimates_for_base_parameters_and_for_physical_ones_standing_alone():
    """The paper's robot: alpha = (I + m3 s3z², m2, m3, m3 s3z). m2 and m3 are base parameters on their
    own, so their σ is theirs; s3z and I enter only in combinations: no σ, and the note says so."""
    model = idkit.run(estimator="ls", cost=None, scenario="torque_noise", seed=1).model
    reported = model.estimate.details["uncertainty"]["std"]
    assert dict(model.base_params.std) == pytest.approx(reported)
    assert model.params.std["m2"] == pytest.approx(reported["m2"])
    assert model.params.std["m3"] == pytest.approx(reported["m3"])
    assert model.params.std["s3z"] is None and model.params.std["I"] is None
    assert "2 of 4 physical parameters" in model.params.note
    assert dict(model.params) == model.estimate.params
    assert model.params.table()[0] == ("m2", model.estimate.params["m2"], reported["m2"])


def test_the_note_and_the_estimates_record_name_the_same_sigma_method():
    """One record: the note says, word for word, what ``details["uncertainty"]["std_source"]`` (and so
    ``result.json``) says, and that it is model-conditional (issue 31: the note called the σ plain
    least squares while result.json said HAC)."""
    model = idkit.run(estimator="ls", cost=None, scenario="torque_noise", seed=1).model
    uncertainty = model.estimate.details["uncertainty"]
    assert uncertainty["method"] == "hac"
    assert model.base_params.note.startswith(uncertainty["std_source"])
    assert model.params.note.startswith(uncertainty["std_source"])
    assert "HAC" in model.params.note and "model-conditional" in model.params.note
    assert "σ²(WᵀW)⁻¹" not in model.params.note


def test_an_estimator_without_an_uncertainty_report_gives_no_sigma_and_says_so():
    model = idkit.run(estimator={"_name_": "pso", "runs": 2, "particles": 6, "iterations": 10}, seed=0).model
    assert all(s is None for s in model.params.std.values())
    assert all(s is None for s in model.base_params.std.values())
    assert "reports no uncertainty" in model.params.note


@pytest.mark.filterwarnings("ignore:urdf export. pseudo-inertia:UserWarning")  # LS keeps no inertia physical
def test_identify_returns_the_model_with_its_held_out_scores_and_run(arm):
    truth = IdentifiedModel.from_params(arm, arm.nominal_params())
    train, test = (simulate(arm, "torque_noise", seed=s, n_samples=400) for s in (0, 1))
    model = idkit.identify(arm, train, validate=[test], estimator="ls", cost=None)
    assert isinstance(model, IdentifiedModel) and model.robot is arm
    assert model.result.estimate is model.estimate and model.result.model is model
    assert model.validation == tuple(model.result.validation) and len(model.validation) == 1
    held = model.validation[0].scores
    np.testing.assert_allclose(
        held.predicted, model.predict(test.q.numpy(), test.qd.numpy(), test.qdd.numpy())
    )
    measured = test.tau.numpy()
    assert held.rel_all == pytest.approx(np.linalg.norm(measured - held.predicted) / np.linalg.norm(measured))
    noiseless = truth.predict(test.q, test.qd, test.qdd)
    assert torch.linalg.norm(model.predict(test.q, test.qd, test.qdd) - noiseless) < 0.05 * torch.linalg.norm(
        noiseless
    )


@pytest.mark.parametrize(
    "typed",
    [(), ("estimator=ls",), ("robot.friction=false", "cost=f1"), ("estimator=pso", "robot.offset=false")],
    ids=str,
)
def test_identify_chooses_what_the_command_chooses(hydra_compose, typed):
    """``idkit robot=urdf robot.urdf=... data=... <typed>`` and ``idkit.identify`` with the same options
    given run the same estimator, cost and joint terms (the real-robot defaults of idkit.studies.defaults
    where not typed, the config's own otherwise)."""
    from idkit.api import _real_robot_defaults
    from idkit.cli.defaults import apply_real_robot_defaults
    from idkit.studies.defaults import RealRobotNote

    urdf = str(Path(idkit.__file__).parent / "robots" / "assets" / "cylindrical.urdf")
    overrides = ["robot=urdf", f"robot.urdf={urdf}", "data=train.csv", *typed]
    config = hydra_compose(*overrides)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RealRobotNote)
        apply_real_robot_defaults(config, overrides)
    robot: dict[str, object] = {"_name_": "urdf", "urdf": urdf}
    options: dict[str, object] = {}
    for item in typed:
        key, value = item.split("=")
        parsed = {"false": False, "true": True}.get(value, value)
        if key.startswith("robot."):
            robot[key.removeprefix("robot.")] = parsed
        else:
            options[key] = parsed
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RealRobotNote)
        robot, options = _real_robot_defaults(robot, "train.csv", options)
    defaults = inspect.signature(single.run).parameters
    estimator = options.get("estimator", defaults["estimator"].default)
    cost = options.get("cost", defaults["cost"].default)
    assert estimator == config.estimator["_name_"]
    assert cost == (None if config.get("cost") is None else config.cost["_name_"])
    assert (robot.get("friction", False), robot.get("offset", False)) == (
        config.robot.friction,
        config.robot.offset,
    )


def test_a_ready_robot_gets_the_real_robot_estimator_and_keeps_its_terms():
    from idkit.api import _real_robot_defaults
    from idkit.studies.defaults import RealRobotNote

    robot = URDFRobot("cylindrical")
    with pytest.warns(RealRobotNote, match="estimator=pcls cost=null"):
        kept, options = _real_robot_defaults(robot, "train.csv", {"seed": 3})
    assert kept is robot and options == {"seed": 3, "estimator": "pcls", "cost": None}
    assert _real_robot_defaults(robot, None, {}) == (robot, {})  # a simulation: the paper's defaults
    cylindrical = idkit.registry.create("robot", "cylindrical")
    assert _real_robot_defaults(cylindrical, "train.csv", {}) == (cylindrical, {})


# --- the KUKA LWR4+ recordings -------------------------------------------------------------------


@pytest.fixture(scope="module")
def kuka_model() -> IdentifiedModel:
    if not (KUKA / "measurements_1.npz").exists():
        pytest.skip(f"KUKA LWR4+ recordings not found in {KUKA}")
    robot = {"_name_": "urdf", "urdf": str(KUKA / "kuka_lwr4.urdf"), "friction": True, "offset": True}
    data, held = KUKA / "measurements_1.npz", KUKA / "measurements_3.npz"
    return idkit.identify(robot, data, validate=[held], estimator="pcls", cost=None)


@pytest.fixture(scope="module")
def kuka_held_out() -> tuple[np.ndarray, ...]:
    data = np.load(KUKA / "measurements_3.npz")
    return data["positions"], data["velocities"], data["accelerations"]


@pytest.mark.kuka
def test_kuka_predict_equals_pinocchios_rescore_of_the_saved_urdf(kuka_model, kuka_held_out, tmp_path):
    """Independent of idkit's dynamics: pinocchio's RNEA of the written identified.urdf plus the friction
    and offsets the file carries (idkit.verify.rescore), on every sample of measurements_3."""
    pytest.importorskip("pinocchio")
    from idkit.verify.rescore import predicted_torques, read_identified

    reference = predicted_torques(
        read_identified(kuka_model.save(tmp_path / "identified.urdf")), kuka_model.joint_names, *kuka_held_out
    )
    predicted = kuka_model.predict(*kuka_held_out)
    assert np.abs(reference).max() > 10  # N·m: a real arm's torques, not a degenerate case
    np.testing.assert_allclose(predicted, reference, rtol=0, atol=1e-9)
    np.testing.assert_allclose(kuka_model.validation[0].scores.predicted, predicted, rtol=0, atol=1e-9)


@pytest.mark.kuka
@pytest.mark.filterwarnings("ignore:mjcf. 1 collision mesh:UserWarning")  # a mesh the data set lacks
def test_kuka_predict_equals_mujocos_inverse_dynamics_of_to_mujoco(kuka_model, kuka_held_out):
    """MuJoCo's mj_inverse on to_mujoco() (contacts off: the converted arm's collision geoms overlap;
    damping and friction loss zeroed and added here, with the offsets the model carries)."""
    mujoco = pytest.importorskip("mujoco")
    model = kuka_model.to_mujoco()
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    fv, fc = model.dof_damping.copy(), model.dof_frictionloss.copy()
    model.dof_damping[:] = model.dof_frictionloss[:] = 0
    offsets = np.array([model.numeric(f"idkit:{j}.offset").data[0] for j in kuka_model.joint_names])
    data = mujoco.MjData(model)
    q, qd, qdd = kuka_held_out
    rigid = []
    for a, b, c in zip(q, qd, qdd, strict=True):
        data.qpos[:], data.qvel[:], data.qacc[:] = a, b, c
        mujoco.mj_inverse(model, data)
        rigid.append(data.qfrc_inverse.copy())
    reference = np.stack(rigid) + fc * np.sign(qd) + fv * qd + offsets
    np.testing.assert_allclose(kuka_model.predict(q, qd, qdd), reference, rtol=0, atol=1e-9)


@pytest.mark.kuka
def test_kuka_predict_over_batches_and_from_torch(kuka_model, kuka_held_out):
    q, qd, qdd = (x[:1000] for x in kuka_held_out)
    flat = kuka_model.predict(q, qd, qdd)
    two = kuka_model.predict(*(x.reshape(2, 500, 7) for x in (q, qd, qdd)))
    one = kuka_model.predict(q[3], qd[3], qdd[3])
    tensor = kuka_model.predict(*(torch.from_numpy(x) for x in (q, qd, qdd)))
    assert two.shape == (2, 500, 7) and one.shape == (7,)
    np.testing.assert_allclose(two.reshape(1000, 7), flat, rtol=0, atol=1e-12)
    np.testing.assert_allclose(one, flat[3], rtol=0, atol=1e-12)
    assert isinstance(tensor, torch.Tensor)
    np.testing.assert_allclose(tensor.numpy(), flat, rtol=0, atol=1e-12)


def test_predict_with_mixed_torch_dtypes_computes_in_the_wider_one(arm_model):
    """float32 with float64 ended in torch's "expected scalar type Double"."""
    q, qd, qdd = (torch.from_numpy(x) for x in states((6,), arm_model.robot.n_joints))
    mixed = arm_model.predict(q.float(), qd, qdd)
    assert mixed.dtype == torch.float64
    torch.testing.assert_close(mixed, arm_model.predict(q.float().double(), qd, qdd), rtol=0, atol=0)
    counts = arm_model.predict(q, qd, qdd.round().to(torch.int64))  # integers join as float64
    torch.testing.assert_close(counts, arm_model.predict(q, qd, qdd.round()), rtol=0, atol=0)
    assert arm_model.predict(q.half(), qd.float(), qdd.float()).dtype == torch.float32


@pytest.mark.parametrize(
    ("robot", "data", "error", "said"),
    [
        ("cylindrical", None, ValueError, "identify: no data (data=None); give the recordings"),
        (None, "train.csv", ValueError, "identify: robot is None; give a registry name"),
        ("cylindrical", 3.5, TypeError, "data=3.5 (float) is not recordings: give a file path"),
        ("cylindrical", ["a.csv", 2], TypeError, "data= holds 2 (int), not a recording"),
        ("cylindrical", {"q": 1}, TypeError, "data={'q': 1} (dict) is not recordings"),
    ],
)
def test_identify_without_usable_robot_or_data_says_so_in_one_line(robot, data, error, said):
    """``identify(urdf, None)`` fitted a simulation without a word; None and 3.5 ended in
    AttributeError / "'float' object is not iterable"."""
    with pytest.raises(error) as refused:
        idkit.identify(robot, data, estimator="ls", cost=None)
    assert str(refused.value).startswith(said) and "\n" not in str(refused.value)


def test_identify_refuses_a_validate_that_is_not_recordings(arm):
    train = simulate(arm, "clean", seed=0, n_samples=50)
    with pytest.raises(TypeError, match=r"^validate=0\.5 \(float\) is not recordings"):
        idkit.identify(arm, train, validate=0.5, estimator="ls", cost=None)
