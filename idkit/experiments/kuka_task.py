"""``idkit +experiment=kuka``: the command-line face of :func:`idkit.experiments.kuka.run_kuka`.

Identifies a real KUKA LWR4+ on one recording and scores the torque prediction on held-out ones;
the recordings are not part of the repository (``kuka.data_dir``, default
``../shared/data/kuka-lwr4`` relative to the working directory, or ``$IDKIT_KUKA_DIR``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from idkit.experiments.build import plain, split


def run_config(cfg: Any, run_dir: Path) -> list[dict[str, Any]]:
    """The ``task=kuka`` entry of the command line: files land in the run directory."""
    from idkit.experiments.kuka import run_kuka

    k = cfg.kuka
    data_dir = Path(k.data_dir)
    if not data_dir.is_dir():
        raise FileNotFoundError(
            f"KUKA recordings not found in {data_dir.resolve()}; set kuka.data_dir=... or IDKIT_KUKA_DIR"
        )
    rows = run_kuka(
        data_dir,
        run_dir,
        estimators=[split("estimator", spec) for spec in plain(k.estimators)],
        models=[tuple(m) for m in plain(k.models)],
        train=k.train,
        test=list(k.test),
        stride=int(k.stride),
        device=cfg.device,
        dtype=cfg.dtype,
        seed=cfg.seed,
    )
    table = run_dir / "kuka_heldout.md"
    if table.exists():
        print(table.read_text())
    print(f"results: {run_dir}")
    return rows
