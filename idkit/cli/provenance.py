"""A run folder is refused when it holds another run, before anything is written into it.

Hydra writes a job's record (``.hydra/config.yaml``, ``hydra.yaml``, ``overrides.yaml``) in
``hydra.core.utils.run_job``, before the task runs — into an existing run's folder too, replacing
that run's record before idkit could refuse. So idkit's config turns that off
(``hydra.output_subdir: null``) and the task writes the same three files itself: :func:`claim`
checks the folder first, then :func:`record` writes. The callback
:class:`idkit.cli.callbacks.RunFolderCheck` refuses a taken run or sweep folder even earlier, before
Hydra creates anything in it (its log file, a sweep's ``multirun.yaml``); :func:`claim` in the task
covers what the callback cannot see: two jobs of one sweep sent to the same folder.
"""

from __future__ import annotations

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
    contents = {
        "config.yaml": task_config,
        "hydra.yaml": hydra_config,
        "overrides.yaml": hydra_config.hydra.overrides.task,
    }
    for name, config in contents.items():
        files.write_text(folder / name, OmegaConf.to_yaml(config))
    return folder
