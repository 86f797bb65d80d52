"""Hostile class: the tune's trial store trusted by name.

The store (``tune.db`` then, ``tune.journal`` now) was keyed by the space's name: an edited
budget reused the old trials, a resumed tune after Ctrl-C picked a different compromise, a
damaged, truncated, read-only or folder store gave a traceback, and two tunes in one folder
collided. Now the store is
checked before anything is written (one line naming it, its bytes untouched), every study
carries the key of its space, budget and code version (another key is refused), a resumed tune
asks exactly what the uninterrupted one asked, and a second study on a folder is refused.
"""

from __future__ import annotations

import hashlib
import os
import stat
from pathlib import Path

import pytest
from optuna.distributions import FloatDistribution
from optuna.trial import TrialState

from pipeline.config import CONF_DIR
from pipeline.errors import StudyError
from pipeline.store.lock import folder_lock
from pipeline.studies.tune import Convergence, load_tune_space, make_study, optimize
from pipeline.studies.tune.search import (
    STORE_FILE,
    STORE_KEY,
    check_trial_store,
    study_name,
    trial_storage,
)
from pipeline.tune import main

QUICK = load_tune_space(CONF_DIR / "tune" / "quick.yaml")
DISTRIBUTIONS = {"planner.beta": FloatDistribution(0.05, 2.0),
                 "planner.alpha_e": FloatDistribution(0.5, 4.0)}


def _planted(p: dict) -> tuple[float, float, float]:
    b, a = p["planner.beta"], p["planner.alpha_e"]
    return ((b - 0.6) ** 2 + 0.1 * (a - 1.0) ** 2, (b - 0.6) ** 2 + 0.1 * (a - 3.0) ** 2,
            abs(b - a))


class Stop(KeyboardInterrupt):
    """Ctrl-C, planted at a chosen moment."""


def _tune(db: Path, space=QUICK, stop_at_call: int | None = None, stop_in: str = "evaluate"):
    """One method's study tuned on planted objectives, stopped at the ``stop_at_call``-th
    evaluation (inside a batch: its trials are running) or log line (between two batches)."""
    study = make_study(space, "improved", 0, trial_storage(db))
    calls = {"evaluate": 0, "log": 0}

    def tick(where: str) -> None:
        calls[where] += 1
        if where == stop_in and calls[where] == stop_at_call:
            raise Stop()

    def evaluate(settings):
        tick("evaluate")
        return [(_planted(p), -1.0) for p in settings]

    optimize(study, DISTRIBUTIONS, evaluate, Convergence.of(space), space.batch_size,
             log=lambda _: tick("log"))
    return study


def _asked(study) -> list[tuple]:
    """The complete trials' settings in the order they were asked."""
    trials = sorted(study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)),
                    key=lambda t: t.number)
    return [tuple(sorted(t.params.items())) for t in trials]


@pytest.mark.parametrize("stop_in, call", [("evaluate", 2), ("evaluate", 3), ("log", 1)])
def test_a_resumed_tune_asks_what_the_uninterrupted_one_asked(tmp_path, stop_in, call):
    """Ctrl-C inside a batch (its trials running) or between two batches, then the same
    command: the complete trials are the uninterrupted tune's, setting for setting (so the
    same front and the same compromise)."""
    space = QUICK.__class__(**{**QUICK.__dict__, "min_trials": 8, "max_trials": 8,
                               "convergence_window": 4})
    whole = _asked(_tune(tmp_path / "whole.journal", space))
    assert len(whole) == 8
    with pytest.raises(Stop):
        _tune(tmp_path / "cut.journal", space, stop_at_call=call, stop_in=stop_in)
    resumed = _tune(tmp_path / "cut.journal", space)
    assert _asked(resumed) == whole


def _store_with_trials(db: Path, space=QUICK, n: int = 2) -> None:
    study = make_study(space, "improved", 0, trial_storage(db))
    for _ in range(n):
        trial = study.ask(DISTRIBUTIONS)
        values = _planted(trial.params)
        study.tell(trial, list(values))


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_a_store_made_under_another_budget_or_an_older_version_is_refused(tmp_path):
    """``python -m pipeline.tune --space quick --set max_trials=5 --out D`` over D's store of
    ``--set max_trials=6``: exit 2, one line naming the study and both keys; the store is the
    same, byte for byte."""
    out = tmp_path / "D"
    out.mkdir()
    db = out / STORE_FILE
    _store_with_trials(db)
    check_trial_store(db, QUICK)  # the same space, budget and code: resumed
    before = _digest(db)
    other = load_tune_space(CONF_DIR / "tune" / "quick.yaml", ["max_trials=5", "name=quick"])
    assert other.trial_key() == QUICK.trial_key() and other.store_key() != QUICK.store_key()
    assert main(["--space", "quick", "--set", "max_trials=5", "--set", "name=quick",
                 "--out", str(out)]) == 2
    assert _digest(db) == before
    with pytest.raises(StudyError) as info:
        check_trial_store(db, other)
    message = str(info.value)  # the store, the study, both keys and what to do
    assert len(message.splitlines()) == 1 and message.startswith(f"{db}: holds 2 trials")
    assert study_name(QUICK, "improved", 0) in message
    assert QUICK.store_key() in message and other.store_key() in message
    assert "not reused" in message and "--out" in message
    # run overrides change the runs, hence the key (the workers' count changes no number)
    assert QUICK.store_key(["controller.horizon=12"]) != QUICK.store_key()
    assert QUICK.store_key(["scenario.family.n_jobs=1", "hydra/launcher=slurm"]) \
        == QUICK.store_key()
    with pytest.raises(StudyError, match="not this tune's"):
        check_trial_store(db, QUICK, QUICK.store_key(["controller.horizon=12"]))
    # a study without a key (written before keys) is another version
    db.write_text("".join(line + "\n" for line in db.read_text().splitlines()
                          if STORE_KEY not in line))
    with pytest.raises(StudyError, match="made under an older version"):
        check_trial_store(db, QUICK)


def _damage(kind: str, db: Path) -> None:
    if kind == "folder":
        db.mkdir()
    elif kind == "not a journal":
        db.write_text("these are my notes\n")
    elif kind == "damaged":
        _store_with_trials(db, n=6)
        lines = db.read_text().splitlines()
        lines[len(lines) // 2] = lines[len(lines) // 2][:20]  # a line cut in the middle
        db.write_text("".join(line + "\n" for line in lines))
    elif kind == "foreign":
        db.write_text('{"op_code": 99, "note": "mine"}\n')
    elif kind == "read-only":
        _store_with_trials(db)
        db.chmod(stat.S_IRUSR | stat.S_IRGRP)


@pytest.mark.parametrize("kind, line", [
    ("folder", "{db}: a folder, not the trial store (a journal file); move it away or choose "
               "another --out"),
    ("not a journal", "{db}: not Optuna's journal, or damaged (line 1 is not an operation); "
                      "delete it (or choose another --out) to start fresh"),
    ("damaged", "{db}: not Optuna's journal, or damaged (line "),
    ("foreign", "{db}: Optuna cannot replay the journal"),
    ("read-only", "{db}: read-only; the trial store must be writable (every trial is recorded "
                  "as it completes): make it writable or choose another --out"),
])
def test_a_broken_store_is_one_line_and_never_modified(tmp_path, capsys, kind, line):
    """``python -m pipeline.tune --space quick --out D`` with D/tune.journal broken: exit 2,
    one line ``error: D/tune.journal: ...``, the store (and its folder) exactly as they
    were."""
    out = tmp_path / "D"
    out.mkdir()
    db = out / STORE_FILE
    _damage(kind, db)
    before = sorted(p.name for p in out.iterdir())
    digest = None if db.is_dir() else _digest(db)
    assert main(["--space", "quick", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: " + line.format(db=db)), err
    assert sorted(p.name for p in out.iterdir() if p.name != ".lock") == before
    if digest is not None:
        assert _digest(db) == digest
    if kind == "read-only":
        assert not os.access(db, os.W_OK) or not db.stat().st_mode & 0o222


def test_a_cut_last_line_is_dropped_and_said_and_an_empty_store_starts_fresh(tmp_path):
    """A crash of the machine mid-write leaves the journal's last line without its end: that
    operation never completed, so it is dropped (the file cut back to the line before it) and
    a line says so; the trials before it are kept. An empty journal is a new one."""
    db = tmp_path / STORE_FILE
    db.write_bytes(b"")
    check_trial_store(db, QUICK)
    _store_with_trials(db, n=3)
    whole = db.read_bytes()
    db.write_bytes(whole + b'{"op_code":4,"worker_id":"x","study_id":0,"dat')
    said: list[str] = []
    check_trial_store(db, QUICK, log=said.append)
    assert db.read_bytes() == whole
    assert len(said) == 1 and "last line was cut" in said[0]
    study = make_study(QUICK, "improved", 0, trial_storage(db))
    assert len(study.get_trials(states=(TrialState.COMPLETE,))) == 3


def test_an_earlier_versions_sqlite_store_is_left_alone_and_said(tmp_path):
    """A tune folder of an earlier version holds ``tune.db`` (SQLite, Optuna 2): it is never
    read (its trials were made by other code: another store key), never removed, and a line
    says so."""
    old = tmp_path / "tune.db"
    old.write_bytes(b"SQLite format 3\x00" + bytes(100))
    said: list[str] = []
    check_trial_store(tmp_path / STORE_FILE, QUICK, log=said.append)
    assert old.read_bytes().startswith(b"SQLite format 3") and len(said) == 1
    assert "not read" in said[0] and STORE_FILE in said[0]


def test_a_second_study_on_the_same_folder_is_refused_in_one_line(tmp_path, capsys):
    """A tune (or multiverse) running in D, then ``python -m pipeline.tune --space quick --out
    D``: exit 2, ``error: D is in use by another study (tune quick, pid N); wait for it
    to finish or choose another output folder``; nothing written."""
    out = tmp_path / "D"
    with folder_lock(out, "tune quick"):
        assert main(["--space", "quick", "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(
            f"error: {out} is in use by another study (tune quick, pid {os.getpid()})")
        assert not (out / STORE_FILE).exists()
    # released with its holder: the next study takes it
    with folder_lock(out, "tune quick"):
        pass
