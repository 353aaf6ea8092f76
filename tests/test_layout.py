"""The direction of the arrows: core <- plugins <- studies <- reports <- command line; within the
plugins, robots <- estimators, and the linear family beside (not on top of) the search estimators.

Checked on the source (every import statement, nested ones included), so a new module that breaks
the layout fails here rather than in review.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "idkit"


def _imports(path: Path, top_level_only: bool = False) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    nodes = tree.body if top_level_only else list(ast.walk(tree))
    found: set[str] = set()
    for node in nodes:
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found |= {node.module} | {f"{node.module}.{alias.name}" for alias in node.names}
    return found


def _modules(*parts: str) -> list[Path]:
    return sorted(PACKAGE.joinpath(*parts).rglob("*.py"))


@pytest.mark.parametrize("path", [p for p in _modules() if "cli" not in p.relative_to(PACKAGE).parts[:1]])
def test_nothing_below_the_command_line_imports_it(path):
    assert not {name for name in _imports(path) if name.startswith("idkit.cli")}


@pytest.mark.parametrize("path", _modules("studies"))
def test_a_study_never_imports_a_report(path):
    """Not at module level, not inside a function: a study computes, ``idkit.reports`` formats it, and
    ``idkit.api`` gives ``idkit.run``'s result the report's shortcuts."""
    assert not {name for name in _imports(path) if name.startswith("idkit.reports")}


@pytest.mark.parametrize("path", _modules("reports"))
def test_a_report_never_runs_a_study(path):
    """Reports import the result types of ``idkit.studies`` but never a study's ``run``."""
    assert not {name for name in _imports(path) if name.startswith("idkit.studies") and name.endswith(".run")}


@pytest.mark.parametrize("path", _modules("robots"))
def test_a_robot_imports_no_estimator(path):
    """Robots, and the URDF reader and writer, take rigid-body physics from ``idkit.robots.inertia``."""
    assert not {name for name in _imports(path) if name.startswith("idkit.estimators")}


#: All the least-squares family (and ``pcls``, which solves the same system under constraints) may
#: take from the rest of ``idkit.estimators``: itself and the trial-batching helpers.
LINEAR_MAY_IMPORT = ("idkit.estimators.linear", "idkit.estimators.trials")


@pytest.mark.parametrize("path", [*_modules("estimators", "linear"), PACKAGE / "estimators" / "physical.py"])
def test_the_linear_family_imports_no_search_estimator(path):
    found = {name for name in _imports(path) if name.startswith("idkit.estimators.")}
    assert not {name for name in found if not name.startswith(LINEAR_MAY_IMPORT)}


@pytest.mark.parametrize("path", _modules("optim"))
def test_the_swarm_engine_imports_no_estimator(path):
    """``idkit.optim`` is array-level: estimators, problems and studies build on it, not the reverse."""
    above = ("idkit.estimators", "idkit.problem", "idkit.studies", "idkit.reports", "idkit.robots")
    assert not {name for name in _imports(path) if name.startswith(above)}


@pytest.mark.parametrize("path", _modules("conic"))
def test_the_conic_toolbox_imports_no_estimator_study_or_report(path):
    """``idkit.conic`` is what ``pcls``, ``payload`` and ``varpro`` share: it sits below all of them."""
    above = ("idkit.estimators", "idkit.studies", "idkit.reports", "idkit.cli")
    assert not {name for name in _imports(path) if name.startswith(above)}


#: What reads files: idkit's readers of data files, and the standard library's and others' file formats.
FILE_READERS = (
    "idkit.data.load",
    "idkit.data.io",
    "idkit.data.table",
    "idkit.data.recording",
    "idkit.data.logs",
    "idkit.data.pipeline",
    "idkit.data.files",
    "csv",
    "pathlib",
    "shutil",
    "glob",
    "yaml",
    "rosbags",
)
#: Calls that open or load a file whatever module they come from (``open``, ``np.load``, ...).
FILE_CALLS = {"open", "load", "loadtxt", "genfromtxt", "read_text", "read_bytes", "read_csv", "fromfile"}


def _calls(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            func = node.func
            found.add(func.id if isinstance(func, ast.Name) else getattr(func, "attr", ""))
    return found


@pytest.mark.parametrize("path", _modules("estimators"))
def test_no_estimator_reads_files(path):
    """An estimator gets samples (``Problem.samples``, ``Problem.recordings``): a payload's reference is
    read by the data pipeline as the data were, never by the estimator."""
    imported = {name for name in _imports(path) if name.startswith(FILE_READERS)}
    assert not imported and not _calls(path) & FILE_CALLS


def test_the_problem_imports_no_loader():
    """``Problem`` is core: it carries samples, and reads nothing (no callback into the loaders)."""
    assert not {name for name in _imports(PACKAGE / "problem.py") if name.startswith("idkit.data")}


@pytest.mark.parametrize("path", _modules("data"))
def test_data_imports_no_excitation(path):
    """The data floor lies below the excitation room (whose files it would otherwise read): a scenario's
    motion is built by ``idkit.excitation.spec.scenario_excitation`` and handed to the simulation."""
    assert not {name for name in _imports(path) if name.startswith(("idkit.excitation", "idkit.studies"))}


def test_the_data_modules_import_one_another_without_a_circle():
    """Within ``idkit.data`` (nested imports included) the imports form no cycle: each module can be read
    knowing only those below it (the recording <-> logs circle is gone)."""
    modules = {f"idkit.data.{p.stem}": p for p in _modules("data") if p.stem != "__init__"}
    edges = {
        name: {
            m for m in modules if m != name and any(i == m or i.startswith(m + ".") for i in _imports(path))
        }
        for name, path in modules.items()
    }
    done: set[str] = set()

    def visit(name: str, trail: tuple[str, ...]) -> None:
        assert name not in trail, " -> ".join((*trail[trail.index(name) :], name))
        if name not in done:
            for other in sorted(edges[name]):
                visit(other, (*trail, name))
            done.add(name)

    for name in sorted(modules):
        visit(name, ())


@pytest.mark.parametrize("path", _modules("sim"))
def test_the_simulator_imports_no_estimator_study_or_report(path):
    """``idkit.sim`` is the simulator's view of a robot (model, quantities, rollouts, the time convention):
    the ``rollout`` estimator and its study build on it, not the reverse."""
    above = ("idkit.estimators", "idkit.studies", "idkit.reports")
    assert not {name for name in _imports(path) if name.startswith(above)}
