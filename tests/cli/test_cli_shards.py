"""A sharded robustness study through Hydra's joblib and submitit (local) launchers, merged by the
sweep's callback into the numbers of one process."""

from __future__ import annotations

import json

import pytest
from test_cli_command import idkit, only

SMALL_STUDY = [
    "+experiment=robustness", "trials=5", "plots=false", "seed=2",
    "robustness.scenarios=[torque_noise,outliers]",
    "robustness.estimators=[{_name_:ls,relative:true},{_name_:rls,relative:true}]",
    "robustness.pso_costs=[f13,f14,huber]",
    "estimator.runs=2", "estimator.particles=6", "estimator.iterations=15",
]  # fmt: skip


def _without_times(row: dict) -> dict:
    return {k: v for k, v in row.items() if k != "mean_fit_time_s"}


def _sweep_merges_into_the_one_process_study(tmp_path, launcher: list[str]) -> None:
    """Two shards through ``launcher``; the sweep's callback must merge them into what one process
    writes: the same per-trial file and the same summary (times aside)."""
    one = idkit(*SMALL_STUDY, "hydra.run.dir=single", cwd=tmp_path)
    assert one.returncode == 0, one.stderr
    sweep = idkit(
        "-m", *SMALL_STUDY, "robustness.shard=0,1", "robustness.shards=2", *launcher, "hydra.sweep.dir=sweep",
        cwd=tmp_path,
    )  # fmt: skip
    assert sweep.returncode == 0, sweep.stderr
    merged = tmp_path / "sweep" / "merged"
    single = tmp_path / "single"
    assert (merged / "robustness_trials.csv").read_text() == (single / "robustness_trials.csv").read_text()
    document = json.loads((merged / "result.json").read_text())
    assert document["status"] == "complete" and document["progress"]["done"] == 5
    expected = json.loads((single / "result.json").read_text())["payload"]["summary"]
    assert [_without_times(r) for r in document["payload"]["summary"]] == [
        _without_times(r) for r in expected
    ]
    assert only(list((tmp_path / "sweep").glob("merged*"))) == merged


@pytest.mark.integration
@pytest.mark.filterwarnings("ignore")
def test_two_shards_through_joblib_merge_into_the_one_process_study(tmp_path):
    _sweep_merges_into_the_one_process_study(tmp_path, ["hydra/launcher=joblib", "hydra.launcher.n_jobs=2"])


@pytest.mark.integration
@pytest.mark.filterwarnings("ignore")
def test_two_shards_through_submitit_local_merge_into_the_one_process_study(tmp_path):
    """Submitit's local executor: each shard a separate job process, as on a SLURM cluster
    (``submitit_slurm`` takes the same sweep, with a partition), its logs under the sweep."""
    _sweep_merges_into_the_one_process_study(
        tmp_path, ["hydra/launcher=submitit_local", "hydra.launcher.timeout_min=10"]
    )
    assert list((tmp_path / "sweep" / ".submitit").glob("*/*_log.out"))  # the jobs ran through submitit
