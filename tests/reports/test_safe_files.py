"""Nothing written where it should not be: names from users' files as file names and CSV cells, the
mode of a file saved over, a model file never without its result.json, one XML policy for every
model loader."""

from __future__ import annotations

import csv
import errno
import json
import os
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from idkit.reports import files
from idkit.untrusted import csv_cell, csv_header, csv_text, safe_basename

#: Joint names a URDF may hold that a spreadsheet would evaluate (issue 32).
FORMULAS = ("=1+1", "+cmd|' /C calc'!A0", "@SUM(1)", "-2+3", "\tx", "\rx")


@pytest.mark.parametrize(
    ("text", "name"),
    [
        ("../../../X", "X"),
        ("/etc/passwd", "etc_passwd"),
        ("a b/c", "a_b_c"),
        ("run-2024.01", "run-2024.01"),
        ("..", "unnamed"),
        (None, "unnamed"),
        ("-rf", "rf"),
        ("CON", "_CON"),
        ("x" * 300, "x" * 80),
    ],
)
def test_safe_basename_examples(text, name):
    assert safe_basename(text) == name


@given(st.text())
def test_safe_basename_is_one_plain_name_inside_any_folder(text):
    name = safe_basename(text)
    assert Path(name).name == name and name not in (".", "..")
    assert not name.startswith((".", "-")) and len(name) <= 80
    assert (Path("/base") / name).resolve().parent == Path("/base")


@pytest.mark.parametrize("cell", FORMULAS)
def test_a_formula_cell_is_escaped_and_read_back(cell):
    assert csv_cell(cell) == "'" + cell
    assert csv_text(csv_cell(cell)) == cell


@pytest.mark.parametrize("cell", ["-0.5", "+1e3", "-inf", "theta1", "a=b", 3, None, -1.5])
def test_numbers_and_plain_text_stay_as_they_are(cell):
    assert csv_cell(cell) == cell


@given(st.text())
def test_csv_text_undoes_csv_cell(text):
    assert csv_text(csv_cell(text)) == text
    assert not str(csv_cell(text)).startswith(("=", "+", "@", "\t", "\r")) or _number(text)


def _number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def test_every_csv_writer_escapes_names(tmp_path):
    """The table writer (summary.csv, history.csv, reports) and the header of ``np.savetxt`` writers."""
    path = files.write_csv(tmp_path / "t.csv", ["t", *FORMULAS], [[0.0, *FORMULAS]])
    header, row = _rows(path)
    assert header[1:] == row[1:] == ["'" + cell for cell in FORMULAS]
    line = csv_header(["t", "=1+1.q", "a,b"])
    assert line == 't,\'=1+1.q,"a,b"'


def _rows(path: Path) -> list[list[str]]:
    with path.open(newline="") as handle:  # a cell's \r stays in it
        return list(csv.reader(handle))


def _header(path: Path) -> list[str]:
    return _rows(path)[0]


def _hostile_urdf(tmp_path: Path) -> tuple[Path, tuple[str, ...]]:
    from idkit.robots.urdf_model import ASSETS

    names = ("=1+1", "+cmd|' /C calc'!A0", "@SUM(1)")
    text = (ASSETS / "cylindrical.urdf").read_text()
    for old, new in zip(("theta1", "d2", "d3"), names, strict=True):
        text = text.replace(f'"{old}"', f'"{new}"')
    path = tmp_path / "hostile.urdf"
    path.write_text(text)
    return path, names


def test_excitation_csv_of_a_urdf_with_formula_joint_names_is_safe_and_reads_back(tmp_path):
    """Issue 32: those names went unescaped into the header of ``excitation.csv``."""
    from idkit.excitation.export import read_trajectory
    from idkit.reports import excitation as report
    from idkit.robots.urdf import URDFRobot
    from idkit.studies.excitation import run

    urdf, names = _hostile_urdf(tmp_path)
    assert URDFRobot(str(urdf)).joint_names == names
    study = run(
        {"_name_": "urdf", "urdf": str(urdf)},
        swarms=1,
        particles=4,
        iterations=2,
        adam_steps=1,
        collision=False,
        t_end=2.0,
        rate=50.0,
    )
    written = report.write(study, tmp_path / "run", plots=False)
    header = _header(Path(written["csv"]))
    assert header[0] == "t" and all(cell.startswith("'") for cell in header[1:])
    assert read_trajectory(written["csv"], names).joint_names == names


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@pytest.mark.parametrize("mode", [0o644, 0o640, 0o600])
def test_saving_over_a_file_keeps_its_mode(tmp_path, mode):
    """``IdentifiedModel.save`` over a 0644 file left it 0600 (``mkstemp`` without a chmod)."""
    from idkit.model import IdentifiedModel
    from idkit.robots.urdf import URDFRobot

    robot = URDFRobot("cylindrical")
    model = IdentifiedModel.from_params(robot, robot.nominal_params())
    path = tmp_path / "identified.urdf"
    path.write_text("old")
    path.chmod(mode)
    assert model.save(path) == path
    assert oct(path.stat().st_mode & 0o777) == oct(mode) and "<robot" in path.read_text()
    fresh = model.save(tmp_path / "new.urdf")
    assert oct(fresh.stat().st_mode & 0o777) == oct(0o666 & ~_umask())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["identified.urdf", "new.urdf"]


@pytest.fixture(scope="module")
def fitted():
    """A fit of the cylindrical URDF robot, whose report writes ``identified.urdf``."""
    import idkit

    result = idkit.run(robot={"_name_": "urdf", "urdf": "cylindrical"}, estimator="ls", cost=None)
    assert result.urdf is not None
    return result


def test_a_full_disk_never_leaves_a_model_without_its_result(fitted, tmp_path, monkeypatch):
    """``identified.urdf`` used to be written before ``result.json``: a full disk in between left the
    model alone in the folder, looking like a finished run."""
    real = files.write_json

    def full_disk(path, data):
        if Path(path).name == "result.json":
            raise files.WriteError(Path(path), OSError(errno.ENOSPC, "No space left on device"))
        return real(path, data)

    monkeypatch.setattr(files, "write_json", full_disk)
    out = tmp_path / "run"
    with pytest.raises(files.WriteError, match="No space left on device"):
        fitted.save(out, make_plots=False)
    left = sorted(p.name for p in out.iterdir())
    assert "identified.urdf" not in left and "result.json" not in left
    assert not [name for name in left if name.endswith(".tmp")]
    monkeypatch.setattr(files, "write_json", real)
    written = fitted.save(out, make_plots=False)  # the same run saved again: all of it
    document = json.loads(Path(written["result"]).read_text())
    assert Path(document["files"]["identified_urdf"]).is_file()
    assert Path(written["identified_urdf"]).read_text().startswith("<")


DTD_CASES = {
    "internal entity": '<!DOCTYPE {root} [ <!ENTITY n "j1"> ]>',
    "external entity": '<!DOCTYPE {root} [ <!ENTITY x SYSTEM "file:///etc/hostname"> ]>',
    "external DTD": '<!DOCTYPE {root} SYSTEM "http://example.com/x.dtd">',
    "billion laughs": '<!DOCTYPE {root} [ <!ENTITY a "aaaaaaaaaa"> <!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;"> ]>',
}


def _with_doctype(text: str, root: str, doctype: str) -> str:
    return text.replace(f"<{root}", doctype.format(root=root) + f"\n<{root}", 1)


@pytest.mark.parametrize("case", sorted(DTD_CASES))
def test_every_model_loader_refuses_a_dtd_in_the_same_words(tmp_path, case):
    """``rollout.model`` accepted a DOCTYPE that ``robot=mjcf`` refused: one policy now, before any
    parser (expat expands entities, MuJoCo's tinyxml2 ignores them) sees the text."""
    pytest.importorskip("mujoco")
    from idkit.robots.mjcf import read_mjcf
    from idkit.robots.urdf_model import ASSETS, parse_urdf
    from idkit.sim.model import load_model

    mjcf = tmp_path / "arm.xml"
    mjcf.write_text(_with_doctype((ASSETS / "arm.xml").read_text(), "mujoco", DTD_CASES[case]))
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(_with_doctype((ASSETS / "cylindrical.urdf").read_text(), "robot", DTD_CASES[case]))
    said = "declares a DTD (<!DOCTYPE {root} …>); idkit reads models without one"
    for load, option, path, root in [
        (read_mjcf, "mjcf", mjcf, "mujoco"),
        (load_model, "rollout.model", mjcf, "mujoco"),
        (load_model, "rollout.model", urdf, "robot"),
        (parse_urdf, "urdf", urdf, "robot"),
    ]:
        with pytest.raises(ValueError, match="DTD") as refused:
            load(str(path))
        assert str(refused.value).startswith(f"{option}: {path} " + said.format(root=root))
    with pytest.raises(ValueError, match="declares a DTD"):  # text, not a file: the same
        parse_urdf(urdf.read_text())


def test_a_rollout_model_of_random_bytes_names_the_file_and_the_option(tmp_path):
    pytest.importorskip("mujoco")
    from idkit.sim.model import load_model

    path = tmp_path / "arm.xml"
    path.write_bytes(bytes([0xFF, 0xFE, 0x00, 0x81]) + os.urandom(200))
    with pytest.raises(ValueError) as refused:
        load_model(str(path))
    assert str(refused.value).startswith(f"rollout.model: {path} is not a text model file (byte 0xff")


def test_a_recording_with_formula_joint_names_is_saved_escaped_and_reads_back(tmp_path):
    """The data writers take their header as text (``np.savetxt``): it goes through the same helper."""
    import numpy as np

    from idkit.data.raw import Recording
    from idkit.data.recording import load_recording, save_recording

    names = ("=1+1", "@SUM(1)", "a,b")
    rng = np.random.default_rng(0)
    original = Recording(
        np.arange(5) * 0.01, rng.standard_normal((5, 3)), rng.standard_normal((5, 3)), joint_names=names
    )
    path = save_recording(original, tmp_path / "raw.csv")
    header = _header(path)
    assert header[:3] == ["t", "'=1+1.q", "'@SUM(1).q"] and header[3] == "a,b.q"
    back = load_recording(path)
    assert back.joint_names == names
    np.testing.assert_array_equal(back.q, original.q)


@given(st.lists(st.lists(st.text(), min_size=1, max_size=4), min_size=1, max_size=4))
def test_csv_lines_read_back_cell_for_cell(rows):
    """Whatever the cells hold (commas, quotes, line breaks, formulas), the file has one CSV row per
    row, and ``csv_text`` of each cell read back is the cell written."""
    import io

    from idkit.untrusted import csv_lines

    width = max(map(len, rows))
    rows = [row + [""] * (width - len(row)) for row in rows]
    back = list(csv.reader(io.StringIO(csv_lines(rows), newline="")))
    if width == 1:  # a row of one empty cell is an empty line, which csv.reader yields as []
        back = [row or [""] for row in back]
    assert [[csv_text(cell) for cell in row] for row in back] == rows


def test_a_torque_runs_model_of_random_bytes_names_the_file_and_the_option(tmp_path):
    """``rollout.model=<run folder>`` reads its ``identified.xml`` under the same policy."""
    from idkit.sim.from_run import read_torque_run

    document = {
        "task": "single",
        "config": {"robot": {"_name_": "urdf", "urdf": "cylindrical"}},
        "payload": {"estimate": {"params": {}}, "joint_names": ["j1"]},
    }
    (tmp_path / "result.json").write_text(json.dumps(document))
    (tmp_path / "identified.xml").write_bytes(b"\xff\xfe<mujoco/>")
    with pytest.raises(ValueError) as refused:
        read_torque_run(tmp_path, lambda spec: None)  # refused before any robot is built
    assert str(refused.value).startswith(f"rollout.model: {tmp_path / 'identified.xml'} is not a text model")
