"""The tiers (issue 57, item 4): the tests stand in folders by stage, and the files of
``tests/integration/`` are the integration tier (marker ``integration``): ``make test`` leaves
them out, ``make test-integration`` runs them, CI runs both. pytest marks exactly those files' tests, and no test file stands
outside a folder."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
FOLDERS = {"loop", "analysis", "store", "studies", "reporting", "commands", "integration"}

#: A plugin for one collection: every collected test's file and whether pytest marked it
#: integration (one collection instead of one per marker expression).
PROBE = '''
import os
import pytest


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(items):
    with open(os.environ["TIER_PROBE_OUT"], "w") as out:
        for item in items:
            marked = item.get_closest_marker("integration") is not None
            machine = item.get_closest_marker("machine") is not None
            out.write(f"{item.nodeid}\\t{int(marked)}\\t{int(machine)}\\n")
'''


def _collected(tmp_path: Path) -> tuple[dict[str, set[bool]], set[str]]:
    """Each test file and the integration marks of its tests, as pytest collects them; and
    the tests marked machine."""
    (tmp_path / "tier_probe.py").write_text(PROBE)
    out = tmp_path / "collected.tsv"
    env = {**__import__("os").environ, "TIER_PROBE_OUT": str(out),
           "PYTHONPATH": str(tmp_path)}
    proc = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q",
                           "-p", "no:cacheprovider", "-p", "tier_probe", str(TESTS)],
                          capture_output=True, text=True, timeout=300, cwd=TESTS.parent, env=env)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    marks: dict[str, set[bool]] = {}
    machine: set[str] = set()
    for line in out.read_text().splitlines():
        node, marked, on_machine = line.split("\t")
        marks.setdefault(node.split("::")[0], set()).add(marked == "1")
        if on_machine == "1":
            machine.add(node)
    return marks, machine


def test_the_integration_marker_is_the_integration_folder(tmp_path):
    marks, machine = _collected(tmp_path)
    marked = {path for path, m in marks.items() if True in m}
    expected = {f"tests/integration/{p.name}" for p in (TESTS / "integration").glob("test_*.py")
                if "def test_" in p.read_text()}
    assert marked == expected and len(expected) >= 10
    # every test of those files is marked, none elsewhere
    assert all(marks[path] == {True} for path in expected)
    unmarked = {path for path, m in marks.items() if m == {False}}
    assert {f.split("/")[1] for f in unmarked} == FOLDERS - {"integration"}
    # the machine tier: make install into fresh venvs, its warm step, a local Dask cluster
    # (integration tests all); make test leaves it out, make test-machine runs it
    assert {node.split("::")[0] for node in machine} == {
        "tests/integration/test_install.py", "tests/integration/test_warm.py",
        "tests/integration/test_tune_workers.py"}
    assert len(machine) == 4
    selection = {target: subprocess.run(["make", "-n", "--no-print-directory", target],
                                         cwd=TESTS.parent, capture_output=True, text=True,
                                         env=_without_make_flags()).stdout
                 for target in ("test", "test-integration", "test-machine")}
    assert '-m "not slow and not slurm and not machine and not integration"' in selection["test"]
    assert '-m "integration and not slow and not slurm and not machine"' \
        in selection["test-integration"]
    assert '-m "machine and not slurm"' in selection["test-machine"]
    # CI runs every tier, make test first
    ci = (TESTS.parent / ".ci" / "run").read_text()
    order = [ci.find(f"\nmake {t}\n") for t in ("test", "test-integration", "test-machine")]
    assert -1 not in order and order == sorted(order)


def _without_make_flags() -> dict[str, str]:
    import os

    return {k: v for k, v in os.environ.items() if k not in ("MAKEFLAGS", "MFLAGS", "MAKELEVEL")}


def test_every_test_file_stands_in_a_stage_folder():
    assert not list(TESTS.glob("test_*.py"))
    assert {p.parent.name for p in TESTS.rglob("test_*.py")} == FOLDERS


def test_the_longest_files_first_are_test_files_of_the_suite():
    """The order ``make test`` starts its files in names files that exist, once each (a
    renamed file would silently fall back to collection order)."""
    from tests.conftest import LONGEST_FILES_FIRST

    names = [p.name for p in TESTS.rglob("test_*.py")]
    assert len(set(LONGEST_FILES_FIRST)) == len(LONGEST_FILES_FIRST) >= 10
    assert [n for n in LONGEST_FILES_FIRST if names.count(n) != 1] == []
