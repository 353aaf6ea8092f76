"""The shipped examples: what their script writes, small enough for a wheel, and copied as they are."""

from __future__ import annotations

import io
from importlib.resources import files

import numpy as np
import pytest

from idkit.examples import EXAMPLES, copy_example
from idkit.examples.make_servo_arm import files as servo_arm_files

SHIPPED = files("idkit.examples") / "servo_arm"


def test_the_shipped_servo_arm_is_what_its_script_writes():
    """The model byte for byte; the logs to their printed digits (MuJoCo's last bits may differ per CPU)."""
    for name, text in servo_arm_files().items():
        shipped = (SHIPPED / name).read_text(encoding="utf-8")
        if name.endswith(".xml"):
            assert shipped == text
        else:
            assert shipped.splitlines()[0] == text.splitlines()[0]
            a, b = (np.loadtxt(io.StringIO(x), delimiter=",", skiprows=1) for x in (shipped, text))
            np.testing.assert_allclose(a, b, rtol=0, atol=2e-5)


def test_the_examples_stay_small():
    assert sum(len((SHIPPED / f).read_bytes()) for f in EXAMPLES["servo_arm"]) < 300_000


def test_copy_example_refuses_to_overwrite_other_content(tmp_path):
    paths = copy_example("servo_arm", tmp_path)
    assert sorted(p.name for p in paths) == sorted(EXAMPLES["servo_arm"])
    assert copy_example("servo_arm", tmp_path) == paths  # the same files again: nothing lost
    (tmp_path / "train.csv").write_text("mine")
    with pytest.raises(FileExistsError, match="train.csv"):
        copy_example("servo_arm", tmp_path)
    assert (tmp_path / "train.csv").read_text() == "mine"
    with pytest.raises(ValueError, match="servo_arm"):
        copy_example("nothing")


def test_the_command_copies_or_says_how_to_call_it(tmp_path):
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-m", "idkit.examples", "servo_arm", str(tmp_path)], capture_output=True, text=True
    )
    assert done.returncode == 0 and (tmp_path / "servo_arm.xml").is_file()
    wrong = subprocess.run([sys.executable, "-m", "idkit.examples", "arm"], capture_output=True, text=True)
    assert wrong.returncode == 2 and "usage: python -m idkit.examples {servo_arm} [FOLDER]" in wrong.stderr
