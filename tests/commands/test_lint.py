"""``make lint`` (ruff, then mypy, as configured in pyproject.toml) as a test of ``make test``:
it runs on one worker beside the other tests (started first: tests/conftest.py's order), and a
finding fails the suite as one of its failures, with the tools' output."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_make_lint_finds_nothing():
    # a make of its own: not the jobserver of the make that may have started the suite
    env = {k: v for k, v in os.environ.items() if k not in ("MAKEFLAGS", "MFLAGS", "MAKELEVEL")}
    proc = subprocess.run(["make", "--no-print-directory", "lint"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-8000:]
