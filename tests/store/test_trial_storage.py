"""The tune's trial store writes a trial in a few commits, not one per parameter and attribute
(issue 41: Optuna's commits were a quarter of the tune parent's CPU with five-member rungs).

Oracle: Optuna's own cached RDB storage on a second file, driven by the same seeded loop; both
files read back by a fresh Optuna (nothing from either process's cache) must hold the same
trials. The commit count is counted on the engine itself."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import optuna
from optuna.distributions import UniformDistribution
from optuna.trial import TrialState
from sqlalchemy import event

from pipeline.config import CONF_DIR
from pipeline.studies.tune import Convergence, load_tune_space, make_study, optimize
from pipeline.studies.tune.search import StudyLoop, study_name, trial_storage

QUICK = load_tune_space(CONF_DIR / "tune" / "quick.yaml")
DISTRIBUTIONS = {"planner.beta": UniformDistribution(0.05, 2.0),
                 "planner.alpha_e": UniformDistribution(0.5, 4.0),
                 "controller.weights.q_ey": UniformDistribution(1.0, 50.0)}
RULE = Convergence(16, 24, 8, 0.0, tuple((float(a), float(b))
                                         for a, b in QUICK.hypervolume_bounds))


def _planted(p: dict) -> tuple[list[float], float, dict]:
    b, a, q = p["planner.beta"], p["planner.alpha_e"], p["controller.weights.q_ey"]
    values = [(b - 0.6) ** 2 + 0.1 * (a - 1.0) ** 2, 1.0 + (b - 0.6) ** 2 + 0.01 * q,
              2.5 + abs(b - a)]
    # attributes as the tune keeps them: rung values, members, where it was stopped
    attrs = {"rungs": {"5": values}, "members": 5 if b > 1.5 else 40}
    if b > 1.5:
        attrs.update(pruned_at=5, pruned_by="front")
    return values, (0.5 if b > 1.5 else -1.0), attrs


def _commits(engine) -> dict[str, int]:
    """Commits on ``engine``, all of them and those after a write (INSERT, UPDATE, DELETE)."""
    count = {"all": 0, "writes": 0, "pending": 0}

    def on_statement(_conn, _cursor, statement, *_args) -> None:
        if statement.lstrip().upper().startswith(("INSERT", "UPDATE", "DELETE")):
            count["pending"] = 1

    def on_commit(_connection) -> None:
        count["all"] += 1
        count["writes"] += count["pending"]
        count["pending"] = 0

    event.listen(engine, "before_cursor_execute", on_statement)
    event.listen(engine, "commit", on_commit)
    return count


def _read_back(db: Path) -> list[tuple]:
    """Every trial of the study as a fresh Optuna reads it from the file."""
    study = optuna.load_study(study_name=study_name(QUICK, "improved", 0),
                              storage=f"sqlite:///{db}")
    return [(t.number, t.state, t.params, t.values, t.user_attrs,
             {k: v for k, v in t.system_attrs.items()}) for t in study.get_trials()]


def test_the_batched_store_holds_optunas_own_trials_in_a_fraction_of_its_commits(tmp_path):
    batched = trial_storage(tmp_path / "batched.db")
    plain = optuna.storages.RDBStorage(f"sqlite:///{tmp_path / 'plain.db'}")
    counts = {"batched": _commits(batched._backend.engine), "plain": _commits(plain.engine)}
    for storage in (batched, plain):
        study = make_study(QUICK, "improved", 0, storage)
        optimize(study, DISTRIBUTIONS, lambda settings: [_planted(p) for p in settings],
                 RULE, 4, log=lambda _: None)
    ours, theirs = _read_back(tmp_path / "batched.db"), _read_back(tmp_path / "plain.db")
    assert len(ours) == 24 and ours == theirs
    assert any(t[4].get("pruned_by") == "front" for t in ours)  # attributes were written
    # per trial: its creation, its parameters once asked, its end (values, attributes,
    # state); per batch two sampler states; a few for the study itself. Reads: the file is
    # not read again for trials this process owns
    n_trials, n_batches = 24, 6
    assert counts["batched"]["writes"] <= 3 * n_trials + 3 * n_batches + 8
    assert counts["plain"]["writes"] >= 2.5 * counts["batched"]["writes"]
    assert counts["plain"]["all"] - counts["plain"]["writes"] \
        >= 2 * (counts["batched"]["all"] - counts["batched"]["writes"])


def test_a_running_trial_is_on_disk_with_its_parameters_once_asked(tmp_path):
    db = tmp_path / "tune.db"
    study = make_study(QUICK, "improved", 0, trial_storage(db))
    loop = StudyLoop(study, DISTRIBUTIONS, RULE, 4, log=lambda _: None)
    settings = loop.next_batch()
    assert settings is not None and len(settings) == 4
    with sqlite3.connect(db) as con:
        running = con.execute("select trial_id from trials where state = 'RUNNING'").fetchall()
        params = con.execute("select trial_id, param_name, param_value from trial_params "
                             "order by trial_id, param_name").fetchall()
    assert len(running) == 4
    assert len(params) == 4 * len(DISTRIBUTIONS)
    on_disk = {}
    for trial_id, name, value in params:
        on_disk.setdefault(trial_id, {})[name] = value
    assert sorted(tuple(sorted(p.items())) for p in on_disk.values()) == sorted(
        tuple(sorted(s.items())) for s in settings)
    # and a fresh process resuming the file sees them running, with those parameters
    fresh = optuna.load_study(study_name=study_name(QUICK, "improved", 0),
                              storage=f"sqlite:///{db}")
    assert sorted(tuple(sorted(t.params.items())) for t in fresh.get_trials(
        states=(TrialState.RUNNING,))) == sorted(tuple(sorted(s.items())) for s in settings)


def test_a_rung_is_measured_as_the_whole_table_would_be():
    """The tune measures each rung on the columns it reads; oracle: the tuning table and the
    tally of the whole table, on planted tables with collisions, censored members (never
    reacted, never recovered), missing values and columns that are not read."""
    import numpy as np
    import pandas as pd

    from pipeline.analysis.objectives import objective_values, tuning_table
    from pipeline.analysis.tally import Tally
    from pipeline.studies.tune.study import family_measure

    space = load_tune_space(CONF_DIR / "tune" / "default.yaml")
    rng = np.random.default_rng(7)
    for n in (1, 5, 10, 40):
        table = pd.DataFrame({
            "member": np.arange(n), "method": "improved",
            "collision": rng.random(n) < 0.2, "duration_s": rng.uniform(8.0, 12.0, n),
            "reacted": rng.random(n) < 0.8, "recovered": rng.random(n) < 0.7,
            "threat_appear_time_s": rng.uniform(0.5, 3.0, n),
            "obstacle_passed_time_s": rng.uniform(3.0, 6.0, n),
            "goal_reached": rng.random(n) < 0.9, "min_clearance_m": rng.uniform(0, 2, n)})
        for objective in space.objectives:
            table[objective.metric] = rng.uniform(0.1, 3.0, n)
        for metric, (_start, flag) in {"reaction_delay_s": ("", "reacted"),
                                       "recovery_time_s": ("", "recovered")}.items():
            if metric in table:
                table.loc[~table[flag], metric] = np.nan  # censored: never happened
        table.loc[rng.random(n) < 0.1, "threat_appear_time_s"] = np.nan
        want = (list(objective_values(tuning_table(table, space.censoring), space.objectives)),
                Tally.of(table).collisions)
        got = family_measure(space)(table)
        assert got[1] == want[1]
        np.testing.assert_array_equal(np.array(got[0]), np.array(want[0]))
        assert table["collision"].sum() == got[1]


def _burn(seconds: float) -> float:
    import time

    end, total = time.process_time() + seconds, 0.0
    while time.process_time() < end:
        total += 1.0
    return total


def test_the_core_clock_does_not_count_workers_earlier_work():
    """Workers busy before the clock starts (a benchmark's families before its tune): their
    CPU time is not the clock's. Planted: two workers burn 3 CPU-s each, then the clock
    watches one worker burn 0.5 s (new workers, started in the window, count their start)."""
    from joblib import Parallel, delayed

    from pipeline.studies.tune.study import CoreClock

    Parallel(n_jobs=2)(delayed(_burn)(3.0) for _ in range(2))  # the workers stay alive
    clock = CoreClock()
    Parallel(n_jobs=2)(delayed(_burn)(0.5) for _ in range(1))
    share = clock.utilisation()
    counted_cpu_s = share * clock.wall_s() * clock.cores
    # not the 6 CPU-s from before (counted, they would make at least 6.45); the new workers'
    # start (an interpreter and joblib's imports each, 1-1.5 CPU-s on a loaded 2-core
    # machine) is in the window
    assert 0.45 <= counted_cpu_s < 5.5, counted_cpu_s
    assert share <= 1.0
