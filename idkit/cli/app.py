"""The Hydra application behind ``idkit``.

``setup()`` must run before Hydra composes anything (``main`` calls it; tests using Hydra's compose
API call it too): it registers the ``idkit://`` config source that turns the plugin registry and the
scenario presets into config groups, and the ``${idkit.uid:}`` resolver that keeps run directories
unique. ``task`` claims Hydra's output directory and records the config in it
(:mod:`idkit.cli.provenance`), runs the study named by ``cfg.task`` with its config section as
arguments (:mod:`idkit.cli.tasks`), then writes its report there. ``main`` reads the command line
first (:mod:`idkit.cli.command_line`: ``--version``, flags anywhere, one-line refusals) and shows
warnings on one line each (:mod:`idkit.cli.output`).
"""

from __future__ import annotations

import contextlib
import inspect
import os
import signal
import sys
import threading
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any, cast

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.core.plugins import Plugins
from hydra.errors import CompactHydraException
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf

from idkit.cli import INTERRUPTED, command_line, errors, output, provenance
from idkit.cli.defaults import apply_real_robot_defaults, preselect_estimator
from idkit.cli.source import RegistryConfigSource, RegistrySearchPath
from idkit.cli.tasks import arguments, get_task
from idkit.options import check_setting

HELP_FLAGS = ("--help", "-h", "--hydra-help")

#: Hydra's switch for full tracebacks. ``main`` sets it for Hydra (which then raises instead of
#: printing) and prints one line itself, unless the user asked for tracebacks: this switch or
#: ``IDKIT_DEBUG=1`` (:mod:`idkit.cli.output`).
FULL_ERROR = "HYDRA_FULL_ERROR"
#: Read when the command starts, before ``main`` sets the switch for Hydra.
TRACEBACKS_REQUESTED = os.environ.get(FULL_ERROR) == "1" or output.debugging()

#: The first word that runs ``idkit compare`` (:mod:`idkit.cli.compare`) instead of a task.
COMPARE = "compare"


def _uid() -> str:
    """Six hex digits, drawn once per config (the resolver is cached) — see ``hydra.run.dir``."""
    return uuid.uuid4().hex[:6]


OmegaConf.register_new_resolver("idkit.uid", _uid, use_cache=True, replace=True)


def setup(names_only: bool = False) -> None:
    """Register idkit's config source with Hydra (idempotent).

    Args:
        names_only: serve plugin nodes without reading constructor signatures, so composing the
            config imports no plugin (and no torch). ``main`` sets it for ``--help``.
    """
    RegistryConfigSource.names_only = names_only
    Plugins.instance().register(RegistryConfigSource)
    Plugins.instance().register(RegistrySearchPath)


def _run(cfg: DictConfig, run_dir: Path) -> Any:
    """Study, then report: the arguments are the config (``idkit.cli.tasks.arguments``)."""
    from idkit.runtime import torch_threads
    from idkit.studies.result import StudyInterrupted

    task = get_task(cfg.task)
    study = task.study_function()
    report = task.report_module()
    # a DictConfig's container is a dict with string keys; OmegaConf's signature allows any container
    resolved = cast("dict[str, Any]", OmegaConf.to_container(cfg, resolve=True))
    kwargs = arguments(cfg.task, resolved, study)
    plots = check_setting("plots", cfg.plots, bool)  # a bad value is refused before the fit, not after
    takes = inspect.signature(study).parameters
    if "progress" in takes:  # a bar on a terminal; in a log file its redraws would pile up
        kwargs["progress"] = sys.stderr.isatty()
    if "checkpoint" in takes:  # a long study saves its partial report as it goes
        kwargs["checkpoint"] = lambda partial: _write(report, partial, resolved, run_dir, plots=False)
    try:
        # One fit is many small tensor operations, for which a second torch thread costs more than it
        # saves (docs/speed.md); the estimators that batch large work (pso, ls) set their own threads.
        with torch_threads(1) if cfg.task == "single" else contextlib.nullcontext():
            result = study(**kwargs)
    except StudyInterrupted as stop:
        _write(report, stop.partial, resolved, run_dir, plots=False)
        p = stop.partial.provenance
        print(
            f"idkit: interrupted; partial results ({p.done} of {p.requested} {p.unit}s) in {run_dir}",
            file=sys.stderr,
        )
        sys.exit(INTERRUPTED)
    written = _write(report, result, resolved, run_dir, plots=plots)
    output.say(report.text(result))
    output.say(f"results: {written['result']}")
    return result


def _write(report: Any, result: Any, config: dict, run_dir: Path, plots: bool) -> dict[str, str]:
    result.provenance.config = config
    return report.write(result, run_dir, plots=plots)


def task(cfg: DictConfig) -> Any:
    """Run the task named by ``cfg.task`` in Hydra's output directory, once it is claimed."""
    hydra_cfg = HydraConfig.get()
    run_dir = Path(hydra_cfg.runtime.output_dir)
    single = hydra_cfg.mode == RunMode.RUN
    claimed = False  # the folder is this run's: what it holds may be tidied after a failure
    interrupts: list[int] = []
    try:
        provenance.claim(run_dir, "hydra.run.dir" if single else "hydra.sweep.dir or hydra.sweep.subdir")
        claimed = True
        _refuse_missing(cfg)
        with output.one_line_warnings():  # also in a launcher's worker process
            apply_real_robot_defaults(cfg, hydra_cfg.overrides.task)
            full = HydraConfig.instance().cfg  # the whole config, {hydra: ...}, once Hydra has set it
            if not isinstance(full, DictConfig):
                raise RuntimeError(f"hydra: no config to record (got {type(full).__name__})")
            provenance.record(run_dir, cfg, full)
            with _noting_interrupts(interrupts):
                return _run(cfg, run_dir)
    except Exception as exc:
        left = provenance.abandon(run_dir) if single and claimed else ""
        if interrupts:  # Ctrl-C, turned into another error by the code it stopped: still Ctrl-C
            print(f"idkit: interrupted ({type(exc).__name__} on the way out){left}", file=sys.stderr)
            sys.exit(INTERRUPTED)  # a sweep runs no further job
        message = errors.one_line(exc)  # a refused input, or more memory than there is
        if message is None:
            raise  # a bug: Hydra reports it with its traceback
        if single and not TRACEBACKS_REQUESTED:
            errors.fail(message + left)  # before Hydra adds "Error executing job with overrides: ..."
        # a sweep goes on; the summary callback records the failed job's cause
        raise CompactHydraException(f"{errors.PREFIX}{message}") from exc
    except KeyboardInterrupt:
        left = provenance.abandon(run_dir) if single and claimed else ""
        print(f"idkit: interrupted; no results were written to {run_dir}{left}", file=sys.stderr)
        sys.exit(INTERRUPTED)


@contextlib.contextmanager
def _noting_interrupts(seen: list[int]) -> Iterator[None]:
    """Record each Ctrl-C in ``seen`` and raise ``KeyboardInterrupt`` as Python does: a library that
    turns it into another error (an index error in a half-built result) then still ends the command,
    and a sweep, with exit status 130."""
    if threading.current_thread() is not threading.main_thread():
        yield  # signals reach the main thread only
        return
    previous = signal.getsignal(signal.SIGINT)
    if previous is not signal.default_int_handler:  # ignored, or someone else's: left alone
        yield
        return

    def noted(signum: int, frame: Any) -> None:
        seen.append(signum)
        signal.default_int_handler(signum, frame)

    signal.signal(signal.SIGINT, noted)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _refuse_missing(cfg: DictConfig) -> None:
    """A setting of the task's section still ``???`` (``rollout.model``) ends the run in one line
    saying what it is, before the run records anything."""
    section = get_task(cfg.task).section
    node = cfg.get(section) if section else None
    if isinstance(node, DictConfig):
        required = errors.required_message(sorted(OmegaConf.missing_keys(node)))  # full dotted keys
        if required:
            raise ValueError(required)


def main() -> None:
    """Run the command; a refused input ends in one line on stderr and exit status 1 (``errors``)."""
    words = sys.argv[1:]
    if words[:1] == [COMPARE]:  # a command of its own, not a Hydra app
        from idkit.cli.compare import main as compare

        sys.exit(compare(words[1:]))
    if command_line.VERSION_FLAG in words:
        import idkit

        print(f"idkit {idkit.__version__}")
        return
    try:
        sys.argv[1:] = preselect_estimator(command_line.arrange(words))
    except command_line.UsageError as exc:
        errors.fail(str(exc))
    setup(names_only=any(arg in HELP_FLAGS for arg in words))
    app = hydra.main(version_base="1.3", config_path="pkg://idkit.conf", config_name="config")(task)
    users_switch = os.environ.get(FULL_ERROR)
    os.environ[FULL_ERROR] = "1"
    try:
        with output.one_line_warnings():
            app()
    except Exception as exc:
        message = None if TRACEBACKS_REQUESTED else errors.one_line(exc)
        if message is None:
            raise  # asked for, or not a refused input but a bug: keep the traceback
        errors.fail(message)
    finally:
        if users_switch is None:
            os.environ.pop(FULL_ERROR, None)
        else:
            os.environ[FULL_ERROR] = users_switch
