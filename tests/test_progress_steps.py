"""The torque path's long steps say where they are to a study that listens (idkit.progress): the
excitation search and polish, and pcls' prior_weight=auto cross-validation; quiet otherwise."""

from __future__ import annotations

from idkit import progress, registry
from idkit.estimators.physical import PRIOR_CANDIDATES, PRIOR_FOLDS


def test_the_excitation_search_and_polish_say_their_iterations(capsys):
    from idkit.excitation.optimize import optimize_excitation

    robot = registry.create("robot", "cylindrical")
    lines: list[str] = []
    budget = {"swarms": 2, "particles": 4, "iterations": 3, "adam_steps": 2, "grid_points": 20}
    with progress.reporting("excitation", write=lines.append, interval=0.0):
        optimize_excitation(robot, check_points=50, **budget)
    assert lines[0].startswith("excitation: search (particle swarm) · iteration 1/3 · best loss ")
    assert any(line.startswith("excitation: search (particle swarm) · iteration 3/3") for line in lines)
    assert any(line.startswith("excitation: polish (Adam) · iteration 3/3") for line in lines)
    optimize_excitation(robot, check_points=50, **budget)  # nobody listens: nothing printed
    assert capsys.readouterr().err == ""


def test_the_prior_weight_choice_says_its_fits(tmp_path):
    from idkit.data.demo import write
    from idkit.studies import single

    write(tmp_path)
    lines: list[str] = []
    with progress.reporting("fit", write=lines.append, interval=0.0):
        single.run(
            {"_name_": "urdf", "urdf": str(tmp_path / "arm.urdf"), "friction": True, "offset": True},
            {"_name_": "pcls", "prior_weight": "auto"},
            None,
            data=str(tmp_path / "train.csv"),
            preprocess={"cutoff": 10.0},
        )
    total = len(PRIOR_CANDIDATES) * PRIOR_FOLDS
    assert lines[-1].startswith(f"fit: prior_weight=auto: cross-validation · iteration {total}/{total}")
