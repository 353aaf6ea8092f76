"""The real-robot defaults: measured data on a model robot gets pcls with friction and offsets,
each option the user typed is kept, the paper's runs are untouched, and the note says what was done."""

from __future__ import annotations

import json
import subprocess
import sys
from importlib.resources import files

import pytest
from hydra import compose, initialize_config_module
from hydra.core.global_hydra import GlobalHydra

from idkit.cli.app import setup
from idkit.cli.defaults import apply_real_robot_defaults, preselect_estimator
from idkit.studies.defaults import RealRobotNote, applies, chosen, describe, searches_cost

URDF = str(files("idkit") / "robots/assets/cylindrical.urdf")


def composed(*overrides: str):
    setup()
    GlobalHydra.instance().clear()
    with initialize_config_module(config_module="idkit.conf", version_base="1.3"):
        cfg = compose("config", overrides=list(overrides))
    GlobalHydra.instance().clear()
    return cfg


def test_only_a_fit_of_a_model_robot_to_measured_data_gets_them():
    assert applies("single", {"_name_": "urdf"}, "train.csv")
    assert applies("single", "mjcf", ["a.csv", "b.csv"])
    assert not applies("single", {"_name_": "cylindrical"}, "train.csv")  # the paper's robot
    assert not applies("single", {"_name_": "urdf"}, None)  # a simulated scenario
    assert not applies("kuka", {"_name_": "urdf"}, "train.csv")  # a study with its own estimators
    # a payload on the arm holds the arm's model (its friction and offsets) fixed
    assert not applies("single", {"_name_": "urdf"}, "train.csv", {"_name_": "payload"})


def test_what_the_user_typed_is_kept():
    assert chosen({"robot", "data"}) == {
        "estimator": "pcls",
        "cost": None,
        "robot.friction": True,
        "robot.offset": True,
        "robot.coulomb_velocity": "auto",
    }
    # a given swarm keeps the config's cost (it searches one); a friction given is kept
    assert chosen({"robot", "estimator", "robot.friction"}, searches_cost=True) == {"robot.offset": True}
    # an estimator with its own criterion gets no cost unless one is given
    smooth = {"robot.coulomb_velocity": "auto"}
    assert chosen({"estimator"}) == {"cost": None, "robot.friction": True, "robot.offset": True, **smooth}
    assert chosen({"estimator", "cost"}) == {"robot.friction": True, "robot.offset": True, **smooth}
    assert searches_cost("pso") and searches_cost({"_name_": "adam"}) and not searches_cost("pcls")


def test_the_composed_config_is_changed_in_place_with_one_note():
    overrides = ["robot=urdf", f"robot.urdf={URDF}", "data=train.csv", "robot.offset=false"]
    cfg = composed(*overrides)
    assert cfg.estimator._name_ == "pso" and cfg.cost._name_ == "f13"  # the config's own defaults
    with pytest.warns(RealRobotNote) as said:
        apply_real_robot_defaults(cfg, overrides)
    assert cfg.estimator._name_ == "pcls" and cfg.estimator.prior_weight == "auto"
    assert cfg.cost is None and cfg.robot.friction is True and cfg.robot.offset is False
    assert [str(w.message) for w in said] == [
        "measured data on a model robot: estimator=pcls cost=null robot.friction=true "
        "robot.coulomb_velocity=auto (a physically consistent fit with friction and a Coulomb term smoothed "
        "at rest where cross-validation prefers it, its links kept plausible unless cross-validation says "
        "it costs accuracy); set any of them to change it, e.g. estimator=ls robot.friction=false"
    ]


def test_the_note_describes_only_what_was_applied():
    """``estimator=ls`` typed: the note said "(a physically consistent fit …)" of a least-squares fit."""
    assert describe(chosen({"estimator"})).startswith(
        "measured data on a model robot: cost=null robot.friction=true robot.offset=true "
        "robot.coulomb_velocity=auto (friction and torque offsets and a Coulomb term smoothed at rest where "
        "cross-validation prefers it in the model); "
    )
    assert "(a physically consistent fit with friction and torque offsets and a Coulomb" in describe(
        chosen(set())
    )
    assert "its links kept plausible unless cross-validation says it costs accuracy)" in describe(
        chosen(set())
    )
    assert "(no cost: the estimator minimises its own criterion)" in describe(
        chosen({"estimator", "robot.friction", "robot.offset", "robot.coulomb_velocity"})
    )


def test_options_of_the_default_estimator_typed_without_naming_it_are_its():
    """``estimator.prior_weight=300`` alone: Hydra would check it against the paper's pso while it
    composes; named first, the pcls node keeps it and the note still says pcls was chosen."""
    typed = ["robot=urdf", f"robot.urdf={URDF}", "data=train.csv", "estimator.prior_weight=300"]
    words = preselect_estimator([*typed, "--multirun"])
    assert words == ["estimator=pcls", *typed, "--multirun"]
    cfg = composed(*words[:-1])
    with pytest.warns(RealRobotNote) as said:
        apply_real_robot_defaults(cfg, words[:-1])
    assert cfg.estimator._name_ == "pcls" and cfg.estimator.prior_weight == 300
    assert "estimator=pcls cost=null robot.friction=true robot.offset=true" in str(said[0].message)
    for untouched in (
        [*typed[:3], "estimator=ls", "estimator.prior_weight=1"],  # an estimator named
        ["estimator.particles=8"],  # the paper's robot
        typed[:2] + typed[3:],  # no measured data
        [*typed, "task=kuka"],  # a study with its own estimators
        typed[:3],  # no estimator option
        ["robot=urdf", "data=[a", "estimator.prior_weight=1"],  # unreadable: Hydra says so itself
    ):
        assert preselect_estimator(untouched) == untouched


@pytest.mark.parametrize(
    "overrides",
    [
        ["+scenario=outliers"],  # the paper's robot and scenario
        ["robot=urdf", f"robot.urdf={URDF}"],  # a model robot on simulated data
        [
            "robot=urdf",
            f"robot.urdf={URDF}",
            "data=a.csv",
            "estimator=pso",
            "robot.friction=false",
            "robot.offset=false",
        ],  # everything typed
    ],
)
def test_the_paper_and_simulations_and_a_fully_typed_command_are_untouched(overrides, recwarn):
    cfg = composed(*overrides)
    before = repr(cfg)
    apply_real_robot_defaults(cfg, overrides)
    assert repr(cfg) == before and not [w for w in recwarn if w.category is RealRobotNote]


@pytest.mark.integration
def test_the_short_command_fits_pcls_with_friction_and_records_it(tmp_path):
    """The command a newcomer types: the recording of test_single_recordings' kind, no estimator."""
    from tests.studies.test_single_recordings import raw_csv

    train = raw_csv(tmp_path / "train.csv", 12.0, 0.2, 1)
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            "from idkit.cli import main; main()",
            "robot=urdf",
            f"robot.urdf={URDF}",
            f"data={train}",
            f"hydra.run.dir={tmp_path / 'run'}",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == 0, out.stderr
    assert "note: measured data on a model robot: estimator=pcls" in out.stderr
    assert "note: robot.coulomb_velocity=auto: Coulomb friction as " in out.stderr  # the choice, said
    result = json.loads((tmp_path / "run" / "result.json").read_text())
    estimate = result["payload"]["estimate"]
    assert (
        estimate["estimator"] == "PCLS"
        and "d2.fc" in estimate["params"]
        and "d2.offset" in estimate["params"]
    )
    assert result["config"]["estimator"]["_name_"] == "pcls" and result["config"]["cost"] is None
    assert "pcls" in (tmp_path / "run" / ".hydra" / "config.yaml").read_text()
