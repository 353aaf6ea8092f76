"""The config side of the ``idkit`` command, through Hydra's compose API (in process, fast)."""

from __future__ import annotations

import textwrap

import pytest
from hydra.core.global_hydra import GlobalHydra
from hydra.errors import ConfigCompositionException, MissingConfigException
from omegaconf import OmegaConf

from idkit import registry
from idkit.cli.app import setup
from idkit.cli.nodes import plugin_node
from idkit.cli.source import RegistryConfigSource
from idkit.cli.tasks import TASKS, arguments
from idkit.registry import MISSING
from idkit.studies.build import constructor_options

UNWRITABLE = object()  # a default no config can hold


def test_constructor_options_map_keyword_arguments():
    class Toy:
        def __init__(self, a, b: int = 2, c=(1.0, 2.0), d=None, e=UNWRITABLE, *args, _private=1, **kw):
            pass

    assert constructor_options(Toy) == {"a": MISSING, "b": 2, "c": [1.0, 2.0], "d": None}


def test_plugin_node_names_only_imports_nothing():
    assert plugin_node("estimator", "pso", names_only=True) == {"_name_": "pso"}


def test_the_issue_command_composes(hydra_compose):
    cfg = hydra_compose("+scenario=outliers", "estimator=pso", "cost=f13")
    assert cfg.scenario.name == "outliers"
    assert cfg.estimator._name_ == "pso"
    assert cfg.cost == {"_name_": "f13", "floor": registry.load("cost", "f13")().floor}
    assert cfg.task == "single"


def test_plugin_options_are_overridable(hydra_compose):
    cfg = hydra_compose("estimator=pso", "estimator.particles=40", "robot.g=9.8")
    assert cfg.estimator.particles == 40
    assert cfg.robot.g == 9.8
    expected = constructor_options(registry.load("estimator", "pso"))
    assert set(cfg.estimator) == {"_name_", *expected}


def test_every_registered_plugin_is_a_group_option(hydra_compose):
    hydra_compose()  # initialises the config loader
    loader = GlobalHydra.instance().config_loader()
    for kind in ("robot", "estimator", "cost"):
        assert set(registry.available(kind)) <= set(loader.get_group_options(kind))


def test_unknown_plugin_name_lists_the_available_ones(hydra_compose):
    with pytest.raises(MissingConfigException) as err:
        hydra_compose("estimator=psoo")
    assert "pso" in str(err.value) and "ls" in str(err.value)


def test_unknown_option_is_rejected(hydra_compose):
    with pytest.raises(ConfigCompositionException, match="particle"):
        hydra_compose("estimator=pso", "estimator.particle=40")


def test_scenario_group_is_generated_from_the_presets(hydra_compose):
    from dataclasses import fields

    from idkit.data.presets import SCENARIOS, Scenario

    source = RegistryConfigSource("idkit-registry", "idkit://registry")
    assert source.list("scenario", None) == sorted(SCENARIOS)
    cfg = hydra_compose("+scenario=all_noise", "scenario.torque_noise=0.1", "n_samples=40")
    assert set(cfg.scenario) == {f.name for f in fields(Scenario)} - {"description", "n_samples"}
    assert cfg.scenario.state_noise == SCENARIOS["all_noise"].state_noise and cfg.scenario.torque_noise == 0.1
    assert cfg.n_samples == 40
    with pytest.raises(ConfigCompositionException, match="n_samples"):  # one knob: the top-level one
        hydra_compose("+scenario=all_noise", "scenario.n_samples=40")


def test_run_dirs_are_unique_within_one_second(hydra_compose):
    dirs = {
        str(hydra_compose(hydra_cfg=True).hydra.run.dir) for _ in range(3)
    }  # same second, three compositions
    assert len(dirs) == 3
    assert all(d.startswith("outputs/") for d in dirs)


def test_experiments_compose(hydra_compose):
    paper = hydra_compose("+experiment=paper")
    assert paper.task == "paper" and len(paper.paper.costs) == 16
    robust = hydra_compose("+experiment=robustness", "trials=7")
    assert robust.task == "robustness" and robust.trials == 7
    assert robust.robustness.baseline == "RLS-rel"
    kuka = hydra_compose("+experiment=kuka", "kuka.stride=5", "kuka.data_dir=/data/kuka")
    assert kuka.task == "kuka" and kuka.kuka.stride == 5 and kuka.kuka.data_dir == "/data/kuka"
    assert "cost" not in paper and "cost" not in robust
    assert not {"robot", "estimator", "cost"} & set(kuka)


@pytest.mark.parametrize(
    "overrides",
    [
        ("+scenario=outliers", "estimator=pso", "cost=f13", "n_samples=20"),
        ("+experiment=paper",),
        ("+experiment=robustness", "trials=7"),
        ("+experiment=kuka",),
    ],
)
def test_each_task_config_is_its_study_signature(hydra_compose, overrides):
    """Every key of the composed config is an argument of the study (or read by the command)."""
    import inspect

    cfg = OmegaConf.to_container(hydra_compose(*overrides), resolve=True)
    task = TASKS[cfg["task"]]
    takes = inspect.signature(task.study_function()).parameters
    kwargs = arguments(cfg["task"], cfg, task.study_function())
    assert set(kwargs) <= set(takes)
    section = cfg.get(task.section or "", {})
    assert set(section) <= set(kwargs)
    inspect.signature(task.study_function()).bind(**kwargs)  # a call the study accepts


def test_a_key_the_task_does_not_take_is_an_error(hydra_compose):
    from idkit.studies import kuka, paper

    cfg = OmegaConf.to_container(hydra_compose("+experiment=kuka", "cost=f13"), resolve=True)
    with pytest.raises(ValueError, match="^the kuka task takes no cost \\(got cost=f13\\)"):
        arguments("kuka", cfg, kuka.run)
    cfg = OmegaConf.to_container(hydra_compose("+experiment=paper", "+paper.trials=3"), resolve=True)
    with pytest.raises(ValueError, match="paper.trials is not an option of the paper task"):
        arguments("paper", cfg, paper.run)
    cfg = OmegaConf.to_container(hydra_compose("+experiment=paper", "n_samples=30"), resolve=True)
    with pytest.raises(ValueError, match="the paper task takes no n_samples"):
        arguments("paper", cfg, paper.run)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (("seed=abc",), "setting 'seed' must be an int, got 'abc' (str)"),
        (("n_samples=2.5",), "setting 'n_samples' must be an int or None, got 2.5 (float)"),
        (("+experiment=robustness", "trials=many"), "setting 'trials' must be an int, got 'many'"),
        (("+experiment=kuka", "kuka.stride=x"), "setting 'kuka.stride' must be an int, got 'x'"),
        (("+experiment=paper", "paper.costs=f13"), "setting 'paper.costs' must be a list of anything"),
    ],
)
def test_every_argument_is_checked_against_the_study_annotation(hydra_compose, overrides, message):
    from idkit.options import OptionError

    cfg = OmegaConf.to_container(hydra_compose(*overrides), resolve=True)
    with pytest.raises(OptionError) as err:
        arguments(cfg["task"], cfg, TASKS[cfg["task"]].study_function())
    assert str(err.value).startswith(message), str(err.value)


def test_arguments_arrive_converted(hydra_compose):
    cfg = OmegaConf.to_container(hydra_compose("seed='7'", "n_samples=20.0"), resolve=True)
    kwargs = arguments("single", cfg, TASKS["single"].study_function())
    assert (kwargs["seed"], kwargs["n_samples"]) == (7, 20)


def test_third_party_plugin_is_a_config_without_yaml(tmp_path, monkeypatch, hydra_compose):
    info = tmp_path / "toy_dist-1.2.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: toy-dist\nVersion: 1.2\n")
    (info / "entry_points.txt").write_text("[idkit.estimators]\ntoy = toy_estimator:Toy\n")
    (tmp_path / "toy_estimator.py").write_text(
        textwrap.dedent(
            """
            class Toy:
                def __init__(self, scale: float = 1.0, steps: int = 3):
                    self.scale, self.steps = scale, steps

                def fit(self, problem):
                    raise NotImplementedError
            """
        )
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    registry.refresh()
    try:
        cfg = hydra_compose("estimator=toy", "estimator.scale=2.5")
        assert OmegaConf.to_container(cfg.estimator) == {"_name_": "toy", "scale": 2.5, "steps": 3}
    finally:
        monkeypatch.undo()
        registry.refresh()


def test_help_mode_serves_names_only():
    setup(names_only=True)
    try:
        source = RegistryConfigSource("idkit-registry", "idkit://registry")
        assert source.load_config("estimator/pso.yaml").config == {"_name_": "pso"}
        assert source.list("cost", None) == sorted(registry.available("cost"))
    finally:
        setup(names_only=False)


def test_a_deleted_cost_reaches_the_study_as_none(hydra_compose):
    """``'~cost'`` means no cost (the estimator's own criterion is reported), not the default f13."""
    from idkit.studies import single

    cfg = OmegaConf.to_container(hydra_compose("estimator=ls", "~cost"), resolve=True)
    assert "cost" not in cfg
    assert arguments("single", cfg, single.run)["cost"] is None
    cfg = OmegaConf.to_container(hydra_compose("estimator=ls"), resolve=True)
    assert arguments("single", cfg, single.run)["cost"] == cfg["cost"]
