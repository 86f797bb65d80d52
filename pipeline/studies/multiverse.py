"""How robust is each verdict: a multiverse over every registered choice (``make multiverse``).

``python -m pipeline.multiverse [--space default|quick|PATH] [--out outputs/multiverse]
[OVERRIDE ...]`` reads a space (``conf/multiverse/<space>.yaml``): dimensions, each a config key
with its defensible values (the first is the default) and a stage. *Simulation* dimensions change
the runs; *analysis* dimensions (metric readings and thresholds, statistics) only re-score them.

1. **Design**: the default specification, every one-at-a-time change, then a seeded sample until
   ``n_specifications``; sampled specifications draw their simulation choices from a pool of
   ``simulation_pool`` seeded combinations, so runs are shared (Steegen et al. 2016; Simonsohn,
   Simmons and Nelson 2020).
2. **Runs**: every distinct simulation configuration runs ``baseline``, ``baseline_matched`` and
   ``improved`` on the same family (``family_size`` >= 100 scenarios), one family folder per
   config hash under ``runs/``; a folder already complete comes back from its hash, never
   recomputed (resume after an interruption loses nothing). The lateral MPC's QP runs on the
   space's ``backend`` (``daqp`` by default: the same condensed QP as the reference
   ``clarabel_direct``, its first input within 1e-6, the QP about 3x faster); a run override
   ``controller.backend=...`` wins, and ``space.json`` records each method's backend.
3. **Re-scoring**: a specification whose metric settings differ from the runs' recomputes the
   metrics from the stored trajectories (cached under ``rescored/``).
4. **Analysis**: per specification, claim and comparison the claims ledger (estimate, interval,
   Holm-adjusted test, outcome); per claim and comparison the share of specifications with each
   outcome, a robustness label (:data:`ROBUSTNESS_RULE`), how much each dimension moves the
   estimate and which of its values flip the outcome.

Writes ``design.csv``, ``specifications.csv``, ``robustness.csv``, ``dimensions.csv`` and one
specification-curve figure per claim under ``figures/``; the report's Robustness section reads
them. Extra arguments are Hydra overrides applied to every run (e.g. ``scenario.family.n_jobs=2``).
"""

from __future__ import annotations

import copy
import logging
import dataclasses
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pipeline.store.runs import (MULTIVERSE_FILES, check, check_derived_table,
                                 member_trajectories, read_family, untrust, write_csv_atomic,
                                 write_derived_table, write_json_atomic, write_manifest)

from pipeline.analysis.claims import ALL_CLAIMS, OUTCOMES, family_ledger
from pipeline.config import CONF_DIR, ClaimsConfig, ExperimentConfig, MetricsConfig
from pipeline.errors import ConfigError, IncompleteSweepError

logger = logging.getLogger(__name__)

#: The methods simulated by default: the claims' controls and treatment (claims.treatment,
#: claims.controls of the user's configuration choose others).
METHODS = ("baseline", "baseline_matched", "improved")
STAGES = ("simulation", "analysis")
#: the lateral MPC's QP backends a space may choose (``controller.backend``)
QP_BACKENDS = ("clarabel_direct", "daqp", "clarabel_dense", "cvxpy")
ANALYSIS_PREFIXES = ("metrics.", "claims.")

ROBUSTNESS_RULE = (
    "per claim and comparison: 'robust' when at least robust_share of the specifications give "
    "the default specification's outcome, 'fragile' when fewer than fragile_share do, "
    "'sensitive' in between. A dimension's influence is the largest share, over its values, of "
    "the specifications with that value whose outcome differs from the default's; the most "
    "influential dimension is the one with the largest influence (ties: the larger spread of "
    "median estimates across its values), named with the values that flip most of their "
    "specifications (or the one value that flips the most)")


@dataclass(frozen=True)
class Dimension:
    """One choice of the multiverse: a config key and its defensible values.

    ``key`` names the dimension (a column of the design); ``config_key`` is the Hydra key it
    sets when that differs, e.g. the baseline's own ``planner.rho0_m`` beside the improved
    APF's (``key: planner.rho0_m[baseline]``).
    """

    key: str
    stage: str
    values: tuple
    applies_to: tuple | None = None
    cap: bool = False
    why: str = ""
    config_key: str = ""

    @property
    def target(self) -> str:
        """The config key the dimension sets."""
        return self.config_key or self.key

    @property
    def default(self) -> Any:
        return self.values[0]


@dataclass(frozen=True)
class Space:
    """A multiverse: its dimensions and how to sample and judge it."""

    name: str
    dimensions: tuple[Dimension, ...]
    family_size: int = 100
    family_seed: int = 0
    n_specifications: int = 128
    sample_seed: int = 0
    simulation_pool: int = 12
    n_resamples: int = 499
    robust_share: float = 0.9
    fragile_share: float = 0.5
    min_pairs: int = 10
    #: the lateral MPC's QP backend of the runs (like the tuning's: DAQP, the reference
    #: Clarabel's QP solved about 3x faster, the first input within 1e-6)
    backend: str = "daqp"

    def of(self, stage: str) -> list[Dimension]:
        return [d for d in self.dimensions if d.stage == stage]


def load_space(path: Path) -> Space:
    """Read and check a space file; a bad one raises :class:`ConfigError` (one line)."""
    import yaml

    path = Path(path)
    if not path.is_file():
        raise ConfigError("multiverse space", str(path), "a file in conf/multiverse/ "
                          "(default, quick) or a path to one")
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as exc:
        raise ConfigError("multiverse space", str(path), f"valid YAML ({str(exc).splitlines()[0]})")
    # strict: an unknown key, a wrong type or a wrong shape stops here, before any work
    if not isinstance(data, dict):
        raise ConfigError("multiverse space", type(data).__name__,
                          "a mapping with 'dimensions' and the space's settings")
    fields = {f.name: f for f in dataclasses.fields(Space)}
    for key, value in data.items():
        if key not in fields:
            raise ConfigError(f"multiverse space: {key}", value,
                              f"one of the keys {sorted(fields)}")
        if key in ("name", "dimensions"):
            continue
        kind = fields[key].type if isinstance(fields[key].type, type) else \
            {"int": int, "float": float}.get(str(fields[key].type), object)
        if isinstance(value, bool) or not isinstance(value, (int, float) if kind is float
                                                     else kind):
            raise ConfigError(f"multiverse space: {key}", value,
                              f"a number ({getattr(kind, '__name__', kind)})")
    if not isinstance(data.get("dimensions", []), list):
        raise ConfigError("multiverse space: dimensions", type(data["dimensions"]).__name__,
                          "a list of dimensions")
    dimension_keys = ("name", "key", "stage", "values", "applies_to", "cap", "why")
    dims = []
    for i, item in enumerate(data.get("dimensions") or []):
        if not isinstance(item, dict):
            raise ConfigError(f"dimensions[{i}]", item, "a mapping with key, stage, values")
        for k in item:
            if k not in dimension_keys:
                raise ConfigError(f"dimensions[{i}].{k}", item[k],
                                  f"one of the keys {list(dimension_keys)}")
        if not isinstance(item.get("values"), list):
            raise ConfigError(f"dimensions[{i}].values", item.get("values"),
                              "a list of two or more values, the first the default")
        if item.get("applies_to") is not None and not isinstance(item["applies_to"], list):
            raise ConfigError(f"dimensions[{i}].applies_to", item["applies_to"],
                              "a list of method names")
        key = str(item.get("name") or item.get("key", ""))
        config_key = str(item.get("key", "")) if item.get("name") else ""
        stage = item.get("stage")
        values = tuple(item.get("values") or ())
        if stage not in STAGES:
            raise ConfigError(f"dimensions[{i}].stage", stage, "simulation or analysis")
        if len(values) < 2:
            raise ConfigError(f"dimensions[{i}].values", list(values), "two or more values, the "
                              "first the default")
        if stage == "analysis" and not (config_key or key).startswith(ANALYSIS_PREFIXES):
            raise ConfigError(f"dimensions[{i}].key", key, "a metrics.* or claims.* key for an "
                              "analysis dimension")
        applies = tuple(item["applies_to"]) if item.get("applies_to") else None
        dims.append(Dimension(key, stage, values, applies, bool(item.get("cap", False)),
                              str(item.get("why", "")), config_key))
    if not dims:
        raise ConfigError("dimensions", [], "at least one dimension")
    if len({d.key for d in dims}) != len(dims):
        raise ConfigError("dimensions", [d.key for d in dims], "each key once")
    settings = {k: v for k, v in data.items() if k not in ("dimensions", "name")}
    space = Space(name=str(data.get("name", path.stem)), dimensions=tuple(dims), **settings)
    if space.family_size < 1 or space.n_specifications < 1:
        raise ConfigError("family_size / n_specifications",
                          [space.family_size, space.n_specifications], "positive integers")
    if space.backend not in QP_BACKENDS:
        raise ConfigError("multiverse space: backend", space.backend,
                          f"one of {list(QP_BACKENDS)} (the lateral MPC's QP backend)")
    return space


def build_design(space: Space) -> pd.DataFrame:
    """Default, one-at-a-time changes, then a seeded sample (simulation choices from a pool).

    Returns
    -------
    DataFrame
        ``spec_id``, ``kind`` (default / one_at_a_time / sampled) and one column per dimension.
    """
    rng = np.random.default_rng(space.sample_seed)
    default = {d.key: d.default for d in space.dimensions}
    rows = [{"kind": "default", **default}]
    for dim in space.dimensions:
        for value in dim.values[1:]:
            rows.append({"kind": "one_at_a_time", **default, dim.key: value})
    sim_dims = space.of("simulation")
    pool = [{d.key: d.values[rng.integers(len(d.values))] for d in sim_dims}
            for _ in range(max(space.simulation_pool, 1))]
    seen = {tuple(str(r[d.key]) for d in space.dimensions) for r in rows}
    attempts = 0
    while len(rows) < space.n_specifications and attempts < 100 * space.n_specifications:
        attempts += 1
        row = {"kind": "sampled", **pool[rng.integers(len(pool))]}
        for dim in space.of("analysis"):
            row[dim.key] = dim.values[rng.integers(len(dim.values))]
        signature = tuple(str(row[d.key]) for d in space.dimensions)
        if signature not in seen:
            seen.add(signature)
            rows.append(row)
    design = pd.DataFrame(rows)
    design.insert(0, "spec_id", [f"s{i:04d}" for i in range(len(design))])
    return design


def simulation_overrides(row: dict, space: Space, method: str) -> list[str]:
    """Hydra overrides of one method's family run for a specification's simulation choices."""
    overrides = [f"method={method}", "scenario=family",
                 f"scenario.family.size={space.family_size}"]
    keys = {d.target for d in space.dimensions}
    if "scenario.family.seed" not in keys:
        overrides.append(f"scenario.family.seed={space.family_seed}")
    for dim in space.of("simulation"):
        value = row[dim.key]
        if dim.applies_to and method not in dim.applies_to:
            if dim.cap and method == "baseline_matched":
                overrides.append(f"planner.step_size={_hydra_value(value)}")
            continue
        overrides.append(f"{dim.target}={_hydra_value(value)}")
    return overrides


def family_config(row: dict, space: Space, method: str, compose) -> ExperimentConfig:
    """One method's family configuration for a specification's simulation choices, its lateral
    MPC on ``space.backend`` (a condensed-QP MPC only; other controllers keep their own, and
    an explicit ``controller.backend`` among the run overrides wins: they come last)."""
    overrides = simulation_overrides(row, space, method)
    cfg = compose(overrides)
    if cfg.controller.kind == "mpc" and cfg.controller.formulation == "condensed" \
            and cfg.controller.backend != space.backend:
        cfg = compose(overrides + [f"controller.backend={space.backend}"])
    return cfg


def qp_backend(cfg: ExperimentConfig) -> str:
    """The QP backend a run's controller solves with (``no QP`` for a pure pursuit)."""
    return cfg.controller.backend if cfg.controller.kind in ("mpc", "kinematic_mpc") \
        else "no QP"


def _hydra_value(value) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def value_text(value) -> str:
    """A dimension value as text, None and NaN alike as "null" (a design table turns None in a
    column of numbers into NaN)."""
    if value is None or (isinstance(value, float) and value != value):
        return "null"
    return str(value)


def matches(column: pd.Series, value) -> pd.Series:
    """Rows of a design column that hold ``value``."""
    return column.map(value_text) == value_text(value)


def simulation_key(row: dict, space: Space) -> tuple:
    return tuple(str(row[d.key]) for d in space.of("simulation"))


def analysis_settings(row: dict, space: Space, base: ExperimentConfig
                      ) -> tuple[MetricsConfig, ClaimsConfig]:
    """The metric and statistics settings of one specification: the settings the runs were made
    with (``base``, the user's configuration) with the specification's analysis choices."""
    metrics, claims, scale = {}, {}, 1.0
    for dim in space.of("analysis"):
        section, _, name = dim.target.partition(".")
        value = None if value_text(row[dim.key]) == "null" else row[dim.key]
        if dim.target == "claims.margin_scale":
            scale = float(value)
        elif section == "metrics":
            metrics[name] = value
        else:
            claims[name] = value
    margins = {k: v * scale for k, v in base.claims.margins.items()}
    return (dataclasses.replace(base.metrics, **metrics),
            dataclasses.replace(base.claims, **{**claims, "margins": margins,
                                                "n_resamples": space.n_resamples,
                                                "min_pairs": space.min_pairs}))


def with_user_defaults(space: Space, base: ExperimentConfig) -> Space:
    """The space with each analysis dimension's default (its first value) set to the user's
    configured value, so that the default specification is the user's configuration."""
    dims = []
    for dim in space.dimensions:
        section, _, name = dim.target.partition(".")
        if dim.stage == "analysis" and dim.target != "claims.margin_scale":
            value = getattr(getattr(base, section), name)
            dim = dataclasses.replace(dim, values=(value,) + tuple(
                v for v in dim.values if str(v) != str(value)))
        dims.append(dim)
    return dataclasses.replace(space, dimensions=tuple(dims))


def _metrics_hash(metrics: MetricsConfig) -> str:
    text = json.dumps(dataclasses.asdict(metrics), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def _family_task(cfg, folder: str) -> str:
    """One family run on a cluster node (resumes by config hash like a local run)."""
    from pipeline.studies.experiment import run_family

    run_family(cfg, Path(folder), progress=False)
    return folder


def run_simulations(design: pd.DataFrame, space: Space, out_dir: Path, compose,
                    log=logger.info, launcher: dict | None = None,
                    methods: tuple[str, ...] = METHODS) -> dict[tuple, dict[str, Path]]:
    """Run every distinct simulation configuration's families (resumed by config hash): here,
    or as a SLURM array when ``launcher`` holds ``hydra/launcher=slurm`` settings.

    Returns
    -------
    folders : dict
        ``simulation key -> {method: family folder}``.
    backends : dict
        ``method -> controller.backend`` of its runs (``a/b`` if they differ; ``no QP`` for
        a controller without one).
    """
    from pipeline.loop.controller import QpCache

    cache = QpCache()
    folders: dict[tuple, dict[str, Path]] = {}
    todo = []
    unique = {}
    for row in design.to_dict("records"):
        unique.setdefault(simulation_key(row, space), row)
    backends: dict[str, set] = {}
    for key, row in unique.items():
        folders[key] = {}
        for method in methods:
            cfg = family_config(row, space, method, compose)
            backends.setdefault(method, set()).add(qp_backend(cfg))
            folder = out_dir / "runs" / method / cfg.config_hash()
            if check(folder, "family", cfg.config_hash(), members=True) is not None \
                    and all(folder != f for _, f in todo):
                todo.append((cfg, folder))
            folders[key][method] = folder
    log(f"{len(unique)} simulation configurations, {len(todo)} family runs to do "
        f"({len(methods) * len(unique) - len(todo)} shared or complete); QP backend: "
        + ", ".join(f"{m} {'/'.join(sorted(b))}" for m, b in backends.items()))
    run_families(todo, out_dir, log, launcher, cache)
    return folders, {m: "/".join(sorted(b)) for m, b in backends.items()}


def run_families(todo: list, out_dir: Path, log=logger.info, launcher: dict | None = None,
                 cache=None, label: str = "family runs") -> None:
    """Run each ``(config, folder)`` family here (one after the other, each on its own joblib
    workers, sharing ``cache``'s compilations), or as one SLURM array when ``launcher`` holds
    ``hydra/launcher=slurm`` settings; complete families are resumed, never redone."""
    from pipeline.loop.controller import QpCache
    from pipeline.studies.experiment import run_family

    if not todo:
        return
    if launcher is not None:
        _run_on_slurm(todo, launcher, out_dir, log)
        return
    from pipeline.studies.progress import Progress

    cache = cache if cache is not None else QpCache()
    with Progress(len(todo), label, "family", every_s=0.0,
                  stream=_LogStream(log)) as bar:
        for cfg, folder in todo:
            run_family(cfg, folder, progress=False, qp_cache=cache)
            bar.update()


class _LogStream:
    """A file-like object that hands each line to ``log`` (plain lines, never a bar)."""

    def __init__(self, log) -> None:
        self.log = log

    def write(self, text: str) -> None:
        if text.strip():
            self.log(text.rstrip("\n"))

    def flush(self) -> None:
        pass

    def isatty(self) -> bool:
        return False


def _run_on_slurm(todo: list, launcher: dict, out_dir: Path, log) -> None:
    """Submit the family runs as one SLURM array and wait (bounded, see pipeline.studies.slurm)."""
    from pipeline.studies.slurm import (executor_for, resume_command,
                                wait_for_tasks, wait_policy)

    executor = executor_for(launcher, out_dir / ".submitit" / "%j")
    jobs = executor.map_array(_family_task, [c for c, _ in todo], [str(f) for _, f in todo])
    log(f"submitted {len(jobs)} family runs to SLURM (array {jobs[0].job_id.split('_')[0]})")
    _, failed = wait_for_tasks(jobs, *wait_policy(launcher))
    if failed:
        lines = [f"error: {len(failed)} of {len(jobs)} family runs did not finish:"]
        lines += [f"  {todo[i][1]}: {reason}" for i, reason in sorted(failed.items())]
        lines.append(f"resume with the same command (complete runs are not redone):\n  "
                     f"{resume_command()}")
        raise IncompleteSweepError("\n".join(lines))


def _rescored_path(folder: Path, metrics: MetricsConfig, out_dir: Path) -> Path:
    return out_dir / "rescored" / f"{folder.parent.name}_{folder.name}_{_metrics_hash(metrics)}.csv"


def rescore_family(folder: Path, readings: list[MetricsConfig], out_dir: Path) -> int:
    """Re-score a family's members under every metric setting in ``readings`` that it was not
    run with and that has no cached table yet, reading each member's trajectory once for all of
    them. Returns the number of member trajectories read."""
    from pipeline.analysis.metrics import compute_metrics_readings
    from pipeline.studies.experiment import trajectory_context

    family = read_family(folder, members=False)
    todo, seen = [], set()
    for metrics in readings:
        key = _metrics_hash(metrics)
        if metrics == family.config.metrics or key in seen:
            continue
        path = _rescored_path(folder, metrics, out_dir)
        reason = check_derived_table(path, {"family": folder})
        if reason is None:
            continue
        if reason != "not computed yet":
            logger.warning("re-scoring %s again: %s", path.name, reason)
        seen.add(key)
        todo.append(metrics)
    if not todo:
        return 0
    context = trajectory_context(family.config)
    rows: list[list[dict]] = [[] for _ in todo]
    reads = 0
    for index, trajectory, previous in member_trajectories(folder):
        reads += 1
        keep = {k: previous.get(k) for k in ("method", "scenario", "track", "config_hash")}
        # every reading of this member in one pass (what no reading changes, computed once)
        for block, scored in zip(rows, compute_metrics_readings(trajectory, context, todo)):
            block.append({"member": index, **scored.to_json(), **keep})
    for block, metrics in zip(rows, todo):
        write_derived_table(_rescored_path(folder, metrics, out_dir), pd.DataFrame(block),
                            {"family": folder})
    return reads


def family_table(folder: Path, metrics: MetricsConfig, out_dir: Path) -> pd.DataFrame:
    """A family's per-member metrics: as run, or re-scored from the stored trajectories with
    other metric settings (cached; :func:`rescore_family` fills the cache in one pass)."""
    family = read_family(folder, members=False)
    if family.config.metrics == metrics:
        return family.table
    cached = _rescored_path(folder, metrics, out_dir)
    if check_derived_table(cached, {"family": folder}) is not None:
        rescore_family(folder, [metrics], out_dir)
    # read back: the same rounding as family_metrics.csv, so a resumed analysis is identical
    return pd.read_csv(cached)


def analyse_specification(row: dict, folders: dict[str, Path], space: Space,
                          out_dir: Path) -> list[dict]:
    """Ledger rows (C0-C5 against each control) of one specification; ``folders`` holds the
    controls' families, then the treatment's (:func:`run_simulations`' order)."""
    treatment = list(folders)[-1]
    base = read_family(folders[treatment], members=False).config
    metrics, claims = analysis_settings(row, space, base)
    tables = {m: family_table(folders[m], metrics, out_dir) for m in folders}
    ledger = family_ledger(tables, claims, improved=treatment,
                           comparisons=tuple(m for m in folders if m != treatment),
                           sensitivity=False)
    return [{"spec_id": row["spec_id"], "claim": r.claim_id, "comparison": r.comparison,
             "metric": r.claim.primary_metric, "estimate": r.result.estimate,
             "ci_low": r.result.ci_low, "ci_high": r.result.ci_high, "p_holm": r.p_holm,
             "prob_improvement": r.result.prob_improvement, "n_pairs": r.result.n_pairs,
             "margin": r.margin, "outcome": str(r.outcome)} for r in ledger]


def robustness(results: pd.DataFrame, design: pd.DataFrame, space: Space
               ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per claim and comparison: outcome shares, label, most influential dimension; and per
    dimension and value: the share of flipped outcomes and the median estimate.

    Returns
    -------
    robustness : DataFrame
    dimensions : DataFrame
    """
    merged = results.merge(design, on="spec_id")
    default_id = design.loc[design["kind"] == "default", "spec_id"].iloc[0]
    rows, dim_rows = [], []
    for (claim, comparison), part in merged.groupby(["claim", "comparison"], sort=False):
        base = part[part["spec_id"] == default_id]
        default_outcome = base["outcome"].iloc[0] if len(base) else "n/a"
        flipped = part["outcome"] != default_outcome
        shares = {f"share_{o}": float(np.mean(part["outcome"] == o)) for o in OUTCOMES}
        agree = 1.0 - float(np.mean(flipped))
        label = "robust" if agree >= space.robust_share else (
            "fragile" if agree < space.fragile_share else "sensitive")
        best, best_key, holds = None, (-1.0, -1.0), []
        for dim in space.dimensions:
            per_value = []
            for value in dim.values:
                subset = part[matches(part[dim.key], value)]
                if not len(subset):
                    continue
                flip_share = float(np.mean(subset["outcome"] != default_outcome))
                estimate = float(np.nanmedian(subset["estimate"])) if \
                    subset["estimate"].notna().any() else float("nan")
                outcomes = subset["outcome"].value_counts()
                supported = float(np.mean(subset["outcome"] == "supported"))
                if supported >= 0.5:
                    holds.append((supported, f"{dim.key}={value_text(value)}"))
                per_value.append((value, flip_share, estimate))
                dim_rows.append({"claim": claim, "comparison": comparison, "dimension": dim.key,
                                 "value": value_text(value), "default": value == dim.default,
                                 "n_specifications": int(len(subset)),
                                 "flipped_share": flip_share, "median_estimate": estimate,
                                 "modal_outcome": outcomes.index[0],
                                 "supported_share": supported})
            if not per_value:
                continue
            influence = max(v[1] for v in per_value)
            estimates = [v[2] for v in per_value if np.isfinite(v[2])]
            spread = (max(estimates) - min(estimates)) if estimates else 0.0
            if (influence, spread) > best_key:
                flips = [str(v[0]) for v in per_value if v[1] >= 0.5 and v[0] != dim.default]
                if not flips and influence > 0:
                    # no value flips most of its specifications: name the one that flips most
                    flips = [str(max(per_value, key=lambda v: v[1])[0])]
                best, best_key = (dim.key, flips, spread), (influence, spread)
        rows.append({"claim": claim, "comparison": comparison,
                     "default_outcome": default_outcome, "agree_share": agree, "label": label,
                     **shares, "n_specifications": int(len(part)),
                     "most_influential": best[0] if best else "",
                     "influence": best_key[0], "flipping_values": ", ".join(best[1]) if best
                     else "", "estimate_spread": best[2] if best else float("nan"),
                     # the choices under which most specifications support the claim
                     "holds_with": "; ".join(f"{name} ({100 * share:.0f} %)" for share, name
                                             in sorted(holds, reverse=True)[:6])})
    return pd.DataFrame(rows), pd.DataFrame(dim_rows)


def specification_curve_figure(results: pd.DataFrame, design: pd.DataFrame, space: Space,
                               claim: str):
    """Specification curve of one claim: estimates with intervals, sorted, coloured by outcome,
    per comparison; below, the indicator matrix of the non-default choices."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colors = {"supported": "#2ca02c", "contradicted": "#d62728", "equivalent": "#7f7f9f",
              "inconclusive": "#e0a000", "mixed": "#9467bd"}
    part = results[results["claim"] == claim].merge(design, on="spec_id")
    comparisons = list(dict.fromkeys(part["comparison"]))
    dims = [d for d in space.dimensions]
    fig, axes = plt.subplots(len(comparisons) + 1, 1, figsize=(11.0, 2.4 * len(comparisons)
                                                                + 0.22 * len(dims) + 1.0),
                             layout="constrained", squeeze=False,
                             gridspec_kw={"height_ratios": [2.2] * len(comparisons)
                                          + [0.22 * len(dims) + 0.4]})
    order = None
    for ax, comparison in zip(axes[:-1, 0], comparisons):
        rows = part[part["comparison"] == comparison].copy()
        if order is None:
            rows = rows.sort_values("estimate", na_position="first").reset_index(drop=True)
            order = rows["spec_id"].tolist()
        else:
            rows = rows.set_index("spec_id").loc[order].reset_index()
        x = np.arange(len(rows))
        for outcome, color in colors.items():
            sel = rows["outcome"] == outcome
            if sel.any():
                ax.vlines(x[sel], rows["ci_low"][sel], rows["ci_high"][sel], color=color,
                          alpha=0.5, lw=1.2)
                ax.scatter(x[sel], rows["estimate"][sel], s=10, color=color, label=outcome,
                           zorder=3)
        default = rows.index[rows["kind"] == "default"]
        if len(default):
            ax.axvline(default[0], color="k", lw=0.8, ls=":", label="default")
        ax.axhline(0.0, color="k", lw=0.6)
        margin = float(rows["margin"].iloc[0]) if len(rows) else 0.0
        ax.axhspan(-margin, margin, color="#dddddd", alpha=0.5, lw=0)
        ax.set_ylabel(f"d vs {comparison}", fontsize=8)
        ax.set_xlim(-1, len(rows))
        ax.set_xticks([])
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=7, ncol=5, loc="upper left")
    first = axes[0, 0]
    first.set_title(f"{claim}: specification curve over {len(order or [])} specifications "
                    "(estimate d = improved - comparison, 95 % CI; grey band: margin)",
                    fontsize=9)
    matrix = axes[-1, 0]
    spec_rows = design.set_index("spec_id").loc[order or []]
    for i, dim in enumerate(dims):
        changed = ~matches(spec_rows[dim.key], dim.default)
        xs = np.nonzero(changed.to_numpy())[0]
        matrix.scatter(xs, np.full(xs.size, i), marker="|", s=40, color="#1f77b4")
    matrix.set_yticks(range(len(dims)))
    matrix.set_yticklabels([d.key for d in dims], fontsize=6)
    matrix.set_ylim(-0.7, len(dims) - 0.3)
    matrix.set_xlim(-1, len(order or []))
    matrix.set_xlabel("specifications, sorted by the estimate against the first comparison; "
                      "a mark: a choice away from its default", fontsize=7)
    matrix.tick_params(axis="x", labelsize=7)
    return fig


def run_multiverse(space: Space, out_dir: Path, overrides: list[str] | None = None,
                   n_jobs: int = 2, log=None) -> pd.DataFrame:
    """Design, runs, re-scoring, analysis and figures; returns the robustness table
    (``log``: where progress lines go, the module's logger by default)."""
    from joblib import Parallel, delayed

    log = log if log is not None else logger.info
    from pipeline.studies.progress import Progress

    from pipeline.reporting.figures import FigureWriter

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    untrust(out_dir)  # tables being rewritten: not trusted until the manifest is written last
    compose, launcher = composer(list(overrides or []))
    # the default specification is the user's configuration (its analysis settings)
    base = compose(["method=improved", "scenario=family"])
    space = with_user_defaults(space, base)
    design = build_design(space)
    write_csv_atomic(out_dir / "design.csv", design)
    # validate every composition before anything runs: a bad value stops here
    for row in design.to_dict("records"):
        analysis_settings(row, space, base)
    # what is compared with what: the user's claims.treatment and claims.controls (last: the
    # treatment)
    methods = tuple(base.claims.controls) + (base.claims.treatment,)
    folders, backends = run_simulations(design, space, out_dir, compose, log, launcher, methods)
    jobs = [(row, folders[simulation_key(row, space)]) for row in design.to_dict("records")]
    # every metric reading a family needs, computed in one pass over its members (each member
    # read once per analysis, not once per reading)
    readings: dict[Path, list[MetricsConfig]] = {}
    for row, family_folders in jobs:
        metrics, _ = analysis_settings(row, space, base)
        for folder in family_folders.values():
            readings.setdefault(Path(folder), []).append(metrics)
    members = sum(len(read_family(f, members=False).table) for f in readings)
    log(f"re-scoring {members} members of {len(readings)} families under their metric "
        "readings ...")
    reads = 0
    with Progress(len(readings), "re-scoring", "family", stream=_LogStream(log)) as bar:
        for n_read in Parallel(n_jobs=n_jobs, return_as="generator_unordered")(
                delayed(rescore_family)(folder, wanted, out_dir)
                for folder, wanted in readings.items()):
            reads += n_read
            bar.update()
    log(f"re-scoring: {reads} member trajectories read for {members} members "
        f"({len(readings)} families)")
    log(f"judging {len(jobs)} specifications ...")
    results = Parallel(n_jobs=n_jobs)(
        delayed(analyse_specification)(row, f, space, out_dir) for row, f in jobs)
    rows = [r for block in results for r in block]
    table = pd.DataFrame(rows).merge(design, on="spec_id")
    write_csv_atomic(out_dir / "specifications.csv", table)
    robust, dims = robustness(pd.DataFrame(rows), design, space)
    write_csv_atomic(out_dir / "robustness.csv", robust)
    write_csv_atomic(out_dir / "dimensions.csv", dims)
    write_json_atomic(out_dir / "space.json", {
        "name": space.name, "n_specifications": int(len(design)),
        "n_simulation_configurations": len(folders), "family_size": space.family_size,
        "backend": space.backend, "backends": backends,
        "member_reads_per_member": reads / members if members else 0.0,
        "rule": ROBUSTNESS_RULE, "robust_share": space.robust_share,
        "fragile_share": space.fragile_share,
        "dimensions": [{"key": d.key, "config_key": d.target, "stage": d.stage,
                        "values": [str(v) for v in d.values],
                        "applies_to": list(d.applies_to or []), "why": d.why}
                       for d in space.dimensions]})
    with FigureWriter() as writer:  # drawn in forked children, all on disk after the block
        for claim in ALL_CLAIMS:
            fig = specification_curve_figure(pd.DataFrame(rows), design, space, claim.claim_id)
            writer.save(fig, out_dir / "figures", f"specification_curve_{claim.claim_id}")
    # written last: the report trusts these tables only when they match it
    write_manifest(out_dir, "multiverse", MULTIVERSE_FILES, space.name)
    return robust


def composer(extra: list[str]):
    """A function composing one run's config (with ``extra`` overrides), and the SLURM
    launcher's settings when ``extra`` selects ``hydra/launcher=slurm`` (else None)."""
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from pipeline.config import register_configs, to_experiment_config, typed_config
    from pipeline.studies.slurm import register_launcher

    register_configs()
    register_launcher()
    # Hydra's own settings stay out of a run's config, except the search path: a user's config
    # folder (their own method) must be found when composing every run
    run_overrides = [o for o in extra if not o.startswith(("hydra/", "hydra."))
                     or o.startswith("hydra.searchpath")]
    launcher = None
    if any(o.startswith("hydra/launcher=slurm") for o in extra):
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
            full = compose(config_name="config", overrides=extra, return_hydra_config=True)
        launcher = OmegaConf.to_container(full.hydra.launcher, resolve=False)

    from hydra.core.override_parser.overrides_parser import OverridesParser

    parser = OverridesParser.create()
    # Hydra composes the defaults list and merges every config file on each call, and the
    # typed schema checks every node (together most of a second); the runs of a multiverse or
    # a tuning differ mostly in values. So each set of structural overrides (config groups,
    # Hydra's own, additions, deletions) is composed and typed once, and a run's plain
    # `dotted.key=value` overrides are set on a copy of the typed config (OmegaConf.update,
    # merge=True, as Hydra applies them after composing; the schema checks their types).
    # Anything else, a config with interpolations, or any failure takes Hydra's whole path.
    typed_bases: dict[tuple, Any] = {}

    def hydra_compose(overrides: list[str]):
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
            return compose(config_name="config", overrides=overrides)

    def typed_base(structural: tuple):
        if structural not in typed_bases:
            cfg = hydra_compose(list(structural))
            # an interpolation could read a key a run overrides: only plain values are shared
            plain = OmegaConf.to_container(cfg, resolve=False) \
                == OmegaConf.to_container(cfg, resolve=True)
            typed_bases[structural] = typed_config(cfg) if plain else None
        return typed_bases[structural]

    def make(overrides: list[str]):
        every = list(overrides) + run_overrides
        values = [o for o in every if _is_value_override(o)]
        base = typed_base(tuple(o for o in every if not _is_value_override(o)))
        if base is not None:
            try:
                parsed = parser.parse_overrides(values)
                if not any(o.is_sweep_override() for o in parsed):
                    cfg = copy.deepcopy(base)
                    for override in parsed:
                        OmegaConf.update(cfg, override.key_or_group, override.value(),
                                         merge=True)
                    return OmegaConf.to_object(cfg)
            except Exception:  # noqa: BLE001 - whatever is wrong, Hydra's path says it
                pass
        fallbacks.append(every)
        return to_experiment_config(hydra_compose(every))

    fallbacks: list[list[str]] = []
    # for inspection (tests): the structures Hydra composed, the runs that took its whole path
    make.typed_bases, make.fallbacks = typed_bases, fallbacks
    return make, launcher


def _is_value_override(text: str) -> bool:
    """``dotted.key=value`` without a prefix: a value Hydra applies after composing (not a
    config group, an addition, a deletion or one of Hydra's own settings)."""
    key = text.split("=", 1)[0]
    return "=" in text and "." in key and not key.startswith(("+", "~", "hydra")) \
        and not any(ch in key for ch in "/@")
