"""The integration tier (issue 57, item 4): ``make test FAST=1`` leaves out the files of
``tests/conftest.py``'s INTEGRATION_FILES (marker ``integration``), CI runs them. Every name
there is a test file, and pytest marks exactly those files' tests."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from conftest import INTEGRATION_FILES

TESTS = Path(__file__).resolve().parent


def test_every_integration_file_exists_and_only_those_are_marked():
    assert all((TESTS / name).is_file() for name in INTEGRATION_FILES)
    proc = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q",
                           "-m", "integration", "-p", "no:cacheprovider", str(TESTS)],
                          capture_output=True, text=True, timeout=300, cwd=TESTS.parent)
    files = {line.split("::")[0].split("/")[-1] for line in proc.stdout.splitlines()
             if "::" in line}
    assert files == set(INTEGRATION_FILES) - {n for n in INTEGRATION_FILES
                                              if not _has_tests(TESTS / n)}


def _has_tests(path: Path) -> bool:
    return "def test_" in path.read_text()
