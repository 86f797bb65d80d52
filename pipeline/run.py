"""Entry point of one closed-loop run: ``python -m pipeline.run [hydra overrides]``.

``run_experiment`` is the plain function (tests call it); ``main`` wraps it with Hydra and turns
configuration errors into one line on stderr and exit code 2 (set ``HYDRA_FULL_ERROR=1`` for the
full traceback).
"""

from __future__ import annotations

import logging
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import hydra
import numpy as np
import pandas as pd
from omegaconf import DictConfig

from pipeline.config import (ConfigError, ExperimentConfig, register_configs,
                             to_experiment_config)
from pipeline.controller import QpCache
from pipeline.metrics import TrajectoryContext, compute_metrics
from pipeline.model import build_lateral_model
from pipeline.runs import (NonFiniteResultError, check, clean_leftovers, write_family,
                           write_run)
from pipeline.scenario import build_scenario, family_members
from pipeline.simulate import simulate
from pipeline.slurm import register_launcher

log = logging.getLogger(__name__)
CONF_DIR = Path(__file__).resolve().parent.parent / "conf"

# Hydra composes configs in worker processes too (joblib, submitit), which import this module
register_configs()
register_launcher()


@dataclass(frozen=True)
class RunSummary:
    """What one run produced."""

    out_dir: Path
    metrics: dict
    skipped: bool


def run_experiment(cfg: ExperimentConfig, out_dir: Path, resume: bool = True,
                   qp_cache: QpCache | None = None) -> RunSummary:
    """Simulate one configuration and write its run folder.

    Parameters
    ----------
    cfg : ExperimentConfig
    out_dir : Path
        Folder that receives ``config.yaml``, ``model.json``, ``trajectory.csv``,
        ``timing.json`` and ``metrics.json`` (written last, atomically).
    resume : bool
        Skip the simulation when ``out_dir`` already holds complete results of the same config
        hash.
    qp_cache : QpCache, optional
        Compiled QPs shared with other runs of this process (or shipped to a worker).

    Returns
    -------
    RunSummary
    """
    import json

    out_dir = Path(out_dir)
    config_hash = cfg.config_hash()
    if resume:
        reason = check(out_dir, "run", config_hash)
        if reason is None:
            clean_leftovers(out_dir)  # temporaries of a write killed after the manifest
            previous = json.loads((out_dir / "metrics.json").read_text())
            return RunSummary(out_dir, previous, skipped=True)
        if reason not in ("not a folder", "empty folder"):
            log.warning("re-running %s: %s", out_dir, reason)

    scenario = build_scenario(cfg.scenario)
    model = build_lateral_model(cfg.vehicle, cfg.scenario.speed_mps, cfg.scenario.sample_time_s,
                                cfg.model.b2_heading_entry)
    result = simulate(cfg, scenario, qp_cache)
    context = trajectory_context(cfg)
    metrics = compute_metrics(result.trajectory, context, cfg.metrics)
    track = "kinematic" if cfg.controller.kind == "kinematic_mpc" else "lateral"
    metrics.update(method=cfg.method_name, scenario=cfg.scenario.name, track=track,
                   config_hash=config_hash, termination=result.termination,
                   compile_count=result.compile_count)
    times = result.solve_times_s
    timing = {
        "solve_time_median_s": float(np.median(times)) if times.size else None,
        "solve_time_p95_s": float(np.percentile(times, 95)) if times.size else None,
        "solve_time_max_s": float(np.max(times)) if times.size else None,
        "compile_time_s": result.compile_time_s,
        "solve_times_s": [float(x) for x in times],
    }
    write_run(out_dir, config_text=config_yaml(cfg), model=model.to_json(),
              trajectory=result.trajectory, timing=timing, metrics=metrics,
              config_hash=config_hash)
    return RunSummary(out_dir, metrics, skipped=False)


def trajectory_context(cfg: ExperimentConfig) -> TrajectoryContext:
    """Geometry and vehicle limits the metrics need, from the run's configuration."""
    v = cfg.vehicle
    return TrajectoryContext(tuple(cfg.scenario.start_xy_m), tuple(cfg.scenario.goal_xy_m),
                             v.footprint_radius_m, cfg.model.validity_heading_rad,
                             wheelbase_m=v.wheelbase_m, steering_max_rad=v.steering_max_rad,
                             steering_rate_max_rad_s=v.steering_rate_max_rad_s,
                             braking_mps2=v.accel_max_mps2)


def config_yaml(cfg: ExperimentConfig) -> str:
    """The resolved configuration as YAML (keys in schema order). PyYAML's C dumper: the
    OmegaConf round trip cost more than a member's whole simulation."""
    import yaml

    dumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
    return yaml.dump(cfg.to_dict(), Dumper=dumper, sort_keys=False, default_flow_style=False,
                     allow_unicode=True)


def _run_chunk(jobs: list[tuple[int, ExperimentConfig, Path]], qp_cache: QpCache
               ) -> list[tuple[int, dict]]:
    """Run a few family members in one worker, all with the compiled QP shipped in
    ``qp_cache`` (so a worker compiles nothing)."""
    return [(index, run_experiment(member_cfg, folder, qp_cache=qp_cache).metrics)
            for index, member_cfg, folder in jobs]


def _chunks(items: list, n_workers: int, per_worker: int = 4) -> list[list]:
    """Split ``items`` into about ``per_worker`` chunks per worker, interleaved so that every
    chunk holds early and late members alike (balanced load)."""
    n = max(1, min(len(items), n_workers * per_worker))
    return [items[i::n] for i in range(n) if items[i::n]]


def run_family(cfg: ExperimentConfig, out_dir: Path, progress: bool = True,
               qp_cache: QpCache | None = None) -> pd.DataFrame:
    """Run every member of ``cfg.scenario.family`` (in parallel with joblib) for one method.

    The QP is compiled once, here, and handed to the workers with their members (chunks of
    members per task, so a worker's process start and imports are paid once per family, and
    loky keeps its workers for the next family of the same process). Each member gets a
    complete run folder ``member_<index>/``; the family folder receives ``family_metrics.csv``
    (one row per member) and ``family.json`` (counts, compilations, config hash). Members
    already complete with the same config hash are not simulated again.

    Returns
    -------
    pandas.DataFrame
        The per-member metrics table.
    """
    import dataclasses
    import json

    from joblib import Parallel, delayed
    from tqdm import tqdm

    from pipeline.controller import make_controller

    out_dir = Path(out_dir)
    family = cfg.scenario.family
    members = family_members(cfg.scenario, cfg.vehicle.footprint_radius_m)
    cache = qp_cache if qp_cache is not None else QpCache()
    compiles_before = cache.compile_count
    metrics_by_index: dict[int, dict] = {}
    pending = []
    for i, member in enumerate(members):
        member_cfg = dataclasses.replace(cfg, scenario=member)
        folder = out_dir / f"member_{i:04d}"
        reason = check(folder, "run", member_cfg.config_hash())
        if reason is None:
            metrics_by_index[i] = json.loads((folder / "metrics.json").read_text())
            continue
        if reason not in ("not a folder", "empty folder"):
            log.warning("re-running %s: %s", folder, reason)
        pending.append((i, member_cfg, folder))
    if pending:
        make_controller(cfg, cfg.scenario.sample_time_s, cache)  # compile once, in the parent
    chunks = _chunks(pending, family.n_jobs)
    results = Parallel(n_jobs=family.n_jobs, return_as="generator_unordered")(
        delayed(_run_chunk)(chunk, cache) for chunk in chunks)
    with tqdm(total=len(members), initial=len(metrics_by_index), disable=not progress,
              desc=f"{cfg.method_name} family", unit="scenario") as bar:
        for done in results:
            for index, metrics in done:
                metrics_by_index[index] = metrics
            bar.update(len(done))
    rows = [{"member": i, **metrics_by_index[i]} for i in range(len(members))]
    table = pd.DataFrame(rows)
    # fixed column order: fresh and resumed (read back from metrics.json) members agree
    table = table[["member"] + sorted(c for c in table.columns if c != "member")]
    member_compiles = int(table["compile_count"].fillna(0).sum()) if "compile_count" in table \
        else 0
    summary = {
        "method": cfg.method_name, "scenario": cfg.scenario.name, "seed": family.seed,
        "size": family.size, "config_hash": cfg.config_hash(),
        "collisions": int(table["collision"].sum()),
        "not_recovered": int((~table["recovered"].astype(bool)).sum()),
        "goal_not_reached": int((~table["goal_reached"].astype(bool)).sum()),
        "fallback_steps": int(table["fallback_count"].sum()) if "fallback_count" in table else 0,
        "compiles": cache.compile_count - compiles_before + member_compiles,
    }
    write_family(out_dir, table, summary, cfg.config_hash(),
                 [out_dir / f"member_{i:04d}" for i in range(len(members))])
    return table


@hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name="config")
def hydra_main(cfg: DictConfig) -> None:
    """Hydra task: validate, run, log where the results are."""
    from hydra.core.hydra_config import HydraConfig

    try:
        experiment = to_experiment_config(cfg)
    except Exception as exc:  # noqa: BLE001 - config errors become one line; others re-raise
        message = describe_config_error(exc)
        if message is None or os.environ.get("PIPELINE_USER_FULL_ERROR") == "1":
            raise
        # SystemExit passes Hydra's job wrapper untouched: one line, exit code 2
        print(message, file=sys.stderr)
        raise SystemExit(2) from None
    out_dir = Path(HydraConfig.get().runtime.output_dir)
    if experiment.scenario.family is not None:
        table = run_family(experiment, out_dir)
        log.info("%s on %s (%d scenarios): %d collisions, %d not recovered -> %s",
                 experiment.method_name, experiment.scenario.name, len(table),
                 int(table["collision"].sum()), int((~table["recovered"].astype(bool)).sum()),
                 out_dir)
        return
    summary = run_experiment(experiment, out_dir)
    m = summary.metrics
    log.info("%s%s on %s: min clearance %.3f m, collision %s, time to goal %s s -> %s",
             "skipped (complete) " if summary.skipped else "", m["method"], m["scenario"],
             m["min_clearance_m"] if m["min_clearance_m"] is not None else float("nan"),
             m["collision"], m["time_to_goal_s"], out_dir)


def describe_config_error(exc: BaseException) -> str | None:
    """One line for a configuration error, or None if ``exc`` is not one."""
    from hydra.errors import (ConfigCompositionException, MissingConfigException,
                              OverrideParseException)
    from omegaconf.errors import MissingMandatoryValue, OmegaConfBaseException

    chain = []
    current: BaseException | None = exc
    while current is not None and current not in chain:
        chain.append(current)
        current = current.__cause__ or current.__context__
    from pipeline.slurm import IncompleteSweepError

    for err in chain:
        if isinstance(err, (ConfigError, NonFiniteResultError, IncompleteSweepError)):
            return str(err)
    for err in chain:
        if isinstance(err, MissingConfigException):
            missing = err.missing_cfg_file or ""
            group, _, name = missing.rpartition("/")
            options = ", ".join(o for o in (err.options or []) if not o.endswith("_schema"))
            options = options or "see conf/" + group
            if group:
                return (f"config error: {group}={name!r} is not a known option; allowed: "
                        f"{options}")
            return "config error: " + str(err).splitlines()[0]
    for err in chain:
        if isinstance(err, MissingMandatoryValue):
            key = getattr(err, "full_key", None) or "?"
            return f"config error: {key} is missing; allowed: a value (required, set {key}=...)"
        if isinstance(err, OmegaConfBaseException):
            key = getattr(err, "full_key", None) or "?"
            message = str(getattr(err, "msg", err)).splitlines()[0]
            return f"config error: {key}: {message}"
    for err in chain:
        if isinstance(err, (OverrideParseException, ConfigCompositionException)):
            return "config error: " + " ".join(str(err).split())
    return None


def main() -> None:
    """Console entry: run Hydra; configuration errors exit 2 with one line on stderr."""
    original = os.environ.get("HYDRA_FULL_ERROR")
    user_wants_trace = original == "1"
    os.environ["PIPELINE_USER_FULL_ERROR"] = "1" if user_wants_trace else "0"
    os.environ["HYDRA_FULL_ERROR"] = "1"  # let exceptions reach us instead of Hydra's printer
    try:
        hydra_main()
    except Exception as exc:  # noqa: BLE001 - turned into a message and an exit code
        if user_wants_trace:
            raise
        message = describe_config_error(exc)
        if message is not None:
            print(message, file=sys.stderr)
            sys.exit(2)
        if isinstance(exc, OSError) and exc.filename:
            # an output folder that cannot be made or written (a file in the way, no
            # permission, a full disk): the run wrote nothing half-way
            print(f"error: cannot write {exc.filename}: {exc.strerror or exc} (choose another "
                  "output folder with hydra.run.dir=... or hydra.sweep.dir=...)",
                  file=sys.stderr)
            sys.exit(2)
        print(f"error: {type(exc).__name__}: {exc} (set HYDRA_FULL_ERROR=1 for the traceback)",
              file=sys.stderr)
        sys.exit(1)
    finally:
        if original is None:
            os.environ.pop("HYDRA_FULL_ERROR", None)
        else:
            os.environ["HYDRA_FULL_ERROR"] = original


if __name__ == "__main__":
    main()
