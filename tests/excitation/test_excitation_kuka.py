"""The KUKA LWR4+ excitation one can run: the task with its default budget, judged on the files it writes.

``t_end = 20 s``, the URDF's position, velocity and effort limits, accelerations bounded by
``measurements_1``'s peaks (given), 100 criterion samples, exported at 1 kHz. Judged: at rest at
both ends (``|qd|, |qdd| <= 1e-6``), every limit including effort kept on every exported sample
(re-checked from the CSV by ``idkit.excitation.check``, as before a run on the arm), no
self-collision (where pinocchio + coal are installed), ≥ 500 Hz, and a condition number better than
``measurements_1``'s computed the same way (100 samples spread evenly over the motion, and all of them).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from idkit.excitation.check import check_file
from idkit.excitation.criterion import excitation_criterion
from idkit.excitation.export import read_trajectory
from idkit.reports import excitation as report
from idkit.robots.urdf import URDFRobot
from idkit.studies import excitation as study

pytestmark = [pytest.mark.kuka, pytest.mark.slow]


@pytest.fixture(scope="module")
def kuka_run(tmp_path_factory):
    from tests.conftest import KUKA_DIR

    if not (KUKA_DIR / "measurements_1.npz").exists():
        pytest.skip(f"KUKA LWR4+ recordings not found in {KUKA_DIR}")
    record = np.load(KUKA_DIR / "measurements_1.npz")
    urdf = str(KUKA_DIR / "kuka_lwr4.urdf")
    peak = np.abs(record["accelerations"]).max(0).tolist()
    robot_spec = {"_name_": "urdf", "urdf": urdf, "friction": True, "offset": True}
    found = study.run(robot_spec, n_samples=100, t_end=20.0, acceleration_limit=peak, rate=1000.0, seed=0)
    files = report.write(found, tmp_path_factory.mktemp("kuka_excitation"), plots=False)
    return found, files, record, urdf, peak


def test_exported_at_1khz_at_rest_at_both_ends(kuka_run):
    found, files, _, urdf, _ = kuka_run
    robot = URDFRobot(urdf)
    for kind in ("csv", "npz"):
        trajectory = read_trajectory(files[kind], robot.joint_names)
        steps = np.diff(trajectory.t)
        assert len(trajectory.t) == 20001 and trajectory.t[-1] == 20.0
        assert 1 / steps.max() >= 500 and np.allclose(steps, 1e-3, rtol=1e-9, atol=0)
        for end in (0, -1):
            assert np.abs(trajectory.qd[end]).max() <= 1e-6 and np.abs(trajectory.qdd[end]).max() <= 1e-6


def test_every_limit_including_effort_is_kept_on_the_exported_samples(kuka_run):
    found, files, _, urdf, peak = kuka_run
    checked, acceleration = check_file(files["csv"], urdf, peak)
    assert acceleration.endswith("given (--acceleration-limit)")
    assert checked.violations == (), [v.line() for v in checked.violations]
    for joint, margins in checked.margins.items():
        assert set(margins) == {"position", "velocity", "acceleration", "effort"}, joint
        assert all(m["share"] >= 0.05 - 1e-9 for m in margins.values()), (joint, margins)  # the default
    assert checked.rate == pytest.approx(1000.0) and found.check.ok
    if checked.collision.startswith("checked"):
        assert "lwr_6_link (mesh not found)" in checked.collision  # the wrist's mesh is not shipped


def test_better_conditioned_than_measurements_1_computed_the_same_way(kuka_run):
    found, _, record, urdf, _ = kuka_run
    robot = URDFRobot(urdf, friction=True, offset=True)
    recorded = [torch.from_numpy(record[k]) for k in ("positions", "velocities", "accelerations")]
    n = len(record["times"])
    spread = np.rint(np.arange(1, 101) * (n - 1) / 100).astype(int)  # as sample_times(100, T) spreads
    recorded_100 = float(excitation_criterion(robot, "cond", *(x[spread] for x in recorded)))
    recorded_all = float(excitation_criterion(robot, "cond", *recorded))
    r = found.result
    optimised_all = float(excitation_criterion(robot, "cond", *r.excitation(r.grid)))
    assert r.after < recorded_100 / 5 and optimised_all < recorded_all / 5
    assert recorded_100 == pytest.approx(77.24, abs=0.01)  # 76.58 with every 50th sample (the bench)
