"""``conf/tune/<name>.yaml``: the budget, the convergence rule, the replicates, the families
and the rules of a fair fight (:class:`TuneSpace`), and each method's search space."""

from __future__ import annotations

import functools
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, List

from pipeline.analysis.objectives import Objective
from pipeline.config import CONF_DIR, schema_from_data
from pipeline.errors import ConfigError
from pipeline.store.files import json_safe
from pipeline.validation import between, choice, flag, safe_name


def _default_objectives() -> list[Objective]:
    return [Objective("reaction_delay_s", "mean", "minimize"),
            Objective("lateral_jerk_rms_mps3", "mean", "minimize"),
            Objective("recovery_time_s", "mean", "minimize")]


def _default_bounds() -> list[list[float]]:
    return [[0.0, 1.2], [0.5, 3.0], [2.0, 5.0]]


#: the fields that decide which trials a replicate runs: a stored study is reused only when
#: they are all the same (its name carries their hash)
TRIAL_FIELDS = ("methods", "batch_size", "sampler_seed", "population_size", "objectives",
                "training_seed", "training_size", "backend", "censoring", "rungs",
                "prune_gain", "prune_after_trials")
#: the families a tuning's trials and held-out judgement run on: the lateral MPC of Section 2 at
#: cruising speed (make reproduce's family), or the Appendix-A track (the kinematic bicycle MPC,
#: start at rest, 100 steps: make reproduce's kinematic_family), the only track of the dynamic
#: window approach; its overrides come after each method's preset
TRACK_OVERRIDES: dict[str, tuple[str, ...]] = {
    "lateral": (),
    "kinematic": ("controller=kinematic", "scenario.initial_speed_mps=0.0",
                  "scenario.n_steps=100"),
}
#: the budget fields that decide when each study stops: with the trial fields and the code
#: version they key the trial store (:meth:`TuneSpace.store_key`)
STORE_FIELDS = ("min_trials", "max_trials", "convergence_window", "convergence_tolerance",
                "hypervolume_bounds")
#: the fields whose default values are the budget a headline needs (at least as much of each)
BUDGET_AT_LEAST = ("replicates", "min_trials", "max_trials", "convergence_window",
                   "training_size", "heldout_size")
#: how the replicates' outcomes settle a claim (``tune.settled_test``): ``binomial``, a
#: one-sided exact binomial test of the leading outcome's count among the judged replicates
#: against even odds, at the claims' ``alpha`` (:func:`pipeline.studies.tune.study.settlement`)
SETTLE_TESTS = ("binomial",)
#: keys a tune space no longer has, each with what took its place: one line, never a silent
#: reading of an old file
RETIRED_KEYS = {
    "settled_share": "no longer a key: a claim is settled by tune.settled_test (binomial: a "
                     "one-sided exact binomial test of the leading outcome's count among the "
                     "judged replicates, p = 0.5, at claims.alpha); remove settled_share",
}


@dataclass
class TuneSpace:
    """``conf/tune/<name>.yaml``: the budget, the convergence rule and the rules of a fair
    fight.

    ``methods`` is ``[treatment, control]``; each has ``conf/hparams_search/<method>.yaml``.
    Each of ``replicates`` independent replicates has its own sampler seed (``sampler_seed +
    r``), training family (seed ``training_seed + r``) and held-out family (seed
    ``heldout_seed + heldout_seed_stride * r``: replicate 0's is ``heldout_seed``, make
    reproduce's family, on which the untuned methods are judged too); no held-out seed is a
    training seed. A claim is settled over the replicates by ``settled_test`` at the claims'
    alpha. A method's search stops when its feasible front's hypervolume (objectives mapped
    by the fixed ``hypervolume_bounds``, one ``[ideal, nadir]`` per objective, the same for
    both methods) grew by at most ``convergence_tolerance`` of its value over the last
    ``convergence_window`` trials, at ``min_trials`` at the earliest and ``max_trials`` at the
    latest (then it is labelled unconverged). ``matched_control`` names the look-ahead-matched
    control built from the tuned control (``baseline_matched``: only with the control
    ``baseline``), or "" for none. A setting is feasible when its training family collides at
    most as often as the untuned ``safety_reference``'s ("": the control's): a peer tuned
    against improved with ``safety_reference: baseline`` keeps improved's trials those of the
    improved-vs-baseline tune.

    Multi-fidelity trials (:mod:`pipeline.studies.tune.search`): a trial runs the first
    ``rungs[0]`` members of its training family, then ``rungs[1]``, ..., then all of it, and
    stops at a rung when it can no longer be feasible (more collisions than the threshold
    already) or when, after ``prune_after_trials`` complete trials of its method, its values on
    those members would raise the hypervolume of its method's complete trials read on the same
    members by at most ``prune_gain`` of it. ``rungs: []`` runs every trial on the whole
    family.
    """

    name: str = "default"
    methods: List[str] = field(default_factory=lambda: ["improved", "baseline"])
    replicates: int = 10
    min_trials: int = 80
    max_trials: int = 300
    convergence_window: int = 60
    convergence_tolerance: float = 0.02
    hypervolume_bounds: List[List[float]] = field(default_factory=_default_bounds)
    batch_size: int = 4
    sampler_seed: int = 0
    population_size: int = 10
    objectives: List[Objective] = field(default_factory=_default_objectives)
    censoring: str = "run_end"
    training_seed: int = 1
    training_size: int = 40
    heldout_seed: int = 0
    #: replicate r's held-out family has seed ``heldout_seed + heldout_seed_stride * r``; 1000
    #: keeps every held-out seed above the training seeds (``training_seed + r``, r < 100)
    heldout_seed_stride: int = 1000
    heldout_size: int = 200
    backend: str = "daqp"
    heldout_backend: str = "clarabel_direct"
    compromise: str = "closest_to_ideal"
    max_heldout_settings: int = 3
    matched_control: str = "baseline_matched"
    safety_reference: str = ""
    settled_test: str = "binomial"
    rungs: List[int] = field(default_factory=lambda: [5, 10, 20])
    prune_gain: float = 0.001
    prune_after_trials: int = 10
    #: whether the training families' members keep what each step planned (``horizon.npz``,
    #: read only by the report's scenario explorer, which shows make reproduce's families, not
    #: the tune's trials): off, it saves about 7 % of a member's CPU and changes no number
    training_horizon: bool = False
    #: whether the training families' members keep run folders (trajectory, settings, timing,
    #: metrics) and member-cache entries: off, a training family's record keeps each member's
    #: metrics in its ``members.jsonl`` (all the tune reads of a training member), which saves
    #: a member's five files, their copy into the member cache, and the tune's disk (a default
    #: tune wrote about 30,000 member folders, 2.2 GB, and as much again into the cache);
    #: ``training_horizon`` true keeps the folders (the horizon record is one of their files)
    training_member_records: bool = False
    track: str = "lateral"
    #: the scenarios tuned and judged on: a family of conf/scenario/ (``family``, the scripted
    #: one; ``pedestrians``, the recorded pedestrians). Where its source splits its family into
    #: parts (its ``parts_key``: the pedestrians' scenes) the tuning trains on
    #: ``training_scenes`` and judges on ``heldout_scenes`` (disjoint: the held-out parts are
    #: unseen by the tuning)
    scenario: str = "family"
    training_scenes: List[str] = field(default_factory=list)
    heldout_scenes: List[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        # a null name (`--set name=`) is refused as the empty name it was typed as
        safe_name("tune.name", "" if self.name is None else self.name)
        if len(self.methods) != 2 or len(set(self.methods)) != 2:
            raise ConfigError("tune.methods", self.methods,
                              "two different methods: [treatment, control]")
        # names only, never a path (`../method/baseline` found a file outside the folder)
        searchable = sorted(p.stem for p in (CONF_DIR / "hparams_search").glob("*.yaml"))
        for i, method in enumerate(self.methods):
            if method not in searchable:
                raise ConfigError(f"tune.methods[{i}]", method, "a method with a search space "
                                  "in conf/hparams_search/ (" + ", ".join(searchable) + ")")
        for key, low, high in (("replicates", 1, 100), ("min_trials", 1, 10_000),
                               ("max_trials", 1, 10_000), ("convergence_window", 1, 10_000),
                               ("batch_size", 1, 64),
                               ("population_size", 2, 1_000), ("training_size", 2, 100_000),
                               ("heldout_size", 2, 100_000), ("max_heldout_settings", 1, 1_000),
                               ("sampler_seed", 0, 2**31 - 1), ("training_seed", 0, 2**31 - 1),
                               ("heldout_seed", 0, 2**31 - 1),
                               ("heldout_seed_stride", 1, 2**31 - 1)):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
                raise ConfigError(f"tune.{key}", value, f"an integer in [{low}, {high}]")
        if self.max_trials < self.min_trials:
            raise ConfigError("tune.max_trials", self.max_trials,
                              f"an integer >= tune.min_trials ({self.min_trials})")
        if self.convergence_window >= self.max_trials:
            raise ConfigError("tune.convergence_window", self.convergence_window,
                              f"an integer below tune.max_trials ({self.max_trials}): a longer "
                              "window can never be filled, so the tune could never converge")
        flag("tune.training_horizon", self.training_horizon)
        flag("tune.training_member_records", self.training_member_records)
        between("tune.convergence_tolerance", self.convergence_tolerance, 0.0, 1.0)
        choice("tune.settled_test", self.settled_test, SETTLE_TESTS)
        self._check_rungs()
        self._check_seeds()
        if not self.objectives:
            raise ConfigError("tune.objectives", [], "a list of at least one objective")
        for i, objective in enumerate(self.objectives):
            objective.check(f"tune.objectives[{i}]")
        self._check_bounds()
        choice("tune.censoring", self.censoring, ("run_end", "drop"))
        choice("tune.compromise", self.compromise, ("closest_to_ideal",))
        self._check_track()
        self._check_controls()
        self._check_scenes()

    def _check_seeds(self) -> None:
        """Every replicate's held-out seed a valid seed and none of them a training seed
        (held-out scenarios must be unseen by every replicate's tuning)."""
        last = self.heldout_seed + self.heldout_seed_stride * (self.replicates - 1)
        if last > 2**31 - 1:
            raise ConfigError("tune.heldout_seed_stride", self.heldout_seed_stride,
                              f"a stride that keeps the last replicate's held-out seed "
                              f"(heldout_seed + heldout_seed_stride * {self.replicates - 1} = "
                              f"{last}) at most {2**31 - 1}")
        training = {seed: r for r, seed in enumerate(self.training_seeds)}
        for r, seed in enumerate(self.heldout_seeds):
            if seed in training:
                raise ConfigError(
                    "tune.heldout_seed", self.heldout_seed,
                    f"held-out seeds (heldout_seed + heldout_seed_stride * r) apart from the "
                    f"training seeds (training_seed + r): replicate {r}'s held-out seed {seed} "
                    f"is replicate {training[seed]}'s training seed; change heldout_seed, "
                    "heldout_seed_stride or training_seed")

    def _check_track(self) -> None:
        choice("tune.track", self.track, tuple(TRACK_OVERRIDES))
        for key in ("backend", "heldout_backend"):
            choice(f"tune.{key}", getattr(self, key), ("clarabel_direct", "daqp", "cvxpy"))
            if self.track == "kinematic" and getattr(self, key) not in ("clarabel_direct",
                                                                          "cvxpy"):
                raise ConfigError(f"tune.{key}", getattr(self, key),
                                  "clarabel_direct or cvxpy with tune.track kinematic (the "
                                  "kinematic MPC's QP has no DAQP or dense form)")

    def _check_scenes(self) -> None:
        parts_key = self.parts_key
        if parts_key is None:
            for key in ("training_scenes", "heldout_scenes"):
                if getattr(self, key):
                    raise ConfigError(f"tune.{key}", list(getattr(self, key)),
                                      f"[] with tune.scenario={self.scenario} (its source "
                                      "splits its family into no parts: scenes are the "
                                      "pedestrians')")
            return
        for key in ("training_scenes", "heldout_scenes"):
            scenes = getattr(self, key)
            if not scenes or any(not isinstance(x, str) or not x or "/" in x for x in scenes):
                raise ConfigError(f"tune.{key}", list(scenes or []),
                                  f"a non-empty list of names for {parts_key} (e.g. track "
                                  "files of data/eth_ucy/ without extension)")
        shared = sorted(set(self.training_scenes) & set(self.heldout_scenes))
        if shared:
            raise ConfigError("tune.heldout_scenes", list(self.heldout_scenes),
                              f"scenes not among tune.training_scenes (shared: "
                              f"{', '.join(shared)}): held-out scenes must be unseen")

    @property
    def parts_key(self) -> str | None:
        """The key whose list the tuning splits into its training and held-out parts (the
        source's ``parts_key``, e.g. ``scenario.pedestrians.scenes``), or None (read once per
        scenario name and process: every trial's families ask)."""
        return _parts_key(self.scenario)

    def scenario_overrides(self, part: str) -> list[str]:
        """The Hydra overrides that choose the scenarios of ``part`` (``training`` or
        ``heldout``): the family of ``scenario``, restricted to that part's scenes where its
        source splits its family (:attr:`parts_key`)."""
        parts_key = self.parts_key
        if parts_key is None:
            return [f"scenario={self.scenario}"]
        scenes = self.training_scenes if part == "training" else self.heldout_scenes
        return [f"scenario={self.scenario}", f"{parts_key}=[{','.join(scenes)}]"]

    def _check_controls(self) -> None:
        choice("tune.matched_control", self.matched_control, ("baseline_matched", ""))
        if self.matched_control == "baseline_matched" and self.control != "baseline":
            raise ConfigError("tune.matched_control", self.matched_control,
                              f"'' with the control {self.control} (baseline_matched is the "
                              "tuned baseline with the treatment's step: control baseline only)")
        # a name of conf/method/, never a path (`../hparams_search/improved` composed a search
        # space as the reference method)
        if self.safety_reference and self.safety_reference not in {
                p.stem for p in (CONF_DIR / "method").glob("*.yaml")}:
            raise ConfigError("tune.safety_reference", self.safety_reference,
                              "'' (the control) or a method of conf/method/")

    def _check_rungs(self) -> None:
        between("tune.prune_gain", self.prune_gain, 0.0, 1.0)
        value = self.prune_after_trials
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 10_000:
            raise ConfigError("tune.prune_after_trials", value, "an integer in [0, 10000]")
        rungs = self.rungs
        if not isinstance(rungs, list) or any(
                isinstance(n, bool) or not isinstance(n, int) for n in rungs) \
                or any(not 1 <= n < self.training_size for n in rungs) \
                or any(b <= a for a, b in zip(rungs, rungs[1:], strict=False)):
            raise ConfigError("tune.rungs", rungs, f"increasing member counts in [1, "
                              f"{self.training_size - 1}] (below tune.training_size), or []")

    def _check_bounds(self) -> None:
        bounds = self.hypervolume_bounds
        if not isinstance(bounds, list) or len(bounds) != len(self.objectives):
            raise ConfigError("tune.hypervolume_bounds", bounds,
                              f"one [ideal, nadir] pair per objective ({len(self.objectives)})")
        for i, (pair, objective) in enumerate(zip(bounds, self.objectives, strict=True)):
            ok = (isinstance(pair, list) and len(pair) == 2
                  and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                          and abs(v) < 1e12 for v in pair))
            better = ok and (pair[0] < pair[1] if objective.direction == "minimize"
                             else pair[0] > pair[1])
            if not better:
                raise ConfigError(f"tune.hypervolume_bounds[{i}]", pair,
                                  f"[ideal, nadir], two finite numbers with the ideal the better "
                                  f"one ({objective.direction} {objective.metric})")

    @property
    def treatment(self) -> str:
        return self.methods[0]

    @property
    def control(self) -> str:
        return self.methods[1]

    @property
    def feasibility_reference(self) -> str:
        """The method whose untuned training family sets the collision threshold."""
        return self.safety_reference or self.control

    @property
    def training_seeds(self) -> list[int]:
        """Replicate ``r``'s training family seed: ``training_seed + r``."""
        return [self.training_seed + r for r in range(self.replicates)]

    @property
    def heldout_seeds(self) -> list[int]:
        """Replicate ``r``'s held-out family seed: ``heldout_seed + heldout_seed_stride * r``
        (replicate 0's is ``heldout_seed``, make reproduce's family by default)."""
        return [self.heldout_seed_of(r) for r in range(self.replicates)]

    def heldout_seed_of(self, replicate: int) -> int:
        return self.heldout_seed + self.heldout_seed_stride * replicate

    def sampler_seed_of(self, replicate: int) -> int:
        return self.sampler_seed + replicate

    def trial_key(self) -> str:
        """A short hash of everything that decides the trials (:data:`TRIAL_FIELDS`): a stored
        study under another key is never resumed."""
        import hashlib
        import json

        data = json_safe({k: asdict(self)[k] for k in TRIAL_FIELDS})
        # only when set: the keys of tunings without them (their stored studies) unchanged
        if self.safety_reference:
            data["safety_reference"] = self.safety_reference
        if self.track != "lateral":
            data["track"] = self.track
        if self.scenario != "family":
            data.update(scenario=self.scenario, training_scenes=list(self.training_scenes))
        return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:10]

    def store_key(self, overrides: list[str] | tuple[str, ...] = ()) -> str:
        """A short hash of what the stored trials of this tune depend on: its trial key, its
        budget (:data:`STORE_FIELDS`), the run ``overrides`` (all but the workers' count,
        which changes no number) and the code version. A stored study made under another key
        is never reused (:func:`pipeline.studies.tune.search.check_trial_store`)."""
        import hashlib
        import json

        from pipeline.store.manifest import code_version

        data = {"trials": self.trial_key(), "code": code_version(),
                "budget": json_safe({k: asdict(self)[k] for k in STORE_FIELDS})}
        runs = [o for o in overrides if not o.startswith(("hydra/", "hydra."))
                and o.split("=", 1)[0].lstrip("+~") != "scenario.family.n_jobs"]
        if runs:
            # only when there are some: the key of a tune without overrides stays as it was
            data["overrides"] = runs
        return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:12]

    def below_budget(self, reference: TuneSpace) -> list[str]:
        """The budget fields in which this tuning does less than ``reference`` (the default
        preset): a tuning below the default budget never writes the headline."""
        short = [k for k in BUDGET_AT_LEAST if getattr(self, k) < getattr(reference, k)]
        if self.convergence_tolerance > reference.convergence_tolerance:
            short.append("convergence_tolerance")
        return short


@functools.lru_cache(maxsize=16)
def _parts_key(scenario: str) -> str | None:
    return getattr(tuned_scenario_source(scenario), "parts_key", None)


def tuned_scenario_source(name: str) -> type:
    """The source class (:class:`pipeline.loop.scenario.ScenarioSource`) of the family
    ``conf/scenario/<name>.yaml`` a tuning runs on: its ``source._target_``, or the built-in
    its shape implies."""
    from pipeline.loop.scenario import source_class
    from pipeline.loop.settings import ScenarioConfig
    from pipeline.store.safe_load import load_yaml

    allowed = "a scenario family of conf/scenario/ (e.g. family, pedestrians)"
    safe_name("tune.scenario", name)
    path = CONF_DIR / "scenario" / f"{name}.yaml"
    data = load_yaml(path, "a scenario (conf/scenario/<name>.yaml)") if path.is_file() else None
    if not isinstance(data, dict) or not isinstance(data.get("family"), dict):
        raise ConfigError("tune.scenario", name, allowed)
    return source_class(ScenarioConfig.source_target_of(data))


def load_tune_space(path: Path, changes: list[str] | None = None) -> TuneSpace:
    """Read and validate a tuning file (unknown keys, wrong types and shapes: one
    :class:`ConfigError` naming the key, before any work starts), with ``changes``
    (``key=value``, the value read as YAML: ``rungs=[]``) applied to it first; a changed
    space is another space: its ``name`` gets the changes appended unless they set it."""
    from pipeline.store.safe_load import load_yaml, parse_yaml

    path = Path(path)
    if not path.exists():
        raise ConfigError("--space", str(path), "a file in conf/tune/ or a path to one")
    # size, UTF-8 and alias limits: one line naming the file (pipeline.store.safe_load)
    data = load_yaml(path, "a tune space (conf/tune/<name>.yaml)")
    if not isinstance(data, dict):
        raise ConfigError("--space", str(path), "a mapping of tune settings" + (
            " (the file is empty)" if data is None else f", not a {type(data).__name__}"))
    for key, instead in RETIRED_KEYS.items():
        if key in data:
            raise ConfigError(f"tune.{key}", data[key], instead)
    if changes:
        data = dict(data)
        names = {f for f in TuneSpace.__dataclass_fields__}
        for change in changes:
            key, sep, text = change.partition("=")
            key = key.strip()
            if key in RETIRED_KEYS:
                raise ConfigError(f"tune.{key}", text, RETIRED_KEYS[key])
            if not sep or key not in names:
                raise ConfigError("--set", change, "key=value with key one of "
                                  + ", ".join(sorted(names)))
            data[key] = parse_yaml(text, f"--set {key}", "a YAML value")
        if not any(c.partition("=")[0].strip() == "name" for c in changes):
            data["name"] = f"{data.get('name', 'tune')}_changed"
    return schema_from_data(TuneSpace, data, "tune")


def default_budget() -> TuneSpace:
    """The default preset (``conf/tune/default.yaml``): the budget a headline needs."""
    return load_tune_space(CONF_DIR / "tune" / "default.yaml")


@dataclass(frozen=True)
class SearchRange:
    """One tuned config key of ``conf/hparams_search/<method>.yaml`` and its range: floats
    in ``[low, high]`` (``log``: log-uniform), integers ``low, low + step, ..., high``, or one
    of ``choices``; ``why`` is the reason for the range (the report shows it).

    In the file: ``float: [low, high]`` (and ``log: true``), ``int: [low, high]`` (and
    ``step``), or ``choice: [a, b, ...]``; with ``why``. Both ends of a range are included.
    """

    key: str
    kind: str
    low: float | int | None = None
    high: float | int | None = None
    log: bool = False
    step: int = 1
    choices: tuple = ()
    why: str = ""

    KINDS = ("float", "int", "choice")

    @classmethod
    def of(cls, key: str, data: Any, where: str) -> SearchRange:
        """The range of ``key`` from its entry ``data``, checked strictly (one
        :class:`ConfigError` naming ``where``.``key``)."""
        name = f"{where}.{key}"
        if not isinstance(data, dict):
            raise ConfigError(name, data, "a mapping: float: [low, high], int: [low, high] or "
                              "choice: [...], with why")
        kinds = [k for k in cls.KINDS if k in data]
        unknown = sorted(set(data) - {*cls.KINDS, "log", "step", "why"})
        if unknown:
            raise ConfigError(f"{name}.{unknown[0]}", data[unknown[0]],
                              "a key of a search range: float, int, choice, log, step, why")
        if len(kinds) != 1:
            raise ConfigError(name, data, "exactly one of float: [low, high], int: [low, "
                              "high] or choice: [...]")
        kind, why = kinds[0], data.get("why", "")
        if not isinstance(why, str):
            raise ConfigError(f"{name}.why", why, "a sentence (text)")
        if kind == "choice":
            choices = data["choice"]
            if not isinstance(choices, list) or len(choices) < 2 or any(
                    not isinstance(c, (str, int, float, bool)) for c in choices) \
                    or len(set(map(repr, choices))) != len(choices):
                raise ConfigError(f"{name}.choice", choices, "a list of at least two different "
                                  "plain values")
            if "log" in data or "step" in data:
                raise ConfigError(name, data, "no log or step with choice")
            return cls(key, kind, choices=tuple(choices), why=why.strip())
        return cls._numeric(key, kind, data, name, why.strip())

    @classmethod
    def _numeric(cls, key: str, kind: str, data: dict, name: str, why: str) -> SearchRange:
        bounds = data[kind]
        number = int if kind == "int" else (int, float)
        if not isinstance(bounds, list) or len(bounds) != 2 or any(
                isinstance(b, bool) or not isinstance(b, number) or not math.isfinite(b)
                for b in bounds) or not bounds[0] < bounds[1]:
            raise ConfigError(f"{name}.{kind}", bounds, f"[low, high], two finite "
                              f"{'integers' if kind == 'int' else 'numbers'} with low < high")
        log = data.get("log", False)
        if not isinstance(log, bool) or (log and bounds[0] <= 0):
            raise ConfigError(f"{name}.log", log, "true (with low > 0) or false")
        step = data.get("step", 1)
        if kind == "float" and "step" in data:
            raise ConfigError(f"{name}.step", step, "no step for a float range (int: [...] "
                              "for integers)")
        if isinstance(step, bool) or not isinstance(step, int) or step < 1 \
                or (kind == "int" and (bounds[1] - bounds[0]) % step) or (log and step != 1):
            raise ConfigError(f"{name}.step", step, f"a positive integer dividing high - low "
                              f"({bounds[1] - bounds[0]}), 1 with log")
        low, high = (bounds[0], bounds[1]) if kind == "int" else (float(bounds[0]),
                                                                   float(bounds[1]))
        return cls(key, kind, low, high, log, step, why=why)

    def distribution(self):
        """Optuna's distribution of this range."""
        from optuna.distributions import (
            CategoricalDistribution,
            FloatDistribution,
            IntDistribution,
        )

        if self.kind == "choice":
            return CategoricalDistribution(self.choices)
        if self.kind == "int":
            return IntDistribution(int(self.low), int(self.high), log=self.log,  # type: ignore[arg-type]
                                   step=self.step)
        return FloatDistribution(float(self.low), float(self.high), log=self.log)  # type: ignore[arg-type]

    def text(self) -> str:
        """The range in words (the report's search spaces)."""
        if self.kind == "choice":
            return "one of " + ", ".join(str(c) for c in self.choices)
        if self.kind == "int":
            steps = f" in steps of {self.step}" if self.step > 1 else ""
            return f"integers {self.low} to {self.high}{steps}" + (", log-uniform" if self.log
                                                                   else "")
        return f"{self.low:g} to {self.high:g}" + (", log-uniform" if self.log else "")


def search_ranges(method: str) -> tuple[SearchRange, ...]:
    """The ranges of ``conf/hparams_search/<method>.yaml`` (the project's schema:
    :class:`SearchRange`), checked strictly: one :class:`ConfigError` naming the key."""
    from pipeline.store.safe_load import load_yaml

    where = f"hparams_search/{method}"
    path = CONF_DIR / "hparams_search" / f"{method}.yaml"
    data = load_yaml(path, "a search space (conf/hparams_search/<method>.yaml)")
    if not isinstance(data, dict) or not isinstance(data.get("params"), dict) \
            or not data["params"]:
        raise ConfigError(f"{where}.params", None if not isinstance(data, dict)
                          else data.get("params"), "a mapping of tuned keys to their ranges")
    unknown = sorted(set(data) - {"method", "params"})
    if unknown:
        raise ConfigError(f"{where}.{unknown[0]}", data[unknown[0]],
                          "a key of a search space: method, params")
    if data.get("method", method) != method:
        raise ConfigError(f"{where}.method", data["method"], f"{method} (the file's name)")
    for key in data["params"]:
        if not isinstance(key, str) or not all(part.isidentifier() for part in key.split(".")):
            raise ConfigError(f"{where}.params", key, "dotted config keys (planner.beta)")
    return tuple(SearchRange.of(k, v, f"{where}.params") for k, v in data["params"].items())


def search_space(method: str) -> tuple[dict, dict]:
    """The Optuna distributions of ``conf/hparams_search/<method>.yaml``, and each key's range
    in words with its reason (:func:`search_ranges`)."""
    ranges = search_ranges(method)
    return ({r.key: r.distribution() for r in ranges},
            {r.key: r.text() + (f"; {r.why}" if r.why else "") for r in ranges})
