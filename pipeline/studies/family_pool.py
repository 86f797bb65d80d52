"""Families handed in one by one and run on one pool of worker processes as they come: the
tune's studies, side by side, keep the cores busy while the parent asks, composes and records.

:func:`pipeline.studies.experiment.run_families_together` runs a known set of families and
returns when the last is in; a tuning batch's next rung, or a study's next batch, is known only
once its families are in, so the cores idled while the parent worked between batches (the
tune's CPU use was 0.81-0.88 of its two cores). :class:`FamilyPool` takes a family at any time
(:meth:`FamilyPool.submit`, with what to do once it is in), keeps every worker busy with the
members of whatever families are pending, and runs each family's callback in the parent as its
last member comes in (:meth:`FamilyPool.wait`). Members are resumed and restored from the member
cache, and family folders written, exactly as :func:`~pipeline.studies.experiment.run_family`
does (the same helpers); a family whose folder another pending family is writing (the same
setting asked twice) waits for it and is then read back.

The parent only hands out: each task is a range of a family's member indices, and the worker
draws those members, finds which are complete or in the member cache and runs the others
(:func:`_family_task`); a complete family's record (its table, summary, rows and manifest) is
written by a worker too, which hands the table back (:func:`_record_family`). In a tune, the
parent's share of that work (drawing and hashing members, checking their folders, writing the
records) was more than half of its own CPU time per trial, which bounds a tune on many cores.
"""

from __future__ import annotations

import concurrent.futures
import logging
import os
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from pipeline.config import ExperimentConfig
from pipeline.loop.controller import QpCache
from pipeline.loop.scenario import scenario_source
from pipeline.store.manifest import check
from pipeline.store.member_cache import MemberCache, MemberCounts
from pipeline.store.runs import read_member_rows
from pipeline.studies.experiment import (
    _member_table,
    _members_to_run,
    _prepare_cache,
    _run_chunk,
    _write_family_folder,
    rows_beyond,
)

#: members per task handed to a worker: a member of a training family is 25-35 ms of CPU, a
#: task's hand-over and what a worker builds again for each task (the pickled compiled QPs,
#: the result, BLAS's thread controller, the nominal model, the sections' YAML) 6-8 ms
#: (measured: 5 % of the workers' CPU in make tune with 4; the tune keeps tens of trials'
#: rungs in flight, so larger tasks leave no core idle)
MEMBERS_PER_TASK = 8
#: the tables of completed families the pool keeps for their callbacks (:meth:`FamilyPool.
#: finished_table`; a tune's families in flight are far fewer)
KEPT_TABLES = 512


@dataclass
class _Family:
    """A family in the pool: what is in, what is left, what to call when it is complete."""

    cfg: ExperimentConfig
    folder: Path
    n_members: int
    metrics: dict[int, dict]
    counts: MemberCounts
    left: int
    compiles: int
    on_done: Callable[[], None]
    #: whether its folder gets the family's record (table, summary, manifest) once complete
    record: bool = True
    #: whether its members get run folders (else the family's record keeps their rows)
    record_members: bool = True
    waiting: deque = field(default_factory=deque)
    #: the whole family it is (a rung of): its config hash, or the rung's ``whole_hash``
    whole: str = ""


def _family_task(cfg: ExperimentConfig, folder: Path, indices: list[int], qp_cache: QpCache,
                 member_cache: MemberCache | None, record_horizon: bool,
                 parent_pid: int | None, record_members: bool
                 ) -> tuple[list[tuple[int, dict]], MemberCounts, list[str]]:
    """The members ``indices`` of ``cfg``'s family, in a worker: drawn, taken where they are
    complete in ``folder`` or in ``member_cache`` and run where not (exactly as
    :func:`~pipeline.studies.experiment.run_family` decides for a whole family,
    :func:`~pipeline.studies.experiment._members_to_run`, and runs,
    :func:`~pipeline.studies.experiment._run_chunk`); each member's metrics by index, where
    they came from, and the warnings of their checks. A worker leaves Ctrl-C to
    ``parent_pid``."""
    from pipeline.errors import leave_interrupts_to

    leave_interrupts_to(parent_pid)
    family = cfg.scenario.family
    if family is None:
        raise ValueError(f"scenario {cfg.scenario.name} is not a family (scenario.family)")
    source = scenario_source(cfg.scenario, cfg.vehicle.footprint_radius_m)
    members = [source.member(family.seed, i) for i in indices]
    # what the members' checks warn of (a damaged member run again) goes back to the parent's
    # log, and only there: a worker's own goes nowhere a user reads (a Dask worker's log,
    # loky's stderr), and a task run in the parent (one job) would log it twice
    warnings = _Warnings()
    logger = logging.getLogger(_members_to_run.__module__)
    logger.addHandler(warnings)
    propagate, logger.propagate = logger.propagate, False
    try:
        metrics, todo, counts = _members_to_run(cfg, members, folder, member_cache, qp_cache,
                                                record_members, indices)
        done = list(metrics.items())
        if todo:
            done.extend(_run_chunk(todo, qp_cache, member_cache, record_horizon,
                                   parent_pid=parent_pid, record_members=record_members))
    finally:
        logger.removeHandler(warnings)
        logger.propagate = propagate
    return done, counts, warnings.messages


class _Warnings(logging.Handler):
    """The messages of the warnings logged while it is attached."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


def _record_family(cfg: ExperimentConfig, folder: Path, metrics: dict[int, dict],
                   n_members: int, compiles: int, counts: MemberCounts, keep_rows: bool,
                   parent_pid: int | None = None) -> pd.DataFrame:
    """A complete family's per-member table and its folder's record (:func:`~pipeline.
    studies.experiment._write_family_folder`; ``keep_rows``: its members' rows in the record,
    with those of the folder's earlier record beyond the family's size, for a family whose
    members keep no run folder), in a worker; the table is handed back. A worker leaves
    Ctrl-C to ``parent_pid``."""
    from pipeline.errors import leave_interrupts_to

    leave_interrupts_to(parent_pid)
    table = _member_table(metrics, n_members)
    if keep_rows:
        metrics = {**rows_beyond(read_member_rows(folder), n_members), **metrics}
    _write_family_folder(cfg, folder, table, n_members, compiles, counts,
                         metrics if keep_rows else None)
    return table


def _snapshot(cache: QpCache) -> QpCache:
    """The cache as a task carries it: copies of its tables, which the parent may grow while
    the pool's feeder thread pickles earlier tasks."""
    return QpCache(entries=dict(cache.entries), memos=dict(cache.memos),
                   compiled_kernels=cache.compiled_kernels,
                   members_planned=cache.members_planned)


def _import_family_task() -> None:
    """What a worker imports to run a family's task (:func:`~pipeline.studies.experiment.
    _run_chunk`: the loop, the metrics, the store)."""
    import pipeline.studies.experiment  # noqa: F401


def _reusable_executor(n_jobs: int):
    """joblib's reusable executor exactly as its ``Parallel(n_jobs)`` makes it (the same
    arguments: its workers' thread limits, idle timeout, reducers), so that later Parallel
    calls of the process find the same workers instead of restarting them (a restart costs
    each worker its imports, about 2 s): the entered ``Parallel`` and the executor (None
    with one job: tasks run here)."""
    from joblib import Parallel

    parallel = Parallel(n_jobs=max(1, int(n_jobs)))
    parallel.__enter__()
    return parallel, getattr(parallel._backend, "_workers", None)


def start_workers(n_jobs: int) -> None:
    """Start joblib's reusable workers (:func:`_reusable_executor`) and have each import what
    a family's task needs, without waiting: a tune's first families then find them ready
    while this process went on opening its store and composing (a worker's start is about 2 s
    of imports, which left a core idle at the start of every tune). Nothing with one job."""
    from pipeline.errors import workers_start_deaf_to_ctrl_c

    parallel, executor = _reusable_executor(n_jobs)
    try:
        if executor is not None:
            with workers_start_deaf_to_ctrl_c():  # the workers start with Ctrl-C blocked
                for _ in range(max(1, int(n_jobs))):
                    executor.submit(_import_family_task)
    finally:
        parallel.__exit__(None, None, None)  # the workers stay for the next Parallel call


def stop_workers() -> None:
    """Shut down joblib's reusable workers, if this process has them (waited for: the kernel
    then counts their time among this process's children); none are started."""
    from joblib.externals.loky import reusable_executor

    executor = getattr(reusable_executor, "_executor", None)
    if executor is not None:
        executor.shutdown(wait=True)


class FamilyPool:
    """One pool of ``n_jobs`` worker processes (joblib's reusable loky executor) running
    the members of the families handed to :meth:`submit`, in the order they come.

    Parameters
    ----------
    n_jobs : int
        Worker processes.
    qp_cache : QpCache
        The parent's compiled QPs (each family's compiled here once, shipped with its tasks).
    member_cache : MemberCache or None
        Where members are restored from and published to.
    counts : MemberCounts
        Where the members came from (simulated, restored, resumed), added to as families start.
    executor : concurrent.futures.Executor, optional
        Another pool's workers to run the members on (a Dask cluster's:
        :func:`pipeline.studies.workers.dask_executor`); ``n_jobs`` is then not used.
    """

    def __init__(self, n_jobs: int, qp_cache: QpCache, member_cache: MemberCache | None,
                 counts: MemberCounts,
                 executor: concurrent.futures.Executor | None = None) -> None:
        self.executor: Any
        if executor is not None:  # another pool's workers (a Dask cluster's), not loky's
            self._parallel, self.executor = None, executor
        else:
            # the held-out families' Parallel calls afterwards reuse these workers
            self._parallel, self.executor = _reusable_executor(n_jobs)
        self.cache, self.member_cache, self.counts = qp_cache, member_cache, counts
        self._futures: dict[concurrent.futures.Future, Path] = {}
        #: the records being written by a worker (:func:`_record_family`), by family folder
        self._records: dict[concurrent.futures.Future, Path] = {}
        self._families: dict[Path, _Family] = {}
        self._ready: deque[Callable[[], None]] = deque()
        #: by family folder and whole family (its config hash, or the ``whole_hash`` a rung is
        #: submitted with), how many of its first members a family completed here holds (a
        #: trial's earlier rung): a later rung hands them out as one task that reads them
        #: back, and its new members in tasks of their own, as its members still to run
        self._complete_below: dict[tuple[Path, str], int] = {}
        #: the tables of the families completed here, by folder and config hash (the latest
        #: ``KEPT_TABLES``: the same family may be asked for by several settings)
        self._tables: dict[tuple[Path, str], pd.DataFrame] = {}

    @property
    def busy(self) -> bool:
        """Whether a family is pending or a callback is still to run."""
        return bool(self._futures or self._records or self._ready or self._families)

    def submit(self, cfg: ExperimentConfig, folder: Path, on_done: Callable[[], None],
               whole_hash: str | None = None, record_horizon: bool = True,
               record: bool = True, record_members: bool = True) -> None:
        """Run ``cfg``'s family into ``folder`` and call ``on_done()`` (in :meth:`wait`) once
        its members are complete; a complete folder of the same config, or of ``whole_hash``
        (the whole family of which ``cfg`` is a rung: it holds these members), is read back,
        not run. ``record_horizon``: whether its new members write what each step planned
        (:func:`~pipeline.studies.experiment.run_experiment`); ``record``: whether the folder
        gets the family's record (its table, summary and manifest; else only its members'
        folders are written, and the table is kept for :meth:`finished_table`);
        ``record_members`` false: its members get no run folder, the family's record keeps
        their rows (:func:`~pipeline.studies.experiment.run_family`'s), and is then always
        written: a later rung or a resumed trial takes the members from it."""
        folder = Path(folder)
        pending = self._families.get(folder)
        if pending is not None:  # the same folder is being written: after it
            pending.waiting.append((cfg, on_done, whole_hash, record_horizon, record,
                                    record_members))
            return
        family = cfg.scenario.family
        if family is None:
            raise ValueError(f"scenario {cfg.scenario.name} is not a family (scenario.family)")
        if check(folder, "family", cfg.config_hash(), members=False) is None or (
                whole_hash is not None
                and check(folder, "family", whole_hash, members=False) is None):
            self.counts.resumed += family.size
            self._ready.append(on_done)
            return
        # the QP compiled here once per statement (a worker compiles nothing), whichever
        # members turn out to be complete (a family read back whole still compiles it: once
        # per process, about 0.9 s for Clarabel's four slot statements, 3 ms for DAQP)
        compiles_before = self.cache.compile_count
        _prepare_cache(cfg, self.cache, family.size)
        state = _Family(cfg, folder, family.size, {}, MemberCounts(), family.size,
                        self.cache.compile_count - compiles_before, on_done,
                        record or not record_members, record_members,
                        whole=whole_hash or cfg.config_hash())
        self._families[folder] = state
        shipped = _snapshot(self.cache)
        # an earlier rung's members (complete: read back in one task; a member found damaged
        # there runs in it all the same), then MEMBERS_PER_TASK at a time
        known = min(self._complete_below.get((folder, state.whole), 0), family.size)
        spans = ([range(known)] if known else []) + [
            range(start, min(start + MEMBERS_PER_TASK, family.size))
            for start in range(known, family.size, MEMBERS_PER_TASK)]
        for span in spans:
            task = (cfg, folder, list(span), shipped, self.member_cache, record_horizon)
            if self.executor is None:
                future: concurrent.futures.Future = concurrent.futures.Future()
                try:
                    future.set_result(_family_task(*task, None, record_members))
                except Exception as exc:  # raised in wait(), as a worker's would be
                    future.set_exception(exc)
            else:
                future = self.executor.submit(_family_task, *task, os.getpid(),
                                              record_members)
            self._futures[future] = folder

    def _complete(self, state: _Family) -> None:
        """A family whose members are all in: its record written by a worker
        (:func:`_record_family`; :meth:`wait` finishes it when the table comes back), or here
        without workers or without a record."""
        if not state.record:
            self._finish(state, _member_table(state.metrics, state.n_members))
            return
        task = (state.cfg, state.folder, state.metrics, state.n_members, state.compiles,
                state.counts, not state.record_members)
        if self.executor is None:
            self._finish(state, _record_family(*task))
            return
        self._records[self.executor.submit(_record_family, *task, os.getpid())] = state.folder

    def _finish(self, state: _Family, table: pd.DataFrame) -> None:
        """A family's table kept and its callback due; the families waiting for its folder
        submitted again (they find it complete)."""
        key = (state.folder, state.whole)
        self._complete_below[key] = max(self._complete_below.get(key, 0), state.n_members)
        if len(self._tables) >= KEPT_TABLES:
            self._tables.pop(next(iter(self._tables)))
        self._tables[state.folder, state.cfg.config_hash()] = table
        del self._families[state.folder]
        self._ready.append(state.on_done)
        for cfg, on_done, whole_hash, record_horizon, record, record_members in state.waiting:
            self.submit(cfg, state.folder, on_done, whole_hash, record_horizon, record,
                        record_members)

    def finished_table(self, folder: Path, config_hash: str) -> pd.DataFrame | None:
        """The per-member table of the family of ``config_hash`` completed here into
        ``folder``, or None (not completed here, or long ago: read its record instead)."""
        return self._tables.get((Path(folder), config_hash))

    def wait(self) -> None:
        """Run the callbacks of the families that are complete; when there are none, wait
        for the next task to come in first. A worker's exception is raised here."""
        if not self._ready and (self._futures or self._records):
            done, _ = concurrent.futures.wait([*self._futures, *self._records],
                                              return_when=concurrent.futures.FIRST_COMPLETED)
            for future in done:
                if future in self._records:  # a record written, its table handed back
                    folder = self._records.pop(future)
                    self._finish(self._families[folder], future.result())
                    continue
                folder = self._futures.pop(future)
                results, counts, warnings = future.result()
                for message in warnings:  # as if the parent had checked the members
                    logging.getLogger(_members_to_run.__module__).warning(message)
                state = self._families[folder]
                for index, metrics in results:
                    state.metrics[index] = metrics
                state.counts.add(counts)
                self.counts.add(counts)
                state.left -= len(results)
                if state.left == 0:
                    self._complete(state)
        while self._ready:
            self._ready.popleft()()

    def run_until_idle(self) -> None:
        """:meth:`wait` until nothing is pending (callbacks may submit more families)."""
        while self.busy:
            self.wait()

    def close(self) -> None:
        """Release the executor to joblib (its workers stay for the next Parallel call); an
        executor handed in stays its owner's."""
        if self._parallel is not None:
            self._parallel.__exit__(None, None, None)

    def stop(self) -> None:
        """Stop the workers and drop what they had (an interrupted tune). The futures are not
        cancelled: loky's manager thread settles each one as the executor shuts down, and
        one cancelled first raised ``InvalidStateError: CANCELLED`` from that thread after
        the command's stop line; the shutdown waits for the thread, so nothing is printed
        after it."""
        if self.executor is not None and self._parallel is not None:
            _quiet_loky_threads()
            self.executor.shutdown(wait=True, kill_workers=True)
        elif self.executor is not None:  # a cluster's: its pending tasks cancelled
            for future in [*self._futures, *self._records]:
                future.cancel()
        self._futures.clear()
        self._records.clear()
        self.close()


def _quiet_loky_threads() -> None:
    """From now on, an exception raised in loky's own threads (its executor manager, which
    races the workers this process has just killed: a ``KeyError`` on a work item, seen under
    load) is not printed: the command is stopping on a signal and says so in its one line.
    Every other thread's exception is printed as before. Installed once per process."""
    import threading

    previous = threading.excepthook
    if getattr(previous, "quiet_loky", False):
        return

    def hook(args) -> None:
        if args.thread is not None and \
                type(args.thread).__module__.startswith("joblib.externals.loky"):
            return
        previous(args)

    hook.quiet_loky = True  # type: ignore[attr-defined]
    threading.excepthook = hook

