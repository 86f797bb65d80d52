"""A resumed tune checks its trial store against the families the trials came from (issue 62,
item 5): an edited objective value in ``tune.db`` once changed the tuned answer without a
word; now the resume refuses in one line naming the trial, and an unedited store resumes."""

from __future__ import annotations

import shutil
import sqlite3

import pytest

from pipeline.tune import main

ARGS = ["--space", "quick", "--set", "replicates=1", "--set", "max_trials=4",
        "--set", "min_trials=4"]


@pytest.fixture(scope="module")
def tuned(tmp_path_factory):
    out = tmp_path_factory.mktemp("tune") / "tune"
    assert main([*ARGS, "--out", str(out)]) == 0
    return out


def test_an_unedited_store_resumes_and_an_edited_one_is_refused(tuned, tmp_path, capsys):
    resumed = tmp_path / "resumed"
    shutil.copytree(tuned, resumed)
    assert main([*ARGS, "--out", str(resumed)]) == 0
    capsys.readouterr()
    edited = tmp_path / "edited"
    shutil.copytree(tuned, edited)
    with sqlite3.connect(edited / "tune.db") as db:
        row = db.execute("SELECT trial_value_id, value FROM trial_values "
                         "ORDER BY trial_value_id LIMIT 1").fetchone()
        db.execute("UPDATE trial_values SET value = ? WHERE trial_value_id = ?",
                   (row[1] * 0.5 + 0.1, row[0]))
    assert main([*ARGS, "--out", str(edited)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) >= 1
    line = err[-1]
    assert line.startswith(f"error: {edited / 'tune.db'}: trial ") and "was edited" in line
    assert "gives" in line and "holds objective values" in line
