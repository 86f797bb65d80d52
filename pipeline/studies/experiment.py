"""One closed-loop run and one scenario family, as plain functions over typed configs.

``run_experiment`` simulates one configuration and writes its run folder (through
:mod:`pipeline.store`); ``run_family`` does so for every member of a scenario family, in
parallel. The Hydra entry point is :mod:`pipeline.run`.
"""

from __future__ import annotations

import functools
import gc
import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.analysis.metrics import RunMetrics, compute_metrics
from pipeline.analysis.metrics.context import trajectory_context
from pipeline.analysis.tally import Tally
from pipeline.config import ExperimentConfig
from pipeline.loop.controller import QpCache
from pipeline.loop.model import build_lateral_model, vehicle_key
from pipeline.loop.scenario import Scenario, build_scenario, family_members
from pipeline.loop.simulate import SimulationResult, simulate
from pipeline.store.files import clean_leftovers
from pipeline.store.manifest import check
from pipeline.store.member_cache import MemberCache, MemberCounts
from pipeline.store.runs import (
    RunInfo,
    read_member_rows,
    read_metrics_json,
    write_family,
    write_run,
)

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RunSummary:
    """What one run produced: its folder, metrics and bookkeeping, and whether it was already
    complete (resume)."""

    out_dir: Path
    metrics: RunMetrics
    info: RunInfo
    skipped: bool

    def flat(self) -> dict:
        """The run's ``metrics.json`` mapping (metrics and bookkeeping)."""
        return {**self.metrics.to_json(), **self.info.to_json()}


def run_experiment(cfg: ExperimentConfig, out_dir: Path, resume: bool = True,
                   qp_cache: QpCache | None = None,
                   scenario: Scenario | None = None, record_horizon: bool = True
                   ) -> RunSummary:
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
    scenario : Scenario, optional
        The scenario to simulate (a CommonRoad file's); by default built from ``cfg.scenario``.
    record_horizon : bool
        Write what each step planned (``horizon.npz``, the report's scenario explorer); a
        tune's training members go without (:attr:`~pipeline.studies.tune.TuneSpace.
        training_horizon`). No other file changes.

    Returns
    -------
    RunSummary
    """
    out_dir = Path(out_dir)
    config_hash = cfg.config_hash()
    if resume:
        resumed = _resumed(cfg, out_dir, config_hash)
        if resumed is not None:
            return resumed

    scenario = scenario if scenario is not None else build_scenario(cfg.scenario)
    qp_cache = qp_cache if qp_cache is not None else QpCache()
    result = simulate(cfg, scenario, qp_cache, record_horizon=record_horizon)
    return record_run(cfg, out_dir, result, qp_cache, config_hash)


def _resumed(cfg: ExperimentConfig, out_dir: Path, config_hash: str) -> RunSummary | None:
    """The summary of a complete run folder of the same config hash (its leftover
    temporaries removed), or None (a folder of other settings or an incomplete one is said
    and run again)."""
    reason = check(out_dir, "run", config_hash)
    if reason is None:
        clean_leftovers(out_dir)  # temporaries of a write killed after the manifest
        previous = read_metrics_json(out_dir)
        return RunSummary(out_dir, RunMetrics.from_json(previous), RunInfo.from_json(previous),
                          skipped=True)
    if reason not in ("not a folder", "empty folder"):
        log.warning("re-running %s: %s", out_dir, reason)
    return None


def measure_run(cfg: ExperimentConfig, out_dir: Path, result: SimulationResult,
                config_hash: str | None = None) -> RunSummary:
    """A simulated run's metrics and bookkeeping, nothing written (a member whose family
    keeps its row, :data:`~pipeline.store.runs.MEMBER_ROWS`; :func:`record_run` writes the
    run folder as well)."""
    config_hash = config_hash if config_hash is not None else cfg.config_hash()
    metrics = compute_metrics(result.table, trajectory_context(cfg), cfg.metrics)
    track = "kinematic" if cfg.controller.kind == "kinematic_mpc" else "lateral"
    info = RunInfo(method=cfg.method_name, scenario=cfg.scenario.name, track=track,
                   config_hash=config_hash, termination=result.termination,
                   compile_count=result.compile_count)
    return RunSummary(Path(out_dir), metrics, info, skipped=False)


def record_run(cfg: ExperimentConfig, out_dir: Path, result: SimulationResult,
               qp_cache: QpCache, config_hash: str | None = None) -> RunSummary:
    """A simulated run's metrics, and its run folder written (:func:`~pipeline.store.runs.
    write_run`): what :func:`run_experiment` does after the closed loop."""
    out_dir = Path(out_dir)
    config_hash = config_hash if config_hash is not None else cfg.config_hash()
    # the model of the nominal speed (model.json), built once per process for a family
    model = qp_cache.memo(("model_json", vehicle_key(cfg.vehicle), cfg.scenario.speed_mps,
                           cfg.scenario.sample_time_s, cfg.model.b2_heading_entry),
                          lambda: build_lateral_model(cfg.vehicle, cfg.scenario.speed_mps,
                                                      cfg.scenario.sample_time_s,
                                                      cfg.model.b2_heading_entry))
    summary = measure_run(cfg, out_dir, result, config_hash)
    metrics, info = summary.metrics, summary.info
    times = result.solve_times_s
    timing = {
        "solve_time_median_s": float(np.median(times)) if times.size else None,
        "solve_time_p95_s": float(np.percentile(times, 95)) if times.size else None,
        "solve_time_max_s": float(np.max(times)) if times.size else None,
        "compile_time_s": result.compile_time_s,
        "solve_times_s": [float(x) for x in times],
    }
    yaml_memo = qp_cache.process_local.setdefault("config_yaml", {})
    write_run(out_dir, config_text=config_yaml(cfg, yaml_memo), model=model.to_json(),
              trajectory=result.table, timing=timing, metrics=metrics, info=info,
              horizon=result.horizon)
    return summary


def run_members(jobs: list[tuple[ExperimentConfig, Path]], qp_cache: QpCache,
                record_horizon: bool = True, record_members: bool = True
                ) -> list[RunSummary]:
    """:func:`run_experiment` for several members at once: those not already complete are
    stepped together by the lockstep engine (:func:`pipeline.loop.engine.simulate_members`),
    then each one's metrics and folder written (``record_members`` false: its metrics alone,
    :func:`measure_run`, for a family that keeps its members' rows). Summaries in the order of
    ``jobs``."""
    from pipeline.loop.engine import simulate_members

    summaries: list[RunSummary | None] = []
    todo: list[tuple[int, ExperimentConfig, Path, str]] = []
    for cfg, out_dir in jobs:
        config_hash = cfg.config_hash()
        summaries.append(_resumed(cfg, Path(out_dir), config_hash))
        if summaries[-1] is None:
            todo.append((len(summaries) - 1, cfg, Path(out_dir), config_hash))
    results = simulate_members([(cfg, build_scenario(cfg.scenario)) for _, cfg, _, _ in todo],
                               qp_cache, record_horizon=record_horizon)
    for (position, cfg, out_dir, config_hash), result in zip(todo, results, strict=True):
        summaries[position] = record_run(cfg, out_dir, result, qp_cache, config_hash) \
            if record_members else measure_run(cfg, out_dir, result, config_hash)
    return [summary for summary in summaries if summary is not None]


def warm_compiled_kernels(configs: list[ExperimentConfig], n_steps: int = 5) -> None:
    """Compile the loop's numba kernels into numba's on-disk cache (:mod:`pipeline.loop.
    compiled`) by running each config's scenario for ``n_steps`` steps with them, as a
    family's workers do: ``make install`` does it once, so that a first ``make reproduce``'s
    eight experiments and their workers load the kernels instead of each compiling them at once
    (measured on a fresh clone: 28 CPU-s)."""
    from dataclasses import replace

    from pipeline.loop.engine import simulate_members

    for cfg in configs:
        short = replace(cfg, scenario=replace(cfg.scenario, n_steps=n_steps))
        scenario = build_scenario(short.scenario)
        # alone and two together: the lockstep engine's batched kernels as well as a lone
        # member's (a worker's task steps its members together)
        simulate(short, scenario, QpCache(compiled_kernels=True))
        simulate_members([(short, scenario), (short, build_scenario(short.scenario))],
                         QpCache(compiled_kernels=True))


def config_yaml(cfg: ExperimentConfig, memo: dict | None = None) -> str:
    """The resolved configuration as YAML (keys in schema order). PyYAML's C dumper: the
    OmegaConf round trip cost more than a member's whole simulation.

    With ``memo`` (a dict of this process), each top-level section's YAML is kept with the
    section object it came from: a family's members share every section but their scenario,
    and a mapping's block YAML is its entries' YAML one after another, so the text is the same
    (tested) at a fraction of the cost (the dump was 6 % of a member's CPU time with DAQP).
    """
    import dataclasses

    import yaml

    dumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)

    def dump(data: dict) -> str:
        return yaml.dump(data, Dumper=dumper, sort_keys=False, default_flow_style=False,
                         allow_unicode=True)

    if memo is None:
        return dump(cfg.to_dict())
    if len(memo) > 1000:  # the scenarios of finished members: let them go
        memo.clear()
    parts = []
    for field in dataclasses.fields(cfg):
        value = getattr(cfg, field.name)
        entry = memo.get((field.name, id(value)))
        if entry is None or entry[0] is not value:
            section = dataclasses.asdict(value) \
                if dataclasses.is_dataclass(value) and not isinstance(value, type) else value
            entry = memo[(field.name, id(value))] = (value, dump({field.name: section}))
        parts.append(entry[1])
    return "".join(parts)


#: Members a process must have run through one cache (over all its families) before its
#: family workers step the plant and roll out the APF with the compiled kernels of
#: :mod:`pipeline.loop.compiled` (the same bits). Measured on the 2-core machine
#: (2026-12-06, default family, Clarabel): numba's import and the kernels' cache loads cost
#: a fresh process about 0.4 CPU-s, and the compiled kernels save 32-37 ms of a member's
#: 100 steps (80-88 ms in CPython, 48-52 ms compiled: the path frame's kernels in CPython
#: alone cost about 0.4 ms a step), so they pay back after 11-13 members. (It was 50 when the
#: saving was the plant's and the APF's alone, about 17 ms a member.)
COMPILED_KERNELS_MIN_MEMBERS = 12


def _run_chunk(jobs: list[tuple[int, ExperimentConfig, Path]], qp_cache: QpCache,
               member_cache: MemberCache | None = None, record_horizon: bool = True,
               parent_pid: int | None = None, record_members: bool = True
               ) -> list[tuple[int, dict]]:
    """Run a few family members in one worker, stepped together (:func:`run_members`), all
    with the compiled QP shipped in ``qp_cache`` (so a worker compiles nothing), and publish
    each new one to ``member_cache`` (``record_horizon``: :func:`run_experiment`'s;
    ``record_members`` false: no run folder and nothing published, the metrics alone, for a
    family that keeps its members' rows); a worker leaves Ctrl-C to ``parent_pid``
    (:func:`~pipeline.errors.leave_interrupts_to`)."""
    from pipeline.errors import leave_interrupts_to

    leave_interrupts_to(parent_pid)
    # loky's worker runs a full gc.collect() after each task (about 0.1 s here, over the ~250k
    # objects of numpy, scipy, cvxpy, numba...); what is alive when a task starts lives for the
    # whole worker (its imports, the kernels), so it is moved out of the collector's scans.
    # Collected first: cyclic garbage of the last task frozen with it was never freed (4 kB a
    # member; a default tune's workers grew past loky's 300 MB leak guard, which restarted
    # them with a warning). After the first freeze this collect scans only the last task's
    # objects: no measurable cost (1,200 members of 150 settings: 30.9 CPU-s against 31.3)
    gc.collect()
    gc.freeze()
    # the chunk's members stepped together by the lockstep engine
    summaries = run_members([(member_cfg, folder) for _, member_cfg, folder in jobs],
                            qp_cache, record_horizon, record_members)
    done = []
    for (index, member_cfg, folder), summary in zip(jobs, summaries, strict=True):
        if member_cache is not None and not summary.skipped and record_members:
            member_cache.publish(member_cfg, folder)
        done.append((index, summary.flat()))
    return done


def _chunks(items: list, n_workers: int, per_worker: int = 4, smallest: int = 2
            ) -> list[list]:
    """Split ``items`` into chunks for ``n_workers`` workers, interleaved so that every chunk
    holds early and late members alike (balanced load).

    One worker: ``per_worker`` chunks. Several: guided sizes, each chunk a ``1 / (2
    n_workers)`` share of the members left (at least ``smallest``), so that the workers, which
    take the chunks in order, start on large ones and end on small ones and no worker idles
    long while another finishes the family's last chunk. With equal chunks a 200-member family
    among walkers ended on one worker for a 25-member chunk: 54-59 s against 46 s guided
    (2026-12-07, the same members back to back). A member's run does not depend on its
    chunk (the engine steps each as alone)."""
    n = max(1, min(len(items), max(n_workers, 1) * per_worker))
    if n_workers <= 1:
        return [items[i::n] for i in range(n) if items[i::n]]
    interleaved = [item for i in range(n) for item in items[i::n]]
    chunks, start = [], 0
    while start < len(interleaved):
        size = max(smallest, math.ceil((len(interleaved) - start) / (2 * n_workers)))
        chunks.append(interleaved[start:start + size])
        start += size
    return chunks


def run_family(cfg: ExperimentConfig, out_dir: Path, progress: bool = True,
               qp_cache: QpCache | None = None, member_cache: MemberCache | None = None,
               counts: MemberCounts | None = None, record_horizon: bool = True,
               record_members: bool = True) -> pd.DataFrame:
    """Run every member of ``cfg.scenario.family`` (in parallel with joblib) for one method.

    The QP is compiled once, here, and handed to the workers with their members (chunks of
    members per task, so a worker's process start and imports are paid once per family, and
    loky keeps its workers for the next family of the same process). Each member gets a
    complete run folder ``member_<index>/``; the family folder receives ``family_metrics.csv``
    (one row per member) and ``family.json`` (counts, compilations, config hash). Members
    already complete with the same config hash are not simulated again, nor are those found
    in ``member_cache`` (:mod:`pipeline.store.member_cache`; by default the one
    ``PIPELINE_MEMBER_CACHE`` names), which receives every member simulated here. Where the
    members came from is added to ``counts`` and written into the family's ``timing.json``.
    ``record_horizon``: whether new members write what each step planned
    (:func:`run_experiment`). ``record_members`` false: the members get no run folder and no
    member-cache entry; the family keeps each one's metrics in ``members.jsonl``
    (:data:`~pipeline.store.runs.MEMBER_ROWS`), from which a later run of the same folder
    takes them (a tune's training families: only their metrics are ever read).

    Returns
    -------
    pandas.DataFrame
        The per-member metrics table.
    """
    from joblib import Parallel, delayed

    from pipeline.errors import workers_start_deaf_to_ctrl_c
    from pipeline.studies.progress import Progress

    out_dir = Path(out_dir)
    family = cfg.scenario.family
    if family is None:
        raise ValueError(f"scenario {cfg.scenario.name} is not a family (scenario.family)")
    members = family_members(cfg.scenario, cfg.vehicle.footprint_radius_m)
    cache = qp_cache if qp_cache is not None else QpCache()
    member_cache = member_cache if member_cache is not None else MemberCache.from_env()
    compiles_before = cache.compile_count
    metrics_by_index, pending, here = _members_to_run(cfg, members, out_dir, member_cache, cache,
                                                      record_members)
    if counts is not None:
        counts.add(here)
    _prepare_cache(cfg, cache, len(pending))
    chunks = _chunks(pending, family.n_jobs)
    with workers_start_deaf_to_ctrl_c():  # the workers start with Ctrl-C blocked
        results = Parallel(n_jobs=family.n_jobs, return_as="generator_unordered")(
            delayed(_run_chunk)(chunk, cache, member_cache, record_horizon, os.getpid(),
                                record_members)
            for chunk in chunks)
    with Progress(len(members), f"{cfg.method_name} family", "scenario",
                  initial=len(members) - len(pending), disable=not progress) as bar:
        try:
            for done in results:
                for index, metrics in done:
                    metrics_by_index[index] = metrics
                bar.update(len(done))
        except BaseException:
            # stopped (a signal, an error): joblib has ended the workers, some perhaps in the
            # middle of an atomic write; their temporaries go, the complete members stay
            _clean_family_leftovers(out_dir)
            raise
    table = _member_table(metrics_by_index, len(members))
    _write_family_folder(cfg, out_dir, table, len(members),
                         cache.compile_count - compiles_before, here,
                         None if record_members else metrics_by_index)
    return table


def _clean_family_leftovers(out_dir: Path) -> None:
    """The hidden temporaries of killed writes (:func:`clean_leftovers`) in a family's folder
    and its members' folders; only once no worker is left writing."""
    for folder in (Path(out_dir), *Path(out_dir).glob("member_*")):
        clean_leftovers(folder)


def _members_to_run(cfg: ExperimentConfig, members: list, out_dir: Path,
                    member_cache: MemberCache | None = None, qp_cache: QpCache | None = None,
                    record_members: bool = True, indices: list[int] | None = None
                    ) -> tuple[dict[int, dict], list[tuple[int, ExperimentConfig, Path]],
                               MemberCounts]:
    """The metrics of the members already complete (same config hash) or restored from
    ``member_cache``, by index, the ``(index, config, folder)`` of those still to run, and
    how many came from where. ``record_members`` false (a family that keeps its members'
    rows): a member is also complete when the folder's family record holds its row (a
    tune's earlier rung), one in the member cache gives its metrics without a copy, and the
    record's rows beyond the family's size come along (by their indices: :func:`rows_beyond`).
    ``indices``: the members' indices when ``members`` is a part of the family (a worker's
    task, :mod:`pipeline.studies.family_pool`; the rows beyond are then the record's
    business), else ``0, 1, ...``."""
    metrics_by_index: dict[int, dict] = {}
    pending = []
    counts = MemberCounts()
    memo = (qp_cache if qp_cache is not None else QpCache()).process_local.setdefault(
        "config_yaml", {})
    hashes = cfg.member_config_hashes(members)
    rows = {} if record_members else read_member_rows(out_dir)
    if indices is None:
        indices = list(range(len(members)))
        metrics_by_index.update(rows_beyond(rows, len(members)))
    for i, member, member_hash in zip(indices, members, hashes, strict=True):
        member_cfg = cfg.with_member(member, member_hash)
        folder = out_dir / f"member_{i:04d}"
        row = rows.get(i)
        if row is not None and row.get("config_hash") == member_hash:
            metrics_by_index[i] = row
            counts.resumed += 1
            continue
        reason = check(folder, "run", member_hash)
        if reason is None:
            metrics_by_index[i] = read_metrics_json(folder)
            counts.resumed += 1
            continue
        if member_cache is not None and not record_members:
            cached = member_cache.metrics(member_cfg, member_hash)
            if cached is not None:
                metrics_by_index[i] = cached
                counts.reused += 1
                continue
        elif member_cache is not None and member_cache.restore(
                member_cfg, folder, functools.partial(config_yaml, member_cfg, memo),
                member_hash):
            metrics_by_index[i] = read_metrics_json(folder)
            counts.reused += 1
            continue
        if reason not in ("not a folder", "empty folder"):
            log.warning("re-running %s: %s", folder, reason)
        pending.append((i, member_cfg, folder))
    counts.simulated = len(pending)
    return metrics_by_index, pending, counts


def rows_beyond(rows: dict[int, dict], n_members: int) -> dict[int, dict]:
    """The rows of a family record's members beyond ``n_members`` (a later rung of the same
    setting, written first: a trial asked again at an earlier rung): kept with a family's
    record, so that no later rung simulates them again."""
    return {i: row for i, row in rows.items() if i >= n_members}


def _prepare_cache(cfg: ExperimentConfig, cache: QpCache, n_pending: int) -> None:
    """Compile the QP once, in the parent (when a member is to run), and switch the cache to
    the compiled kernels once this process has planned enough members."""
    from pipeline.loop.controller import make_controller

    if n_pending:
        make_controller(cfg, cfg.scenario.sample_time_s, cache)  # compile once, in the parent
    # the plant and the APF rollout as compiled kernels (the same bits) once this process has
    # runs enough to pay numba's import and cache load in its workers (kept for later families)
    cache.members_planned += n_pending
    if cache.members_planned >= COMPILED_KERNELS_MIN_MEMBERS:
        cache.compiled_kernels = True


def _member_table(metrics_by_index: dict[int, dict], n_members: int) -> pd.DataFrame:
    """The per-member metrics table, one row per member in index order."""
    rows = [{"member": i, **metrics_by_index[i]} for i in range(n_members)]
    table = pd.DataFrame(rows)
    # fixed column order: fresh and resumed (read back from metrics.json) members agree
    return table[["member"] + sorted(c for c in table.columns if c != "member")]


def _write_family_folder(cfg: ExperimentConfig, out_dir: Path, table: pd.DataFrame,
                         n_members: int, parent_compiles: int,
                         counts: MemberCounts | None = None,
                         member_rows: dict[int, dict] | None = None) -> None:
    """Write the family folder: its table, its counts and the compilations of this process;
    ``member_rows`` (members without run folders): each member's metrics by index (and those
    of the folder's earlier record beyond the family's size, :func:`_members_to_run`'s), kept
    in the family's ``members.jsonl`` instead of its members' folders."""
    family = cfg.scenario.family
    if family is None:
        raise ValueError(f"scenario {cfg.scenario.name} is not a family (scenario.family)")
    member_compiles = int(table["compile_count"].fillna(0).sum()) if "compile_count" in table \
        else 0
    tally = Tally.of(table)
    summary = {
        "method": cfg.method_name, "scenario": cfg.scenario.name, "seed": family.seed,
        "size": family.size, "config_hash": cfg.config_hash(),
        "collisions": tally.collisions, "not_recovered": tally.not_recovered,
        "goal_not_reached": tally.goal_not_reached, "fallback_steps": tally.fallback_steps,
    }
    # compilations depend on the process (a resumed family compiles again): kept apart
    timing: dict[str, object] = {"compiles": parent_compiles + member_compiles}
    if counts is not None:
        timing["member_cache"] = counts.to_json()
    if member_rows is not None:
        write_family(out_dir, table, summary, cfg.config_hash(), [], timing=timing,
                     member_rows=[{"member": i, **member_rows[i]} for i in sorted(member_rows)])
        return
    write_family(out_dir, table, summary, cfg.config_hash(),
                 [out_dir / f"member_{i:04d}" for i in range(n_members)], timing=timing)


def run_families_together(todo: list[tuple[ExperimentConfig, Path]],
                          qp_cache: QpCache | None = None,
                          member_cache: MemberCache | None = None,
                          counts: MemberCounts | None = None,
                          record_horizon: bool = True, record_members: bool = True) -> None:
    """Run several families' members in one pool of workers (a tuning batch: a few small
    families, one after the other, would leave the cores idle between them) and write each
    family folder as soon as its last member is in, while the others still run. Resumes and
    restores members like :func:`run_family`; the families' ``n_jobs`` is the largest of
    theirs.
    """
    from joblib import Parallel, delayed

    from pipeline.errors import workers_start_deaf_to_ctrl_c

    if not todo:
        return
    cache = qp_cache if qp_cache is not None else QpCache()
    member_cache = member_cache if member_cache is not None else MemberCache.from_env()
    compiles_before = cache.compile_count
    n_jobs = max((cfg.scenario.family.n_jobs for cfg, _ in todo if cfg.scenario.family), default=1)
    states, work = [], []
    for k, (cfg, folder) in enumerate(todo):
        if cfg.scenario.family is None:
            raise ValueError(f"scenario {cfg.scenario.name} is not a family (scenario.family)")
        members = family_members(cfg.scenario, cfg.vehicle.footprint_radius_m)
        done, pending, here = _members_to_run(cfg, members, Path(folder), member_cache, cache,
                                              record_members)
        if counts is not None:
            counts.add(here)
        _prepare_cache(cfg, cache, len(pending))
        states.append((cfg, Path(folder), len(members), done, here, len(pending)))
        work += [(k, job) for job in pending]
    compiles = cache.compile_count - compiles_before
    left = [state[5] for state in states]

    def finish(k: int) -> None:
        cfg, folder, n_members, done, here, _ = states[k]
        _write_family_folder(cfg, folder, _member_table(done, n_members), n_members,
                             compiles if k == 0 else 0, here,
                             None if record_members else done)

    for k, n_left in enumerate(left):
        if n_left == 0:
            finish(k)
    if not work:
        return
    chunks = _chunks(work, n_jobs)
    with workers_start_deaf_to_ctrl_c():  # the workers start with Ctrl-C blocked
        results = Parallel(n_jobs=n_jobs, return_as="generator_unordered")(
            delayed(_run_tagged_chunk)(chunk, cache, member_cache, record_horizon,
                                       record_members)
            for chunk in chunks)
    _collect_blocks(results, states, left, finish)


def _collect_blocks(results, states: list, left: list[int], finish) -> None:
    """:func:`run_families_together`'s results as they come: each member's metrics into its
    family, a family finished when its last member is in; stopped, no temporary of a killed
    worker stays in any family's folder (as in :func:`run_family`)."""
    try:
        for block in results:
            for k, index, metrics in block:
                states[k][3][index] = metrics
                left[k] -= 1
                if left[k] == 0:
                    finish(k)
    except BaseException:
        for state in states:
            _clean_family_leftovers(state[1])
        raise


def _run_tagged_chunk(jobs: list[tuple[int, tuple[int, ExperimentConfig, Path]]],
                      qp_cache: QpCache, member_cache: MemberCache | None,
                      record_horizon: bool = True, record_members: bool = True
                      ) -> list[tuple[int, int, dict]]:
    """:func:`_run_chunk` over members of several families (tagged with their family)."""
    done = _run_chunk([job for _, job in jobs], qp_cache, member_cache, record_horizon,
                      record_members=record_members)
    return [(k, index, metrics) for (k, _), (index, metrics) in zip(jobs, done, strict=True)]
