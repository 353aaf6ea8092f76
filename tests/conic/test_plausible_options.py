"""The plausibility options refuse what they cannot mean in one line that states the rule."""

from __future__ import annotations

import pytest

from idkit.conic.plausible import Plausibility


@pytest.mark.parametrize("ratio", [(1.5, 3), (0.2, 0.8), (-1, 2), (0.5, float("inf"))], ids=str)
def test_a_mass_band_without_the_cad_mass_is_refused_with_the_rule_and_the_way_out(ratio):
    """``estimator.mass_ratio=[1.5, 3]`` was refused by a rule the docs did not state."""
    with pytest.raises(ValueError) as refused:
        Plausibility.checked("pcls", mass_ratio=ratio)
    said = str(refused.value)
    assert said.startswith("pcls: mass_ratio [lo, hi] needs 0 <= lo <= 1 <= hi, got [")
    assert "around each link's CAD mass" in said and "total_mass" in said


def test_the_rule_is_in_the_docs():
    from pathlib import Path

    page = (Path(__file__).resolve().parents[2] / "docs" / "real-robots.md").read_text()
    assert "`0 <= lo <= 1 <= hi`" in page


def test_a_band_around_cad_is_kept():
    assert Plausibility.checked("pcls", mass_ratio=[0.5, 2]).mass_ratio == (0.5, 2.0)
