"""The multiverse's runs: every distinct simulation configuration's families (resumed by
config hash, here or as a SLURM array), and their members re-scored under other metric
readings (cached beside the study, read back as the family tables were written)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pandas as pd

from pipeline.config import ExperimentConfig, MetricsConfig
from pipeline.errors import IncompleteSweepError
from pipeline.store.manifest import check, check_derived_table, write_derived_table
from pipeline.store.member_cache import MemberCache, MemberCounts
from pipeline.store.runs import (
    RunFolderError,
    family_timing,
    member_folders,
    member_settings,
    member_trajectories,
    read_family,
)
from pipeline.studies.multiverse.design import family_config, qp_backend, simulation_key
from pipeline.studies.multiverse.space import METHODS, Space

logger = logging.getLogger("pipeline.studies.multiverse")

def _metrics_hash(metrics: MetricsConfig) -> str:
    text = json.dumps(dataclasses.asdict(metrics), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def _family_task(cfg, folder: str, member_cache: MemberCache | None = None,
                 record_horizon: bool = True, record_members: bool = True) -> str:
    """One family run on a cluster node (resumes by config hash like a local run, shares the
    study's member cache)."""
    from pipeline.studies.experiment import run_family

    run_family(cfg, Path(folder), progress=False, member_cache=member_cache,
               record_horizon=record_horizon, record_members=record_members)
    return folder


def run_simulations(design: pd.DataFrame, space: Space, out_dir: Path,
                    compose: Callable[[list[str]], ExperimentConfig],
                    log: Callable[[str], Any] = logger.info,
                    launcher: dict[str, Any] | None = None,
                    methods: tuple[str, ...] = METHODS,
                    counts: MemberCounts | None = None
                    ) -> tuple[dict[tuple[str, ...], dict[str, Path]], dict[str, str]]:
    """Run every distinct simulation configuration's families (resumed by config hash): here,
    or as a SLURM array when ``launcher`` holds ``hydra/launcher=slurm`` settings. Where their
    members came from is added to ``counts``.

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
    folders: dict[tuple[str, ...], dict[str, Path]] = {}
    todo: list[tuple[ExperimentConfig, Path]] = []
    unique: dict[tuple[str, ...], dict[str, Any]] = {}
    for row in design.to_dict("records"):
        unique.setdefault(simulation_key(row, space), row)
    backends: dict[str, set[str]] = {}
    for key, row in unique.items():
        folders[key] = {}
        for method in methods:
            cfg = family_config(row, space, method, compose)
            backends.setdefault(method, set()).add(qp_backend(cfg))
            folder = out_dir / "runs" / method / cfg.config_hash()
            if family_reason(folder, cfg.config_hash()) is not None \
                    and all(folder != f for _, f in todo):
                todo.append((cfg, folder))
            folders[key][method] = folder
    log(f"{len(unique)} simulation configurations, {len(todo)} family runs to do "
        f"({len(methods) * len(unique) - len(todo)} shared or complete); QP backend: "
        + ", ".join(f"{m} {'/'.join(sorted(b))}" for m, b in backends.items()))
    run_families(todo, out_dir, log, launcher, cache, counts=counts)
    return folders, {m: "/".join(sorted(b)) for m, b in backends.items()}


def family_reason(folder: Path, config_hash: str) -> str | None:
    """Why a family folder cannot be resumed as complete, or None: its manifest, each
    member's record in it, and each member's own files against the member's manifest (a
    member file cut or changed after the family was written sends the family back to
    :func:`run_families`, which simulates that member again and keeps the others)."""
    reason = check(folder, "family", config_hash, members=True)
    if reason is not None:
        return reason
    try:
        members = member_folders(folder)
    except RunFolderError as exc:
        return str(exc)
    for member in members:
        reason = check(member, "run")
        if reason is not None:
            return f"{member.name}: {reason}"
    return None


def run_families(todo: list, out_dir: Path, log=logger.info, launcher: dict | None = None,
                 cache=None, label: str = "family runs", counts: MemberCounts | None = None,
                 member_cache: MemberCache | None = None, record_horizon: bool = True,
                 record_members: bool = True) -> None:
    """Run each ``(config, folder)`` family here (one after the other, each on its own joblib
    workers, sharing ``cache``'s compilations), or as one SLURM array when ``launcher`` holds
    ``hydra/launcher=slurm`` settings; complete families are resumed, never redone, and
    members found in ``member_cache`` (default: ``PIPELINE_MEMBER_CACHE``'s) are restored, not
    simulated. Where the members came from is added to ``counts``. ``record_horizon``: whether
    new members write what each step planned (a tune's training members do not);
    ``record_members`` false: the members get no run folder, each family's record keeps their
    rows (:func:`~pipeline.studies.experiment.run_family`'s)."""
    from pipeline.loop.controller import QpCache
    from pipeline.studies.experiment import run_families_together

    if not todo:
        return
    member_cache = member_cache if member_cache is not None else MemberCache.from_env()
    if launcher is not None:
        _run_on_slurm(todo, launcher, out_dir, log, member_cache, record_horizon,
                      record_members)
        if counts is not None:
            for _, folder in todo:
                counts.add(MemberCounts.from_json(family_timing(folder).get("member_cache")))
        return
    from pipeline.studies.progress import Progress

    cache = cache if cache is not None else QpCache()
    with Progress(len(todo), label, "family", every_s=0.0,
                  stream=_LogStream(log)) as bar:
        # a few families' members in one pool of workers: no idle cores between families
        for start in range(0, len(todo), FAMILIES_PER_POOL):
            group = todo[start:start + FAMILIES_PER_POOL]
            run_families_together(group, cache, member_cache, counts, record_horizon,
                                  record_members)
            bar.update(len(group))


#: Families whose members share one pool of workers (:func:`run_families`): enough to keep
#: the cores busy across a tuning batch, few enough that progress is reported as it goes.
FAMILIES_PER_POOL = 8


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


def _run_on_slurm(todo: list, launcher: dict, out_dir: Path, log,
                  member_cache: MemberCache | None = None, record_horizon: bool = True,
                  record_members: bool = True) -> None:
    """Submit the family runs as one SLURM array and wait (bounded, see pipeline.studies.slurm)."""
    from pipeline.studies.slurm import executor_for, resume_command, wait_for_tasks, wait_policy

    executor = executor_for(launcher, out_dir / ".submitit" / "%j")
    jobs = executor.map_array(_family_task, [c for c, _ in todo], [str(f) for _, f in todo],
                              [member_cache] * len(todo), [record_horizon] * len(todo),
                              [record_members] * len(todo))
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
    todo: list[MetricsConfig] = []
    seen: set[str] = set()
    for metrics in readings:
        key = _metrics_hash(metrics)
        if metrics == family.settings.metrics or key in seen:
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
    rows: list[list[dict]] = [[] for _ in todo]
    reads = 0
    for index, trajectory, previous in member_trajectories(folder):
        reads += 1
        # each member's own settings: a family's members may differ beyond their obstacles
        # (crossings among walkers each have their start and goal)
        context = trajectory_context(member_settings(folder, index))
        keep = {k: previous.get(k) for k in ("method", "scenario", "track", "config_hash")}
        # every reading of this member in one pass (what no reading changes, computed once)
        for block, scored in zip(rows, compute_metrics_readings(trajectory, context, todo), strict=True):
            block.append({"member": index, **scored.to_json(), **keep})
    for block, metrics in zip(rows, todo, strict=True):
        write_derived_table(_rescored_path(folder, metrics, out_dir), pd.DataFrame(block),
                            {"family": folder})
    return reads


def family_table(folder: Path, metrics: MetricsConfig, out_dir: Path) -> pd.DataFrame:
    """A family's per-member metrics: as run, or re-scored from the stored trajectories with
    other metric settings (cached; :func:`rescore_family` fills the cache in one pass)."""
    family = read_family(folder, members=False)
    if family.settings.metrics == metrics:
        return family.table
    cached = _rescored_path(folder, metrics, out_dir)
    if check_derived_table(cached, {"family": folder}) is not None:
        rescore_family(folder, [metrics], out_dir)
    # read back: the same rounding as family_metrics.csv, so a resumed analysis is identical
    return pd.read_csv(cached)
