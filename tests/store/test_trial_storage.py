"""The tune's trial store: Optuna's journal, appended without a disk sync per line (Optuna's
own file backend syncs every line, a dozen per trial), shared safely by several processes.

Oracles: Optuna's own journal file backend, driven by the same seeded loop, and Optuna's own
reader on our file (a fresh process's view: nothing from either writer's memory) must hold the
same trials; two processes tuning one study through the store lose no trial."""

from __future__ import annotations

import multiprocessing
from pathlib import Path

import optuna
from optuna.distributions import FloatDistribution
from optuna.storages import JournalStorage
from optuna.storages.journal import JournalFileBackend
from optuna.trial import TrialState

from pipeline.config import CONF_DIR
from pipeline.studies.tune import Convergence, load_tune_space, make_study, optimize
from pipeline.studies.tune.search import StudyLoop, study_name, trial_storage

QUICK = load_tune_space(CONF_DIR / "tune" / "quick.yaml")
DISTRIBUTIONS = {"planner.beta": FloatDistribution(0.05, 2.0),
                 "planner.alpha_e": FloatDistribution(0.5, 4.0),
                 "controller.weights.q_ey": FloatDistribution(1.0, 50.0)}
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


def _read_back(path: Path, name: str | None = None) -> list[tuple]:
    """Every trial of the study as a fresh Optuna reads it from the file (its own backend)."""
    study = optuna.load_study(study_name=name or study_name(QUICK, "improved", 0),
                              storage=JournalStorage(JournalFileBackend(str(path))))
    return [(t.number, t.state, t.params, t.values, t.user_attrs, dict(t.system_attrs))
            for t in study.get_trials()]


def test_the_store_holds_optunas_own_trials(tmp_path):
    """The same seeded tune through our store and through Optuna's own journal file: a fresh
    Optuna reads the same trials from both (parameters, values, attributes, the safety
    constraint NSGA-II ranks by)."""
    ours = trial_storage(tmp_path / "ours.journal")
    theirs = JournalStorage(JournalFileBackend(str(tmp_path / "theirs.journal")))
    for storage in (ours, theirs):
        study = make_study(QUICK, "improved", 0, storage)
        optimize(study, DISTRIBUTIONS, lambda settings: [_planted(p) for p in settings],
                 RULE, 4, log=lambda _: None)
    mine, optunas = _read_back(tmp_path / "ours.journal"), _read_back(
        tmp_path / "theirs.journal")
    assert len(mine) == 24 and mine == optunas
    assert any(t[4].get("pruned_by") == "front" for t in mine)  # attributes were written
    # the constraint is the one NSGA-II reads (Trial.set_constraint), equal to the table's
    assert all(t[5]["constraints:safety"] == t[4]["constraint"] for t in mine)
    assert {t[4]["constraint"] for t in mine} == {0.5, -1.0}


def test_a_running_trial_is_on_disk_with_its_parameters_once_asked(tmp_path):
    path = tmp_path / "tune.journal"
    study = make_study(QUICK, "improved", 0, trial_storage(path))
    loop = StudyLoop(study, DISTRIBUTIONS, RULE, 4, log=lambda _: None)
    settings = loop.next_batch()
    assert settings is not None and len(settings) == 4
    # a fresh process resuming the file sees them running, with those parameters
    running = [t for t in _read_back(path) if t[1] == TrialState.RUNNING]
    assert sorted(tuple(sorted(t[2].items())) for t in running) == sorted(
        tuple(sorted(s.items())) for s in settings)


def _tune_share(path: str, seed: int, n: int) -> None:
    """One of two processes telling ``n`` trials of one study through the shared store."""
    storage = trial_storage(Path(path))
    study = optuna.load_study(study_name="shared", storage=storage,
                              sampler=optuna.samplers.RandomSampler(seed=seed))
    for _ in range(n):
        trial = study.ask(DISTRIBUTIONS)
        trial.set_user_attr("writer", seed)
        study.tell(trial, [trial.params["planner.beta"]])


def test_two_processes_sharing_the_store_lose_no_trial(tmp_path):
    """Two processes ask and tell 40 trials each on one study at once: 80 complete trials,
    numbered 0..79 once each, 40 of each writer, every one read back by Optuna's own
    backend."""
    path = tmp_path / "shared.journal"
    optuna.create_study(study_name="shared", storage=trial_storage(path))
    context = multiprocessing.get_context("spawn")
    writers = [context.Process(target=_tune_share, args=(str(path), seed, 40))
               for seed in (1, 2)]
    for writer in writers:
        writer.start()
    for writer in writers:
        writer.join(120)
        assert writer.exitcode == 0
    trials = _read_back(path, "shared")
    assert sorted(t[0] for t in trials) == list(range(80))
    assert all(t[1] == TrialState.COMPLETE for t in trials)
    assert sorted(t[4]["writer"] for t in trials) == [1] * 40 + [2] * 40


def test_a_rung_is_measured_as_the_whole_table_would_be():
    """The tune measures each rung on the columns it reads; oracle: the tuning table and the
    tally of the whole table, on planted tables with collisions, censored members (never
    reacted, never recovered), missing values and columns that are not read."""
    import io

    import numpy as np
    import pandas as pd

    from pipeline.analysis.objectives import objective_values, tuning_table
    from pipeline.analysis.tally import Tally
    from pipeline.store.files import csv_text
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
        # the oracle reads the table as the family's record holds it (written, read back);
        # the tune measures it from memory or from that record: the same numbers either way
        written = pd.read_csv(io.StringIO(csv_text(table)))
        want = (list(objective_values(tuning_table(written, space.censoring),
                                      space.objectives)), Tally.of(written).collisions)
        for source in (table, written):
            got = family_measure(space)(source)
            assert got[1] == want[1]
            np.testing.assert_array_equal(np.array(got[0]), np.array(want[0]))
        assert table["collision"].sum() == got[1]
        # from memory without the file's rounding the means differ in their last digits:
        # the rounding is what makes the two paths agree
        unrounded = objective_values(tuning_table(table, space.censoring), space.objectives)
        assert n < 5 or list(unrounded) != want[0]


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
