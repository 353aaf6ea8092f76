"""Packaging: the explicit package list covers idkit/, and the wheel ships the Hydra configs."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import tomllib
import zipfile
from pathlib import Path

from conftest import REPO


def shipped_folders(root: Path, prefix: tuple[str, ...]) -> set[str]:
    """Every folder under ``root`` holding a file, as the package name Python would import it by."""
    return {
        ".".join(prefix + p.parent.relative_to(root).parts)
        for p in root.rglob("*")
        if p.is_file() and "__pycache__" not in p.parts
    }


def test_package_list_covers_every_folder_that_ships():
    """Code packages and folders of data alike: a folder left out of the list is either missing from
    the wheel or, where package-data names it, one of setuptools' "Package would be ignored" banners."""
    listed = set(tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    code = {name for name in shipped_folders(REPO / "idkit", ("idkit",)) if not name.startswith("idkit.conf")}
    assert code | shipped_folders(REPO / "conf", ("idkit", "conf")) == listed


def test_wheel_ships_configs_and_assets(tmp_path):
    """Editable installs hide missing package data; build the real wheel and look inside.

    Built from a copy of the sources, so no stale ``build/`` folder can leak into (or out of) it.
    """
    source = tmp_path / "src"
    for folder in ("idkit", "conf"):
        shutil.copytree(REPO / folder, source / folder, ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO / name, source / name)
    build = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-v"]
        + ["-w", str(tmp_path), str(source)],
        check=True,
        capture_output=True,
        text=True,
    )
    # none of setuptools' warnings about idkit's own configuration (the install's output stays clean)
    said = build.stdout + build.stderr
    assert "would be ignored" not in said and "BuildBackendWarning" not in said, said[-3000:]
    names = zipfile.ZipFile(next(tmp_path.glob("robot_idkit-*.whl"))).namelist()
    yaml_on_disk = {f"idkit/conf/{p.relative_to(REPO / 'conf')}" for p in (REPO / "conf").rglob("*.yaml")}
    assert yaml_on_disk and yaml_on_disk <= set(names)
    assert "idkit/py.typed" in names
    assert "idkit/robots/assets/cylindrical.urdf" in names
    assert "idkit/robots/assets/arm.xml" in names
    assert "idkit/studies/data/paper-tables.csv" in names
    for file in ("servo_arm.xml", "train.csv", "held_out.csv"):  # docs/rollout.md's example
        assert f"idkit/examples/servo_arm/{file}" in names
    assert not [n for n in names if n.endswith((".c", ".so", ".pyd"))]  # nothing compiled, nothing to compile


def test_help_does_not_import_torch():
    code = "import sys, idkit.cli; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False", "importing the CLI must not import torch"


def test_single_fit_path_does_not_import_scipy():
    """scipy.signal (recordings only) cost ~1 s of every command's start-up when imported eagerly."""
    code = "import sys, idkit.studies.single, idkit.cli.app; print('scipy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False", "the single-fit path must import scipy lazily"


def test_the_suite_never_uses_the_real_cache_directory():
    """The root conftest points every cache at a per-session temporary folder."""
    home_cache = Path.home() / ".cache"
    for name in ("XDG_CACHE_HOME", "IDKIT_CACHE_DIR", "MPLCONFIGDIR"):
        where = Path(os.environ[name]).resolve()
        assert not where.is_relative_to(home_cache.resolve()), name
        assert where.is_relative_to(Path(tempfile.gettempdir()).resolve()), name


#: Features idkit's source uses and the torch release that first has them: the declared floor must
#: admit no release without them (an older torch would install and then fail mid-fit).
TORCH_FEATURES = {"fused=True": (2, 4)}  # torch.optim.Adam(fused=True) on CPU tensors: torch 2.4


def test_the_torch_floor_has_every_feature_the_source_uses():
    declared = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["dependencies"]
    floor = next(d for d in declared if d.replace(" ", "").startswith("torch>="))
    version = tuple(int(part) for part in floor.split(">=")[1].split(",")[0].split(".")[:2])
    source = "\n".join(p.read_text() for p in (REPO / "idkit").rglob("*.py"))
    for feature, needed in TORCH_FEATURES.items():
        if feature in source:
            assert version >= needed, f"{feature} needs torch>={'.'.join(map(str, needed))}, declared {floor}"
