"""Hostile class: a study's ``--out`` that holds another study's record, or that another study
is writing.

``python -m pipeline.nmpc_check --out outputs/tune`` replaced the tune's ``summary.json`` and
``manifest.json`` with its own (the tune's result was lost and the report left the fair fight
out), a tune into an nmpc_check's folder did the same the other way round, and an nmpc_check
started while a tune ran in that folder wrote beside it. Now a study refuses a folder whose
manifest is another kind's record in one line naming ``--out`` (exit 2, nothing written), and
the nmpc_check takes the studies' folder lock, so a running tune or multiverse refuses it.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pipeline.errors import plain_value
from pipeline.nmpc_check import main as nmpc_main
from pipeline.store.lock import folder_lock
from pipeline.tune import main as tune_main


def _record(folder: Path, kind: str) -> dict[str, bytes]:
    """A finished study's top files, as its command leaves them; returns their bytes."""
    folder.mkdir(parents=True)
    (folder / "summary.json").write_text(json.dumps({"study": kind}))
    (folder / "manifest.json").write_text(json.dumps({"schema": 1, "kind": kind, "files": {}}))
    return {p.name: p.read_bytes() for p in folder.iterdir()}


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_an_nmpc_check_into_a_tunes_folder_is_refused_and_keeps_the_tune(tmp_path, capsys):
    """``python -m pipeline.nmpc_check --family-size 1 --out TUNE`` (TUNE: a tune's folder): exit 2,
    ``config error: --out='TUNE' is invalid; allowed: a new folder or one a nmpc_check wrote
    (this one holds a tune record, whose files would be replaced)``; the tune's files intact."""
    out = tmp_path / "tune"
    before = _record(out, "tune")
    assert nmpc_main(["--family-size", "1", "--track", "lateral", "--out", str(out)]) == 2
    line = _one_line(capsys)  # the key, what it may be, what the folder holds
    assert f"--out={plain_value(str(out))}" in line and "allowed: a new folder" in line
    assert "nmpc_check" in line and "holds a tune record" in line
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_a_tune_into_an_nmpc_checks_folder_is_refused(tmp_path, capsys):
    """``python -m pipeline.tune --space quick --out CHECK`` (CHECK: an nmpc_check's folder):
    exit 2, ``config error: --out='CHECK' is invalid; allowed: a new folder or one a tune
    wrote (this one holds a nmpc_check record, whose files would be replaced)``."""
    out = tmp_path / "check"
    before = _record(out, "nmpc_check")
    assert tune_main(["--space", "quick", "--out", str(out)]) == 2
    line = _one_line(capsys)
    assert f"--out={plain_value(str(out))}" in line and "allowed: a new folder" in line
    assert "a tune wrote" in line and "holds a nmpc_check record" in line
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


@pytest.mark.parametrize("holder", ["tune quick", "multiverse quick"])
def test_an_nmpc_check_into_a_folder_a_study_is_writing_is_refused(tmp_path, capsys, holder):
    """``python -m pipeline.nmpc_check --family-size 1 --out D`` while a tune (or multiverse) runs
    in D: exit 2, ``error: D is in use by another study (tune quick, pid N on HOST); wait for
    it to finish or choose another --out``."""
    out = tmp_path / "busy"
    with folder_lock(out, holder):
        assert nmpc_main(["--family-size", "1", "--track", "lateral", "--out", str(out)]) == 2
    line = _one_line(capsys)
    assert line.startswith(f"error: {out} is in use by another study ({holder}, pid "), line
    assert not (out / "summary.json").exists()


def test_a_run_into_a_studys_folder_is_refused(tmp_path, capsys, monkeypatch):
    """``python -m pipeline.run hydra.run.dir=TUNE`` (TUNE: a tune's folder): exit 2,
    ``config error: hydra.run.dir='TUNE' is invalid; allowed: a new folder or one a run wrote
    (this one holds a tune record, whose files would be replaced)`` (the run replaced the
    tune's manifest.json with its own); the tune's files intact."""
    import sys

    from pipeline.run import main as run_main

    out = tmp_path / "tune"
    before = _record(out, "tune")
    monkeypatch.setattr(sys, "argv", ["pipeline.run", "method=improved",
                                      f"hydra.run.dir={out}"])
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    with pytest.raises(SystemExit) as info:
        run_main()
    assert info.value.code == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert lines == [
        f"config error: hydra.run.dir={plain_value(str(out))} is invalid; allowed: a new "
        "folder or one a run wrote (this one holds a tune record, whose files would be "
        "replaced)"]
    # (Hydra itself makes .hydra/ and run.log before the job starts)
    assert {p.name: p.read_bytes() for p in out.iterdir()
            if p.name not in (".hydra", "run.log")} == before
