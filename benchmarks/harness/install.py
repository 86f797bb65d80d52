"""How long the set-up takes: ``make install`` into a fresh venv with uv (the default) over the
same command with pip alone (``INSTALLER=pip``), both the Makefile's own recipe, timed here once
each (``install_over_pip`` in ``bench_summary.json``; package caches as this machine has them)."""

from __future__ import annotations

import shutil
import subprocess
import tempfile
import time
from pathlib import Path

#: the repository (where the Makefile and constraints.txt are); absent in an installed wheel
ROOT = Path(__file__).resolve().parents[2]


def measure_install(timeout_s: float = 1800.0) -> dict[str, float | str | None]:
    """Seconds of ``make install`` with uv and with pip into fresh venvs, and their ratio; None
    with the reason when it cannot be measured (no Makefile or make, an install that failed)."""
    if not (ROOT / "Makefile").is_file() or not (ROOT / "constraints.txt").is_file():
        return {"install_over_pip": None, "install_note": "no Makefile (an installed package)"}
    if shutil.which("make") is None:
        return {"install_over_pip": None, "install_note": "make is not on the PATH"}
    seconds: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="bench_install_") as folder:
        for installer in ("uv", "pip"):
            venv = Path(folder) / installer
            start = time.perf_counter()
            proc = subprocess.run(["make", "install", f"VENV={venv}", f"INSTALLER={installer}"],
                                  cwd=ROOT, capture_output=True, text=True, timeout=timeout_s)
            seconds[installer] = time.perf_counter() - start
            if proc.returncode != 0:
                return {"install_over_pip": None,
                        "install_note": f"make install INSTALLER={installer} failed"}
            if installer == "uv" and "installed with uv" not in proc.stdout:
                return {"install_over_pip": None, "install_s_pip": None,
                        "install_note": "uv was not usable here: make install fell back to pip"}
    return {"install_s_uv": round(seconds["uv"], 2), "install_s_pip": round(seconds["pip"], 2),
            "install_over_pip": round(seconds["uv"] / seconds["pip"], 3), "install_note": ""}
