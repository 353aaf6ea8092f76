"""``scenario.excitation=``: a family name or a file, checked against the robot, errors named."""

from __future__ import annotations

import pytest
import torch

from idkit.data.presets import Scenario
from idkit.data.scenarios import get_scenario, shared_fields, simulate
from idkit.excitation.files import excitation_yaml
from idkit.excitation.fourier import FourierExcitation
from idkit.excitation.paper import PaperExcitation
from idkit.excitation.spec import excitation_of, family_name, scenario_excitation


def test_a_family_name_is_its_default_member(cylindrical):
    assert torch.equal(excitation_of("paper", cylindrical).to_vector(), PaperExcitation().to_vector())
    assert excitation_of("fourier", cylindrical).n_joints == 3
    default = simulate(cylindrical, "outliers", seed=1)
    named = get_scenario({"name": "outliers", "excitation": "paper"})
    by_name = simulate(cylindrical, named, seed=1, excitation=scenario_excitation(named, cylindrical))
    assert torch.equal(default.tau, by_name.tau)  # the cylindrical robot's default is eq. (39)


def test_a_file_is_loaded_and_checked(cylindrical, tmp_path):
    motion = FourierExcitation(
        3, harmonics=2, period=5.0, offset=[0.0, 0.5, 0.5], a=[[0.1, 0.2]] * 3, b=[[0.0, 0.1]] * 3
    )
    path = tmp_path / "excitation.yaml"
    path.write_text(excitation_yaml("fourier", motion))
    assert torch.equal(excitation_of(path, cylindrical).to_vector(), motion.to_vector())
    two = tmp_path / "two.yaml"
    two.write_text(excitation_yaml("fourier", FourierExcitation(2)))
    with pytest.raises(
        ValueError, match=f"moves 2 joints, but robot CylindricalRobot \\(excitation file {two}\\) has 3"
    ):
        excitation_of(two, cylindrical)
    unknown = tmp_path / "unknown.yaml"
    unknown.write_text("excitation: fourrier\noptions: {}\n")
    with pytest.raises(ValueError, match=f"excitation file {unknown}: unknown excitation 'fourrier'"):
        scenario_excitation(get_scenario("clean", excitation=str(unknown)), cylindrical)


def test_neither_a_file_nor_a_family(cylindrical, tmp_path):
    with pytest.raises(
        ValueError,
        match="excitation 'nope.yaml': no such file, and not an excitation family \\(fourier, paper\\)",
    ):
        scenario_excitation(get_scenario({"name": "clean", "excitation": "nope.yaml"}), cylindrical)


def test_family_name_of_an_object():
    assert family_name(PaperExcitation()) == "paper" and family_name(FourierExcitation(1)) == "fourier"


def test_scenario_field_and_shared_fields_are_checked():
    with pytest.raises(ValueError, match="excitation must be a family name or the path"):
        Scenario(excitation=3)
    assert shared_fields({"excitation": "a.yaml", "t_end": None}, "robustness") == {"excitation": "a.yaml"}
    with pytest.raises(ValueError, match="robustness: scenario.name='outliers' is not for this study"):
        shared_fields({"name": "outliers"}, "robustness")
    with pytest.raises(TypeError, match="unknown field\\(s\\) \\['excitaton'\\]"):
        shared_fields({"excitaton": "a.yaml"}, "paper")
