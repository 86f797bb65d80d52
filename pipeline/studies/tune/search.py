"""The tuning loop: one Optuna study per replicate and method, asked in batches until its
front's hypervolume has converged or the cap is reached; families composed and run here or on
SLURM, resumed by config hash."""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pipeline.config import ExperimentConfig
from pipeline.store.manifest import check
from pipeline.store.runs import read_family, read_member_rows
from pipeline.studies.tune.pareto import HypervolumeHistory, convergence_point
from pipeline.studies.tune.space import TRACK_OVERRIDES, TuneSpace

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Convergence:
    """When a study stops: at ``min_trials`` at the earliest, ``max_trials`` at the latest,
    once the hypervolume grew by at most ``tolerance`` of its value over ``window`` trials."""

    min_trials: int
    max_trials: int
    window: int
    tolerance: float
    bounds: tuple[tuple[float, float], ...]

    @classmethod
    def of(cls, space: TuneSpace) -> Convergence:
        return cls(space.min_trials, space.max_trials, space.convergence_window,
                   space.convergence_tolerance,
                   tuple((float(a), float(b)) for a, b in space.hypervolume_bounds))

    def history(self, study, kept: HypervolumeHistory | None = None) -> np.ndarray:
        """The hypervolume after each complete trial, in trial order (``kept``: the history of
        an earlier call on the same study, which then computes only what is new)."""
        values, feasible = study_values(study)
        if not len(values):
            return np.zeros(0)
        kept = kept if kept is not None else HypervolumeHistory([list(b) for b in self.bounds])
        return kept.of(values, feasible)

    def stop_at(self, history: np.ndarray, effort: np.ndarray | None = None) -> int | None:
        return convergence_point(history, self.min_trials, self.window, self.tolerance, effort)

    def effort(self, study, size: int) -> np.ndarray:
        """The work done until each complete trial, in whole-trial equivalents (members
        simulated over ``size``; a trial without a count is one whole trial)."""
        from optuna.trial import TrialState

        trials = sorted(study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)),
                        key=lambda t: t.number)
        members = np.array([float(t.user_attrs.get("members", size)) for t in trials])
        return np.cumsum(members) / float(size)


def study_values(study) -> tuple[np.ndarray, np.ndarray]:
    """The complete trials' objective values (rows in trial order) and feasibility."""
    from optuna.trial import TrialState

    trials = sorted(study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)),
                    key=lambda t: t.number)
    values = np.array([list(t.values) for t in trials], float)
    feasible = np.array([float(t.user_attrs.get("constraint", 0.0)) <= 0.0 for t in trials],
                        bool)
    return values, feasible


def complete_trials(study) -> int:
    """How many of the study's trials are complete."""
    from optuna.trial import TrialState

    return len(study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)))


def optimize(study, distributions: dict, evaluate: Callable[[list[dict]], list[tuple]],
             rule: Convergence, batch_size: int, log=logger.info, label: str = "",
             family_size: int | None = None) -> tuple[np.ndarray, int | None]:
    """Run ``study`` until its hypervolume has converged (:class:`Convergence`) or it holds
    ``rule.max_trials`` complete trials, ``batch_size`` at a time; return the hypervolume
    history and the trial count at which it converged (None: stopped by the cap).

    ``evaluate`` takes a list of parameter dicts and returns, per setting, ``(values,
    constraint)`` or ``(values, constraint, attrs)``: the objective values, the safety
    constraint (<= 0 feasible) and what to keep with the trial (its rungs, the members it
    simulated, where it was stopped). One study at a time (:class:`StudyLoop`, whose batches
    the tune also runs side by side with other studies' on one pool of workers).
    """
    loop = StudyLoop(study, distributions, rule, batch_size, log, label, family_size)
    loop.run(evaluate)
    return loop.history, loop.converged


class StudyLoop:
    """One study's tuning loop, a batch at a time: :meth:`next_batch` asks the sampler for the
    next ``batch_size`` settings (None once the study has converged or reached the cap), and
    :meth:`tell` records their results; :func:`optimize` alternates the two, the tune runs many
    studies' loops side by side (:func:`run_studies_together`).
    The asks and tells of a study are the same whichever way its batches run, so are its
    trials.

    A trial left running by an interrupted process is closed as failed and its batch asked
    again from the sampler's state at the batch's start (kept in the study), so that a resumed
    study asks what the uninterrupted one asked (their finished families are read back, not
    simulated). A resumed study that had converged stops where it converged. With
    ``family_size``, the rule's trial counts are whole-trial equivalents of simulated members
    (:func:`convergence_point`).
    """

    def __init__(self, study, distributions: dict, rule: Convergence, batch_size: int,
                 log=logger.info, label: str = "", family_size: int | None = None) -> None:
        from optuna.trial import TrialState

        self.study, self.distributions, self.rule = study, distributions, rule
        self.batch_size, self.log, self.label, self.family_size = (batch_size, log, label,
                                                                   family_size)
        #: the hypervolume history and the convergence point, once the study has stopped
        self.history: np.ndarray = np.zeros(0)
        self.converged: int | None = None
        self._batch: list = []
        # a batch left running by an interrupted process: its trials closed as failed and the
        # batch asked again from the sampler's state at its start (the same settings: their
        # finished families are read back, not simulated), so that a resumed tune asks what
        # the uninterrupted one would have asked
        running = study.get_trials(deepcopy=False, states=(TrialState.RUNNING,))
        for trial in running:
            study.tell(trial.number, state=TrialState.FAIL)
        if not restore_sampler_state(study):
            # no state kept for this count (a study of an older version, or a kill between two
            # tells): the running trials' settings are asked again first
            for trial in running:
                study.enqueue_trial(dict(trial.params))
        # the trials' rate is counted from the first ask (a loop may be made before its
        # study's first batch can start: the tune's untuned families run in between)
        self._start: float | None = None
        #: the sampler states kept in the study (read once here, then as this loop writes them)
        self._sampler_states: dict | None = None
        #: the study's hypervolume history so far (only new trials are computed again)
        self._volumes = HypervolumeHistory([list(b) for b in rule.bounds])
        self._done_before = complete_trials(study)
        #: studies running side by side with this one (its progress line says so: its time
        #: per trial is then shared)
        self.side_by_side = 1

    def _effort(self) -> np.ndarray | None:
        return self.rule.effort(self.study, self.family_size) if self.family_size else None

    def next_batch(self) -> list[dict] | None:
        """The next batch's settings (their trials asked and left running), or None once the
        study has converged or spent its cap (then :attr:`history` and :attr:`converged`)."""
        history = self.rule.history(self.study, self._volumes)
        complete = len(history)
        effort = self._effort()
        converged = self.rule.stop_at(history, effort)
        spent = float(effort[-1]) if effort is not None and len(effort) else float(complete)
        if converged is not None or spent >= self.rule.max_trials:
            self.history, self.converged = history, converged
            return None
        self._sampler_states = save_sampler_state(self.study, complete, "before",
                                                  self._sampler_states)
        if self._start is None:
            self._start = time.perf_counter()
        size = max(1, min(self.batch_size, int(np.ceil(self.rule.max_trials - spent))))
        self._batch = [self.study.ask(self.distributions) for _ in range(size)]
        settings = [dict(trial.params) for trial in self._batch]
        self._sampler_states = save_sampler_state(self.study, complete + len(self._batch),
                                                  "after", self._sampler_states)
        return settings

    def run(self, evaluate: Callable[[list[dict]], list[tuple]]) -> None:
        """Ask, evaluate and tell batch after batch until the study stops (one study at a
        time: :func:`optimize`, and the tune on SLURM)."""
        while (settings := self.next_batch()) is not None:
            self.tell(evaluate(settings))

    def tell(self, results: list[tuple]) -> None:
        """Record the last batch's results (per setting ``(values, constraint[, attrs])``) and
        log the study's progress."""
        for trial, (values, constraint, *more) in zip(self._batch, results, strict=True):
            # the safety constraint as NSGA-II ranks it (<= 0 feasible), and as the tables read it
            trial.set_constraint("safety", float(constraint))
            trial.set_user_attr("constraint", float(constraint))
            for key, value in (more[0] if more else {}).items():
                trial.set_user_attr(key, value)
            self.study.tell(trial, list(values))
        self._batch = []
        complete = complete_trials(self.study)
        started = self._start if self._start is not None else time.perf_counter()
        rate = (time.perf_counter() - started) / max(complete - self._done_before, 1)
        # with pruning the rule counts whole-trial equivalents of simulated members: a pruned
        # trial counts for the share of its family it ran
        effort = self._effort()
        counted = (f", {float(effort[-1]):.0f} whole-trial equivalents"
                   if effort is not None and len(effort) else "")
        shared = (f" with {self.side_by_side} studies side by side" if self.side_by_side > 1
                  else "")
        self.log(f"{self.label}trials {complete}{counted} (converged at the earliest at "
                 f"{self.rule.min_trials}, cap {self.rule.max_trials}; {rate:.1f} s per trial"
                 f"{shared})")


#: the study's attribute holding its sampler's random state at the start of the last
#: batch (with the number of complete trials then)
SAMPLER_STATE = "pipeline:sampler_state_at_batch"


def _random_states(sampler) -> list:
    """The numpy random states an NSGA-II sampler draws from (its own and its random
    sampler's; Optuna keeps each in a lazily made holder), or [] for another sampler."""
    holders = [getattr(sampler, "_rng", None),
               getattr(getattr(sampler, "_random_sampler", None), "_rng", None)]
    states = [getattr(h, "rng", h) for h in holders if h is not None]
    return [s for s in states if isinstance(s, np.random.RandomState)]


def save_sampler_state(study, complete: int, when: str, saved: dict | None = None) -> dict:
    """Keep the sampler's random state in the study: at the start of a batch (``when`` is
    ``"before"``, ``complete`` the complete trials then) and once its settings are asked
    (``"after"``, ``complete`` the count once the batch is told): a resumed study restores
    the one that matches its count (:func:`restore_sampler_state`). ``saved``: what the last
    call returned (the study's kept states as this process wrote them: the study is its
    alone), so that the store is not read again; by default read from the study. Returns
    what is now kept."""
    states = []
    for rng in _random_states(study.sampler):
        name, keys, pos, has_gauss, gauss = rng.get_state()
        states.append([name, [int(k) for k in keys], int(pos), int(has_gauss), float(gauss)])
    if saved is None:
        saved = study.user_attrs.get(SAMPLER_STATE)
    saved = dict(saved) if isinstance(saved, dict) else {}
    saved[when] = {"complete": int(complete), "states": states}
    if when == "before":
        saved.pop("after", None)
    study.set_user_attr(SAMPLER_STATE, saved)
    return saved


def restore_sampler_state(study) -> bool:
    """Put the sampler back in the state the uninterrupted run had with the study's present
    number of complete trials (at the start of the interrupted batch, or once the last batch
    was asked), when the study kept it; whether it did. With it a resumed tune asks the
    settings the uninterrupted one asked."""
    saved = study.user_attrs.get(SAMPLER_STATE)
    complete = complete_trials(study)
    rngs = _random_states(study.sampler)
    if not isinstance(saved, dict) or not rngs:
        return False
    for entry in (saved.get("before"), saved.get("after")):
        if isinstance(entry, dict) and entry.get("complete") == complete \
                and len(entry.get("states", [])) == len(rngs):
            for rng, (name, keys, pos, has_gauss, gauss) in zip(rngs, entry["states"],
                                                                strict=True):
                rng.set_state((name, np.array(keys, dtype=np.uint32), pos, has_gauss, gauss))
            return True
    return False


#: The constraint value of a trial stopped at a rung because it cannot move its method's front:
#: infeasible (never on a front, never picked), but ranked by NSGA-II before every setting that
#: collided more often than the threshold (whose constraint is the excess count, >= 1).
CANNOT_MOVE_FRONT_AT_RUNG = 0.5

#: How a trial is judged on a growing share of its training family (``tune.rungs``).
PRUNING_RULE = ("a trial runs the first tune.rungs[0] members of its training family, then "
                "tune.rungs[1], ..., then all of it; it stops at a rung when its collisions "
                "there already exceed the safety threshold (it can no longer be feasible), or "
                "when, once its method has tune.prune_after_trials complete trials, its values "
                "on those members would raise the hypervolume of its method's complete feasible "
                "trials, read on the same members, by at most tune.prune_gain of it (it cannot "
                "move the front); a stopped trial is kept as infeasible with its values at that "
                "rung. Both methods follow the same rule; the members each simulated are "
                "counted")


@dataclass(frozen=True)
class Rungs:
    """The member counts a trial is judged at (the last: the whole training family) and the
    rule that stops it early (:data:`PRUNING_RULE`)."""

    sizes: tuple[int, ...]
    gain: float
    after_trials: int
    bounds: tuple[tuple[float, float], ...]

    @classmethod
    def of(cls, space: TuneSpace) -> Rungs:
        return cls(tuple(space.rungs) + (space.training_size,), space.prune_gain,
                   space.prune_after_trials,
                   tuple((float(a), float(b)) for a, b in space.hypervolume_bounds))

    def front_at_rungs(self, study) -> dict[int, np.ndarray]:
        """Per early rung, the rung values of the method's complete, feasible trials that ran
        the whole family (empty before ``after_trials`` complete trials)."""
        from optuna.trial import TrialState

        trials = list(study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)))
        if len(trials) < self.after_trials or len(self.sizes) == 1:
            return {}
        full = [t for t in trials if t.user_attrs.get("pruned_at") is None
                and float(t.user_attrs.get("constraint", 0.0)) <= 0.0]
        out = {}
        for n in self.sizes[:-1]:
            rows = [t.user_attrs.get("rungs", {}).get(str(n)) for t in full]
            rows = [r for r in rows if r is not None and np.isfinite(r).all()]
            if rows:
                out[n] = np.array(rows, float)
        return out

    def cannot_reach(self, values, front: np.ndarray | None) -> bool:
        """Whether ``values`` would raise the hypervolume of ``front`` (the same members'
        values of the complete trials) by at most ``gain`` of it."""
        from pipeline.studies.tune.pareto import hypervolume, normalized

        if front is None or not len(front) or not np.isfinite(values).all():
            return False
        bounds = [list(b) for b in self.bounds]
        reference = np.ones(len(bounds))
        points = normalized(np.asarray(front, float), bounds)
        base = hypervolume(points, reference)
        if base <= 0.0:
            return False
        grown = hypervolume(np.vstack([points, normalized(
            np.asarray(values, float)[None, :], bounds)]), reference)
        return bool(grown - base <= self.gain * base)


class RungTrials:
    """One batch's settings judged rung by rung (:data:`PRUNING_RULE`): each setting runs the
    first ``rungs.sizes[0]`` members of its training family, then the next rung's, and stops
    at a rung or after the last; settings move on independently of each other (each is
    judged on its own values, the batch's ``front`` and the ``threshold``), so the result is
    the same whether a batch's rungs run together (:func:`evaluate_in_rungs`) or each setting
    as its family comes in (the tune's studies side by side). ``measure`` turns a family table
    into the objective values and the collision count."""

    def __init__(self, settings: list[dict], threshold: int, rungs: Rungs,
                 front: dict[int, np.ndarray],
                 measure: Callable[[pd.DataFrame], tuple[list[float], int]]) -> None:
        self.settings, self.threshold, self.rungs = settings, threshold, rungs
        self.front, self.measure = front, measure
        self._results: list[tuple[list[float], float, dict] | None] = [None] * len(settings)
        self._seen: list[dict[str, list[float]]] = [{} for _ in settings]
        self._rung = [0] * len(settings)

    def members(self, i: int) -> int:
        """The members setting ``i`` runs next (its present rung)."""
        return self.rungs.sizes[self._rung[i]]

    def finished(self, i: int) -> bool:
        return self._results[i] is not None

    @property
    def done(self) -> bool:
        return all(r is not None for r in self._results)

    def record(self, i: int, table: pd.DataFrame) -> bool:
        """Setting ``i``'s family table at its present rung; whether it is finished (else it
        runs the next rung)."""
        n = self.members(i)
        last = self._rung[i] == len(self.rungs.sizes) - 1
        values, collisions = self.measure(table)
        self._seen[i][str(n)] = [float(v) for v in values]
        attrs = {"rungs": self._seen[i], "members": n}
        if last:
            self._results[i] = (values, collisions - self.threshold, attrs)
        elif collisions > self.threshold:
            self._results[i] = (values, collisions - self.threshold,
                                {**attrs, "pruned_at": n, "pruned_by": "collisions"})
        elif self.rungs.cannot_reach(values, self.front.get(n)):
            self._results[i] = (values, CANNOT_MOVE_FRONT_AT_RUNG,
                                {**attrs, "pruned_at": n, "pruned_by": "front"})
        else:
            self._rung[i] += 1
        return self._results[i] is not None

    def results(self) -> list[tuple[list[float], float, dict]]:
        """Per setting ``(values, constraint, attrs)`` for :meth:`StudyLoop.tell`."""
        return [r for r in self._results if r is not None]


def evaluate_in_rungs(runner: Runner, method: str, replicate: int, settings: list[dict],
                      threshold: int, rungs: Rungs, front: dict[int, np.ndarray],
                      measure: Callable[[pd.DataFrame], tuple[list[float], int]]
                      ) -> list[tuple[list[float], float, dict]]:
    """Each setting's training family, run rung by rung (all still-running settings of a rung
    in one pool of workers, or one SLURM array) and stopped by :data:`PRUNING_RULE`
    (:class:`RungTrials`); per setting ``(values, constraint, attrs)`` for :func:`optimize`."""
    batch = RungTrials(settings, threshold, rungs, front, measure)
    alive = list(range(len(settings)))
    while alive:
        n = batch.members(alive[0])
        jobs = [runner.job(method, "trial", settings[i], "training", replicate, members=n)
                for i in alive]
        where = f"replicate {replicate}: {method} training families" + (
            "" if n == rungs.sizes[-1] else f" (first {n} members)")
        for i, table in zip(alive, runner.run(jobs, where, "training"), strict=True):
            batch.record(i, table)
        alive = [i for i in alive if not batch.finished(i)]
    return batch.results()


def trial_storage(path: Path):
    """The journal file that keeps the trials (Optuna's :class:`~optuna.storages.
    JournalStorage` over :class:`~pipeline.studies.tune.trial_store.TrialJournal`: one line
    per operation, appended without a disk sync). A killed process loses nothing written;
    several processes may share it (each replays the others' lines)."""
    from optuna.storages import JournalStorage

    from pipeline.studies.tune.trial_store import TrialJournal

    return JournalStorage(TrialJournal(Path(path)))


#: the user attribute of a study holding the store key it was made under
STORE_KEY = "pipeline:store_key"
#: the trial store's file in a tune's folder (an Optuna journal: :func:`trial_storage`)
STORE_FILE = "tune.journal"
#: the trial store of versions before Optuna 3 (an SQLite file): never read, left in place
OLD_STORE_FILE = "tune.db"


def study_name(space: TuneSpace, method: str, replicate: int) -> str:
    """The name of one method's study in one replicate (by the space's trial key)."""
    return f"{space.name}-{space.trial_key()}-r{replicate}-{method}"


def check_trial_store(path: Path, space: TuneSpace, store_key: str | None = None,
                      log=logger.info) -> None:
    """Raise :class:`StudyError` (one line naming the file, nothing written) when the trial
    store at ``path`` cannot be used as it is: a folder or a device in its place, a damaged
    file or one that is not Optuna's journal, a read-only store, or a study of this tune made
    under another store key (another budget or code version: :meth:`TuneSpace.store_key`;
    ``store_key``: this tune's, by default without run overrides), whose trials would be
    reused silently. A missing or empty store is fine (it is started). A last line cut without
    its end (a crash of the machine mid-write; a killed process never leaves one) is an
    operation that never completed: it is dropped, and ``log`` says so."""
    from pipeline.errors import StudyError

    path = Path(path)
    old = path.with_name(OLD_STORE_FILE)
    if old.is_file():
        log(f"{old}: the trial store of an earlier version (SQLite, Optuna 2): not read, left "
            f"in place; the trials are kept in {path.name}")
    if not _check_store_file(path):
        return
    names = {study_name(space, m, r) for m in space.methods for r in range(space.replicates)}
    key = store_key or space.store_key()
    for name, stored_key, n_trials in _stored_keys(path, log):
        if name in names and n_trials and stored_key != key:
            raise StudyError(
                f"{path}: holds {n_trials} trials of {name} made under "
                + (f"store key {stored_key}" if stored_key else "an older version")
                + f", not this tune's {key} (another budget, run overrides or code version); "
                  "they are not "
                  f"reused: {START_FRESH}")


#: what a refused trial store's line ends with
START_FRESH = "delete it (or choose another --out) to start fresh"


def _check_store_file(path: Path) -> bool:
    """Whether a trial store is there (False: none yet); :class:`StudyError` for a path that
    is not a readable, writable file."""
    import stat

    from pipeline.errors import StudyError

    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        return False
    if stat.S_ISDIR(mode):
        raise StudyError(f"{path}: a folder, not the trial store (a journal file); move it "
                         "away or choose another --out")
    if not stat.S_ISREG(mode):
        raise StudyError(f"{path}: not a regular file (a device or a pipe); move it away or "
                         "choose another --out")
    if not os.access(path, os.R_OK):
        raise StudyError(f"{path}: the trial store cannot be read (permission denied)")
    if _read_only(path) or _read_only(path.parent):
        raise StudyError(f"{path}: read-only; the trial store must be writable (every trial "
                         "is recorded as it completes): make it writable or choose another --out")
    return True


def _read_only(path: Path) -> bool:
    """Whether ``path`` cannot be written: no write permission (its mode bits, which bind
    the superuser's intent too) or a read-only file system."""
    mode = path.stat().st_mode
    return not os.access(path, os.W_OK) or not mode & 0o222 \
        or bool(os.statvfs(path).f_flag & os.ST_RDONLY)


def _stored_keys(path: Path, log=logger.info) -> list[tuple[str, str | None, int]]:
    """Every study in the store: its name, the store key it was made under (None before
    keys) and its trial count, as Optuna replays the journal (in memory: the file is not
    written, but for a cut last line, dropped); :class:`StudyError` for a file that is not
    Optuna's journal or is damaged."""
    from optuna.storages import JournalStorage

    from pipeline.errors import StudyError
    from pipeline.studies.tune.trial_store import JournalCutError, LogsInMemory, read_journal

    try:
        logs = read_journal(path)
    except JournalCutError as exc:
        if not exc.last:
            raise StudyError(f"{path}: not Optuna's journal, or damaged ({exc}); "
                             f"{START_FRESH}") from None
        data = path.read_bytes()
        kept = data[:data.rfind(b"\n") + 1]
        with open(path, "r+b") as handle:
            handle.truncate(len(kept))
        logs = read_journal(path)
        log(f"{path}: its last line was cut (a write stopped midway, as a crash of the "
            f"machine leaves it): dropped; the {len(logs)} operations before it are kept")
    try:
        storage = JournalStorage(LogsInMemory(logs))
        return [(s.study_name, s.user_attrs.get(STORE_KEY),
                 len(storage.get_all_trials(s._study_id, deepcopy=False)))
                for s in storage.get_all_studies()]
    except Exception as exc:  # an operation Optuna cannot replay: whatever it is, one line
        raise StudyError(f"{path}: Optuna cannot replay the journal ({type(exc).__name__}: "
                         f"{exc}); {START_FRESH}") from None


def make_study(space: TuneSpace, method: str, replicate: int, storage,
               store_key: str | None = None):
    """The NSGA-II study of one method in one replicate (its own sampler seed), named by the
    space's trial key so that an edited space never resumes another's trials, and carrying
    the store key it is made under (``store_key``, by default the space's without run
    overrides: :func:`check_trial_store`)."""
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    # the safety constraint is told with each trial (Trial.set_constraint), which NSGA-II ranks by
    sampler = optuna.samplers.NSGAIISampler(population_size=space.population_size,
                                            seed=space.sampler_seed_of(replicate))
    study = optuna.create_study(
        study_name=study_name(space, method, replicate), storage=storage,
        sampler=sampler, load_if_exists=True,
        directions=[optuna.study.StudyDirection[o.direction.upper()] for o in space.objectives])
    if STORE_KEY not in study.user_attrs:
        study.set_user_attr(STORE_KEY, store_key or space.store_key())
    return study


def _override(name: str, value) -> str:
    return f"{name}={value!r}" if isinstance(value, float) else f"{name}={value}"


def design_holds(cfg: ExperimentConfig, expected: dict, method: str) -> None:
    """Raise :class:`ConfigError` when a composed run does not hold what the tune asked for
    (a preset among the run overrides, e.g. a sweep or an ablation point, set one of its
    families' seed or size, its QP backend or a tuned setting): the tune would run another
    design than the one its summary describes."""
    import math

    from pipeline.errors import ConfigError

    def value_of(key: str) -> Any:
        value: Any = cfg
        for part in key.split("."):
            value = value.get(part) if isinstance(value, dict) else getattr(value, part, None)
        return value

    for key, want in expected.items():
        got = value_of(key)
        same = got == want or str(got) == str(want) or (
            isinstance(got, (int, float)) and isinstance(want, (int, float))
            and not isinstance(got, bool) and math.isclose(float(got), float(want),
                                                           rel_tol=1e-12, abs_tol=0.0))
        if not same:
            raise ConfigError(f"tune: {method}'s run {key}", got,
                              f"{want!r}, what the tune sets (a run override changed it: "
                              "leave the tune's own keys to its space file)")


@dataclass(frozen=True)
class FamilyJob:
    """One family to run: its config and folder, and the settings it stands for."""

    method: str
    setting: str
    cfg: ExperimentConfig
    folder: Path
    replicate: int | None = None
    #: for a rung (the first members of a family), the config hash of the whole family, whose
    #: complete record in the same folder holds the rung's members too
    whole_hash: str | None = None


class Runner:
    """Composes family configs and runs them (here or on SLURM), resuming by config hash."""

    def __init__(self, space: TuneSpace, out_dir: Path, overrides: list[str], log) -> None:
        from pipeline.loop.controller import QpCache
        from pipeline.store.member_cache import MemberCache, MemberCounts
        from pipeline.studies.compose import composer

        self.space, self.out_dir, self.log = space, Path(out_dir), log
        self.compose, self.launcher = composer(list(overrides))
        self.cache = QpCache()
        #: where this tuning's members came from (simulated, from the member cache, resumed)
        self.counts = MemberCounts()
        self.member_cache = MemberCache.from_env()
        self._composed: dict[tuple[str, ...], ExperimentConfig] = {}
        #: the workers of a Dask cluster the families run on (``--workers``), or None for
        #: this machine's loky pool (or SLURM arrays with ``hydra/launcher=slurm``)
        self.executor: Any = None

    def job(self, method: str, setting: str, params: dict, part: str,
            replicate: int | None = None, members: int | None = None) -> FamilyJob:
        """One family of ``method`` with ``params``: the training or the held-out family of
        ``replicate`` (None: replicate 0's, where the untuned methods are judged); with
        ``members``, only its first ``members`` members (a rung), in the folder of the whole
        family (its members are the same runs)."""
        import dataclasses

        if part == "training":
            seed, size = self.space.training_seeds[replicate or 0], self.space.training_size
            backend = self.space.backend
        else:
            seed, size = self.space.heldout_seed_of(replicate or 0), self.space.heldout_size
            backend = self.space.heldout_backend
        overrides = ([f"method={method}", *self.space.scenario_overrides(part),
                      f"scenario.family.seed={seed}", f"scenario.family.size={size}",
                      f"controller.backend={backend}"]
                     + list(TRACK_OVERRIDES[self.space.track])
                     + [_override(k, v) for k, v in params.items()])
        # a trial's rungs are one composition (Hydra's compose is 0.05-0.1 s)
        key = tuple(overrides)
        cfg = self._composed.get(key)
        if cfg is None:
            if len(self._composed) > 64:
                self._composed.clear()
            cfg = self._composed[key] = self.compose(overrides)
            track = dict(o.split("=", 1) for o in TRACK_OVERRIDES[self.space.track]
                         if "." in o.split("=", 1)[0])
            expected = {"scenario.family.seed": seed, "scenario.family.size": size,
                        "controller.backend": backend, **track, **params}
            design_holds(cfg, expected, method)
        whole_hash = cfg.config_hash()
        folder = self.out_dir / "runs" / part / method / whole_hash
        family = cfg.scenario.family
        if members is not None and family is not None and members < family.size:
            cfg = dataclasses.replace(cfg, scenario=dataclasses.replace(
                cfg.scenario, family=dataclasses.replace(family, size=members)))
            return FamilyJob(method, setting, cfg, folder, replicate, whole_hash)
        return FamilyJob(method, setting, cfg, folder, replicate)

    def records_horizon(self, part: str) -> bool:
        """Whether new members of ``part``'s families write what each step planned: the
        held-out families always (make reproduce's members, the report's explorer), the
        training families with ``tune.training_horizon``."""
        return part != "training" or bool(self.space.training_horizon)

    def records_members(self, part: str) -> bool:
        """Whether new members of ``part``'s families get run folders (and member-cache
        entries): the held-out families always (judged like make reproduce's, read by the
        report), the training families with ``tune.training_member_records`` (or
        ``tune.training_horizon``, which is kept in the members' folders); else a training
        family's record keeps its members' rows, all the tune reads of them."""
        return part != "training" or bool(self.space.training_member_records) \
            or bool(self.space.training_horizon)

    @property
    def local(self) -> bool:
        """Whether families run on this machine's cores (not as SLURM arrays)."""
        return self.launcher is None

    def pool(self, n_jobs: int):
        """A :class:`~pipeline.studies.family_pool.FamilyPool` of ``n_jobs`` workers that
        counts into this runner's counts and shares its caches."""
        from pipeline.studies.family_pool import FamilyPool

        return FamilyPool(n_jobs, self.cache, self.member_cache, self.counts, self.executor)

    @staticmethod
    def complete(job: FamilyJob) -> bool:
        """Whether ``job``'s folder already holds its members: its own record, or (a rung)
        the whole family's, complete. A trial asked again after an interruption then reads
        its rung from the whole family instead of writing the rung's record over it."""
        return check(job.folder, "family", job.cfg.config_hash(), members=False) is None or (
            job.whole_hash is not None
            and check(job.folder, "family", job.whole_hash, members=False) is None)

    def table(self, job: FamilyJob) -> pd.DataFrame:
        """The per-member table of a complete family job (its first ``members`` members),
        read from its ``family_metrics.csv``; a rung's own record (an early rung of a
        trial whose members keep no run folder, asked again) from the rows it keeps: the
        very table the members' own ``metrics.json`` files gave when an early rung had no
        record and its members were read back (JSON keeps every float; the CSV 10 digits),
        so the tune asks what it asked before the rows."""
        from pipeline.studies.experiment import _member_table

        family = job.cfg.scenario.family
        if job.whole_hash is not None and family is not None:
            rows = read_member_rows(job.folder, job.cfg.config_hash())
            if rows and all(i in rows for i in range(family.size)):
                return _member_table({i: rows[i] for i in range(family.size)}, family.size)
        table = read_family(job.folder, members=False, settings=False).table
        if family is not None and len(table) > family.size:  # a rung of a whole family
            table = table[table["member"] < family.size].reset_index(drop=True)
        return table

    def run(self, jobs: list[FamilyJob], label: str, part: str = "heldout"
            ) -> list[pd.DataFrame]:
        """Run ``jobs`` (families of ``part``: a training family's new members keep what each
        step planned only with ``tune.training_horizon``) and return their tables."""
        from pipeline.studies.multiverse.runs import run_families

        todo, seen = [], set()
        for job in jobs:
            if job.folder not in seen and not self.complete(job):
                todo.append((job.cfg, job.folder))
                seen.add(job.folder)
        if self.executor is not None:  # a Dask cluster's workers, through the family pool
            pool = self.pool(0)
            self.log(f"{label}: {len(todo)} families on the cluster's workers")
            for cfg, folder in todo:
                pool.submit(cfg, folder, lambda: None,
                            record_horizon=self.records_horizon(part),
                            record_members=self.records_members(part))
            try:
                pool.run_until_idle()
            except BaseException:
                pool.stop()
                raise
            pool.close()
        else:
            run_families(todo, self.out_dir, self.log, self.launcher, self.cache, label,
                         counts=self.counts, member_cache=self.member_cache,
                         record_horizon=self.records_horizon(part),
                         record_members=self.records_members(part))
        tables = [self.table(job) for job in jobs]
        # families complete before this call: their members count as already complete
        counted = {folder for _, folder in todo}
        for job, table in zip(jobs, tables, strict=True):
            if job.folder not in counted:
                counted.add(job.folder)
                self.counts.resumed += len(table)
        return tables


@dataclass(frozen=True)
class TunedStudy:
    """One study's place in the tune: its replicate and method, its loop, and its training
    family's feasibility threshold (collisions)."""

    replicate: int
    method: str
    loop: StudyLoop
    threshold: int


def run_studies_together(runner: Runner, studies: list[TunedStudy], rungs: Rungs,
                         measure: Callable[[pd.DataFrame], tuple[list[float], int]],
                         n_jobs: int) -> None:
    """Every study's batches at once on one pool of ``n_jobs`` workers, until each study has
    converged or spent its cap (:meth:`StudyLoop.next_batch` returns None).

    Each study asks its next batch as soon as its last one is told, and each setting of a
    batch runs its next rung as soon as its family at this rung is in (:class:`RungTrials`),
    so the workers always have members of some study to run while the parent asks, composes
    and records. A study's asks and tells, and so its trials, are those of :func:`optimize`
    (tested: the same trials table as the studies one after the other).
    """
    pool = runner.pool(n_jobs)
    for entry in studies:
        entry.loop.side_by_side = len(studies)

    def start_batch(entry: TunedStudy) -> None:
        settings = entry.loop.next_batch()
        if settings is None:
            return
        batch = RungTrials(settings, entry.threshold, rungs,
                           rungs.front_at_rungs(entry.loop.study), measure)
        for i in range(len(settings)):
            run_rung(entry, batch, i)

    def run_rung(entry: TunedStudy, batch: RungTrials, i: int) -> None:
        job = runner.job(entry.method, "trial", batch.settings[i], "training",
                         entry.replicate, members=batch.members(i))

        def done() -> None:
            # the table the pool has just made (an early rung's is not written: the next rung
            # writes the family's record over it), else the family's record read back
            table = pool.finished_table(job.folder, job.cfg.config_hash())
            if not batch.record(i, table if table is not None else runner.table(job)):
                run_rung(entry, batch, i)
            elif batch.done:
                entry.loop.tell(batch.results())
                start_batch(entry)

        # an early rung's family record is left out when its members have run folders
        # (about 10 ms of the parent's time a rung: a table, a summary and a manifest written
        # and read back): a resumed trial or a later rung reads the members back; without
        # them (tune.training_member_records false) the record keeps the members' rows and is
        # written
        pool.submit(job.cfg, job.folder, done, job.whole_hash,
                    record_horizon=runner.records_horizon("training"),
                    record=job.whole_hash is None,
                    record_members=runner.records_members("training"))

    try:
        for entry in studies:
            start_batch(entry)
        pool.run_until_idle()
    except BaseException:
        pool.stop()
        raise
    pool.close()
