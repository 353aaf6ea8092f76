"""estimator=payload on the branched test robot: torques simulated by pinocchio with the payload
appended as its own body (an independent simulator), recovery, the reference recording, the
identified.urdf round trip, and the refusals."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from urdf_cases import TREE_URDF, pin_model, pin_torques_and_regressor, random_states

from idkit.estimators.payload import PayloadIdentification
from idkit.problem import IdentificationError, Problem, Recorded, Samples
from idkit.reports import payload as payload_report
from idkit.robots.inertia import standard_parameters
from idkit.robots.urdf import URDFRobot
from idkit.robots.urdf_export import identified_urdf

pin = pytest.importorskip("pinocchio")

MASS, COM = 0.7, np.array([0.03, -0.02, 0.1])
# A physical inertia (principal moments obey the triangle inequality: the payload's pseudo-inertia is
# positive definite, so the truth lies inside the estimator's constraints).
INERTIA = np.array([[0.002, 0.0003, -0.0001], [0.0003, 0.0025, 0.0002], [-0.0001, 0.0002, 0.0015]])


# The test robot with a tool mount welded to its continuous-joint link ``c`` (a rotated, offset frame).
FLANGED_URDF = TREE_URDF.replace(
    "</robot>",
    '  <link name="mount"/>\n  <joint name="mount_joint" type="fixed"><parent link="c"/>'
    '<child link="mount"/><origin xyz="0.05 -0.02 0.2" rpy="0.3 -0.4 1.0"/></joint>\n</robot>',
)


def simulate(
    robot: URDFRobot,
    urdf: str,
    joint: str | None,
    n: int,
    seed: int,
    noise: float = 0.0,
    placement: pin.SE3 | None = None,
    states: tuple[torch.Tensor, ...] | None = None,
) -> Samples:
    """Random states; pinocchio's torques of ``urdf`` with the payload appended to ``joint`` (at
    ``placement`` in its frame; none for ``joint=None``), plus Gaussian noise of ``noise`` × each
    joint's RMS torque. ``states`` replace the random ones."""
    model = pin_model(urdf)
    if joint is not None:
        inertia = pin.Inertia(MASS, COM, INERTIA)
        model.appendBodyToJoint(model.getJointId(joint), inertia, placement or pin.SE3.Identity())
    q, qd, qdd = random_states(robot, n, seed) if states is None else states
    torques, _ = pin_torques_and_regressor(robot, model, q, qd, qdd)
    rows = [model.joints[model.getJointId(name)].idx_v for name in robot.joint_names]
    tau = torch.as_tensor(torques[:, rows])
    generator = torch.Generator().manual_seed(seed + 1000)
    tau = tau + noise * tau.square().mean(0).sqrt() * torch.randn(
        tau.shape, generator=generator, dtype=torch.float64
    )
    return Samples(q, qd, qdd, tau)


@pytest.fixture(scope="module")
def tree() -> URDFRobot:
    return URDFRobot(TREE_URDF)


def payload_of(robot: URDFRobot, samples: Samples, **options) -> dict:
    return PayloadIdentification(**options).fit(Problem(robot, samples)).details["payload"]


def with_reference(robot: URDFRobot, samples: Samples, name: str, reference: Samples) -> Problem:
    """A problem whose reference recording ``name`` was read (as a study reads it) into ``reference``."""
    return Problem(robot, samples, recordings={name: Recorded(reference)})


def test_noise_free_payload_is_recovered_exactly(tree):
    found = payload_of(tree, simulate(tree, TREE_URDF, "j3", 200, seed=0), link="c")
    assert found["mass"] == pytest.approx(MASS, rel=1e-9)
    np.testing.assert_allclose(found["com"], COM, atol=1e-10)
    np.testing.assert_allclose(found["inertia"], INERTIA, atol=1e-10)
    assert found["rank"] == 10 and found["unidentifiable"] == []


def test_one_percent_noise_mass_and_centre_of_mass_within_the_judged_bounds(tree):
    found = payload_of(tree, simulate(tree, TREE_URDF, "j3", 500, seed=1, noise=0.01), link="c")
    assert abs(found["mass"] - MASS) < 0.01 * MASS
    assert np.linalg.norm(np.subtract(found["com"], COM)) < 0.003
    # and the standard deviations describe the errors (none beyond 4 sigma)
    assert abs(found["mass"] - MASS) < 4 * found["mass_std"]
    assert (np.abs(np.subtract(found["com"], COM)) < 4 * np.array(found["com_std"])).all()
    assert (np.abs(np.subtract(found["inertia"], INERTIA)) < 4 * np.array(found["inertia_std"])).all()


def test_a_payload_on_a_welded_mount_is_reported_in_the_mount_frame():
    robot = URDFRobot(FLANGED_URDF)
    model = pin_model(FLANGED_URDF)
    mount = model.frames[model.getFrameId("mount", pin.BODY)].placement  # in the frame of joint j3
    samples = simulate(robot, FLANGED_URDF, "j3", 300, seed=2, placement=mount)
    found = payload_of(robot, samples, link="mount")
    assert (found["link"], found["body"]) == ("mount", "c")
    np.testing.assert_allclose(found["com"], COM, atol=1e-10)
    np.testing.assert_allclose(found["inertia"], INERTIA, atol=1e-10)


#: Coulomb and viscous friction and offsets of the test robot's four joints.
DRIVE = (np.array([0.3, 0.2, 0.1, 0.25]), np.array([0.5, 0.4, 0.2, 0.3]), np.array([0.1, -0.2, 0.05, 0.3]))


def _with_drive_terms(robot: URDFRobot, samples: Samples, fc, fv, offset) -> Samples:
    """``samples`` with Coulomb, viscous friction and offsets added (numpy: pinocchio has none)."""
    qd = samples.qd.numpy()
    tau = samples.tau.numpy() + fc * np.sign(qd) + fv * qd + offset
    return Samples(samples.q, samples.qd, samples.qdd, torch.as_tensor(tau))


def test_the_reference_recording_cancels_a_ten_percent_error_of_the_arm_model(tree, tmp_path):
    truth = URDFRobot(TREE_URDF, friction=True, offset=True)
    fc, fv, offset = DRIVE
    nb = len(truth.link_names)
    wrong = truth.nominal_params().clone()
    scales = np.random.default_rng(3).choice([0.9, 1.1], nb)  # each link 10 % off (scaled: still physical)
    for i, scale in enumerate(scales):
        wrong[10 * i : 10 * i + 10] *= scale
    wrong[10 * nb :] = torch.as_tensor(np.concatenate([fc, fv, offset]) * 1.1)
    (tmp_path / "arm.urdf").write_text(identified_urdf(truth, wrong))
    model = URDFRobot(str(tmp_path / "arm.urdf"), friction=True, offset=True)  # the arm as identified
    data = _with_drive_terms(tree, simulate(tree, TREE_URDF, "j3", 400, seed=4, noise=0.01), fc, fv, offset)
    reference = _with_drive_terms(
        tree, simulate(tree, TREE_URDF, None, 400, seed=5, noise=0.01), fc, fv, offset
    )
    alone = payload_of(model, data, link="c")
    both = payload_of(model, data, link="c", reference=reference)
    error_alone, error_both = abs(alone["mass"] - MASS) / MASS, abs(both["mass"] - MASS) / MASS
    assert error_alone > 0.05  # the arm's errors leak into the payload ...
    assert error_both < 0.01 and np.linalg.norm(np.subtract(both["com"], COM)) < 0.003  # ... and cancel
    assert abs(both["mass"] - MASS) < 4 * both["mass_std"]


def test_the_arm_model_takes_the_friction_and_offsets_the_file_records(tree, tmp_path):
    truth = URDFRobot(TREE_URDF, friction=True, offset=True)
    fc, fv, offset = DRIVE
    params = truth.nominal_params().clone()
    params[10 * len(truth.link_names) :] = torch.as_tensor(np.concatenate([fc, fv, offset]))
    (tmp_path / "identified.urdf").write_text(identified_urdf(truth, params))
    data = _with_drive_terms(tree, simulate(tree, TREE_URDF, "j3", 200, seed=6), fc, fv, offset)
    held = URDFRobot(str(tmp_path / "identified.urdf"), friction=True, offset=True)
    estimate = PayloadIdentification(link="c").fit(Problem(held, data))
    assert estimate.details["payload"]["mass"] == pytest.approx(MASS, rel=1e-9)
    assert estimate.details["arm_model"]["joint_terms"]["j2.offset"] == pytest.approx(-0.2, abs=0)
    assert estimate.params["j4.fv"] == 0.3 and estimate.details["arm_model"]["not_recorded"] == []
    rigid = URDFRobot(str(tmp_path / "identified.urdf"))  # holds no joint terms: they are listed, not used
    left_out = PayloadIdentification(link="c").fit(Problem(rigid, data)).details
    assert set(left_out["arm_model"]["not_used"]) == {
        f"{j}.{k}" for j in held.joint_names for k in ("fc", "fv", "offset")
    }
    assert left_out["payload"]["rel_error"] > 0.01  # the friction it left out is not explained


def test_a_recorded_stribeck_scale_other_than_the_robots_is_refused(tmp_path):
    robot = URDFRobot(TREE_URDF, friction=True, stribeck_velocity=0.05)
    (tmp_path / "identified.urdf").write_text(identified_urdf(robot, robot.nominal_params()))
    other = URDFRobot(str(tmp_path / "identified.urdf"), friction=True, stribeck_velocity=0.1)
    samples = simulate(other, TREE_URDF, "j3", 50, seed=7)
    with pytest.raises(ValueError, match=r"records stribeck_velocity=0.05 for j1 but the robot uses 0.1"):
        PayloadIdentification(link="c").fit(Problem(other, samples))


def test_a_recorded_coulomb_scale_is_written_and_one_the_robot_lacks_is_refused(tmp_path):
    """An arm identified with ``tanh(q̇ / 0.05)`` Coulomb friction records the scale; the payload fit
    on a robot with the sign (or another scale) would subtract another friction: refused."""
    robot = URDFRobot(TREE_URDF, friction=True, coulomb_velocity=0.05)
    (tmp_path / "identified.urdf").write_text(identified_urdf(robot, robot.nominal_params()))
    assert "coulomb_velocity=0.05" in (tmp_path / "identified.urdf").read_text()
    path = str(tmp_path / "identified.urdf")
    samples = simulate(robot, TREE_URDF, "j3", 50, seed=7)
    for other, used in (
        (URDFRobot(path, friction=True), "0"),
        (URDFRobot(path, friction=True, coulomb_velocity=0.1), "0.1"),
    ):
        with pytest.raises(
            ValueError, match=rf"records coulomb_velocity=0.05 for j1 but the robot uses {used};"
        ):
            PayloadIdentification(link="c").fit(Problem(other, samples))
    same = URDFRobot(path, friction=True, coulomb_velocity=0.05)
    assert PayloadIdentification(link="c").fit(Problem(same, samples)).details["payload"]["mass"] > 0


@pytest.mark.parametrize("link", ["c", "mount"])
def test_identified_urdf_carries_the_payload_link_and_reads_back_merged(tmp_path, link):
    robot, model = URDFRobot(FLANGED_URDF), pin_model(FLANGED_URDF)
    placement = model.frames[model.getFrameId(link, pin.BODY)].placement
    samples = simulate(robot, FLANGED_URDF, "j3", 200, seed=8, noise=0.01, placement=placement)
    estimate = PayloadIdentification(link=link).fit(Problem(robot, samples))
    path = tmp_path / "identified.urdf"
    path.write_text(identified_urdf(robot, estimate.params, estimate.details["payload"]))
    back = URDFRobot(str(path))
    assert "payload" in back.tree.bodies[back.link_names.index("c")].welded
    values = list(estimate.params.values())
    np.testing.assert_allclose(back.nominal_params().numpy(), values, rtol=0, atol=1e-12)
    # pinocchio loads the written file (payload as a fixed child link) and agrees with idkit
    written = pin_model(str(path))
    assert written.frames[written.getFrameId("payload")].parentFrame == written.getFrameId("payload_joint")
    q, qd, qdd = random_states(back, 30, seed=9)
    torques, _ = pin_torques_and_regressor(back, written, q, qd, qdd)
    rows = [written.joints[written.getJointId(name)].idx_v for name in back.joint_names]
    expected = robot.inverse_dynamics(torch.tensor(values, dtype=torch.float64), q, qd, qdd)
    np.testing.assert_allclose(torques[:, rows], expected.numpy(), rtol=0, atol=1e-9)
    # the payload link is the fitted payload, in the frame of the link it was fitted on
    text = path.read_text()
    assert f'<parent link="{link}" />' in text.split('name="payload_joint"')[1].split("</joint>")[0]
    assert f'<mass value="{estimate.details["payload"]["mass"]!r}" />' in text


def test_the_payload_link_name_avoids_taken_names(tree, tmp_path):
    estimate = PayloadIdentification(link="c").fit(
        Problem(tree, simulate(tree, TREE_URDF, "j3", 100, seed=10))
    )
    once = identified_urdf(tree, estimate.params, estimate.details["payload"])
    (tmp_path / "once.urdf").write_text(once)
    again = URDFRobot(str(tmp_path / "once.urdf"))  # its payload is now part of the arm
    twice = identified_urdf(again, again.nominal_params(), estimate.details["payload"])
    assert '<link name="payload">' in twice and '<link name="payload_2">' in twice


def test_rewriting_an_identified_urdf_keeps_the_terms_the_fit_does_not_hold(tmp_path):
    robot = URDFRobot(TREE_URDF, friction=True, offset=True, stribeck_velocity=0.05)
    params = robot.nominal_params().clone()
    params[-4:] = torch.tensor([0.1, 0.2, 0.3, 0.4], dtype=torch.float64)  # offsets
    params[-8:-4] = torch.tensor([-0.01, -0.02, -0.03, -0.04], dtype=torch.float64)  # fs
    (tmp_path / "first.urdf").write_text(identified_urdf(robot, params))
    offsets_only = URDFRobot(str(tmp_path / "first.urdf"), offset=True)
    moved = offsets_only.nominal_params().clone()
    moved[-4:] = torch.tensor([1.0, 2.0, 3.0, 4.0], dtype=torch.float64)
    text = identified_urdf(offsets_only, moved)
    assert text.count("idkit: ") == 4  # one comment per joint, not a second one
    assert "<!-- idkit: fs=-0.02 offset=2.0 stribeck_velocity=0.05 (no URDF field) -->" in text


def test_a_trajectory_that_cannot_identify_the_payload_says_so():
    robot = URDFRobot("cylindrical")  # prismatic last joint: the payload's inertia never shows
    t = torch.linspace(0.5, 10, 60, dtype=torch.float64)
    q, qd, qdd = robot.excitation(t)
    truth = robot.nominal_params().clone()
    truth[20] += 0.5  # half a kilogram on link3
    samples = Samples(q, qd, qdd, robot.inverse_dynamics(truth, q, qd, qdd))
    estimate = PayloadIdentification().fit(Problem(robot, samples))
    found = estimate.details["payload"]
    assert found["mass"] == pytest.approx(0.5, rel=1e-6) and found["rank"] < 10
    assert any("payload.Ixx" in d for d in found["unidentifiable"])
    assert np.isinf(np.array(found["inertia_std"])).any()
    assert found["verdict"]["mass"] and not found["verdict"]["inertia"]
    lines = payload_report.lines(estimate.details)
    assert "  mass            identified      0.5 ± " in "\n".join(lines)
    assert any(line.startswith("  inertia         not identified") for line in lines)
    assert any(line.startswith("not identified, free: ") and "the inertia's Ixx" in line for line in lines)
    assert not any("setLoad(" in line or "set_target_payload(" in line for line in lines)


@pytest.mark.parametrize(
    ("inserted", "message"),
    [
        ('<dynamics friction="abc"/>', r"joint 'j2': <dynamics friction> is 'abc', not a number$"),
        (
            "<!-- idkit: offset=1.2.3 -->",
            r"joint 'j2': offset of its idkit: comment is '1\.2\.3', not a number$",
        ),
    ],
)
def test_a_recorded_joint_term_that_is_no_number_is_named(inserted, message):
    """The arm model reads these; a bare 'could not convert string to float' named neither file nor joint."""
    from idkit.robots.joint_terms import recorded_joint_terms

    tag = '<joint name="j2" type="prismatic">'
    robot = URDFRobot(TREE_URDF.replace(tag, tag + inserted, 1), friction=True, offset=True)
    with pytest.raises(ValueError, match=r"^urdf \(<URDF text>\): " + message):
        recorded_joint_terms(robot)


def test_bad_input_is_refused_in_one_line(tree, cylindrical):
    samples = simulate(tree, TREE_URDF, "j3", 50, seed=11)
    with pytest.raises(ValueError) as unknown:
        PayloadIdentification(link="gripper").fit(Problem(tree, samples))
    message = str(unknown.value)
    assert "\n" not in message and "'gripper'" in message
    assert all(name in message for name in ("a", "b (welded: tool)", "c", "d"))
    with pytest.raises(
        ValueError, match=r"the tree has 2 end links \(c, d\); choose one with estimator.link="
    ):
        PayloadIdentification().fit(Problem(tree, samples))
    with pytest.raises(ValueError, match=r"never moves"):
        PayloadIdentification(link="pedestal").fit(Problem(tree, samples))
    q, qd, qdd = cylindrical.excitation(torch.linspace(0.5, 10, 20, dtype=torch.float64))
    plain = Samples(q, qd, qdd, cylindrical.inverse_dynamics(cylindrical.nominal_params(), q, qd, qdd))
    with pytest.raises(
        ValueError, match=r"^payload: needs a robot with a kinematic tree .* got CylindricalRobot$"
    ):
        PayloadIdentification().fit(Problem(cylindrical, plain))
    few = Samples(samples.q[:2], samples.qd[:2], samples.qdd[:2], samples.tau[:2])
    with pytest.raises(IdentificationError, match=r"8 equations"):
        PayloadIdentification(link="c").fit(Problem(tree, few))
    with pytest.raises(ValueError, match=r"reference file three_joints.npz has 3 joints but the robot has 4"):
        PayloadIdentification(link="c", reference="three_joints.npz").fit(
            with_reference(tree, samples, "three_joints.npz", plain)
        )
    with pytest.raises(
        ValueError, match=r"^payload: the reference file unread.npz was not read: an estimator reads"
    ):
        PayloadIdentification(link="c", reference="unread.npz").fit(Problem(tree, samples))
    with pytest.raises(
        ValueError, match=r"^payload: min_mass must be .*a finite number >= 0 \(kg\), got -1.0$"
    ):
        PayloadIdentification(min_mass=-1.0)


def test_a_non_physical_truth_is_fitted_on_the_boundary_of_the_cone(tree):
    """Principal moments that break the triangle inequality: least squares leaves the cone, the conic
    program returns the closest real body (smallest pseudo-inertia eigenvalue 0), and both solvers agree."""
    model = pin_model(TREE_URDF)
    wrong = np.diag([0.001, 0.001, 0.003])  # 0.001 + 0.001 < 0.003: no rigid body has it
    model.appendBodyToJoint(model.getJointId("j3"), pin.Inertia(MASS, COM, wrong), pin.SE3.Identity())
    q, qd, qdd = random_states(tree, 200, seed=12)
    torques, _ = pin_torques_and_regressor(tree, model, q, qd, qdd)
    rows = [model.joints[model.getJointId(name)].idx_v for name in tree.joint_names]
    samples = Samples(q, qd, qdd, torch.as_tensor(torques[:, rows]))
    fits = {
        solver: PayloadIdentification(link="c", solver=solver).fit(Problem(tree, samples))
        for solver in ("clarabel", "scs")
    }
    found = fits["clarabel"].details
    assert found["status"] == "optimal" and found["solver"] == "CLARABEL"
    assert -1e-9 < found["payload"]["min_eigenvalue"] < 1e-6
    assert found["payload"]["rel_error"] > 1e-6  # the real body fits worse (least squares: ~1e-15)
    assert found["payload"]["mass"] == pytest.approx(MASS, rel=0.05)
    for key in ("mass", "com", "inertia"):
        np.testing.assert_allclose(
            fits["scs"].details["payload"][key], found["payload"][key], rtol=0, atol=1e-3
        )


def _unmodelled(samples: Samples) -> Samples:
    """Repeatable torques outside the rigid-body model: cogging 0.3 N·m sin(6 q) and a friction
    0.4 N·m tanh(q̇ / 0.05) on every joint."""
    extra = 0.3 * torch.sin(6 * samples.q) + 0.4 * torch.tanh(samples.qd / 0.05)
    return Samples(samples.q, samples.qd, samples.qdd, samples.tau + extra)


def smooth_states(n: int) -> tuple[torch.Tensor, ...]:
    """A smooth 20 s motion of the test robot (sines; the prismatic j2 inside its 0–0.5 m)."""
    t = torch.linspace(0, 20, n, dtype=torch.float64)[:, None]
    omega = 2 * torch.pi * torch.tensor([0.11, 0.17, 0.23, 0.31], dtype=torch.float64)
    amplitude = torch.tensor([1.5, 0.2, 2.5, 0.8], dtype=torch.float64)
    centre = torch.tensor([0.0, 0.25, 0.0, 0.0], dtype=torch.float64)
    phase = omega * t + torch.tensor([0.0, 1.0, 2.0, 3.0], dtype=torch.float64)
    return (
        centre + amplitude * torch.sin(phase),
        amplitude * omega * torch.cos(phase),
        -amplitude * omega**2 * torch.sin(phase),
    )


def test_the_same_trajectory_replayed_cancels_what_the_model_cannot(tree, tmp_path):
    """Noise-free, so that what is left is the method's: with the reference on the same states both
    corrections cancel the arm's 10 % error and torques outside the model exactly (``model``: the
    payload's columns lie in the span of the arm's, so only the difference of the recordings
    determines them); without a reference the payload absorbs both."""
    wrong = tree.nominal_params().clone()
    for i, scale in enumerate([1.1, 0.9, 1.1, 0.9]):
        wrong[10 * i : 10 * i + 10] *= scale
    (tmp_path / "arm.urdf").write_text(identified_urdf(tree, wrong))
    model = URDFRobot(str(tmp_path / "arm.urdf"))
    states = smooth_states(400)
    data = _unmodelled(simulate(tree, TREE_URDF, "j3", 400, seed=13, states=states))
    bare = _unmodelled(simulate(tree, TREE_URDF, None, 400, seed=13, states=states))
    for correction in ("model", "samples"):
        details = (
            PayloadIdentification(link="c", reference="bare.npz", correction=correction)
            .fit(with_reference(model, data, "bare.npz", bare))
            .details
        )
        assert details["payload"]["mass"] == pytest.approx(MASS, rel=1e-8), correction
        np.testing.assert_allclose(details["payload"]["com"], COM, atol=1e-9)
    assert details["reference"]["max_mismatch"] == 0.0
    assert any("subtracted sample by sample" in line for line in payload_report.lines(details))
    alone = PayloadIdentification(link="c").fit(Problem(model, data)).details["payload"]
    assert abs(alone["mass"] - MASS) > 0.05 * MASS


def test_correction_by_samples_refuses_another_trajectory(tree):
    data = simulate(tree, TREE_URDF, "j3", 100, seed=15)
    shorter = simulate(tree, TREE_URDF, None, 90, seed=15)
    with pytest.raises(
        ValueError, match=r"shorter.npz has 90 samples, the data 100 \(use correction=model\)$"
    ):
        PayloadIdentification(link="c", reference="shorter.npz", correction="samples").fit(
            with_reference(tree, data, "shorter.npz", shorter)
        )
    moved = Samples(data.q.clone(), data.qd, data.qdd, data.tau)
    moved.q[17, 2] += 0.2
    with pytest.raises(ValueError, match=r"<Samples> differs from the data by 0.2 at sample 17, joint j3"):
        PayloadIdentification(link="c", reference=moved, correction="samples").fit(Problem(tree, data))
    with pytest.raises(
        ValueError, match=r"^payload: correction must be one of 'model', 'samples', got 'both'$"
    ):
        PayloadIdentification(correction="both")


def test_an_mjcf_arm_gives_its_damping_frictionloss_and_offsets(tmp_path):
    pytest.importorskip("mujoco")
    from idkit.robots.joint_terms import recorded_joint_terms
    from idkit.robots.mjcf import MJCFRobot
    from idkit.robots.mjcf_export import identified_mjcf

    robot = MJCFRobot("arm", friction=True, offset=True)
    params = robot.nominal_params().clone()
    params[-9:] = torch.tensor(
        [0.1, 0.1, 0.5, 0.2, 0.2, 1.0, 0.05, -0.1, 0.2], dtype=torch.float64
    )  # fc fv offset
    (tmp_path / "identified.xml").write_text(identified_mjcf(robot, params))
    written = MJCFRobot(str(tmp_path / "identified.xml"), friction=True, offset=True)
    terms = recorded_joint_terms(written)  # frictionloss, damping and the idkit numerics
    assert [terms[name] for name in written.param_names[-9:]] == pytest.approx(
        params[-9:].tolist(), abs=1e-12
    )
    # a payload on link3 (the slide's body), the arm's drive terms subtracted as the file records them
    truth = written.nominal_params().clone()
    truth[20:30] += torch.as_tensor(
        standard_parameters(0.4, np.array([0.05, 0.0, 0.02]), np.diag([1e-3, 2e-3, 2e-3]))
    )
    truth[-9:] = params[-9:]
    q, qd, qdd = written.random_states(300, torch.Generator().manual_seed(16))
    samples = Samples(q, qd, qdd, written.inverse_dynamics(truth, q, qd, qdd))
    found = PayloadIdentification().fit(Problem(written, samples)).details
    assert found["payload"]["link"] == "link3" and found["arm_model"]["not_recorded"] == []
    assert found["payload"]["mass"] == pytest.approx(0.4, rel=1e-6)
