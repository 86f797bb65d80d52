"""A fair fight: every compared method tuned by the same rules on training scenarios until its
front stops moving, in independent replicates, each then judged on its own held-out family
(``make tune``, ``python -m pipeline.tune``).

Benchmarking practice (Lucic et al. 2018; Melis et al. 2018) tunes every contender with the same
effort and judges on data the tuning never saw: differences that vanish under equal tuning were
tuning, not method. Here:

1. **Rules.** Each method of ``conf/tune/<name>.yaml`` is searched by NSGA-II over its own search
   space (``conf/hparams_search/<method>.yaml``: every free parameter of its APF, the ranges the
   paper allows, each with its reason) until its feasible front's hypervolume converges (one
   fixed normalisation for both methods; :class:`pipeline.studies.tune.search.Convergence`),
   between the same minimum and cap: equal rules, not an equal count.
2. **Replicates.** ``replicates`` independent tunings, each with its own sampler seed, its
   own training family and its own held-out family (so that the replicates' agreement
   measures the held-out sampling too, not only the tuner's randomness); the answer per claim
   is the count of replicates per outcome, settled by a one-sided exact binomial test
   (:func:`answer_in_counts`).
3. **Training.** A trial runs its replicate's training family and returns the objectives
   (statistics of the claims' primary metrics over the members, read as the ledger reads them:
   :func:`pipeline.analysis.objectives.tuning_table`). Safety is a constraint: a setting whose
   family collides more often than the untuned control's (or ``safety_reference``'s) is
   infeasible.
4. **Pareto sets.** Per replicate, the feasible non-dominated trials of each method and one
   compromise setting per method (:data:`COMPROMISE_RULE`).
5. **Held-out judgement.** Per replicate, on that replicate's held-out family (seed
   ``heldout_seed + heldout_seed_stride * r``, never a training seed), the compromises, the
   matched control built from them and up to ``max_heldout_settings`` Pareto settings per
   method; the claims ledger compares the tuned treatment with the tuned control and the
   matched control. The untuned methods once, on replicate 0's held-out family (seed
   ``heldout_seed``: make reproduce's family, its members restored from the member cache).

Trials live in an Optuna journal in the output folder (``tune.journal``), one study per
replicate and method named by the space's trial key: an interrupted tuning resumes without repeating a completed trial;
an edited space starts new studies. Families run here or, with ``hydra/launcher=slurm``, as
SLURM arrays.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pipeline.analysis.claims import ALL_CLAIMS, FORCE_CLAIMS, Ledger, family_ledger
from pipeline.analysis.objectives import (
    CENSORED_AT_RUN_END,
    objective_value,
    objective_values,
    tuning_table,
)
from pipeline.analysis.tally import Tally, collided
from pipeline.errors import ConfigError, StudyError
from pipeline.store.files import as_written, json_safe
from pipeline.store.lock import folder_lock
from pipeline.store.manifest import refuse_other_record, untrust
from pipeline.studies.overrides import PRESET_GROUPS, applied_overrides, refuse_controlled
from pipeline.studies.results.tune import TuneResult, TuneSummary
from pipeline.studies.tune.pareto import (
    COMPROMISE_RULE,
    distances_to_ideal,
    front_dominance,
    pareto_mask,
)
from pipeline.studies.tune.search import (
    PRUNING_RULE,
    STORE_FILE,
    Convergence,
    Rungs,
    Runner,
    StudyLoop,
    TunedStudy,
    check_trial_store,
    complete_trials,
    evaluate_in_rungs,
    make_study,
    run_studies_together,
    trial_storage,
)
from pipeline.studies.tune.space import TRACK_OVERRIDES, TuneSpace, default_budget, search_space
from pipeline.studies.workers import Workers, dask_executor

logger = logging.getLogger(__name__)


class NoFeasibleSettingError(StudyError):
    """Every trial of a method collided more often than the untuned control."""


#: How the outcome counts over replicates become a sentence (``tune.settled_test``).
ANSWER_RULE = ("per claim, the tuned outcome (tuned treatment against tuned control on the "
               "replicate's own held-out family) in every replicate, counted; the leading "
               "outcome, held in k of the n judged replicates, settles the claim when a "
               "one-sided exact binomial test against even odds (p-value P(X >= k), X ~ "
               "Binomial(n, 1/2): tune.settled_test = binomial) is at most claims.alpha, "
               "'not settled' otherwise (at alpha 0.05: from 9 of 10, or 5 of 5; fewer than 5 "
               "judged replicates can never settle); a replicate in which a method has no "
               "feasible setting (every trial collided more often than the untuned reference "
               "on its training family) is not judged (not among the n) and counts as 'no "
               "feasible setting of <method>' among the replicates; a "
               "tuning whose budget is below the default preset's, with any replicate's "
               "method stopped by its cap before converging, or with a replicate not judged, is "
               "shown but never writes the opening summary")


def run_tuning(space: TuneSpace, out_dir: Path, overrides: list[str] | None = None,
               log=logger.info, workers: Workers | None = None) -> TuneResult:
    """Tune every replicate until convergence, pick, judge each on its held-out family; the result
    written into ``out_dir`` (its manifest last) and returned. The figures are the command's
    to draw. ``workers``: where the families run (:mod:`pipeline.studies.workers`; this
    machine's pool by default)."""
    out_dir = Path(out_dir)
    workers = workers or Workers()
    if not workers.local and any(o.startswith("hydra/launcher=slurm") for o in overrides or []):
        raise ConfigError("--workers", workers.kind, "local with hydra/launcher=slurm (SLURM "
                          "arrays), or no hydra/launcher=slurm with a Dask cluster "
                          "(dask-slurm:N submits its workers to SLURM itself)")
    spaces = {m: search_space(m) for m in space.methods}
    # an override of what the tune sets itself (methods, families, tuned settings): one line,
    # before anything is written; every other override runs on both sides and is recorded
    refuse_controlled(list(overrides or []), controlled_keys(space, spaces), "tune")
    refuse_other_record(out_dir, ("tune",))
    out_dir.mkdir(parents=True, exist_ok=True)
    # one study per folder at a time (a second is refused in one line), for as long as it runs
    with folder_lock(out_dir, f"tune {space.name}"), contextlib.ExitStack() as stack:
        executor = None
        if not workers.local:
            log(f"families run on {workers.describe()}")
            executor = stack.enter_context(dask_executor(workers, out_dir / "slurm_logs"))
        return _run_tuning(space, out_dir, spaces, list(overrides or []), log, executor)


def _run_tuning(space: TuneSpace, out_dir: Path, spaces: dict, overrides: list[str],
                log, executor=None) -> TuneResult:
    # the trial store checked before anything is written (damaged, read-only, another key)
    store_key = space.store_key(overrides)
    check_trial_store(out_dir / STORE_FILE, space, store_key, log)
    untrust(out_dir)
    clock = CoreClock()
    runner = Runner(space, out_dir, overrides, log)
    runner.executor = executor
    reference = space.feasibility_reference
    # one composition gives the workers' number; they start (and import, about 2 s of both
    # cores) while this process composes the rest, opens the store and makes the studies
    untuned_jobs = [runner.job(reference, "default", {}, "training", 0)]
    n_jobs = untuned_jobs[0].cfg.scenario.family.n_jobs \
        if untuned_jobs[0].cfg.scenario.family is not None else 1
    if runner.local and executor is None:
        from pipeline.studies.family_pool import start_workers

        start_workers(n_jobs)
    untuned_jobs += [runner.job(reference, "default", {}, "training", replicate)
                     for replicate in range(1, space.replicates)]
    base = runner.compose(["method=improved", *space.scenario_overrides("heldout")])
    never = cannot_settle_sentence(space.replicates, float(base.claims.alpha))
    if never:
        # shown, not refused: a small tune is a first look
        log(f"{never}: every claim will read 'not settled'")
    storage = trial_storage(out_dir / STORE_FILE)
    rule, rungs = Convergence.of(space), Rungs.of(space)
    measure = family_measure(space)
    loops = {(replicate, method): StudyLoop(
                 make_study(space, method, replicate, storage, store_key), spaces[method][0],
                 rule, space.batch_size, log, label=f"replicate {replicate}, {method}: ",
                 family_size=space.training_size)
             for replicate in range(space.replicates) for method in space.methods}

    # every replicate's feasibility threshold first: the untuned reference on its training
    # family (the five families in one pool)
    untuned_tables = runner.run(untuned_jobs, "untuned "
                                + ("control" if reference == space.control else reference),
                                "training")
    thresholds: dict[int, int] = {}
    entries: list[TunedStudy] = []
    for replicate, untuned in enumerate(untuned_tables):
        threshold = thresholds[replicate] = Tally.of(untuned).collisions
        log(f"replicate {replicate}: a setting is feasible when its training family (seed "
            f"{space.training_seeds[replicate]}) collides at most {threshold} times (the "
            f"untuned {reference})")
        entries.extend(TunedStudy(replicate, method, loops[replicate, method], threshold)
                       for method in space.methods)
    # a resumed tune's stored trials are checked against the families they came from
    check_stored_trials(runner, entries, measure, out_dir / STORE_FILE)
    coordinator_ms: float | None = None
    if runner.local:
        # every study's batches side by side on one pool: the cores never wait for the
        # parent's asks, compositions and records between batches
        told_before, cpu_before = _complete_in(entries), CoreClock.own_cpu_s()
        run_studies_together(runner, entries, rungs, measure, n_jobs)
        told = _complete_in(entries) - told_before
        if (n_jobs > 1 or executor is not None) and told:  # one local worker: members ran here
            coordinator_ms = 1000.0 * (CoreClock.own_cpu_s() - cpu_before) / told
    else:
        # SLURM: each rung of a batch one array, one study after the other
        for entry in entries:

            def evaluate(settings: list[dict], entry: TunedStudy = entry) -> list[tuple]:
                return evaluate_in_rungs(runner, entry.method, entry.replicate, settings,
                                         entry.threshold, rungs,
                                         rungs.front_at_rungs(entry.loop.study), measure)

            entry.loop.run(evaluate)
    trial_tables, histories = [], []
    for entry in entries:
        history, converged = entry.loop.history, entry.loop.converged
        histories.append({"replicate": entry.replicate, "method": entry.method,
                          "trials": int(len(history)),
                          "members": members_simulated(entry.loop.study),
                          "converged_at": converged, "converged": converged is not None,
                          "hypervolume": [float(v) for v in history]})
        log(f"replicate {entry.replicate}, {entry.method}: "
            + (f"converged at {converged} trials" if converged is not None else
               f"stopped by the cap ({len(history)} trials) before converging")
            + f", hypervolume {history[-1] if len(history) else 0:.4f}")
    for replicate in range(space.replicates):
        trial_tables.append(trials_table({e.method: e.loop.study for e in entries
                                          if e.replicate == replicate}, space, replicate))
    trials = pd.concat(trial_tables, ignore_index=True)
    chosen = pick_settings(trials, space)
    without = replicates_without_setting(trials, space)
    for replicate, methods in sorted(without.items()):
        log(f"replicate {replicate}: {infeasible_outcome(methods)} (every trial collided more "
            f"often than the untuned {space.feasibility_reference}): not judged, counted as such")
    judged = judge_heldout(runner, space, chosen, base.claims)
    log(f"family runs: {runner.counts.sentence()}")
    data = summarize(space, spaces, thresholds, trials, histories, chosen, judged, without,
                     alpha=float(base.claims.alpha))
    data.update(members=runner.counts.to_json(), core_utilisation=clock.utilisation(),
                coordinator_ms_per_trial=coordinator_ms,
                wall_s=round(clock.wall_s(), 1), cores=clock.cores,
                overrides=applied_overrides(overrides), store_key=store_key)
    summary = TuneSummary.from_json(json_safe(data))
    return TuneResult(summary, trials, judged.heldout, judged.default.to_frame(),
                      judged.tuned_frame(), judged.outcomes).write(out_dir)


def check_stored_trials(runner: Runner, entries: list[TunedStudy],
                        measure: Callable[[pd.DataFrame], tuple[list[float], int]],
                        store: Path) -> None:
    """A resumed tune's complete trials against their sources: each one's training family
    (at the members it ran, :class:`~pipeline.studies.tune.search.Runner`'s folder, read back
    through its manifest, or simulated again where it is gone or damaged) gives its objective
    values again, and they must be the stored ones (to 1e-9): an edited store once changed the
    tuned answer without a word.

    Raises
    ------
    StudyError
        A trial whose stored values are not its family's, in one line naming the store, the
        trial and both values.
    """
    import optuna

    stored = [(entry, trial) for entry in entries
              for trial in entry.loop.study.get_trials(deepcopy=False,
                                                       states=(optuna.trial.TrialState.COMPLETE,))]
    if not stored:
        return
    jobs = [runner.job(entry.method, "trial", dict(trial.params), "training", entry.replicate,
                       members=int(trial.user_attrs.get("members",
                                                        runner.space.training_size)))
            for entry, trial in stored]
    tables = runner.run(jobs, f"{len(jobs)} stored trials, checked against their families",
                        "training")
    for (entry, trial), job, table in zip(stored, jobs, tables, strict=True):
        fresh, _ = measure(table)
        kept = [float(v) for v in trial.values]
        if not np.allclose(fresh, kept, rtol=1e-9, atol=1e-12, equal_nan=True):
            raise StudyError(
                f"{store}: trial {trial.number} of replicate {entry.replicate}, "
                f"{entry.method} holds objective values {kept} but its training family "
                f"({job.folder}) gives {[float(v) for v in fresh]}: the store was edited or "
                "damaged; remove it to tune again (the families are kept and reused)")


def family_measure(space: TuneSpace) -> Callable[[pd.DataFrame], tuple[list[float], int]]:
    """The function a trial's family table is judged by: its objective values (the tuning
    table, :func:`~pipeline.analysis.objectives.tuning_table`) and its collision count.
    Only the columns these read are copied (the parent measures every rung of every trial)."""
    read = {"collision", "duration_s", *(o.metric for o in space.objectives),
            *(c for start_flag in CENSORED_AT_RUN_END.values() for c in start_flag)}

    def measure(table: pd.DataFrame) -> tuple[list[float], int]:
        fast = _measured_in_numpy(table, space)
        if fast is not None:
            return fast
        narrow = table[[c for c in table.columns if c in read]]
        return (list(objective_values(tuning_table(narrow, space.censoring), space.objectives)),
                int(collided(narrow).sum()))

    return measure


def _measured_in_numpy(table: pd.DataFrame, space: TuneSpace
                       ) -> tuple[list[float], int] | None:
    """:func:`family_measure`'s values with numpy on the columns' arrays (a table made in
    memory: boolean flags, numeric metrics; a tenth of pandas' time, the same numbers); None
    for a table whose flags are not booleans or whose metrics are not numbers (pandas' path
    reads them). Numbers are read as the family's table on disk holds them
    (:func:`~pipeline.store.files.as_written`): a rung measured from memory and one read
    back from its record give the same values."""
    def array(name: str) -> np.ndarray | None:
        if name not in table:
            return None
        values = table[name].to_numpy()
        return as_written(values) if values.dtype.kind == "f" else values

    collision = array("collision")
    if collision is not None and collision.dtype != bool:
        return None
    kept = ~collision if collision is not None else np.ones(len(table), bool)
    duration = array("duration_s")
    values = []
    for objective in space.objectives:
        column = array(objective.metric)
        if column is None:
            values.append(objective_value(np.zeros(0), objective))
            continue
        if column.dtype.kind not in "fiu":
            return None
        column = column.astype(float)
        censored = CENSORED_AT_RUN_END.get(objective.metric)
        if space.censoring == "run_end" and duration is not None and censored is not None \
                and censored[0] in table:
            begun, flag = array(censored[0]), array(censored[1])
            if begun is None:
                return None
            if duration.dtype.kind not in "fiu" or begun.dtype.kind not in "fiu" or (
                    flag is not None and flag.dtype != bool):
                return None
            missed = np.isnan(column) & ~np.isnan(begun.astype(float))
            if flag is not None:
                missed &= ~flag
            column = np.where(missed, duration.astype(float) - begun, column)
        values.append(objective_value(column[kept], objective))
    return values, int(collision.sum()) if collision is not None else 0


def controlled_keys(space: TuneSpace, spaces: dict) -> dict[str, str]:
    """The config keys the tune sets in its runs, each with what to do instead of overriding
    it (:func:`pipeline.studies.overrides.refuse_controlled`)."""
    keys = dict(PRESET_GROUPS)
    keys.update({
        "scenario.family.seed": "no override: the tune sets its families' seeds (the space's "
                                "training_seed and heldout_seed: --set training_seed=N)",
        "scenario.family.size": "no override: the tune sets its families' sizes (the space's "
                                "training_size and heldout_size: --set training_size=N)",
        "controller.backend": "no override: the tune sets its runs' QP backend (the space's "
                              "backend and heldout_backend: --set backend=NAME)",
        "claims.treatment": "no override: the tune compares its space's methods "
                            "(--set 'methods=[treatment, control]')",
        "claims.controls": "no override: the tune compares its space's methods "
                           "(--set 'methods=[treatment, control]')",
        "tune": "no override: the tune's settings are its space file's (--space, --set "
                "key=value)"})
    if space.parts_key is not None:  # the source's parts (the pedestrians' scenes)
        keys[space.parts_key] = ("no override: the tune sets each part's scenes (the space's "
                                 "training_scenes and heldout_scenes)")
    for override in TRACK_OVERRIDES[space.track]:
        keys.setdefault(override.split("=", 1)[0], f"no override: the tune's track "
                        f"({space.track}) sets it (the space's track)")
    for method in space.methods:
        for key in spaces[method][1]:
            keys.setdefault(key, f"no override: {key} is tuned (conf/hparams_search/"
                                 f"{method}.yaml)")
    return keys


class CoreClock:
    """CPU-seconds over (wall-clock seconds x cores) since it was made, of this process and
    of its worker processes (joblib's workers are shut down first, so that the kernel has
    counted their time). Workers left running by earlier work of the process (a benchmark's
    families before its tune) are shut down when the clock starts: the kernel adds a child's
    whole life to its parent's count when it ends, so their earlier work would count here."""

    def __init__(self) -> None:
        import os
        import time

        from pipeline.studies.family_pool import stop_workers

        stop_workers()
        self.start_wall = time.perf_counter()
        self.start_cpu = self._cpu()
        self.cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") \
            else (os.cpu_count() or 1)

    @staticmethod
    def own_cpu_s() -> float:
        """This process's CPU-seconds (user and system), without its workers'."""
        import resource

        own = resource.getrusage(resource.RUSAGE_SELF)
        return own.ru_utime + own.ru_stime

    @staticmethod
    def _cpu() -> float:
        import resource

        own = resource.getrusage(resource.RUSAGE_SELF)
        children = resource.getrusage(resource.RUSAGE_CHILDREN)
        return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime

    def wall_s(self) -> float:
        """Wall-clock seconds since it was made."""
        import time

        return time.perf_counter() - self.start_wall

    def utilisation(self) -> float:
        import time

        from pipeline.studies.family_pool import stop_workers

        stop_workers()
        wall = time.perf_counter() - self.start_wall
        return (self._cpu() - self.start_cpu) / max(wall * self.cores, 1e-9)


def _complete_in(entries: list[TunedStudy]) -> int:
    """The complete trials of every study of ``entries``."""
    return sum(complete_trials(e.loop.study) for e in entries)


def members_simulated(study) -> int:
    """The training members a method's trials ran in one replicate (every rung counted once:
    a later rung resumes the earlier one's members)."""
    from optuna.trial import TrialState

    return int(sum(int(t.user_attrs.get("members", 0))
                   for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))))


def trials_table(studies: dict, space: TuneSpace, replicate: int) -> pd.DataFrame:
    """Every complete trial of every method in one replicate: parameters, training objectives,
    collisions over the threshold, feasibility and Pareto membership."""
    from optuna.trial import TrialState

    rows = []
    for method, study in studies.items():
        complete = sorted(study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)),
                          key=lambda t: t.number)
        # a trial's number among its study's complete trials: the numbers of an uninterrupted
        # tune, also after a resume (whose interrupted batch left failed trials in the store)
        for rank, trial in enumerate(complete):
            row = {"replicate": replicate, "method": method, "trial": rank,
                   "constraint": float(trial.user_attrs.get("constraint", 0.0)),
                   "members": int(trial.user_attrs.get("members", space.training_size)),
                   "pruned_at": trial.user_attrs.get("pruned_at"),
                   "params": json.dumps(trial.params, sort_keys=True)}
            row.update({f"train:{o.label}": v
                        for o, v in zip(space.objectives, trial.values, strict=True)})
            rows.append(row)
    table = pd.DataFrame(rows)
    columns = [f"train:{o.label}" for o in space.objectives]
    table["feasible"] = (table["constraint"] <= 0.0) & np.isfinite(
        table[columns].to_numpy(float)).all(axis=1) & table["pruned_at"].isna()
    table["pareto"] = False
    for method in space.methods:
        part = table[(table["method"] == method) & table["feasible"]]
        if len(part):
            mask = pareto_mask(part[columns].to_numpy(), space.objectives)
            table.loc[part.index[mask], "pareto"] = True
    return table


def replicates_without_setting(trials: pd.DataFrame, space: TuneSpace) -> dict[int, list[str]]:
    """Per replicate, the methods with no feasible setting in it (no Pareto trial: every
    complete trial collided more often than the untuned reference, or was pruned); replicates
    where every method has one are left out."""
    out: dict[int, list[str]] = {}
    for replicate, part in trials.groupby("replicate", sort=True):
        missing = [m for m in space.methods
                   if not ((part["method"] == m) & part["pareto"]).any()]
        if missing:
            out[int(replicate)] = missing
    return out


def infeasible_outcome(methods: list[str]) -> str:
    """The outcome a replicate that could not be judged counts as."""
    return "no feasible setting of " + " and ".join(methods)


def pick_settings(trials: pd.DataFrame, space: TuneSpace) -> dict[tuple[int, str], pd.DataFrame]:
    """Per replicate and method, the Pareto settings to judge on held-out scenarios (closest to
    the ideal first, at most ``max_heldout_settings``) with the compromise marked. A replicate
    in which a method has no feasible setting is left out (:func:`replicates_without_setting`);
    :class:`NoFeasibleSettingError` when that leaves none."""
    columns = [f"train:{o.label}" for o in space.objectives]
    without = replicates_without_setting(trials, space)
    replicates = sorted(int(r) for r in trials["replicate"].unique())
    if all(r in without for r in replicates):
        detail = "; ".join(f"replicate {r}: {', '.join(m)}" for r, m in sorted(without.items()))
        raise NoFeasibleSettingError(
            f"no replicate has a feasible setting of every method ({detail}): every trial "
            f"collided more often than the untuned {space.feasibility_reference}; widen the "
            "search space or raise tune.max_trials")
    chosen = {}
    for replicate, part in trials.groupby("replicate", sort=True):
        if int(replicate) in without:
            continue
        scale = part[part["feasible"]][columns].to_numpy(float)
        for method in space.methods:
            front = part[(part["method"] == method) & part["pareto"]].copy()
            front["distance_to_ideal"] = distances_to_ideal(front[columns].to_numpy(float),
                                                            scale, space.objectives)
            front = front.sort_values(["distance_to_ideal", "trial"])
            front["compromise"] = np.arange(len(front)) == 0
            chosen[(int(replicate), method)] = front.head(space.max_heldout_settings)
    return chosen


def _matched_params(control: dict, treatment: dict) -> dict:
    """The look-ahead-matched control from the tuned control: its normalized step as long as
    the tuned treatment's step cap (or step, when it has no cap)."""
    params = {k: v for k, v in control.items() if k != "planner.step_size"}
    step = treatment.get("planner.step_max_m", treatment.get("planner.step_size"))
    if step is not None:
        params["planner.step_size"] = step
    return params


def is_peer(cfg) -> bool:
    """Whether a composed config runs one of the methods the paper names (a planner or a
    controller of :mod:`pipeline.peers`, chosen by ``_target_``): no APF, no repulsive force."""
    return any(str(getattr(section, "_target_", None) or "").startswith("pipeline.peers.")
               for section in (cfg.planner, cfg.controller))


def without_force_claims(ledger: Ledger) -> Ledger:
    """``ledger`` without C3a/C3b (:data:`FORCE_CLAIMS`), as the report's peers ledger: a peer
    has no repulsive force to time."""
    return ledger.without_claims(FORCE_CLAIMS)


def _ledger_maker(claims_cfg, treatment: str, peer: bool) -> Callable[..., Ledger]:
    """``family_ledger`` of the treatment against ``names``; against a peer without the force
    claims and with each run's own C2 window (the report's peers ledger)."""
    if peer:
        claims_cfg = dataclasses.replace(claims_cfg, c2_window="own")

    def ledger_of(tables: dict, names: tuple, **kwargs) -> Ledger:
        ledger = family_ledger(tables, claims_cfg, None, treatment, names, **kwargs)
        return without_force_claims(ledger) if peer else ledger

    return ledger_of


class Judged:
    """The held-out judgement: the table of judged settings, the untuned ledger, one tuned
    ledger per replicate and the outcomes of every judged treatment setting."""

    def __init__(self, heldout: pd.DataFrame, default: Ledger, tuned: dict[int, Ledger],
                 outcomes: pd.DataFrame) -> None:
        self.heldout, self.default, self.tuned, self.outcomes = heldout, default, tuned, outcomes

    def tuned_frame(self) -> pd.DataFrame:
        frames = [ledger.to_frame().assign(replicate=r) for r, ledger in self.tuned.items()]
        return pd.concat(frames, ignore_index=True)


def judge_heldout(runner: Runner, space: TuneSpace, chosen: dict[tuple[int, str], pd.DataFrame],
                  claims_cfg) -> Judged:
    """Held-out families of the untuned methods (replicate 0's family), every chosen Pareto
    setting and each replicate's tuned matched control (each on its replicate's own held-out
    family); the default ledger, a tuned ledger per replicate, and per judged treatment
    setting its outcomes against its replicate's tuned control (always on the same family:
    the pairs are the same scenarios).

    Against a peer (:func:`is_peer`) the ledgers are the report's peers ledger's: without the
    APF force claims (C3a/C3b) and with each run's own C2 window."""
    treatment, control = space.treatment, space.control
    matched = space.matched_control
    comparisons = (control,) + ((matched,) if matched else ())
    jobs = [runner.job(m, "default", {}, "heldout") for m in (treatment,) + comparisons]
    ledger_of = _ledger_maker(claims_cfg, treatment, is_peer(jobs[1].cfg))
    compromise: dict[tuple[int, str], int] = {}
    params_of: dict[tuple[int, str, int], dict] = {}
    for (replicate, method), front in chosen.items():
        for r in front.to_dict("records"):
            params = json.loads(r["params"])
            params_of[(replicate, method, int(r["trial"]))] = params
            jobs.append(runner.job(method, f"trial {r['trial']}", params, "heldout", replicate))
            if r["compromise"]:
                compromise[(replicate, method)] = int(r["trial"])
    replicates = sorted({r for r, _ in chosen})
    if matched:
        for replicate in replicates:
            jobs.append(runner.job(matched, "tuned", _matched_params(
                params_of[(replicate, control, compromise[(replicate, control)])],
                params_of[(replicate, treatment, compromise[(replicate, treatment)])]),
                "heldout", replicate))
    tables = runner.run(jobs, "held-out families")
    by_setting = {(j.replicate, j.method, j.setting): t for j, t in zip(jobs, tables, strict=True)}
    rows = []
    for job, table in zip(jobs, tables, strict=True):
        values = objective_values(tuning_table(table, space.censoring), space.objectives)
        tally = Tally.of(table)
        trial = int(job.setting.split()[1]) if job.setting.startswith("trial") else None
        rows.append({"replicate": job.replicate, "method": job.method, "setting": job.setting,
                     "trial": trial,
                     "compromise": trial is not None
                     and compromise.get((job.replicate or 0, job.method)) == trial,
                     "collisions": tally.collisions, "scenarios": tally.scenarios,
                     # the replicate's own held-out family (the untuned: replicate 0's)
                     "family_seed": space.heldout_seed_of(job.replicate or 0),
                     **{f"heldout:{o.label}": v
                        for o, v in zip(space.objectives, values, strict=True)},
                     "folder": str(job.folder.relative_to(runner.out_dir))})
    heldout = pd.DataFrame(rows)
    # the ledgers (bootstrap intervals: the parent's last serial step) side by side on the
    # families' workers: the default one, a tuned one per replicate, one per judged setting
    tuned_tables = {}
    for replicate in replicates:
        tuned_tables[replicate] = {
            m: by_setting[(replicate, m, f"trial {compromise[(replicate, m)]}")]
            for m in (treatment, control)}
        if matched:
            tuned_tables[replicate][matched] = by_setting[(replicate, matched, "tuned")]
    judged_settings = [(replicate, r) for replicate in replicates
                       for r in chosen[(replicate, treatment)].to_dict("records")]
    asked: list[tuple[dict, tuple, dict]] = [
        ({m: by_setting[(None, m, "default")] for m in (treatment,) + comparisons},
         comparisons, {})]
    asked += [(tuned_tables[replicate], comparisons, {}) for replicate in replicates]
    asked += [({treatment: by_setting[(replicate, treatment, f"trial {r['trial']}")],
                control: tuned_tables[replicate][control]}, (control,), {"sensitivity": False})
              for replicate, r in judged_settings]
    family = jobs[0].cfg.scenario.family
    ledgers = _ledgers_side_by_side(
        ledger_of, asked, family.n_jobs if runner.local and family is not None else 1)
    default = ledgers[0]
    tuned = dict(zip(replicates, ledgers[1:1 + len(replicates)], strict=True))
    outcome_rows = [{"replicate": replicate, "trial": r["trial"],
                     "compromise": bool(r["compromise"]), "claim": row.claim_id,
                     "outcome": str(row.outcome), "estimate": row.result.estimate,
                     "params": r["params"]}
                    for (replicate, r), ledger in zip(judged_settings,
                                                      ledgers[1 + len(replicates):], strict=True)
                    for row in ledger]
    return Judged(heldout, default, tuned, pd.DataFrame(outcome_rows))


def _ledgers_side_by_side(ledger_of: Callable[..., Ledger],
                          asked: list[tuple[dict, tuple, dict]], n_jobs: int) -> list[Ledger]:
    """``ledger_of(tables, names, **kwargs)`` for each of ``asked``, in order, on ``n_jobs``
    of joblib's reusable workers (the families' own; here with one job). A ledger is a pure
    function of its tables (seeded bootstraps): the same ledgers wherever it runs."""
    if n_jobs <= 1 or len(asked) <= 1:
        return [ledger_of(tables, names, **kwargs) for tables, names, kwargs in asked]
    from joblib import Parallel, delayed

    return list(Parallel(n_jobs=n_jobs)(delayed(ledger_of)(tables, names, **kwargs)
                                        for tables, names, kwargs in asked))


def counts_in_words(outcomes: list[str]) -> tuple[str, tuple[str, int]]:
    """``"supported 4/5, inconclusive 1/5"`` (most frequent first) and the most frequent
    outcome with its count."""
    counts = pd.Series(outcomes, dtype=object).value_counts()
    order = sorted(counts.items(), key=lambda kv: (-kv[1], str(kv[0])))
    words = ", ".join(f"{outcome} {count}/{len(outcomes)}" for outcome, count in order)
    return words, (str(order[0][0]), int(order[0][1]))


def binomial_p_value(count: int, judged: int) -> float:
    """The one-sided exact binomial test of ``count`` successes in ``judged`` trials against
    even odds: P(X >= count) for X ~ Binomial(judged, 1/2) (scipy's ``binomtest``,
    alternative 'greater')."""
    from scipy.stats import binomtest

    return float(binomtest(int(count), int(judged), 0.5, alternative="greater").pvalue)


def fewest_replicates_to_settle(alpha: float) -> int:
    """The fewest judged replicates with which an outcome can settle a claim at ``alpha``:
    the smallest n whose best case, n of n alike (p = 2^-n), is significant."""
    n = 1
    while 0.5 ** n > alpha:
        n += 1
    return n


def cannot_settle_sentence(replicates: int, alpha: float) -> str:
    """Why ``replicates`` (judged) replicates can never settle a claim at ``alpha`` ("" when
    they can)."""
    fewest = fewest_replicates_to_settle(alpha)
    if replicates >= fewest:
        return ""
    return (f"{replicates} replicates can never settle a claim at alpha {alpha:g}: even "
            f"{replicates} of {replicates} alike gives p = {0.5 ** replicates:.3g} (one-sided "
            f"binomial); at least {fewest} are needed")


@dataclass(frozen=True)
class Settlement:
    """One claim's tuned outcomes over the replicates, settled or not (:data:`ANSWER_RULE`):
    the sentence, whether it is settled and on which outcome, the leading outcome among the
    judged replicates with its count, their number, and the binomial test's p-value (None
    when no replicate was judged)."""

    sentence: str
    settled: bool
    outcome: str | None
    leading: str
    count: int
    judged: int
    p_value: float | None


def answer_in_counts(claim_id: str, outcomes: list[str], alpha: float,
                     judged: list[bool] | None = None) -> Settlement:
    """The tuned answer on one claim over replicates (see :data:`ANSWER_RULE`): the leading
    outcome among the judged replicates (``judged``: one flag per outcome, by default all)
    settles the claim when :func:`binomial_p_value` of its count among them is at most
    ``alpha``."""
    flags = [True] * len(outcomes) if judged is None else list(judged)
    words = counts_in_words(outcomes)[0]
    among = [o for o, j in zip(outcomes, flags, strict=True) if j]
    if not among:
        return Settlement(f"{claim_id}: {words}: not settled (no replicate judged).", False,
                          None, "", 0, 0, None)
    top, count = counts_in_words(among)[1]
    n = len(among)
    p_value = binomial_p_value(count, n)
    settled = p_value <= alpha
    test = (f"{top} in {count} of {n} judged replicates, one-sided binomial p = "
            f"{p_value:.3g} {'<=' if settled else '>'} alpha {alpha:g}")
    if settled:
        return Settlement(f"{claim_id}: {words}: settled ({test}).", True, top, top, count, n,
                          p_value)
    fewest = fewest_replicates_to_settle(alpha)
    never = (f"; {n} judged replicates can never settle at alpha {alpha:g}: at least {fewest} "
             "are needed") if n < fewest else ""
    return Settlement(f"{claim_id}: {words}: not settled ({test}{never}).", False, None, top,
                      count, n, p_value)


def artefact_sentence(claim_id: str, default: str, settled: str | None, counts: str,
                      n_heldout: int) -> str:
    """Whether a claim's default verdict (against the control, on replicate 0's held-out
    family) was a tuning artefact, read off the replicates' counts (each on its own held-out
    family of ``n_heldout`` scenarios)."""
    where = f"on held-out scenarios ({n_heldout} per replicate)"
    if settled is None:
        return (f"{claim_id} {where}: {default} with our settings; when both methods are tuned "
                f"by the same rules the replicates disagree ({counts}): not settled.")
    if settled == default:
        return (f"{claim_id} {where}: {default} with our settings and {settled} when both "
                f"methods are tuned by the same rules ({counts}): not a tuning artefact.")
    return (f"{claim_id} {where}: {default} with our settings but {settled} when both methods "
            f"are tuned by the same rules ({counts}): the default verdict was a tuning "
            "artefact.")


def front_points(trials: pd.DataFrame, heldout: pd.DataFrame, space: TuneSpace, part: str,
                 replicate: int = 0) -> dict[str, np.ndarray]:
    """Per method, one replicate's Pareto settings' objective values on the training or
    held-out family."""
    out = {}
    for method in space.methods:
        if part == "training":
            rows = trials[(trials["method"] == method) & trials["pareto"]
                          & (trials["replicate"] == replicate)]
            out[method] = rows[[f"train:{o.label}" for o in space.objectives]].to_numpy(float)
        else:
            rows = heldout[(heldout["method"] == method) & heldout["trial"].notna()
                           & (heldout["replicate"] == replicate)]
            out[method] = rows[[f"heldout:{o.label}" for o in space.objectives]].to_numpy(float)
    return out


def summarize(space: TuneSpace, spaces: dict, thresholds: dict[int, int], trials: pd.DataFrame,
              histories: list[dict], chosen: dict[tuple[int, str], pd.DataFrame],
              judged: Judged, without: dict[int, list[str]] | None = None,
              alpha: float = 0.05) -> dict[str, Any]:
    """``summary.json``: the rules, the spaces, per replicate and method the trials, the
    convergence and the hypervolume history, and per claim the default verdict beside the
    tuned outcome of every replicate, counted and settled or not by the binomial test at
    ``alpha`` (the claims' ``alpha``)."""
    control, matched = space.control, space.matched_control
    without = without or {}
    claims = []
    n_replicates = len(judged.tuned)
    # every replicate, in order: the judged ones' ledgers, the others' missing methods
    order = sorted(set(judged.tuned) | set(without))
    for claim in ALL_CLAIMS:
        default = judged.default.get((claim.claim_id, control))
        judged_rows = [judged.tuned[r].get((claim.claim_id, control)) for r in sorted(judged.tuned)]
        if default is None or any(row is None for row in judged_rows):
            continue
        per_replicate = [judged.tuned[r].get((claim.claim_id, control)) if r in judged.tuned
                         else None for r in order]
        outcomes = [str(row.outcome) if row is not None else infeasible_outcome(without[r])
                    for r, row in zip(order, per_replicate, strict=True)]
        settlement = answer_in_counts(claim.claim_id, outcomes, alpha,
                                      [r in judged.tuned for r in order])
        settled, settled_outcome = settlement.settled, settlement.outcome
        counts = counts_in_words(outcomes)[0]
        vs_matched = [str(judged.tuned[r][(claim.claim_id, matched)].outcome)
                      for r in sorted(judged.tuned)
                      if matched and judged.tuned[r].get((claim.claim_id, matched))]
        holds = judged.outcomes[(judged.outcomes["claim"] == claim.claim_id)
                                & (judged.outcomes["outcome"] == "supported")] \
            if len(judged.outcomes) else judged.outcomes
        claims.append({
            "claim": claim.claim_id, "text": claim.text, "metric": claim.primary_metric,
            "default": str(default.outcome), "default_estimate": default.result.estimate,
            "tuned_outcomes": outcomes,
            "tuned_estimates": [row.result.estimate if row else None
                                for row in per_replicate],
            "tuned_cis": [[row.result.ci_low, row.result.ci_high] if row else [None, None]
                          for row in per_replicate],
            "counts": counts, "settled": settled, "tuned": settled_outcome or "not settled",
            "answer": settlement.sentence, "leading": settlement.leading,
            "leading_count": settlement.count, "judged_replicates": settlement.judged,
            "p_value": settlement.p_value, "tuned_vs_matched": vs_matched,
            "holds_with_trials": [[int(r), int(t)] for r, t in
                                  zip(holds["replicate"], holds["trial"], strict=True)]
            if len(holds) else [],
            "sentence": artefact_sentence(claim.claim_id, str(default.outcome),
                                          settled_outcome, counts, space.heldout_size)})
    reference = default_budget()
    short = space.below_budget(reference)
    unconverged = [f"replicate {h['replicate']} {h['method']}" for h in histories
                   if not h["converged"]]
    parity = []
    for method in space.methods:
        rows = trials[trials["method"] == method]
        mine = [h for h in histories if h["method"] == method]
        parity.append({"method": method, "dimensions": len(spaces[method][0]),
                       "trials": [h["trials"] for h in mine],
                       "members": [h.get("members") for h in mine],
                       "pruned_share": float(rows["pruned_at"].notna().mean())
                       if len(rows) else 0.0,
                       # of the trials that ran their whole training family
                       "feasible_share": float(rows.loc[rows["pruned_at"].isna(), "feasible"]
                                               .mean()) if rows["pruned_at"].isna().any()
                       else 0.0,
                       "converged": [h["converged"] for h in mine],
                       "converged_at": [h["converged_at"] for h in mine]})
    compromise: dict[str, dict[str, dict]] = {}
    for (replicate, method), front in chosen.items():
        compromise.setdefault(method, {})[str(replicate)] = json.loads(
            front.loc[front["compromise"], "params"].iloc[0])
    return {
        "name": space.name, "settings": json_safe(asdict(space)),
        "budget": {"replicates": space.replicates, "min_trials": space.min_trials,
                   "max_trials": space.max_trials, "window": space.convergence_window,
                   "tolerance": space.convergence_tolerance,
                   "hypervolume_bounds": space.hypervolume_bounds,
                   "sampler": "NSGA-II (optuna)", "sampler_seeds": [
                       space.sampler_seed_of(r) for r in range(space.replicates)],
                   "population_size": space.population_size, "batch_size": space.batch_size,
                   "censoring": space.censoring, "rungs": list(space.rungs),
                   "prune_gain": space.prune_gain,
                   "prune_after_trials": space.prune_after_trials},
        "families": {"training": {"seeds": space.training_seeds, "size": space.training_size,
                                  "track": space.track},
                     # replicate r's on seeds[r]; the untuned methods on seed (replicate 0's)
                     "heldout": {"seed": space.heldout_seed, "seeds": space.heldout_seeds,
                                 "stride": space.heldout_seed_stride,
                                 "size": space.heldout_size, "track": space.track}},
        "backend": space.backend,
        "objectives": [o.label + f" ({o.direction})" for o in space.objectives],
        "safety_threshold_collisions": {str(k): v for k, v in thresholds.items()},
        "search_spaces": {m: spaces[m][1] for m in space.methods},
        "compromise_rule": COMPROMISE_RULE, "answer_rule": ANSWER_RULE,
        "settle_test": space.settled_test, "settle_alpha": float(alpha),
        "fewest_replicates_to_settle": fewest_replicates_to_settle(alpha),
        "pruning_rule": PRUNING_RULE if space.rungs else "",
        "compromise": compromise,
        "replicates": histories, "parity": parity,
        "below_default_budget": short, "unconverged": unconverged,
        "without_feasible_setting": {str(r): m for r, m in sorted(without.items())},
        "headline": not short and not unconverged and n_replicates == space.replicates,
        "dominance": {part: front_dominance(*_fronts(trials, judged.heldout, space, part),
                                            space.objectives)
                      for part in ("training", "heldout")},
        "claims": claims}


def _fronts(trials: pd.DataFrame, heldout: pd.DataFrame, space: TuneSpace, part: str
            ) -> tuple[np.ndarray, np.ndarray]:
    """Both methods' Pareto points pooled over the replicates."""
    replicates = sorted(trials["replicate"].unique())
    points = [front_points(trials, heldout, space, part, int(r)) for r in replicates]
    return (np.vstack([p[space.treatment] for p in points]),
            np.vstack([p[space.control] for p in points]))
