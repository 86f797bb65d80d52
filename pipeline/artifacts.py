"""Run folders: atomic writing and reading of the files every run leaves behind.

A run folder holds ``config.yaml`` (resolved config), ``model.json``, ``trajectory.csv``,
``metrics.json`` (deterministic numbers and the config hash) and ``timing.json`` (wall-clock
solve times, which differ between identical runs and so are kept out of ``metrics.json``).
Every file is written to a temporary name and renamed, so a killed run never leaves a
half-written file; ``metrics.json`` is written last and marks the folder complete.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import pandas as pd

RUN_FILES = ("config.yaml", "model.json", "trajectory.csv", "timing.json", "metrics.json")


def write_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` via a temporary file in the same folder and ``os.replace``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as handle:
            handle.write(text)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; results are meant to be shared
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_json_atomic(path: Path, data: dict) -> None:
    write_text_atomic(path, json.dumps(data, indent=2, sort_keys=True, allow_nan=False) + "\n")


def write_csv_atomic(path: Path, frame: pd.DataFrame) -> None:
    # fixed float format so identical runs give byte-identical files
    write_text_atomic(path, frame.to_csv(index=False, float_format="%.10g", lineterminator="\n"))


def is_complete(run_dir: Path) -> bool:
    """True when every run file exists (``metrics.json`` is written last)."""
    return all((Path(run_dir) / name).is_file() for name in RUN_FILES)


def find_run_dirs(root: Path) -> list[Path]:
    """Complete run folders under ``root`` (recursive), sorted by path."""
    root = Path(root)
    return sorted(p.parent for p in root.rglob("metrics.json") if is_complete(p.parent))


def read_run(run_dir: Path) -> dict:
    """Read a run folder into ``{"dir", "config", "metrics", "timing", "trajectory"}``."""
    import yaml

    run_dir = Path(run_dir)
    return {
        "dir": run_dir,
        "config": yaml.safe_load((run_dir / "config.yaml").read_text()),
        "metrics": json.loads((run_dir / "metrics.json").read_text()),
        "timing": json.loads((run_dir / "timing.json").read_text()),
        "trajectory": pd.read_csv(run_dir / "trajectory.csv"),
    }
