"""Excitation YAML files: exact round trips and errors that name the file and the problem."""

from __future__ import annotations

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from idkit.excitation.files import excitation_from_yaml, excitation_yaml, load_excitation
from idkit.excitation.fourier import FourierExcitation
from idkit.excitation.paper import PaperExcitation

finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)


@st.composite
def fourier_excitations(draw) -> FourierExcitation:
    n, k = draw(st.integers(1, 4)), draw(st.integers(1, 4))
    matrix = st.lists(st.lists(finite, min_size=k, max_size=k), min_size=n, max_size=n)
    return FourierExcitation(
        n,
        k,
        draw(st.floats(1e-3, 1e3)),
        draw(st.lists(finite, min_size=n, max_size=n)),
        draw(matrix),
        draw(matrix),
    )


@st.composite
def paper_excitations(draw) -> PaperExcitation:
    n, k = draw(st.integers(1, 4)), draw(st.integers(1, 4))
    matrix = st.lists(st.lists(finite, min_size=k, max_size=k), min_size=n, max_size=n)
    return PaperExcitation(draw(matrix), draw(matrix), draw(st.lists(finite, min_size=n, max_size=n)))


@given(excitation=st.one_of(fourier_excitations(), paper_excitations()))
@settings(max_examples=60, deadline=None)
def test_yaml_round_trip_is_exact(excitation):
    name = "fourier" if isinstance(excitation, FourierExcitation) else "paper"
    again = excitation_from_yaml(excitation_yaml(name, excitation))
    assert type(again) is type(excitation)
    assert again.options() == excitation.options()
    assert torch.equal(again.to_vector(), excitation.to_vector())


def test_load_excitation_reads_a_file(tmp_path):
    path = tmp_path / "excitation.yaml"
    path.write_text(excitation_yaml("fourier", FourierExcitation(3)), encoding="utf-8")
    t = torch.linspace(0.0, 10.0, 11, dtype=torch.float64)
    for a, b in zip(load_excitation(path)(t), FourierExcitation(3)(t), strict=True):
        assert torch.equal(a, b)
    assert excitation_yaml("fourier", FourierExcitation(3)).startswith("excitation: fourier\noptions:\n")


@pytest.mark.parametrize(
    ("text", "match"),
    [
        (
            "excitation: fourier\n",
            r"expected exactly the keys \['excitation', 'options'\], got \['excitation'\]",
        ),
        ("[1, 2]", "expected exactly the keys"),
        ("excitation: nope\noptions: {}\n", "unknown excitation 'nope'"),
        ("excitation: fourier\noptions: {n_joints: 2, colour: red}\n", "has no option 'colour'"),
        ("excitation: fourier\noptions: {n_joints: 2, offset: [1]}\n", r"offset: expected shape \[2\]"),
        ("excitation: [\n", "not valid YAML"),
    ],
)
def test_bad_documents_name_the_file_and_the_problem(tmp_path, text, match):
    path = tmp_path / "bad.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ValueError, match=match) as info:
        load_excitation(path)
    assert str(path) in str(info.value)


def test_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(ValueError, match="cannot read it"):
        load_excitation(tmp_path / "absent.yaml")
