"""A fair fight: every compared method tuned with the same budget on training scenarios, then
judged on held-out ones (``make tune``, ``python -m pipeline.tune``).

Benchmarking practice (Lucic et al. 2018; Melis et al. 2018) tunes every contender with the same
effort and judges on data the tuning never saw: differences that vanish under equal tuning were
tuning, not method. Here:

1. **Budget.** Each method of ``conf/tune/<name>.yaml`` gets the same number of Optuna trials,
   the same sampler (NSGA-II) and the same sampler seed, over its own search space
   (``conf/hparams_search/<method>.yaml``, the ranges the paper allows, each with its reason).
2. **Training.** A trial runs a *training* family (its own seed) and returns the objectives
   (statistics of the claims' primary metrics, :mod:`pipeline.analysis.objectives`). Safety is a
   constraint: a setting whose family collides more often than the untuned baseline's is
   infeasible (Optuna's ``constraints_func``).
3. **Pareto sets.** The feasible non-dominated trials of each method, and one best-compromise
   setting per method by the rule in config (``closest_to_ideal``: the smallest Euclidean
   distance to the ideal point after min-max scaling of every objective over both methods'
   feasible trials, one scale for both).
4. **Held-out judgement.** The Pareto settings (at most ``max_heldout_settings`` per method,
   closest to the ideal first) and the compromises run on a *held-out* family (another seed);
   the claims ledger compares the tuned treatment with the tuned control and with the
   look-ahead-matched control built from it, beside the same ledger for the untuned methods on
   the same held-out scenarios.

Trials live in an SQLite file in the output folder: an interrupted tuning resumes without
repeating a completed trial (a trial cut off mid-run is re-run with the same parameters; its
finished families are read back, never simulated again). Families run here or, with
``hydra/launcher=slurm``, as SLURM arrays.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, List

import numpy as np
import pandas as pd

from pipeline.analysis.claims import ALL_CLAIMS, Ledger, family_ledger
from pipeline.analysis.objectives import Objective, objective_values
from pipeline.analysis.tally import Tally
from pipeline.config import CONF_DIR, ExperimentConfig, schema_from_data
from pipeline.errors import ConfigError, StudyError
from pipeline.store.files import json_safe
from pipeline.store.manifest import untrust
from pipeline.store.runs import read_family
from pipeline.studies.results.tune import TuneResult, TuneSummary
from pipeline.validation import choice, safe_name

logger = logging.getLogger(__name__)

#: The rule that picks one setting per method from its Pareto set.
COMPROMISE_RULE = ("closest_to_ideal: among the method's feasible Pareto settings, the one with "
                   "the smallest Euclidean distance to the ideal point (the best value of every "
                   "objective), each objective min-max scaled over both methods' feasible "
                   "trials (one scale for both methods)")


class NoFeasibleSettingError(StudyError):
    """Every trial of a method collided more often than the untuned control."""


def _default_objectives() -> list[Objective]:
    return [Objective("reaction_delay_s", "mean", "minimize"),
            Objective("lateral_jerk_rms_mps3", "mean", "minimize"),
            Objective("recovery_time_s", "mean", "minimize")]


@dataclass
class TuneSpace:
    """``conf/tune/<name>.yaml``: the budget, the families and the rules of a fair fight.

    ``methods`` is ``[treatment, control]``; each has ``conf/hparams_search/<method>.yaml``.
    ``matched_control`` names the look-ahead-matched control built from the tuned control
    (its normalized step set to the tuned treatment's step cap), or "" for none.
    """

    name: str = "default"
    methods: List[str] = field(default_factory=lambda: ["improved", "baseline"])
    n_trials: int = 60
    batch_size: int = 4
    sampler_seed: int = 0
    population_size: int = 10
    objectives: List[Objective] = field(default_factory=_default_objectives)
    training_seed: int = 1
    training_size: int = 40
    heldout_seed: int = 0
    heldout_size: int = 200
    backend: str = "daqp"
    compromise: str = "closest_to_ideal"
    max_heldout_settings: int = 8
    matched_control: str = "baseline_matched"

    def __post_init__(self) -> None:
        safe_name("tune.name", self.name)
        if len(self.methods) != 2 or len(set(self.methods)) != 2:
            raise ConfigError("tune.methods", self.methods,
                              "two different methods: [treatment, control]")
        for i, method in enumerate(self.methods):
            if not (CONF_DIR / "hparams_search" / f"{method}.yaml").is_file():
                raise ConfigError(f"tune.methods[{i}]", method, "a method with a search space "
                                  "in conf/hparams_search/ (improved, baseline)")
        for key, low, high in (("n_trials", 1, 10_000), ("batch_size", 1, 64),
                               ("population_size", 2, 1_000), ("training_size", 2, 100_000),
                               ("heldout_size", 2, 100_000), ("max_heldout_settings", 1, 1_000),
                               ("sampler_seed", 0, 2**31 - 1), ("training_seed", 0, 2**31 - 1),
                               ("heldout_seed", 0, 2**31 - 1)):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
                raise ConfigError(f"tune.{key}", value, f"an integer in [{low}, {high}]")
        if self.training_seed == self.heldout_seed:
            raise ConfigError("tune.heldout_seed", self.heldout_seed,
                              f"a seed other than tune.training_seed ({self.training_seed}): "
                              "held-out scenarios must be unseen")
        if not self.objectives:
            raise ConfigError("tune.objectives", [], "a list of at least one objective")
        for i, objective in enumerate(self.objectives):
            objective.check(f"tune.objectives[{i}]")
        choice("tune.backend", self.backend, ("clarabel_direct", "clarabel_dense", "daqp",
                                              "cvxpy"))
        choice("tune.compromise", self.compromise, ("closest_to_ideal",))
        choice("tune.matched_control", self.matched_control, ("baseline_matched", ""))

    @property
    def treatment(self) -> str:
        return self.methods[0]

    @property
    def control(self) -> str:
        return self.methods[1]


def load_tune_space(path: Path) -> TuneSpace:
    """Read and validate a tuning file (unknown keys, wrong types and shapes: one
    :class:`ConfigError` naming the key, before any work starts)."""
    import yaml

    path = Path(path)
    if not path.is_file():
        raise ConfigError("--space", str(path), "a file in conf/tune/ or a path to one")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ConfigError("--space", str(path), f"valid YAML ({str(exc).splitlines()[0]})") from None
    return schema_from_data(TuneSpace, data, "tune")


def search_space(method: str) -> tuple[dict, dict]:
    """The distributions and the reasons of ``conf/hparams_search/<method>.yaml`` (its
    ``hydra.sweeper.params``, parsed by hydra-optuna-sweeper's own parser)."""
    import yaml

    from hydra_plugins.hydra_optuna_sweeper._impl import create_params_from_overrides

    path = CONF_DIR / "hparams_search" / f"{method}.yaml"
    params = yaml.safe_load(path.read_text())["hydra"]["sweeper"]["params"]
    distributions, fixed = create_params_from_overrides([f"{k}={v}" for k, v in params.items()])
    if fixed:
        raise ConfigError(f"hparams_search/{method}: hydra.sweeper.params", sorted(fixed),
                          "ranges only (interval(...), choice(...)); fix values elsewhere")
    return distributions, {k: str(v) for k, v in params.items()}


# --- Pareto sets and the compromise ----------------------------------------------------------

def _signed(values: np.ndarray, objectives: list[Objective]) -> np.ndarray:
    """Objective values turned so that smaller is better in every column."""
    signs = np.array([1.0 if o.direction == "minimize" else -1.0 for o in objectives])
    return np.asarray(values, float).reshape(-1, len(objectives)) * signs


def dominates(a: np.ndarray, b: np.ndarray) -> bool:
    """``a`` at least as good as ``b`` everywhere and better somewhere (smaller is better)."""
    return bool(np.all(a <= b) and np.any(a < b))


def pareto_mask(values: np.ndarray, objectives: list[Objective]) -> np.ndarray:
    """Which rows are not dominated by another row."""
    signed = _signed(values, objectives)
    return np.array([not any(dominates(other, row) for j, other in enumerate(signed) if j != i)
                     for i, row in enumerate(signed)], dtype=bool)


def distances_to_ideal(candidates: np.ndarray, scale_rows: np.ndarray,
                       objectives: list[Objective]) -> np.ndarray:
    """Each candidate's distance to the ideal point, every objective min-max scaled over
    ``scale_rows`` (see :data:`COMPROMISE_RULE`)."""
    scale = _signed(scale_rows, objectives)
    low, high = scale.min(axis=0), scale.max(axis=0)
    span = np.where(high > low, high - low, 1.0)
    return np.linalg.norm((_signed(candidates, objectives) - low) / span, axis=1)


def closest_to_ideal(candidates: np.ndarray, scale_rows: np.ndarray,
                     objectives: list[Objective]) -> int:
    """Index of the candidate nearest the ideal point (see :data:`COMPROMISE_RULE`)."""
    return int(np.argmin(distances_to_ideal(candidates, scale_rows, objectives)))


# --- the tuning loop ------------------------------------------------------------------------

def optimize(study, distributions: dict, evaluate: Callable[[list[dict]], list[tuple]],
             n_trials: int, batch_size: int, log=logger.info, label: str = "") -> None:
    """Run ``study`` until it holds ``n_trials`` complete trials, ``batch_size`` at a time.

    ``evaluate`` takes a list of parameter dicts and returns, per setting, ``(values,
    constraint)``: the objective values and the safety constraint (<= 0 feasible). A trial
    left running by an interrupted process is closed as failed and its parameters are asked
    again first (their finished families are read back, not simulated).
    """
    from optuna.trial import TrialState

    for trial in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
        study.tell(trial.number, state=TrialState.FAIL)
        study.enqueue_trial(dict(trial.params))
    start, done_before = time.perf_counter(), None
    while True:
        complete = len(study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)))
        done_before = complete if done_before is None else done_before
        if complete >= n_trials:
            return
        batch = [study.ask() for _ in range(min(batch_size, n_trials - complete))]
        settings = [{name: trial._suggest(name, dist) for name, dist in distributions.items()}
                    for trial in batch]
        for trial, (values, constraint) in zip(batch, evaluate(settings), strict=True):
            trial.set_user_attr("constraint", float(constraint))
            study.tell(trial, list(values))
        complete += len(batch)
        elapsed = time.perf_counter() - start
        rate = elapsed / max(complete - done_before, 1)
        log(f"{label}trials {complete}/{n_trials} done "
            f"(about {rate * (n_trials - complete):.0f} s left)")


def _constraint(trial) -> list[float]:
    """Optuna's constraints_func: the safety constraint the evaluation stored (<= 0 feasible)."""
    return [float(trial.user_attrs.get("constraint", 0.0))]


def _study(space: TuneSpace, method: str, storage: str):
    import warnings

    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    with warnings.catch_warnings():
        # constraints_func is marked experimental in optuna 2.10 (pinned); it is what we need
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        sampler = optuna.samplers.NSGAIISampler(population_size=space.population_size,
                                                seed=space.sampler_seed,
                                                constraints_func=_constraint)
    return optuna.create_study(study_name=f"{space.name}-{method}", storage=storage,
                               sampler=sampler, load_if_exists=True,
                               directions=[o.direction for o in space.objectives])


def _override(name: str, value) -> str:
    return f"{name}={value!r}" if isinstance(value, float) else f"{name}={value}"


@dataclass(frozen=True)
class FamilyJob:
    """One family to run: its config and folder, and the settings it stands for."""

    method: str
    setting: str
    cfg: ExperimentConfig
    folder: Path


class Runner:
    """Composes family configs and runs them (here or on SLURM), resuming by config hash."""

    def __init__(self, space: TuneSpace, out_dir: Path, overrides: list[str], log) -> None:
        from pipeline.loop.controller import QpCache
        from pipeline.studies.compose import composer

        self.space, self.out_dir, self.log = space, Path(out_dir), log
        self.compose, self.launcher = composer(list(overrides))
        self.cache = QpCache()

    def job(self, method: str, setting: str, params: dict, part: str) -> FamilyJob:
        seed, size = ((self.space.training_seed, self.space.training_size) if part == "training"
                      else (self.space.heldout_seed, self.space.heldout_size))
        cfg = self.compose([f"method={method}", "scenario=family",
                            f"scenario.family.seed={seed}", f"scenario.family.size={size}",
                            f"controller.backend={self.space.backend}"]
                           + [_override(k, v) for k, v in params.items()])
        return FamilyJob(method, setting, cfg, self.out_dir / "runs" / part / method
                         / cfg.config_hash())

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


# --- the whole study --------------------------------------------------------------------------

def run_tuning(space: TuneSpace, out_dir: Path, overrides: list[str] | None = None,
               log=logger.info) -> TuneResult:
    """Tune, pick, judge on held-out scenarios; the result written into ``out_dir`` (its
    manifest last) and returned. The Pareto fronts are the command's to draw
    (:func:`front_points` gives their data)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    untrust(out_dir)
    runner = Runner(space, out_dir, list(overrides or []), log)
    spaces = {m: search_space(m) for m in space.methods}
    base = runner.compose(["method=improved", "scenario=family"])
    # the safety threshold: the untuned control's collisions on the training family
    untuned = runner.run([runner.job(space.control, "default", {}, "training")],
                         "untuned control")[0]
    threshold = Tally.of(untuned).collisions
    log(f"safety: a setting is feasible when its training family collides at most {threshold} "
        f"times (the untuned {space.control})")
    storage = f"sqlite:///{(out_dir / 'tune.db').resolve()}"
    studies = {}
    for method in space.methods:
        distributions, _ = spaces[method]

        def evaluate(settings: list[dict], method=method) -> list[tuple]:
            jobs = [runner.job(method, "trial", p, "training") for p in settings]
            tables = runner.run(jobs, f"{method} training families")
            return [(objective_values(t, space.objectives), Tally.of(t).collisions - threshold)
                    for t in tables]

        studies[method] = _study(space, method, storage)
        optimize(studies[method], distributions, evaluate, space.n_trials, space.batch_size,
                 log, label=f"{method}: ")
    trials = trials_table(studies, space)
    chosen = pick_settings(trials, space)
    heldout, ledgers, outcomes = judge_heldout(runner, space, trials, chosen, base.claims)
    summary = TuneSummary.from_json(json_safe(summarize(
        space, spaces, threshold, trials, chosen, heldout, ledgers, outcomes)))
    return TuneResult(summary, trials, heldout, ledgers["default"].to_frame(),
                      ledgers["tuned"].to_frame(), outcomes).write(out_dir)


def trials_table(studies: dict, space: TuneSpace) -> pd.DataFrame:
    """Every trial of every method: parameters, training objectives, collisions over the
    threshold, feasibility and Pareto membership."""
    from optuna.trial import TrialState

    rows = []
    for method, study in studies.items():
        for trial in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)):
            row = {"method": method, "trial": trial.number,
                   "constraint": float(trial.user_attrs.get("constraint", 0.0)),
                   "params": json.dumps(trial.params, sort_keys=True)}
            row.update({f"train:{o.label}": v for o, v in zip(space.objectives, trial.values, strict=True)})
            rows.append(row)
    table = pd.DataFrame(rows)
    table["feasible"] = (table["constraint"] <= 0.0) & np.isfinite(
        table[[f"train:{o.label}" for o in space.objectives]].to_numpy(float)).all(axis=1)
    table["pareto"] = False
    for method in space.methods:
        part = table[(table["method"] == method) & table["feasible"]]
        if len(part):
            mask = pareto_mask(part[[f"train:{o.label}" for o in space.objectives]].to_numpy(),
                               space.objectives)
            table.loc[part.index[mask], "pareto"] = True
    return table


def pick_settings(trials: pd.DataFrame, space: TuneSpace) -> dict[str, pd.DataFrame]:
    """Per method, the Pareto settings to judge on held-out scenarios (closest to the ideal
    first, at most ``max_heldout_settings``) with the compromise marked."""
    columns = [f"train:{o.label}" for o in space.objectives]
    feasible = trials[trials["feasible"]]
    scale = feasible[columns].to_numpy(float)
    chosen = {}
    for method in space.methods:
        front = trials[(trials["method"] == method) & trials["pareto"]].copy()
        if not len(front):
            raise NoFeasibleSettingError(
                f"no feasible setting of {method}: every trial collided more often than the "
                "untuned control; widen its search space or raise n_trials")
        front["distance_to_ideal"] = distances_to_ideal(front[columns].to_numpy(float), scale,
                                                        space.objectives)
        front = front.sort_values(["distance_to_ideal", "trial"])
        # the compromise: the nearest to the ideal point (first after sorting)
        front["compromise"] = np.arange(len(front)) == 0
        chosen[method] = front.head(space.max_heldout_settings)
    return chosen


def _matched_params(control: dict, treatment: dict) -> dict:
    """The look-ahead-matched control from the tuned control: its normalized step as long as
    the tuned treatment's step cap (or step, when it has no cap)."""
    params = {k: v for k, v in control.items() if k != "planner.step_size"}
    step = treatment.get("planner.step_max_m", treatment.get("planner.step_size"))
    if step is not None:
        params["planner.step_size"] = step
    return params


def judge_heldout(runner: Runner, space: TuneSpace, trials: pd.DataFrame,
                  chosen: dict[str, pd.DataFrame], claims_cfg):
    """Held-out families of the untuned methods, every chosen Pareto setting and the tuned
    matched control; the default and the tuned ledger; per treatment setting its outcomes
    against the tuned control."""
    treatment, control = space.treatment, space.control
    matched = space.matched_control
    jobs = [runner.job(m, "default", {}, "heldout")
            for m in space.methods + ([matched] if matched else [])]
    params_of = {}
    for method, front in chosen.items():
        for r in front.to_dict("records"):
            params = json.loads(r["params"])
            params_of[(method, r["trial"])] = params
            jobs.append(runner.job(method, f"trial {r['trial']}", params, "heldout"))
    compromise = {m: int(front.loc[front["compromise"], "trial"].iloc[0])
                  for m, front in chosen.items()}
    if matched:
        jobs.append(runner.job(matched, "tuned", _matched_params(
            params_of[(control, compromise[control])],
            params_of[(treatment, compromise[treatment])]), "heldout"))
    tables = runner.run(jobs, "held-out families")
    by_setting = {(j.method, j.setting): t for j, t in zip(jobs, tables, strict=True)}
    rows = []
    for job, table in zip(jobs, tables, strict=True):
        values = objective_values(table, space.objectives)
        tally = Tally.of(table)
        trial = int(job.setting.split()[1]) if job.setting.startswith("trial") else None
        rows.append({"method": job.method, "setting": job.setting, "trial": trial,
                     "compromise": trial is not None and compromise.get(job.method) == trial,
                     "collisions": tally.collisions, "scenarios": tally.scenarios,
                     **{f"heldout:{o.label}": v for o, v in zip(space.objectives, values, strict=True)},
                     "folder": str(job.folder.relative_to(runner.out_dir))})
    heldout = pd.DataFrame(rows)
    comparisons = (control,) + ((matched,) if matched else ())
    default_tables = {m: by_setting[(m, "default")] for m in (treatment,) + comparisons}
    tuned_tables = {treatment: by_setting[(treatment, f"trial {compromise[treatment]}")],
                    control: by_setting[(control, f"trial {compromise[control]}")]}
    if matched:
        tuned_tables[matched] = by_setting[(matched, "tuned")]
    ledgers = {"default": family_ledger(default_tables, claims_cfg, None, treatment,
                                        comparisons),
               "tuned": family_ledger(tuned_tables, claims_cfg, None, treatment, comparisons)}
    outcome_rows = []
    for r in chosen[treatment].to_dict("records"):
        ledger = family_ledger({treatment: by_setting[(treatment, f"trial {r['trial']}")],
                                control: tuned_tables[control]}, claims_cfg, None, treatment,
                               (control,), sensitivity=False)
        for row in ledger:
            outcome_rows.append({"trial": r["trial"], "compromise": bool(r["compromise"]),
                                 "claim": row.claim_id, "outcome": str(row.outcome),
                                 "estimate": row.result.estimate, "params": r["params"]})
    return heldout, ledgers, pd.DataFrame(outcome_rows)


def artefact_sentence(claim_id: str, default: str, tuned: str, n_heldout: int) -> str:
    """Whether a claim's default verdict (against the control, on the held-out family) was a
    tuning artefact."""
    where = f"on {n_heldout} held-out scenarios"
    if default == tuned:
        return (f"{claim_id} {where}: {default} with our settings and {tuned} when both methods "
                "are tuned with the same budget: not a tuning artefact.")
    return (f"{claim_id} {where}: {default} with our settings but {tuned} when both methods are "
            "tuned with the same budget: the default verdict was a tuning artefact.")


def front_points(trials: pd.DataFrame, heldout: pd.DataFrame, space: TuneSpace,
                  part: str) -> dict[str, np.ndarray]:
    """Per method, the Pareto settings' objective values on the training or held-out family."""
    out = {}
    for method in space.methods:
        if part == "training":
            rows = trials[(trials["method"] == method) & trials["pareto"]]
            out[method] = rows[[f"train:{o.label}" for o in space.objectives]].to_numpy(float)
        else:
            rows = heldout[(heldout["method"] == method) & heldout["trial"].notna()]
            out[method] = rows[[f"heldout:{o.label}" for o in space.objectives]].to_numpy(float)
    return out


def front_dominance(points: dict[str, np.ndarray], space: TuneSpace) -> dict:
    """How many of the control's points some treatment point dominates, and the reverse."""
    a = _signed(points[space.treatment], space.objectives)
    b = _signed(points[space.control], space.objectives)
    return {"treatment_dominates": int(sum(any(dominates(p, q) for p in a) for q in b)),
            "control_points": int(len(b)),
            "control_dominates": int(sum(any(dominates(q, p) for q in b) for p in a)),
            "treatment_points": int(len(a))}


def summarize(space: TuneSpace, spaces: dict, threshold: int, trials: pd.DataFrame,
              chosen: dict, heldout: pd.DataFrame, ledgers: dict[str, Ledger],
              outcomes: pd.DataFrame) -> dict:
    """``summary.json``: the budget, the spaces, the picks and per claim the default beside the
    tuned verdict with the sentence on tuning artefacts."""
    control = space.control
    claims = []
    for claim in ALL_CLAIMS:
        default = ledgers["default"].get((claim.claim_id, control))
        tuned = ledgers["tuned"].get((claim.claim_id, control))
        if default is None or tuned is None:
            continue
        holds = outcomes[(outcomes["claim"] == claim.claim_id)
                         & (outcomes["outcome"] == "supported")] if len(outcomes) else outcomes
        claims.append({
            "claim": claim.claim_id, "text": claim.text, "metric": claim.primary_metric,
            "default": str(default.outcome), "default_estimate": default.result.estimate,
            "tuned": str(tuned.outcome), "tuned_estimate": tuned.result.estimate,
            "tuned_ci": [tuned.result.ci_low, tuned.result.ci_high],
            "tuned_vs_matched": str(ledgers["tuned"][(claim.claim_id, space.matched_control)]
                                    .outcome) if space.matched_control and ledgers["tuned"].get(
                (claim.claim_id, space.matched_control)) else None,
            "holds_with": [json.loads(p) for p in holds["params"]] if len(holds) else [],
            "holds_with_trials": [int(t) for t in holds["trial"]] if len(holds) else [],
            "sentence": artefact_sentence(claim.claim_id, str(default.outcome),
                                          str(tuned.outcome), space.heldout_size)})
    compromise = {m: json.loads(f.loc[f["compromise"], "params"].iloc[0])
                  for m, f in chosen.items()}
    return {
        "name": space.name, "settings": json_safe(asdict(space)),
        "budget": {"n_trials_per_method": space.n_trials, "sampler": "NSGA-II (optuna)",
                   "sampler_seed": space.sampler_seed, "population_size": space.population_size,
                   "batch_size": space.batch_size},
        "families": {"training": {"seed": space.training_seed, "size": space.training_size},
                     "heldout": {"seed": space.heldout_seed, "size": space.heldout_size}},
        "backend": space.backend,
        "objectives": [o.label + f" ({o.direction})" for o in space.objectives],
        "safety_threshold_collisions": threshold,
        "search_spaces": {m: spaces[m][1] for m in space.methods},
        "compromise_rule": COMPROMISE_RULE, "compromise": compromise,
        "trials": {m: {"complete": int((trials["method"] == m).sum()),
                       "feasible": int(((trials["method"] == m) & trials["feasible"]).sum()),
                       "pareto": int(((trials["method"] == m) & trials["pareto"]).sum())}
                   for m in space.methods},
        "dominance": {part: front_dominance(front_points(trials, heldout, space, part), space)
                      for part in ("training", "heldout")},
        "claims": claims}
