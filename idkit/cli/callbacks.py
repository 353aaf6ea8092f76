"""Hydra callbacks: a taken run or sweep folder refused, and every job of a multirun gathered into
``summary.csv`` and ``summary.md``.

:class:`RunFolderCheck` refuses a run or sweep folder that another run used before Hydra writes
into it (see :mod:`idkit.cli.provenance`).

:class:`MultirunSummary` rebuilds the summary from the job folders on disk after every job (under a
file lock, since parallel launchers end jobs concurrently) and once more at the end of the sweep.
Rebuilding from disk is what lets a failing job leave the others intact: Hydra stops calling back
once a job has failed, but by then the summary already lists every job that finished, and the
failed one has an ``error.json`` in its folder. Import-light (no torch): Hydra instantiates the
callbacks in the launching process.

At the end of the sweep, the jobs of a sharded robustness study (``robustness.shard=0,1
robustness.shards=2``) are merged into one report in ``<sweep>/merged`` (``merged_<k>`` when the
sweep holds several sharded studies), so no manual merge call is needed.
"""

from __future__ import annotations

import contextlib
import json
import logging
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from hydra.core.utils import JobReturn, JobStatus
from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from idkit.cli.provenance import ERROR_FILE, RUN_FILES, RunDirectoryTaken, claim, refusal, run_files

log = logging.getLogger(__name__)

SUMMARY_CSV = "summary.csv"
SUMMARY_MD = "summary.md"
MERGED_DIR = "merged"
#: What Hydra writes into a sweep folder before its first job.
MULTIRUN_FILE = "multirun.yaml"


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    try:
        import fcntl
    except ImportError:  # Windows: no advisory locks; the atomic writes still keep files whole
        yield
        return
    with open(path, "a+") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def _overrides(job_dir: Path) -> str:
    import yaml

    file = job_dir / ".hydra" / "overrides.yaml"
    if not file.exists():
        return ""
    return " ".join(yaml.safe_load(file.read_text()) or [])


def _job_number(path: Path) -> tuple[int, str]:
    return (int(path.name), "") if path.name.isdigit() else (1 << 30, path.name)


def _row_from_result(document: dict[str, Any], params: list[str]) -> dict[str, Any]:
    """Envelope keys of any task's ``result.json``; a single fit adds its estimate and errors."""
    progress = document.get("progress") or {}
    row: dict[str, Any] = {
        "status": document.get("status"),
        "task": document.get("task"),
        "label": document.get("label"),
        "progress": f"{progress.get('done')}/{progress.get('requested')}" if progress else None,
    }
    payload = document.get("payload") or {}
    estimate = payload.get("estimate") or {}
    for name, value in (estimate.get("params") or {}).items():
        row[name] = value
        if name not in params:
            params.append(name)
    cost = payload.get("cost") or {}
    row.update(
        parameter_error=payload.get("parameter_error"),
        cost_name=cost.get("name"),
        cost=cost.get("value"),
        cost_ignored=cost.get("used_by_fit") is False,
        wall_time_s=estimate.get("wall_time_s", payload.get("wall_time_s")),
    )
    return row


def summary_rows(sweep_dir: Path) -> tuple[list[str], list[dict[str, Any]]]:
    """One row per job folder: status, overrides, task, label, parameters, errors, cost, time."""
    rows: list[dict[str, Any]] = []
    params: list[str] = []
    for job_dir in sorted((p for p in sweep_dir.iterdir() if p.is_dir()), key=_job_number):
        result, error = job_dir / "result.json", job_dir / ERROR_FILE
        row: dict[str, Any] = {"job": job_dir.name, "overrides": _overrides(job_dir)}
        if result.exists():
            row.update(_row_from_result(json.loads(result.read_text()), params))
        elif error.exists():
            row.update(status="failed", error=json.loads(error.read_text()).get("error"))
        else:
            row.update(status="running or killed")
        rows.append(row)
    mark_repeats(rows)
    header = [
        "job",
        "status",
        "overrides",
        "task",
        "label",
        "progress",
        *params,
        "parameter_error",
        "cost_name",
        "cost",
        "wall_time_s",
        "repeats",
        "error",
    ]
    return header, rows


def mark_repeats(rows: list[dict[str, Any]]) -> None:
    """``repeats``: for a job whose estimator ignores ``cost=`` (LS, TLS, RLS …), the earlier job it
    differs from only in ``cost=`` — the same fit, run again (its note says so once)."""
    first: dict[str, str] = {}
    for row in rows:
        if not row.pop("cost_ignored", False):
            continue
        others = " ".join(
            o for o in str(row.get("overrides", "")).split() if not o.lstrip("+~").startswith("cost=")
        )
        if others in first:
            row["repeats"] = f"job {first[others]} (the estimator ignores cost=)"
        else:
            first[others] = str(row["job"])


def write_summary(sweep_dir: Path) -> None:
    """Rebuild ``summary.csv`` and ``summary.md`` in ``sweep_dir`` from its job folders."""
    from idkit.reports import files
    from idkit.reports.tables import markdown_table

    header, rows = summary_rows(sweep_dir)
    table = [[row.get(k) for k in header] for row in rows]
    files.write_csv(sweep_dir / SUMMARY_CSV, header, table)
    files.write_text(sweep_dir / SUMMARY_MD, markdown_table(header, table) + "\n")


def sweep_files(folder: Path) -> list[str]:
    """What another sweep left in ``folder``: its own files and each job folder's run files."""
    if not folder.is_dir():
        return []
    names = (MULTIRUN_FILE, SUMMARY_CSV, SUMMARY_MD, *RUN_FILES)
    found = [name for name in names if (folder / name).exists()]
    for job in sorted(p for p in folder.iterdir() if p.is_dir()):
        found += [f"{job.name}/{name}" for name in run_files(job)]
    return found


def claim_sweep(sweep_dir: Path) -> None:
    """Refuse ``sweep_dir`` when another sweep (or run) used it.

    Raises:
        idkit.cli.provenance.RunDirectoryTaken: it holds a sweep's files or a job folder with another
            run's files.
    """
    found = sweep_files(sweep_dir)
    if found:
        raise refusal(sweep_dir, found, "sweep", "hydra.sweep.dir")


class RunFolderCheck(Callback):
    """Refuses a run folder (``hydra.run.dir``) or sweep folder (``hydra.sweep.dir``) that another
    run used, before Hydra creates anything in it: one line, exit status 1."""

    def on_run_start(self, config: DictConfig, **kwargs: Any) -> None:
        self._check(config, lambda: claim(Path(config.hydra.run.dir)), "hydra.run.dir")

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        self._check(config, lambda: claim_sweep(Path(config.hydra.sweep.dir)), "hydra.sweep.dir")

    @staticmethod
    def _check(config: DictConfig, check: Callable[[], None], setting: str) -> None:
        # Hydra turns a callback's exception into a warning and goes on: a refusal must exit here.
        from hydra.core.hydra_config import HydraConfig

        from idkit.cli import errors
        from idkit.reports.files import FolderError, writable_folder

        HydraConfig.instance().set_config(config)  # as run_job does first: ${hydra:...} in a folder name

        if config.hydra.output_subdir is not None:
            errors.fail(
                f"hydra.output_subdir={config.hydra.output_subdir} is not supported: idkit writes the "
                "run's config into .hydra/ itself, after checking that the folder holds no other run"
            )
        try:
            check()
            # Hydra's own mkdir would end in a traceback (a file in the way, a read-only place)
            writable_folder(config.hydra[setting.split(".")[1]].dir, setting)
        except (RunDirectoryTaken, FolderError) as refused:
            errors.fail(str(refused))


class MultirunSummary(Callback):
    """Writes ``error.json`` for a failed job and keeps the sweep's summary up to date."""

    def on_job_end(self, config: DictConfig, job_return: JobReturn, **kwargs: Any) -> None:
        from hydra.types import RunMode

        from idkit.reports import files

        hydra_cfg = config.hydra
        job_dir = Path(hydra_cfg.runtime.output_dir)
        if job_return.status == JobStatus.FAILED:
            # JobReturn.return_value re-raises for a failed job; the exception itself is kept here.
            # idkit.cli.app wraps user errors for Hydra's compact printing: record the original.
            exc = job_return._return_value
            cause = exc.__cause__ or exc
            if not isinstance(cause, RunDirectoryTaken):  # that folder is another run's: leave it be
                error = {"status": "failed", "error": f"{type(cause).__name__}: {cause}"}
                files.write_json(job_dir / ERROR_FILE, error)
        if hydra_cfg.mode == RunMode.MULTIRUN:
            self._summarise(Path(hydra_cfg.sweep.dir))

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        sweep_dir = Path(config.hydra.sweep.dir)
        self._summarise(sweep_dir)
        log.info("sweep summary: %s", sweep_dir / SUMMARY_MD)
        for merged in merge_shards(sweep_dir):
            log.info("merged robustness shards: %s", merged)

    @staticmethod
    def _summarise(sweep_dir: Path) -> None:
        if not sweep_dir.is_dir():
            return
        with _locked(sweep_dir / ".summary.lock"):
            write_summary(sweep_dir)


def _shard_groups(sweep_dir: Path) -> list[list[tuple[Path, dict[str, Any]]]]:
    """Complete robustness result folders of a sweep, grouped by study (config without the shard)."""
    groups: dict[str, list[tuple[Path, dict[str, Any]]]] = {}
    for result in sorted(sweep_dir.glob("*/result.json")):
        document = json.loads(result.read_text())
        sharding = (document.get("payload") or {}).get("sharding") or {}
        if document.get("task") != "robustness" or sharding.get("shards", 1) < 2:
            continue
        config = dict(document.get("config") or {})
        config["robustness"] = {k: v for k, v in (config.get("robustness") or {}).items() if k != "shard"}
        groups.setdefault(json.dumps(config, sort_keys=True, default=str), []).append(
            (result.parent, document)
        )
    return list(groups.values())


def merge_shards(sweep_dir: Path) -> list[Path]:
    """Merge each sharded robustness study of a sweep into one report; returns the folders written.

    A study whose shards are not all there (a job failed or was killed) is left unmerged, with a
    warning naming the missing shards.
    """
    from idkit.reports import robustness as report
    from idkit.studies import robustness

    groups, written = _shard_groups(sweep_dir), []
    for index, group in enumerate(groups):
        shards = group[0][1]["payload"]["sharding"]["shards"]
        present = {document["payload"]["sharding"]["shard"] for _, document in group}
        missing = sorted(set(range(shards)) - present)
        if missing:
            log.warning("robustness shards %s missing in %s: not merged", missing, sweep_dir)
            continue
        merged = robustness.merge([robustness.load(job_dir) for job_dir, _ in group])
        merged.provenance.config = group[0][1].get("config")
        plots = bool((merged.provenance.config or {}).get("plots", True))
        out = sweep_dir / (MERGED_DIR if len(groups) == 1 else f"{MERGED_DIR}_{index}")
        report.write(merged, out, plots=plots)
        written.append(out)
    return written
