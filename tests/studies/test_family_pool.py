"""FamilyPool (pipeline.studies.family_pool): families handed in at any time and run on one
pool of workers give the same family folders as run_family; a family whose folder another
pending family is writing waits for it and is read back (simulated once); a complete folder
is not run again; a worker's exception reaches the caller."""

from __future__ import annotations

import dataclasses

import pytest

from pipeline.loop.controller import QpCache
from pipeline.store.member_cache import MemberCounts
from pipeline.studies.experiment import run_family
from pipeline.studies.family_pool import FamilyPool


def _family(make_config, size: int, seed: int = 3):
    return make_config(["method=improved", "scenario=family", f"scenario.family.size={size}",
                        f"scenario.family.seed={seed}", "controller.backend=daqp",
                        "scenario.family.n_jobs=1"])


@pytest.mark.parametrize("n_jobs", [1, 2])
def test_pool_writes_the_folders_run_family_writes(tmp_path, make_config, n_jobs):
    """Two families submitted together, the second from the first's callback-free queue: each
    folder's table and record bytes equal run_family's for the same config; the callbacks run
    once each, in the parent."""
    cfgs = [_family(make_config, 5, seed) for seed in (3, 4)]
    for k, cfg in enumerate(cfgs):
        run_family(cfg, tmp_path / "reference" / str(k), progress=False, member_cache=None)
    counts, called = MemberCounts(), []
    pool = FamilyPool(n_jobs, QpCache(), None, counts)
    for k, cfg in enumerate(cfgs):
        pool.submit(cfg, tmp_path / "pool" / str(k), lambda k=k: called.append(k))
    pool.run_until_idle()
    pool.close()
    assert sorted(called) == [0, 1]
    assert counts.simulated == 10 and counts.resumed == 0
    for k in range(2):
        for name in ("family_metrics.csv", "family.json"):
            assert (tmp_path / "pool" / str(k) / name).read_bytes() == \
                (tmp_path / "reference" / str(k) / name).read_bytes(), name


def test_the_same_folder_twice_is_simulated_once(tmp_path, make_config):
    """The same setting asked twice while the first is pending: the second waits, then finds
    the folder complete and is read back (counted as already complete)."""
    cfg = _family(make_config, 4)
    counts, called = MemberCounts(), []
    pool = FamilyPool(2, QpCache(), None, counts)
    pool.submit(cfg, tmp_path / "f", lambda: called.append("first"))
    pool.submit(cfg, tmp_path / "f", lambda: called.append("second"))
    pool.run_until_idle()
    pool.close()
    assert called == ["first", "second"]
    assert counts.simulated == 4 and counts.resumed == 4


def test_a_family_without_its_record_gives_its_table_to_every_callback(tmp_path, make_config):
    """An early rung's family is run without its record (record=False: no table, summary or
    manifest in its folder, only its members'); the same setting asked twice while the first
    is pending (a tune's batch can ask one setting twice): both callbacks find the table in
    the pool (a callback that found none read the missing record: 'empty folder', found by
    the quick bench). Oracle: run_family's table of the same config."""
    import pandas as pd

    cfg = _family(make_config, 4)
    reference = run_family(cfg, tmp_path / "reference", progress=False, member_cache=None)
    pool = FamilyPool(2, QpCache(), None, MemberCounts())
    tables = []

    def done() -> None:
        tables.append(pool.finished_table(tmp_path / "f", cfg.config_hash()))

    pool.submit(cfg, tmp_path / "f", done, record=False)
    pool.submit(cfg, tmp_path / "f", done, record=False)
    pool.run_until_idle()
    pool.close()
    assert len(tables) == 2 and all(t is not None for t in tables)
    for table in tables:
        pd.testing.assert_frame_equal(table[reference.columns].reset_index(drop=True),
                                      reference.reset_index(drop=True), check_dtype=False)
    assert not (tmp_path / "f" / "family_metrics.csv").exists()
    assert len(list((tmp_path / "f").glob("member_*/manifest.json"))) == 4
    assert pool.finished_table(tmp_path / "f", "another hash") is None


def test_a_rung_then_the_whole_family_simulates_each_member_once(tmp_path, make_config):
    """A trial's rung (its first 2 members) and then its whole family (4) in the same folder:
    the rung's members are resumed, the other two simulated; a third submission of the
    complete folder runs nothing."""
    whole = _family(make_config, 4)
    rung = dataclasses.replace(whole, scenario=dataclasses.replace(
        whole.scenario, family=dataclasses.replace(whole.scenario.family, size=2)))
    counts = MemberCounts()
    pool = FamilyPool(2, QpCache(), None, counts)
    pool.submit(rung, tmp_path / "f", lambda: pool.submit(whole, tmp_path / "f", lambda: None))
    pool.run_until_idle()
    assert (counts.simulated, counts.resumed) == (4, 2)
    pool.submit(whole, tmp_path / "f", lambda: None)
    pool.run_until_idle()
    pool.close()
    assert (counts.simulated, counts.resumed) == (4, 6)


def test_a_workers_exception_reaches_the_caller(tmp_path, make_config, monkeypatch):
    """A member that raises (one job: run in the parent, as a worker would): run_until_idle
    raises it, not submit (nothing hangs)."""
    import pipeline.studies.family_pool as family_pool

    def broken(jobs, qp_cache, member_cache=None, record_horizon=True, **_):
        raise RuntimeError("planted failure in a worker")

    monkeypatch.setattr(family_pool, "_run_chunk", broken)
    pool = FamilyPool(1, QpCache(), None, MemberCounts())
    pool.submit(_family(make_config, 2), tmp_path / "f", lambda: None)
    with pytest.raises(RuntimeError, match="planted failure"):
        pool.run_until_idle()
    pool.stop()


def test_a_rung_of_a_complete_whole_family_is_read_not_rewritten(tmp_path, make_config):
    """A trial asked again after an interruption runs its first rung (2 members) in a folder
    whose whole family (4) is complete: with the whole family's hash the record is read back
    and not rewritten; without it the rung's record would replace the whole one (the oracle)."""
    whole = _family(make_config, 4)
    rung = dataclasses.replace(whole, scenario=dataclasses.replace(
        whole.scenario, family=dataclasses.replace(whole.scenario.family, size=2)))
    counts = MemberCounts()
    pool = FamilyPool(1, QpCache(), None, counts)
    pool.submit(whole, tmp_path / "f", lambda: None)
    pool.run_until_idle()
    before = (tmp_path / "f" / "manifest.json").stat().st_mtime_ns
    pool.submit(rung, tmp_path / "f", lambda: None, whole.config_hash())
    pool.run_until_idle()
    assert (tmp_path / "f" / "manifest.json").stat().st_mtime_ns == before
    assert (counts.simulated, counts.resumed) == (4, 2)
    pool.submit(rung, tmp_path / "f", lambda: None)
    pool.run_until_idle()
    pool.close()
    assert (tmp_path / "f" / "manifest.json").stat().st_mtime_ns != before


def _worker_pid() -> int:
    import os

    return os.getpid()


def test_started_workers_are_up_at_once_and_serve_the_next_parallel_call():
    """start_workers (the tune's first step) starts joblib's reusable workers without waiting
    for them, and the families' Parallel calls then run on those same processes."""
    import psutil
    from joblib import Parallel, delayed

    from pipeline.studies.family_pool import start_workers, stop_workers

    stop_workers()
    before = {p.pid for p in psutil.Process().children(recursive=True)}
    start_workers(2)
    started = {p.pid for p in psutil.Process().children(recursive=True)} - before
    assert len(started) >= 2  # the workers (and loky's resource tracker, when it is new)
    used = set(Parallel(n_jobs=2)(delayed(_worker_pid)() for _ in range(16)))
    assert used and used <= started
    stop_workers()


def test_a_tune_starts_its_workers_and_makes_its_studies_before_its_first_families(
        tmp_path, monkeypatch):
    """The tune's first step composes one family, starts the workers, and opens the store
    and makes every study (the parent's serial start) before the untuned families run, so
    that this work overlaps the workers' imports instead of leaving the cores idle."""
    import optuna
    from joblib.externals.loky import reusable_executor

    from pipeline.config import CONF_DIR
    from pipeline.studies.family_pool import stop_workers
    from pipeline.studies.tune import load_tune_space, run_tuning
    from pipeline.studies.tune.search import STORE_FILE, Runner, trial_storage

    class FirstFamilies(Exception):
        pass

    seen = {}

    def first_run(self, jobs, label, part="heldout"):
        executor = getattr(reusable_executor, "_executor", None)
        seen["workers"] = executor is not None and len(executor._processes) == 2
        summaries = optuna.get_all_study_summaries(trial_storage(tmp_path / "tune" / STORE_FILE))
        seen["studies"] = sorted("-".join(s.study_name.rsplit("-", 2)[-2:]) for s in summaries)
        seen["jobs"] = (label, part, len(jobs))
        raise FirstFamilies

    stop_workers()
    monkeypatch.setattr(Runner, "run", first_run)
    space = load_tune_space(CONF_DIR / "tune" / "quick.yaml")
    with pytest.raises(FirstFamilies):
        run_tuning(space, tmp_path / "tune", ["scenario.family.n_jobs=2"], log=lambda _: None)
    stop_workers()
    assert seen["workers"]
    assert seen["studies"] == ["r0-baseline", "r0-improved", "r1-baseline", "r1-improved"]
    assert seen["jobs"] == ("untuned control", "training", 2)


def test_a_stopped_family_leaves_no_temporary_of_a_killed_worker(tmp_path, make_config,
                                                                 monkeypatch):
    """A worker killed in the middle of an atomic write leaves ``.<name>.<random>.tmp``; when
    the family stops (here: Ctrl-C while its results come), those go and the rest stays."""
    import joblib

    import pipeline.studies.experiment as experiment

    out = tmp_path / "fam"
    (out / "member_0003").mkdir(parents=True)
    left = out / "member_0003" / ".manifest.json.k1ll3d.tmp"
    left.write_text("half")
    kept = out / "member_0003" / "trajectory.csv"
    kept.write_text("t\n")

    def stopped(*args, **kwargs):
        def results(tasks):
            list(tasks)
            raise KeyboardInterrupt
            yield  # a generator, as joblib's
        return results

    monkeypatch.setattr(joblib, "Parallel", stopped)  # run_family imports it when it runs
    cfg = make_config(["scenario=family", "scenario.family.size=4", "scenario.family.n_jobs=1"])
    with pytest.raises(KeyboardInterrupt):
        experiment.run_family(cfg, out, progress=False)
    assert not left.exists() and kept.read_text() == "t\n"


def test_the_parent_only_hands_out_members_and_records(tmp_path, make_config, monkeypatch):
    """With workers (here a thread handed in as a cluster's executor would be), the
    parent neither draws, checks nor runs a member nor writes a family's record: every call
    of those helpers is on a worker's thread (the parent's share of a tune's CPU, measured by
    the bench's coordinator_ms_per_trial). The folders are run_family's, byte for byte, and
    the counts add up (one family run, then read back whole)."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    import pipeline.studies.family_pool as family_pool

    threads: dict[str, set[bool]] = {}

    def on_thread(name):
        original = getattr(family_pool, name)

        def wrapped(*args, **kwargs):
            threads.setdefault(name, set()).add(
                threading.current_thread() is threading.main_thread())
            return original(*args, **kwargs)

        monkeypatch.setattr(family_pool, name, wrapped)

    for name in ("_members_to_run", "_run_chunk", "_write_family_folder", "_member_table"):
        on_thread(name)
    cfg = _family(make_config, 5)
    run_family(cfg, tmp_path / "reference", progress=False, member_cache=None)
    counts = MemberCounts()
    # one thread: a thread pool shares the shipped cache (its kept QP workspaces) between
    # its tasks, which processes never do
    with ThreadPoolExecutor(1) as executor:
        pool = FamilyPool(0, QpCache(), None, counts, executor)
        pool.submit(cfg, tmp_path / "pool", lambda: None)
        pool.run_until_idle()
        pool.close()
    assert threads == {name: {False} for name in ("_members_to_run", "_run_chunk",
                                                  "_write_family_folder", "_member_table")}
    assert (counts.simulated, counts.resumed) == (5, 0)
    for name in ("family_metrics.csv", "family.json"):
        assert (tmp_path / "pool" / name).read_bytes() == \
            (tmp_path / "reference" / name).read_bytes(), name


def test_a_later_rung_hands_out_its_new_members_as_the_tasks_of_their_own(tmp_path,
                                                                           make_config):
    """A trial's rung (2 members) and then its whole family (12) in one folder: the whole
    family's earlier members are one task that reads them back, and its new members go
    out MEMBERS_PER_TASK at a time from the first new one (the engine's batches as before
    the workers resolved members: 8 and 2, not 6 and 4); each member simulated once."""
    from concurrent.futures import ThreadPoolExecutor

    from pipeline.studies.family_pool import MEMBERS_PER_TASK

    class Recording(ThreadPoolExecutor):
        def __init__(self) -> None:
            super().__init__(1)
            self.spans: list[list[int]] = []

        def submit(self, fn, /, *args, **kwargs):
            if fn.__name__ == "_family_task":
                self.spans.append(list(args[2]))
            return super().submit(fn, *args, **kwargs)

    whole = _family(make_config, 12)
    rung = dataclasses.replace(whole, scenario=dataclasses.replace(
        whole.scenario, family=dataclasses.replace(whole.scenario.family, size=2)))
    counts = MemberCounts()
    with Recording() as executor:
        pool = FamilyPool(0, QpCache(), None, counts, executor)
        # the rung with its whole family's hash, as the tune submits it
        pool.submit(rung, tmp_path / "f", lambda: pool.submit(whole, tmp_path / "f",
                                                              lambda: None),
                    whole.config_hash())
        pool.run_until_idle()
        pool.close()
    assert MEMBERS_PER_TASK == 8
    assert executor.spans == [[0, 1], [0, 1], list(range(2, 10)), [10, 11]]
    assert (counts.simulated, counts.resumed) == (12, 2)


def test_another_setting_in_a_folder_is_not_taken_for_its_earlier_rung(tmp_path, make_config):
    """A family of one setting completed into a folder, then another setting's family into
    the same folder: the first one's members are not taken for the second's earlier rung (the
    pool knows a rung by its whole family, not by its folder), so the second's members go out
    as members to run, with the compiled QPs (its table is run_family's, byte for byte: a
    member run in a task without them compiled, and its compile_count said so)."""
    first = make_config(["method=improved", "scenario=family", "scenario.family.size=3",
                         "scenario.family.n_jobs=1"])
    second = make_config(["method=baseline", "scenario=family", "scenario.family.size=3",
                          "scenario.family.n_jobs=1"])
    run_family(second, tmp_path / "reference", progress=False, member_cache=None)
    counts = MemberCounts()
    pool = FamilyPool(1, QpCache(), None, counts)
    pool.submit(first, tmp_path / "f", lambda: None)
    pool.run_until_idle()
    pool.submit(second, tmp_path / "f", lambda: None)
    pool.run_until_idle()
    pool.close()
    assert (counts.simulated, counts.resumed) == (6, 0)
    assert (tmp_path / "f" / "family_metrics.csv").read_bytes() == \
        (tmp_path / "reference" / "family_metrics.csv").read_bytes()


def test_a_workers_warnings_reach_the_parents_log(tmp_path, make_config, caplog):
    """A damaged member found by a worker (its metrics edited after its manifest) is run
    again, and the warnings that say so are logged in the parent, where the tune's log is (a
    worker's own log reaches no user: a Dask worker's, loky's stderr): the same ones with two
    worker processes as with one job, where the tasks run in the parent."""
    import logging
    import shutil

    cfg = _family(make_config, 3)
    pool = FamilyPool(1, QpCache(), None, MemberCounts())
    pool.submit(cfg, tmp_path / "f", lambda: None)
    pool.run_until_idle()
    (tmp_path / "f" / "manifest.json").unlink()
    metrics = tmp_path / "f" / "member_0001" / "metrics.json"
    metrics.write_text(metrics.read_text().replace("{", "{ ", 1))
    shutil.copytree(tmp_path / "f", tmp_path / "g")
    said = {}
    for n_jobs, folder in ((1, tmp_path / "f"), (2, tmp_path / "g")):
        counts = MemberCounts()
        pool = FamilyPool(n_jobs, QpCache(), None, counts)
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="pipeline.studies.experiment"):
            pool.submit(cfg, folder, lambda: None)
            pool.run_until_idle()
        pool.close()
        assert (counts.simulated, counts.resumed) == (1, 2)
        said[n_jobs] = [r.getMessage().replace(str(folder), "F") for r in caplog.records
                        if r.name == "pipeline.studies.experiment"]
    assert said[1] and all("re-running F/member_0001" in message for message in said[1])
    assert said[2] == said[1]
