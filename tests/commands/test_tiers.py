"""The tiers (issue 57, item 4): the tests stand in folders by stage, and the files of
``tests/integration/`` are the integration tier (marker ``integration``): ``make test FAST=1``
leaves them out, CI runs them. pytest marks exactly those files' tests, and no test file stands
outside a folder."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
FOLDERS = {"loop", "analysis", "store", "studies", "reporting", "commands", "integration"}


def _collected(*marker: str) -> set[str]:
    proc = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q",
                           "-p", "no:cacheprovider", *marker, str(TESTS)],
                          capture_output=True, text=True, timeout=300, cwd=TESTS.parent)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    return {line.split("::")[0] for line in proc.stdout.splitlines() if "::" in line}


def test_the_integration_marker_is_the_integration_folder():
    marked = _collected("-m", "integration")
    expected = {f"tests/integration/{p.name}" for p in (TESTS / "integration").glob("test_*.py")
                if "def test_" in p.read_text()}
    assert marked == expected and len(expected) >= 10
    unmarked = _collected("-m", "not integration")
    assert not {f for f in unmarked if f.startswith("tests/integration/")}
    assert {f.split("/")[1] for f in unmarked} == FOLDERS - {"integration"}


def test_every_test_file_stands_in_a_stage_folder():
    assert not list(TESTS.glob("test_*.py"))
    assert {p.parent.name for p in TESTS.rglob("test_*.py")} == FOLDERS
