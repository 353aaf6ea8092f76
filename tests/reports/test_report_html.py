"""``report.html`` and the compare page, read back with ``html.parser``: the sections, numbers equal
to ``result.json``, and nothing fetched from a network."""

from __future__ import annotations

import json
import math
from html.parser import HTMLParser
from pathlib import Path

import pytest

import idkit
from idkit.cli.compare import main as compare_main
from idkit.reports import compare, single_page
from idkit.reports import excitation as excitation_report
from idkit.studies import excitation as excitation_study
from tests.reports import report_cases


@pytest.fixture(scope="module")
def validated_run(tmp_path_factory):
    return report_cases.validated_run(tmp_path_factory.mktemp("run"))


class Page(HTMLParser):
    """Sections, tables (rows of cells with their ``data-value``), and every URL-bearing attribute."""

    def __init__(self, text: str) -> None:
        super().__init__()
        self.sections: list[str] = []
        self.tables: dict[str, list[list[tuple[str, str | None]]]] = {}
        self.urls: list[str] = []
        self.tags: set[str] = set()
        self._table: str | None = None
        self._cell: list[str] | None = None
        self._value: str | None = None
        self.feed(text)

    def handle_starttag(self, tag, attrs):
        found = dict(attrs)
        self.tags.add(tag)
        self.urls += [v for k, v in attrs if k in ("src", "href", "action", "data") and v]
        if tag == "section":
            self.sections.append(found.get("id", ""))
        elif tag == "table":
            self._table = found.get("class", "") or f"table{len(self.tables)}"
            self.tables.setdefault(self._table, [])
        elif tag == "tr" and self._table is not None:
            self.tables[self._table].append([])
        elif tag in ("td", "th") and self._table is not None:
            self._cell, self._value = [], found.get("data-value")

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None and self._table is not None:
            self.tables[self._table][-1].append(("".join(self._cell), self._value))
            self._cell = None
        elif tag == "table":
            self._table = None

    def rows(self, table: str) -> dict[str, list[tuple[str, str | None]]]:
        """Body rows of a table by their first cell's text."""
        return {row[0][0]: row[1:] for row in self.tables[table][1:]}


def value(cell: tuple[str, str | None]) -> float:
    assert cell[1] is not None, cell
    return float(cell[1])


def offline(page: Page) -> None:
    """Nothing a browser would fetch: every URL is an embedded ``data:`` image or an anchor."""
    assert all(url.startswith(("data:image/png;base64,", "#")) for url in page.urls), page.urls
    assert not page.tags & {"script", "link", "iframe", "object", "embed"}


def test_the_single_page_has_its_sections_and_the_numbers_of_result_json(validated_run):
    _, folder = validated_run
    document = json.loads((folder / "result.json").read_text())
    assert document["files"]["report"] == str(folder / "report.html")
    page = Page((folder / "report.html").read_text())
    assert page.sections == ["verdicts", "parameters", "prediction", "run"]
    offline(page)
    assert sum(url.startswith("data:image/png") for url in page.urls) == 1  # the validation plot
    scores = document["payload"]["validation"][str(Path(folder).parent / "test.npz")]
    held = page.rows("held-out")
    for j, name in enumerate(["theta1", "d2", "d3"]):
        assert value(held[name][0]) == scores["rms"][j] and value(held[name][1]) == scores["relative"][j]
    # a revolute joint's error is a torque, a prismatic (sliding) joint's a force
    assert document["payload"]["joint_kinds"] == ["revolute", "prismatic", "prismatic"]
    assert [held[name][0][0].split()[-1] for name in ("theta1", "d2", "d3")] == ["N·m", "N", "N"]
    assert value(held["all joints (‖E‖/‖T‖)"][1]) == scores["rel_all"]
    params, nominal = document["payload"]["estimate"]["params"], document["payload"]["nominal"]
    shown = page.rows("parameters")
    assert set(shown) == set(params)
    for name, estimate in params.items():
        assert value(shown[name][0]) == estimate and value(shown[name][1]) == nominal[name]
    std = document["payload"]["estimate"]["details"]["uncertainty"]["std"]
    base = page.rows("base-parameters")
    assert {name: value(cells[1]) for name, cells in base.items()} == std
    links = page.rows("plausibility")
    record = document["payload"]["estimate"]["details"]["plausibility"]["links"]  # the run's one verdict
    assert set(links) == set(record) == {"link1", "link2", "link3"}
    for link, verdict in record.items():
        cells = links[link]
        assert value(cells[1]) == verdict["mass"] == params[f"{link}.m"]
        assert value(cells[3]) == verdict["min_eigenvalue"]
        assert cells[6][0] == ("yes" if verdict["plausible"] else "no")
        assert cells[7][0] == "; ".join(verdict["reasons"])


def test_the_page_reads_the_recorded_verdict_and_judges_nothing_itself(validated_run):
    """One rule: a link the record calls implausible is implausible on the page, with the record's
    reason, whatever its numbers look like (the page used to apply its own "within 10 cm of CAD")."""
    _, folder = validated_run
    document = json.loads((folder / "result.json").read_text())
    record = document["payload"]["estimate"]["details"]["plausibility"]
    record["links"]["link2"] |= {"plausible": False, "reasons": ["a reason only the record knows"]}
    record["implausible"] = ["link2"]
    html = single_page.render(document, folder)
    links = Page(html).rows("plausibility")
    assert links["link2"][6][0] == "no" and links["link2"][7][0] == "a reason only the record knows"
    assert links["link1"][6][0] == ("yes" if record["links"]["link1"]["plausible"] else "no")
    assert "implausible: link2" in html
    del document["payload"]["estimate"]["details"]["plausibility"]
    assert "No plausibility verdict recorded" in single_page.render(document, folder)


def test_every_recorded_reason_is_a_choice_on_the_page():
    document = {
        "config": {"x": {"reason": "not this one: the config is what was asked"}},
        "data": {
            "preprocess": {"cutoff_choice": {"cutoff": 4.0, "reason": "auto: lowest error"}},
            "delays": {"a.csv": {"seconds": 0.004, "estimated": True}, "b.csv": {"seconds": 0.0}},
        },
        "payload": {"estimate": {"details": {"prior_weight_cv": {"chosen": 300.0, "reason": "within 1 SE"}}}},
    }
    assert list(single_page.recorded_choices(document)) == [
        ("low-pass cut-off (preprocess.cutoff=auto)", 4.0, "auto: lowest error"),
        ("prior weight (estimator.prior_weight=auto)", 300.0, "within 1 SE"),
        ("torque delay of a.csv (recording.torque_lag=auto)", 0.004, "estimated from the recording"),
    ]


def test_the_excitation_page_shows_limits_and_the_margins_kept(tmp_path):
    study = excitation_study.run("cylindrical", seed=1, swarms=2, particles=8, iterations=5, adam_steps=3)
    written = excitation_report.write(study, tmp_path)
    document = json.loads(Path(written["result"]).read_text())
    page = Page(Path(written["report"]).read_text())
    assert page.sections == ["verdicts", "criterion", "limits", "motion", "run"]
    offline(page)
    check = document["payload"]["check"]
    rows = page.tables["limits"][1:]
    assert len(rows) == 9  # 3 joints × position, velocity, acceleration (no effort limits)
    for row in rows:
        joint, quantity = row[0][0], row[1][0]
        kept = check["margins"][joint][quantity]
        assert value(row[5]) == kept["worst"] and value(row[6]) == kept["share"]
        assert value(row[4]) == check["required_margins"][quantity] == 0.05
        assert value(row[2]) == document["payload"]["limits"][joint][quantity][0]
    criterion = page.rows("criterion")
    assert value(criterion["result"][0]) == document["payload"]["after"]


@pytest.fixture(scope="module")
def second_run(validated_run, tmp_path_factory):
    """The same data fitted with ``pcls`` (its prior weight given): its run folder, for the compare page."""
    result, _ = validated_run
    folder = tmp_path_factory.mktemp("second")
    idkit.run(
        robot={"_name_": "urdf", "urdf": "cylindrical"},
        estimator={"_name_": "pcls", "prior_weight": 10.0},
        cost=None,
        data=result.provenance.data["file"],
        validate=result.provenance.data["validate"],
        identified_urdf=False,
        out_dir=folder,
    )
    return folder


def test_the_compare_page_sets_parameters_side_by_side_in_sigma_units(validated_run, second_run):
    a = json.loads((validated_run[1] / "result.json").read_text())
    b = json.loads((second_run / "result.json").read_text())
    page = Page(compare.render(a, b, ("A", "B")))
    assert page.sections == ["runs", "held-out", "plausibility", "parameters", "config"]
    offline(page)
    base = page.rows("base-parameters")
    std_a = a["payload"]["estimate"]["details"]["uncertainty"]["std"]
    std_b = b["payload"]["estimate"]["details"]["uncertainty"]["std"]
    assert set(base) == set(std_a)
    for name, cells in base.items():
        pa, pb = a["payload"]["estimate"]["base_params"][name], b["payload"]["estimate"]["base_params"][name]
        assert value(cells[0]) == pa and value(cells[2]) == pb
        assert value(cells[5]) == pytest.approx((pb - pa) / math.hypot(std_a[name], std_b[name]), rel=1e-12)
    verdicts = page.rows("plausibility")  # each run's recorded verdict, link by link
    for k, document in ((0, a), (3, b)):
        record = document["payload"]["estimate"]["details"]["plausibility"]["links"]
        assert set(verdicts) == set(record)
        for link, cells in verdicts.items():
            assert cells[k][0] == ("yes" if record[link]["plausible"] else "no")
            assert cells[k + 2][0] == "; ".join(record[link]["reasons"])
    config = page.rows("config")
    assert config["plugins.estimator.name"] == [("ls", None), ("pcls", None)]
    (file,) = a["payload"]["validation"]
    held = page.rows("held-out")
    assert value(held["‖E‖/‖T‖"][0]) == a["payload"]["validation"][file]["rel_all"]
    assert value(held["‖E‖/‖T‖"][1]) == b["payload"]["validation"][file]["rel_all"]


def test_idkit_compare_writes_the_page_or_refuses_in_one_line(validated_run, tmp_path, capsys):
    _, folder = validated_run
    out = tmp_path / "same.html"
    assert compare_main([str(folder), str(folder / "result.json"), "--out", str(out)]) == 0
    assert capsys.readouterr().out == f"compare page: {out}\n"
    page = Page(out.read_text())
    offline(page)
    assert "The same settings." in out.read_text()
    assert compare_main([str(folder), str(tmp_path / "nothing")]) == 2
    assert capsys.readouterr().err == (
        f"idkit: compare: {tmp_path / 'nothing'}: no result.json (give a run folder or its result.json)\n"
    )
    (tmp_path / "other.json").write_text('{"a": 1}')
    assert compare_main([str(folder), str(tmp_path / "other.json")]) == 2
    assert "not an idkit result.json" in capsys.readouterr().err


def test_the_idkit_command_runs_compare(validated_run, run_idkit, tmp_path):
    _, folder = validated_run
    status, said = run_idkit("compare", str(folder), str(folder), "--out", str(tmp_path / "c.html"))
    assert status == 0 and said == [] and (tmp_path / "c.html").is_file()
    status, said = run_idkit("compare", str(folder))
    assert status == 2 and said[-1].endswith("the following arguments are required: RUN_B")
