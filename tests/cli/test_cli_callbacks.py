"""The multirun callback's merge of a sharded robustness study (in-process; the launcher test is
``test_cli_shards.py``)."""

from __future__ import annotations

import logging

import numpy as np

from idkit.cli.callbacks import merge_shards
from idkit.reports import robustness as report
from idkit.studies import robustness

STUDY = {
    "estimator": {"_name_": "pso", "runs": 2, "particles": 6, "iterations": 15},
    "scenarios": ["torque_noise"],
    "estimators": [{"_name_": "rls", "relative": True}],
    "pso_costs": ["f13", "f14"],
    "progress": False,
}


def _shard(sweep, job: int, shard: int, seed: int = 0) -> None:
    study = robustness.run(trials=5, shard=shard, shards=2, seed=seed, **STUDY)
    study.provenance.config = {"seed": seed, "plots": False, "robustness": {"shard": shard, "shards": 2}}
    report.write(study, sweep / str(job), plots=False)


def test_callback_merges_each_sharded_study_of_a_sweep(tmp_path):
    for job, (seed, shard) in enumerate([(0, 0), (0, 1), (1, 0), (1, 1)]):
        _shard(tmp_path, job, shard, seed)
    written = merge_shards(tmp_path)
    assert [p.name for p in written] == ["merged_0", "merged_1"]
    for folder, seed in zip(written, (0, 1), strict=True):
        merged, whole = robustness.load(folder), robustness.run(trials=5, seed=seed, **STUDY)
        assert merged.seed == seed and merged.provenance.status == "complete"
        for label, values in whole.params["torque_noise"].items():
            np.testing.assert_allclose(merged.params["torque_noise"][label], values, rtol=1e-15)


def test_callback_leaves_a_study_with_a_missing_shard_unmerged(tmp_path, caplog):
    _shard(tmp_path, 0, 1)
    with caplog.at_level(logging.WARNING):
        assert merge_shards(tmp_path) == []
    assert "shards [0] missing" in caplog.text
