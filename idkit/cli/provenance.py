"""A run folder is refused when it holds another run, before anything is written into it.

Hydra writes a job's record (``.hydra/config.yaml``, ``hydra.yaml``, ``overrides.yaml``) in
``hydra.core.utils.run_job``, before the task runs — into an existing run's folder too, replacing
that run's record before idkit could refuse. So idkit's config turns that off
(``hydra.output_subdir: null``) and the task writes the same three files itself: :func:`claim`
checks the folder first, then :func:`record` writes. The callback
:class:`idkit.cli.callbacks.RunFolderCheck` refuses a taken run or sweep folder even earlier, before
Hydra creates anything in it (its log file, a sweep's ``multirun.yaml``); :func:`claim` in the task
covers what the callback cannot see: two jobs of one sweep sent to the same folder.

A run that fails or is interrupted before it writes a result calls :func:`abandon`: its record and
an empty log are removed (and the folder, when that empties it), so ``outputs/`` does not fill with
folders holding only ``.hydra``, and a re-run into the same ``hydra.run.dir`` is not refused.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from idkit.reports.result_file import RESULT_FILE

#: Where the run's config goes (Hydra's own ``hydra.output_subdir`` default).
RECORD_DIR = ".hydra"
#: A failed job's cause, written by the sweep callback.
ERROR_FILE = "error.json"
#: Any of these in a folder means another run used it.
RUN_FILES = (RESULT_FILE, RECORD_DIR, ERROR_FILE)


class RunDirectoryTaken(FileExistsError):
    """The folder holds another run's files; nothing was written into it."""


def run_files(folder: Path) -> list[str]:
    """The files in ``folder`` that another run left (``RUN_FILES``), as ``folder``-relative names."""
    return [name for name in RUN_FILES if (folder / name).exists()]


def refusal(folder: Path, found: list[str], what: str, setting: str) -> RunDirectoryTaken:
    """The error for ``folder`` holding ``found`` of another ``what`` (run, sweep) named by ``setting``."""
    listed = ", ".join(found[:4]) + (", …" if len(found) > 4 else "")
    return RunDirectoryTaken(
        f"{folder} already holds another {what} ({listed}); nothing was written: choose another "
        f"{setting} (a new folder) or leave it unset"
    )


def claim(run_dir: Path, setting: str = "hydra.run.dir") -> None:
    """Refuse ``run_dir`` when another run used it.

    Args:
        run_dir: the job's folder (``hydra.runtime.output_dir``).
        setting: the option that named the folder, for the message.

    Raises:
        RunDirectoryTaken: ``run_dir`` holds ``result.json``, ``.hydra/`` or ``error.json``.
    """
    found = run_files(run_dir)
    if found:
        raise refusal(run_dir, found, "run", setting)


#: What :func:`record` writes into ``RECORD_DIR``.
RECORD_FILES = ("config.yaml", "hydra.yaml", "overrides.yaml")


def abandon(run_dir: Path) -> str:
    """Tidy the folder of a run that wrote no result; returns what to add to its last message.

    Only a folder that holds nothing but the run's record (``.hydra`` with :data:`RECORD_FILES`) and
    logs is touched: the record and empty logs go, then the folder once empty (nothing to add). A log
    with content stays and is named in the returned clause; a re-run may then reuse the folder
    (without the record it is no other run's). A folder holding anything else keeps everything.
    """
    record = run_dir / RECORD_DIR
    try:
        entries = list(run_dir.iterdir())
        ours = record.is_dir() and all(p.name in RECORD_FILES and p.is_file() for p in record.iterdir())
        logs = [p for p in entries if p.suffix == ".log" and p.is_file()]
        if any(p not in logs and not (p == record and ours) for p in entries):
            return ""
        if ours:
            shutil.rmtree(record)
        kept = [log for log in logs if log.stat().st_size > 0]
        for log in logs:
            if log not in kept:
                log.unlink()
        if not kept:
            if ours or logs:  # a folder that was empty before the run is the user's: it stays
                run_dir.rmdir()
            return ""
    except OSError:
        return ""  # tidying is a courtesy: never the reason a run's own message is lost
    return f" (its log: {', '.join(map(str, kept))})"


def record(run_dir: Path, task_config: DictConfig, hydra_config: DictConfig) -> Path:
    """Write the job's record into ``run_dir/.hydra``, the three files Hydra would have written.

    Args:
        run_dir: the claimed job folder.
        task_config: the job's config without ``hydra`` (``config.yaml``).
        hydra_config: the full Hydra config, ``{hydra: ...}`` (``hydra.yaml``; its
            ``hydra.overrides.task`` go to ``overrides.yaml``).

    Returns:
        The ``.hydra`` folder.
    """
    from idkit.reports import files

    folder = run_dir / RECORD_DIR
    configs = (task_config, hydra_config, hydra_config.hydra.overrides.task)
    contents = dict(zip(RECORD_FILES, configs, strict=True))
    for name, config in contents.items():
        files.write_text(folder / name, OmegaConf.to_yaml(config))
    return folder
