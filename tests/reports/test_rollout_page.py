"""``report.html`` of a rollout run, from its ``result.json`` alone: verdicts first and graded by one rule,
every unknown with its interval, bound hits and flat directions named, the figures embedded."""

from __future__ import annotations

import re

from idkit.reports import rollout_page


def document(held_out_error: float = 3e-4, with_plots: bool = False) -> dict:
    """A rollout run's ``result.json`` as the report writes it: two joints, one unknown on its bound, a flat
    direction, a fit log and a held-out log whose j2 error is ``held_out_error`` (noise 1e-4)."""

    def scores(segments: int, q2: float) -> dict:
        return {
            "segments": segments,
            "rms": {"q": {"j1": 1.1e-4, "j2": q2 * 1.1}, "qd": {"j1": 0.011, "j2": 0.012}},
            "robust": {"q": {"j1": 1.0e-4, "j2": q2}, "qd": {"j1": 0.01, "j2": 0.011}},
            "noise": {"q": {"j1": 1.0e-4, "j2": 1.0e-4}, "qd": {"j1": 0.01, "j2": 0.01}},
        }

    return {
        "task": "rollout",
        "label": "rollout",
        "status": "complete",
        "seed": 0,
        "data": {"model": "arm.xml", "files": ["train.csv"]},
        "plugins": {"estimator": {"name": "rollout", "options": {}}},
        "files": {"fit_plot": "/elsewhere/fit.png", "validation_plot_1": "/elsewhere/validation_1.png"}
        if with_plots
        else {},
        "payload": {
            "estimate": {
                "estimator": "rollout",
                "params": {"j1.damping": 1.25, "j2.damping": 5.0, "j1.armature": 0.1},
                "wall_time_s": 2.5,
                "details": {
                    "sigma": {"j1.damping": 0.01, "j2.damping": 0.2, "j1.armature": 0.003},
                    "ci95": {"j1.damping": [1.23, 1.27], "j2.damping": [4.6, 5.4],
                             "j1.armature": [0.094, 0.106]},
                    "flat_directions": [{"direction": {"j1.armature": 1.0, "j1.damping": -0.8},
                                         "sigma": 0.7}],
                    "rollouts": 1234,
                    "polish": [{"segments": 4, "initial_states_free": True, "iterations": 3, "losses": [0.5],
                                "stop": "ftol"}],
                },
            },
            "unknowns": {
                "j1.damping": {"kind": "damping", "start": 1.0, "bounds": [0.1, 10.0]},
                "j2.damping": {"kind": "damping", "start": 0.5, "bounds": [0.05, 5.0]},
                "j1.armature": {"kind": "armature", "start": 0.05, "bounds": [0.005, 0.5]},
            },
            "fit": {"train.csv": scores(8, 1.0e-4)},
            "validation": {"held_out.csv": scores(1, held_out_error)},
            "identified_xml": "identified.xml",
            "identified_xml_problem": None,
        },
    }  # fmt: skip


def section(page: str, anchor: str) -> str:
    return re.search(f'<section id="{anchor}">(.*?)</section>', page, re.S).group(1)


def test_verdicts_come_first_and_grade_each_joint_against_its_noise(tmp_path):
    """A record without verdicts (before held-out modes): each joint's error over the log's noise level,
    within noise up to ``WITHIN`` times it."""
    page = rollout_page.render(document(held_out_error=3e-4), tmp_path)
    assert page.index('id="verdicts"') < page.index('id="parameters"') < page.index('id="prediction"')
    verdicts = section(page, "verdicts")
    held = verdicts[verdicts.index("held_out.csv") : verdicts.index("Model-limited")]
    assert "whole: one rollout from its first logged state" in held  # the mode, named
    ratios = re.findall(r'<td class="num (\w+)" data-value="([0-9.e-]+)">[0-9.]+×', held)
    assert [(css, round(float(v), 9)) for css, v in ratios] == [("good", 1.0), ("poor", 3.0)]  # j2: 3× noise
    assert 'class="badge poor">3× noise (j2)' in held
    good = rollout_page.render(document(held_out_error=1.5e-4), tmp_path)
    assert 'class="badge good">within noise' in section(good, "verdicts")


def held_out_record(mode: str, values: str, ratio2: float, default: bool) -> dict:
    """A held-out record as :mod:`idkit.sim.validation` writes it (per mode and values)."""
    return {
        "mode": mode, "horizon": 0.5 if mode == "segments" else None, "values": values,
        "segments": 6 if mode == "segments" else 1, "default": default,
        "reason": "every joint is held by a position servo" if default else "",
        "rms_q": {"j1": 2e-4, "j2": 3e-4 * ratio2}, "rms_qd": {"j1": 0.02, "j2": 0.02},
        "robust_q": {"j1": 1.5e-4, "j2": 2e-4 * ratio2}, "robust_qd": {"j1": 0.01, "j2": 0.01},
        "noise_q": {"j1": 1e-4, "j2": 1e-4}, "noise_qd": {"j1": 0.01, "j2": 0.01},
        "expected_q": {"j1": 1.5e-4, "j2": 2e-4}, "ratio": {"j1": 1.0, "j2": ratio2},
        "verdicts": {"j1": "within noise", "j2": "within noise" if ratio2 <= 2 else f"{ratio2:.2g}× noise"},
        "verdict": "within noise",
    }  # fmt: skip


def test_a_held_out_record_is_read_with_its_own_verdicts_modes_and_the_start_values(tmp_path):
    """The held-out record of idkit.sim.validation: its verdicts as recorded (not graded again), the
    default mode first with its reason, the start values' error beside, the other mode below."""
    doc = document()
    doc["payload"]["validation"] = {
        "held_out.csv": [
            held_out_record("segments", "fitted", 4.0, False),
            held_out_record("whole", "fitted", 1.2, True),
            held_out_record("whole", "start", 9.0, True),
            held_out_record("segments", "start", 9.0, False),
        ]
    }
    doc["payload"]["estimate"]["details"].update(
        {
            "model_limited": False,
            "misfit": 1.04,
            "uncertainty_reason": "textbook intervals: at the noise",
            "heavier_links": {"j1.damping": 0.02, "j2.damping": -0.3},
        }
    )
    verdicts = section(rollout_page.render(doc, tmp_path), "verdicts")
    held = verdicts[verdicts.index("held_out.csv") : verdicts.index("Model-limited")]
    assert 'class="badge good">within noise' in held  # the default mode's verdict (whole), as recorded
    assert held.index("whole: one rollout") < held.index("Also simulated in 6 segments of 0.5 s")
    assert "the default: every joint is held by a position servo" in held
    assert "4× noise (j2)" in held and "perfect model&#x27;s error" in held
    assert "q error, start values" in held and ">0.0018<" in held  # start values: 9 × 2e-4
    assert "textbook intervals: at the noise" in verdicts
    heavier = verdicts[verdicts.index("heavier") :]
    assert heavier.index("j2.damping") < heavier.index("j1.damping") and "-30 %" in heavier  # largest first


def test_the_fit_log_is_named_with_the_states_it_started_from(tmp_path):
    verdicts = section(rollout_page.render(document(), tmp_path), "verdicts")
    assert "in 8 segments, each from its initial state the fit estimated" in verdicts


def test_bound_hits_flat_directions_and_model_limitation_are_said(tmp_path):
    verdicts = section(rollout_page.render(document(), tmp_path), "verdicts")
    bounds = verdicts[verdicts.index("Estimates on a bound") : verdicts.index("Flat directions")]
    assert "j2.damping" in bounds and "upper" in bounds and "j1.damping" not in bounds
    assert "1·j1.armature + -0.8·j1.damping" in verdicts
    assert "Not assessed by this run" in verdicts  # the record does not say: no verdict invented
    limited = document()
    limited["payload"]["estimate"]["details"]["model_limited"] = True
    assert "model-limited" in section(rollout_page.render(limited, tmp_path), "verdicts")


def test_every_unknown_has_its_estimate_sigma_and_interval(tmp_path):
    parameters = section(rollout_page.render(document(), tmp_path), "parameters")
    for name, value, sigma, interval in [
        ("j1.damping", "1.25", "0.01", "[1.23, 1.27]"),
        ("j2.damping", "5.0", "0.2", "[4.6, 5.4]"),
        ("j1.armature", "0.1", "0.003", "[0.094, 0.106]"),
    ]:
        row = re.search(f"<tr><td>{re.escape(name)}</td>(.*?)</tr>", parameters).group(1)
        assert f'data-value="{value}"' in row and f'data-value="{sigma}"' in row and interval in row


def test_figures_are_embedded_from_the_run_folder(tmp_path):
    (tmp_path / "validation_1.png").write_bytes(b"\x89PNG held")
    (tmp_path / "fit.png").write_bytes(b"\x89PNG fit")
    prediction = section(rollout_page.render(document(with_plots=True), tmp_path), "prediction")
    assert prediction.count("data:image/png;base64,") == 2
    assert prediction.index("held out: held_out.csv") < prediction.index("fit log")
    assert "plots=false" in section(rollout_page.render(document(), tmp_path), "prediction")


def test_idkit_compare_sets_two_rollout_runs_side_by_side(tmp_path):
    """``idkit compare`` of two rollout run folders: the held-out error per joint of each, graded by the
    report's rule, and each unknown with its σ and the change in σ units (a bound hit named)."""
    import json

    from idkit.cli import compare

    a, b = document(held_out_error=1e-4), document(held_out_error=8e-4)
    a["run_id"], b["run_id"] = "run-a", "run-b"
    b["payload"]["estimate"]["params"]["j1.damping"] = 1.5  # 25 σ from A's 1.25
    for name, doc in (("a", a), ("b", b)):
        (tmp_path / name).mkdir()
        (tmp_path / name / "result.json").write_text(json.dumps(doc))
    out = tmp_path / "compare.html"
    assert compare.main([str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(out)]) == 0
    page = out.read_text()
    held = section(page, "held-out")
    assert re.findall(r'class="num (\w+)" data-value="[0-9.e-]+">[0-9.]+×', held) == [
        "good",
        "good",
        "good",
        "poor",
    ]  # fmt: skip  (A: j1, j2 at the noise; B: j1 at it, j2 8×)
    unknowns = section(page, "parameters")
    row = re.search(r"<tr><td>j1.damping</td>(.*?)</tr>", unknowns).group(1)
    z = float(re.search(r'class="num poor" data-value="([0-9.e-]+)"', row).group(1))
    assert abs(z - 0.25 / (2**0.5 * 0.01)) < 1e-9  # flagged: (1.5 − 1.25) / √(0.01² + 0.01²)
    assert "A at its upper bound, B at its upper bound" in unknowns  # j2.damping in both
