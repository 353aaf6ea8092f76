"""KUKA LWR4+ identification on real recordings (skips when ../shared/data/kuka-lwr4 is absent)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from idkit.data.load import load_data_file
from idkit.reports import kuka as report
from idkit.studies.kuka import run, urdf_joint_data


def test_missing_recording_is_explained(tmp_path):
    with pytest.raises(FileNotFoundError, match="measurements_9"):
        load_data_file(tmp_path / "measurements_9.npz")
    with pytest.raises(FileNotFoundError, match="kuka_lwr4.urdf.*kuka.data_dir"):
        run(tmp_path)


@pytest.mark.kuka
def test_cad_friction_read_from_urdf(kuka_dir):
    data = urdf_joint_data(kuka_dir / "kuka_lwr4.urdf", ["lwr_0_joint", "lwr_6_joint"])
    np.testing.assert_array_equal(data["coulomb"], [0.5, 0.05])
    np.testing.assert_array_equal(data["viscous"], [1.0, 0.2])


@pytest.mark.kuka
def test_stride_thins_samples_and_times(kuka_dir):
    full = load_data_file(kuka_dir / "measurements_1.npz")
    thin = load_data_file(kuka_dir / "measurements_1.npz", stride=5)
    torch.testing.assert_close(thin.samples.q, full.samples.q[::5], rtol=0, atol=0)
    np.testing.assert_array_equal(thin.times, full.times[::5])


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


@pytest.mark.kuka
def test_pcls_rows_are_consistent_and_generalise_better_than_ls(kuka_dir, tmp_path):
    """Every 5th sample: LS leaves the physical set (links < 0) and predicts the faster
    measurements_3 worse than pcls with the CAD prior, whose links are all PSD."""
    study = run(
        kuka_dir,
        estimators=("ls", {"_name_": "pcls", "prior_weight": 300.0}),
        models=((True, True), (True, True, 0.05)),
        test=("measurements_3",),
        stride=5,
    )
    on_3 = {(r["model"], r["stribeck"]): r for r in study.rows if r["recording"] == "measurements_3"}
    ls, pcls = on_3[("LS", None)], on_3[("PCLS", None)]
    assert ls["links_negative"] > 0 and pcls["links_negative"] == 0 and pcls["min_eig"] > 0
    assert pcls["rel_all"] < 0.6 * ls["rel_all"]
    assert on_3[("PCLS", 0.05)]["links_negative"] == 0
    assert "min eig" in report.text(study) and "low-speed (0.05 rad/s)" in report.text(study)


@pytest.mark.kuka
def test_idkit_filter_replaces_the_files_derivatives_on_request(kuka_dir):
    study = run(
        kuka_dir,
        estimators=("ls",),
        models=((True, True),),
        test=("measurements_2",),
        stride=5,
        preprocess={"apply": "on", "cutoff": 5.0},
    )
    assert study.provenance.data["preprocess"]["cutoff"] == 5.0
    on_2 = next(r for r in study.rows if r["recording"] == "measurements_2" and r["model"] == "LS")
    assert on_2["rel_all"] < 0.05  # the identified model still predicts the repeated trajectory
