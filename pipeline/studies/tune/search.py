"""The tuning loop: one Optuna study per replicate and method, asked in batches until its
front's hypervolume has converged or the cap is reached; families composed and run here or on
SLURM, resumed by config hash."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.config import ExperimentConfig
from pipeline.store.runs import read_family
from pipeline.studies.tune.pareto import convergence_point, hypervolume_history
from pipeline.studies.tune.space import TuneSpace

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

    def history(self, study) -> np.ndarray:
        """The hypervolume after each complete trial, in trial order."""
        values, feasible = study_values(study)
        if not len(values):
            return np.zeros(0)
        return hypervolume_history(values, feasible, [list(b) for b in self.bounds])

    def stop_at(self, history: np.ndarray) -> int | None:
        return convergence_point(history, self.min_trials, self.window, self.tolerance)


def study_values(study) -> tuple[np.ndarray, np.ndarray]:
    """The complete trials' objective values (rows in trial order) and feasibility."""
    from optuna.trial import TrialState

    trials = sorted(study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)),
                    key=lambda t: t.number)
    values = np.array([list(t.values) for t in trials], float)
    feasible = np.array([float(t.user_attrs.get("constraint", 0.0)) <= 0.0 for t in trials],
                        bool)
    return values, feasible


def optimize(study, distributions: dict, evaluate: Callable[[list[dict]], list[tuple]],
             rule: Convergence, batch_size: int, log=logger.info, label: str = ""
             ) -> tuple[np.ndarray, int | None]:
    """Run ``study`` until its hypervolume has converged (:class:`Convergence`) or it holds
    ``rule.max_trials`` complete trials, ``batch_size`` at a time; return the hypervolume
    history and the trial count at which it converged (None: stopped by the cap).

    ``evaluate`` takes a list of parameter dicts and returns, per setting, ``(values,
    constraint)``: the objective values and the safety constraint (<= 0 feasible). A trial
    left running by an interrupted process is closed as failed and its parameters are asked
    again first (their finished families are read back, not simulated). A resumed study that
    had converged stops where it converged.
    """
    from optuna.trial import TrialState

    for trial in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
        study.tell(trial.number, state=TrialState.FAIL)
        study.enqueue_trial(dict(trial.params))
    start, done_before = time.perf_counter(), None
    while True:
        history = rule.history(study)
        complete = len(history)
        done_before = complete if done_before is None else done_before
        converged = rule.stop_at(history)
        if converged is not None or complete >= rule.max_trials:
            return history, converged
        batch = [study.ask() for _ in range(min(batch_size, rule.max_trials - complete))]
        settings = [{name: trial._suggest(name, dist) for name, dist in distributions.items()}
                    for trial in batch]
        for trial, (values, constraint) in zip(batch, evaluate(settings), strict=True):
            trial.set_user_attr("constraint", float(constraint))
            study.tell(trial, list(values))
        complete += len(batch)
        rate = (time.perf_counter() - start) / max(complete - done_before, 1)
        log(f"{label}trials {complete} (converged at the earliest at {rule.min_trials}, cap "
            f"{rule.max_trials}; {rate:.1f} s per trial)")


def _constraint(trial) -> list[float]:
    """Optuna's constraints_func: the safety constraint the evaluation stored (<= 0 feasible)."""
    return [float(trial.user_attrs.get("constraint", 0.0))]


def make_study(space: TuneSpace, method: str, replicate: int, storage: str | None):
    """The NSGA-II study of one method in one replicate (its own sampler seed), named by the
    space's trial key so that an edited space never resumes another's trials."""
    import warnings

    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    with warnings.catch_warnings():
        # constraints_func is marked experimental in optuna 2.10 (pinned); it is what we need
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        sampler = optuna.samplers.NSGAIISampler(population_size=space.population_size,
                                                seed=space.sampler_seed_of(replicate),
                                                constraints_func=_constraint)
    return optuna.create_study(
        study_name=f"{space.name}-{space.trial_key()}-r{replicate}-{method}", storage=storage,
        sampler=sampler, load_if_exists=True, directions=[o.direction for o in space.objectives])


def _override(name: str, value) -> str:
    return f"{name}={value!r}" if isinstance(value, float) else f"{name}={value}"


@dataclass(frozen=True)
class FamilyJob:
    """One family to run: its config and folder, and the settings it stands for."""

    method: str
    setting: str
    cfg: ExperimentConfig
    folder: Path
    replicate: int | None = None


class Runner:
    """Composes family configs and runs them (here or on SLURM), resuming by config hash."""

    def __init__(self, space: TuneSpace, out_dir: Path, overrides: list[str], log) -> None:
        from pipeline.loop.controller import QpCache
        from pipeline.studies.compose import composer

        self.space, self.out_dir, self.log = space, Path(out_dir), log
        self.compose, self.launcher = composer(list(overrides))
        self.cache = QpCache()

    def job(self, method: str, setting: str, params: dict, part: str,
            replicate: int | None = None) -> FamilyJob:
        if part == "training":
            seed, size = self.space.training_seeds[replicate or 0], self.space.training_size
        else:
            seed, size = self.space.heldout_seed, self.space.heldout_size
        cfg = self.compose([f"method={method}", "scenario=family",
                            f"scenario.family.seed={seed}", f"scenario.family.size={size}",
                            f"controller.backend={self.space.backend}"]
                           + [_override(k, v) for k, v in params.items()])
        return FamilyJob(method, setting, cfg, self.out_dir / "runs" / part / method
                         / cfg.config_hash(), replicate)

    def run(self, jobs: list[FamilyJob], label: str) -> list[pd.DataFrame]:
        from pipeline.store.manifest import check
        from pipeline.studies.multiverse.runs import run_families

        todo, seen = [], set()
        for job in jobs:
            if job.folder not in seen and check(job.folder, "family", job.cfg.config_hash(),
                                                members=False) is not None:
                todo.append((job.cfg, job.folder))
                seen.add(job.folder)
        run_families(todo, self.out_dir, self.log, self.launcher, self.cache, label)
        return [read_family(job.folder, members=False, settings=False).table for job in jobs]
