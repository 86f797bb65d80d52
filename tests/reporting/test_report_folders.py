"""Hostile class: the report's ``--tune`` and ``--multiverse`` naming a folder without that
study's result.

``python -m pipeline.report RUNS --tune outputs/tnue`` (a typo, a folder that does not exist, or
another study's folder) left the fair fight section out without a word and exited 0, even with
``--strict``. Now a folder named on the command line is read or skipped with its reason: one
line on stderr, the folder listed as skipped on the page, and ``--strict`` exits 1.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.report import main


@pytest.fixture(scope="module")
def runs(small_reproduce) -> Path:
    """The session's :func:`small_reproduce` (read-only): the paper scenario and a family of
    improved and the baseline."""
    return small_reproduce


@pytest.mark.parametrize("option, line", [
    ("--tune", "skipped {folder}: fair fight section left out (ResultError: tuning tables not "
               "trusted: not a folder)"),
    ("--multiverse", "skipped {folder}: robustness section left out (ResultError: multiverse "
                     "tables not trusted: not a folder)"),
])
def test_a_named_study_folder_without_its_result_is_skipped_with_a_line(runs, tmp_path,
                                                                        capsys, option, line):
    """``python -m pipeline.report RUNS --strict --tune MISSING``: the line above on stderr, the
    report written with the folder listed as skipped, and ``error: --strict: 1 folder(s)
    skipped``, exit 1 (it exited 0 without a word)."""
    folder = tmp_path / "typo"
    assert main([str(runs), "--out", str(tmp_path / "report"), "--figure-jobs", "1",
                 "--strict", option, str(folder)]) == 1
    err = capsys.readouterr().err.splitlines()
    assert line.format(folder=folder) in err
    assert err[-1] == "error: --strict: 1 folder(s) skipped"
