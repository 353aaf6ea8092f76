"""The single fit's printed summary and validation plot: the model's joint names, each joint's
relative error, and the residual under measured vs predicted."""

from __future__ import annotations

import numpy as np
import pytest

from idkit.reports import plots, single
from tests.reports import report_cases


@pytest.fixture(scope="module")
def validated_run(tmp_path_factory):
    return report_cases.validated_run(tmp_path_factory.mktemp("run"))


def test_the_summary_names_the_joints_and_gives_each_its_relative_error(validated_run):
    result, _ = validated_run
    text = single.text(result)
    scores = result.validation[0].scores
    assert result.joint_names == ("theta1", "d2", "d3")
    units = ["N·m", "N", "N"]  # theta1 turns, d2 and d3 slide
    for name, unit, rms, relative in zip(result.joint_names, units, scores.rms, scores.relative, strict=True):
        assert f"  {name:<12}{rms:12.4g} {unit:<4}{100 * relative:9.2f} %" in text
    assert f"test.npz: ‖E‖/‖T‖ {100 * scores.rel_all:.2f} %" in text
    assert " j1 " not in text


def test_the_validation_plot_has_a_residual_panel_under_each_joint(validated_run, monkeypatch, tmp_path):
    result, folder = validated_run
    assert (folder / "validation_1.png").stat().st_size > 0
    drawn = []
    monkeypatch.setattr(plots, "save_figure", lambda fig, path: drawn.append(fig) or path)
    held = result.validation[0]
    single._validation_plot("LS", held, tmp_path / "v.png", list(result.joint_names), ["N·m", "N", "N"])
    (fig,) = drawn
    axes = fig.axes
    assert len(axes) == 6  # measured vs predicted, then the residual, per joint
    assert [ax.get_ylabel() for ax in axes] == [
        "theta1 (N·m)", "residual", "d2 (N)", "residual", "d3 (N)", "residual"
    ]  # fmt: skip
    measured, predicted = held.scores.measured, held.scores.predicted
    for j in range(3):
        (line,) = [ln for ln in axes[2 * j + 1].get_lines() if len(ln.get_ydata()) > 2]
        np.testing.assert_allclose(line.get_ydata(), (measured - predicted)[: len(line.get_ydata()), j])


def test_efforts_are_newtons_on_a_sliding_joint_and_newton_metres_on_a_revolute_one():
    from idkit.reports.units import effort_unit, effort_units

    assert [effort_unit(k) for k in ("revolute", "prismatic", None)] == ["N·m", "N", "N·m or N"]
    assert effort_units(["revolute", "prismatic"], 2) == ["N·m", "N"]
    assert (
        effort_units(None, 2) == effort_units(["revolute"], 2) == ["N·m or N"] * 2
    )  # unknown, or not one each
