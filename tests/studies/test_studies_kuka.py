"""KUKA LWR4+ identification on real recordings (skips when ../shared/data/kuka-lwr4 is absent)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from idkit.reports import kuka as report
from idkit.studies.kuka import load_recording, run, torque_metrics, urdf_joint_data


def test_torque_metrics_by_hand():
    measured = torch.tensor([[1.0, -2.0], [3.0, 2.0]], dtype=torch.float64)
    predicted = torch.tensor([[0.0, -2.0], [3.0, 0.0]], dtype=torch.float64)
    m = torque_metrics(measured, predicted, np.array([10.0, 4.0]))
    assert m["rms_j1"] == pytest.approx(np.sqrt(0.5))
    assert m["rms_j2"] == pytest.approx(np.sqrt(2.0))
    assert m["rel_j1"] == pytest.approx(np.sqrt(0.5) / np.sqrt(5.0))
    assert m["rel_j2"] == pytest.approx(np.sqrt(2.0) / np.sqrt(4.0))
    assert m["rel_all"] == pytest.approx(np.sqrt(5.0) / np.sqrt(18.0))
    assert m["nrms_limit"] == pytest.approx(np.sqrt((0.1**2 + 0.5**2) / 4))


def test_missing_recording_is_explained(tmp_path):
    with pytest.raises(FileNotFoundError, match="measurements_9"):
        load_recording(tmp_path / "measurements_9.npz")
    with pytest.raises(FileNotFoundError, match="kuka_lwr4.urdf.*kuka.data_dir"):
        run(tmp_path)


@pytest.mark.kuka
def test_cad_friction_read_from_urdf(kuka_dir):
    data = urdf_joint_data(kuka_dir / "kuka_lwr4.urdf", ["lwr_0_joint", "lwr_6_joint"])
    np.testing.assert_array_equal(data["effort"], [176.0, 38.0])
    np.testing.assert_array_equal(data["coulomb"], [0.5, 0.05])
    np.testing.assert_array_equal(data["viscous"], [1.0, 0.2])


def test_stride_thins_samples_and_times(kuka_dir):
    full, times = load_recording(kuka_dir / "measurements_1.npz")
    thin, thin_times = load_recording(kuka_dir / "measurements_1.npz", stride=5)
    torch.testing.assert_close(thin.q, full.q[::5], rtol=0, atol=0)
    np.testing.assert_array_equal(thin_times, times[::5])


@pytest.mark.kuka
def test_identification_with_friction_beats_cad_on_held_out(kuka_dir, tmp_path):
    """LS with friction on every 5th sample of measurements_1 predicts measurements_2 far better."""
    study = run(kuka_dir, estimators=("ls",), models=((True, False),), test=("measurements_2",), stride=5)
    rows = study.rows
    held_out = {r["model"]: r for r in rows if r["recording"] == "measurements_2"}
    cad, ls = held_out["CAD"], held_out["LS"]
    assert ls["rel_all"] < 0.6 * cad["rel_all"]
    assert ls["nrms_limit"] < 0.6 * cad["nrms_limit"]
    # measurements_2 repeats the training trajectory: the repeat's own torque difference is listed.
    assert "measurements_1 torques (same trajectory)" in held_out
    written = report.write(study, tmp_path, plots=False)
    for name in ("kuka_heldout.csv", "kuka_heldout.md", "result.json"):
        assert (tmp_path / name).stat().st_size > 0
    document = json.loads(Path(written["result"]).read_text())
    assert document["task"] == "kuka" and document["status"] == "complete"
    assert document["payload"]["estimates"][0]["estimate"]["estimator"] == "LS"
    with (tmp_path / "kuka_heldout.csv").open() as handle:
        assert len(list(csv.DictReader(handle))) == len(rows)


@pytest.mark.slow
@pytest.mark.kuka
def test_full_run_writes_table_and_plot(kuka_dir, tmp_path):
    """The README run: all default estimators and models on every sample, both held-out recordings."""
    study = run(kuka_dir)
    report.write(study, tmp_path)
    rows = study.rows
    on_2 = [r for r in rows if r["recording"] == "measurements_2"]
    best = min((r for r in on_2 if r["friction"] and r["model"] != "CAD"), key=lambda r: r["rel_all"])
    cad = next(r for r in on_2 if r["model"] == "CAD" and r["friction"])
    assert best["rel_all"] < 0.5 * cad["rel_all"]
    assert (tmp_path / "kuka_heldout_torques.png").stat().st_size > 10_000
