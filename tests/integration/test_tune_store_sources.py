"""A resumed tune checks its trial store against the families the trials came from (issue 62,
item 5): an edited objective value in the trial store once changed the tuned answer without a
word; now the resume refuses in one line naming the trial, and an unedited store resumes."""

from __future__ import annotations

import json
import shutil

import pytest

from pipeline.studies.tune.search import STORE_FILE
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
    store = edited / STORE_FILE
    # the first told trial's first objective value, edited in its journal line
    lines = store.read_text().splitlines()
    told = next(i for i, line in enumerate(lines) if json.loads(line).get("values"))
    op = json.loads(lines[told])
    op["values"][0] = op["values"][0] * 0.5 + 0.1
    lines[told] = json.dumps(op, separators=(",", ":"))
    store.write_text("".join(line + "\n" for line in lines))
    assert main([*ARGS, "--out", str(edited)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) >= 1
    line = err[-1]
    assert line.startswith(f"error: {store}: trial ") and "was edited" in line
    assert "gives" in line and "holds objective values" in line
