"""The jobs of a Hydra sweep folder: which job folders belong to the sweep recorded in
``multirun.yaml``, their overrides, and the ones passed over (stale, copied in, untrusted).

Read by the aggregation (:mod:`pipeline.studies.aggregate`) and by its result's reader
(:class:`pipeline.studies.results.SweepSummary`), which ties the summary to these jobs.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

METHOD_KEYS = ("method", "run.method", "planner")
IGNORED_KEYS = ("sweep", "experiment", "hydra", "hydra.sweep.dir")


@dataclass(frozen=True)
class Job:
    """One job folder of a sweep."""

    folder: Path
    overrides: dict
    kind: str  # "single" or "family"


def _parse_value(text: str) -> Any:
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return text


def read_overrides(folder: Path) -> dict:
    """``key=value`` overrides of a job from ``.hydra/overrides.yaml`` (values parsed as YAML)."""
    path = folder / ".hydra" / "overrides.yaml"
    if not path.is_file():
        return {}
    result = {}
    for item in yaml.safe_load(path.read_text()) or []:
        key, sep, value = str(item).partition("=")
        key = key.lstrip("+~")
        if sep and key not in IGNORED_KEYS and not key.startswith("hydra"):
            result[key] = _parse_value(value)
    return result


def _override_list(path: Path) -> list[str]:
    return [str(item) for item in (yaml.safe_load(path.read_text()) or [])]


def current_sweep_jobs(sweep_dir: Path) -> set[frozenset] | None:
    """The override sets of every job of the sweep recorded in ``multirun.yaml`` (its sweeper
    parameters and command-line overrides, expanded as Hydra's basic sweeper expands them), or
    None when that cannot be told."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from omegaconf import OmegaConf

    path = Path(sweep_dir) / "multirun.yaml"
    if not path.is_file():
        return None
    try:
        config = OmegaConf.load(path)
        params = OmegaConf.select(config, "hydra.sweeper.params") or {}
        task = list(OmegaConf.select(config, "hydra.overrides.task") or [])
        arguments = [f"{k}={v}" for k, v in params.items()] + [str(t) for t in task]
        overrides = OverridesParser.create().parse_overrides(arguments)
        batches = BasicSweeper.split_arguments(overrides, None)
    except Exception:  # another sweeper or an unreadable file: no stale check
        return None
    return {frozenset(job) for batch in batches for job in batch}


def job_sources(sweep_dir: Path, jobs: list[Job]) -> dict[str, Path]:
    """The record folders a summary is computed from, by their path in the sweep."""
    return {str(job.folder.relative_to(sweep_dir)): job.folder for job in jobs}


def find_jobs(sweep_dir: Path) -> tuple[list[Job], list[dict]]:
    """Trusted job folders of the sweep in ``sweep_dir`` (any depth, family members excluded),
    and every folder passed over with its reason.

    A job whose recorded overrides (``.hydra/overrides.yaml``) are not among the jobs of the
    sweep in ``multirun.yaml`` was written by an earlier sweep into the same folder: it is
    flagged stale, not mixed in.
    """
    from pipeline.store.runs import discover

    sweep_dir = Path(sweep_dir)
    found = discover(sweep_dir)
    members = current_sweep_jobs(sweep_dir)
    jobs, skipped = [], []

    def name(folder: Path) -> str:
        return str(folder.relative_to(sweep_dir))

    for item in found.skipped:
        skipped.append({"job": name(item.folder), "status": "skipped", "reason": item.reason,
                        **read_overrides(item.folder)})
    for kind, folders in (("family", found.families), ("single", found.runs)):
        for folder in folders:
            recorded = folder / ".hydra" / "overrides.yaml"
            if members is not None and not recorded.is_file():
                # a job copied in without Hydra's record: which swept values did it run?
                skipped.append({"job": name(folder), "status": "skipped",
                                "reason": "no provenance (.hydra/overrides.yaml): its swept "
                                          "values cannot be told; copied in from elsewhere?"})
                continue
            if members is not None and recorded.is_file() \
                    and frozenset(_override_list(recorded)) not in members:
                skipped.append({"job": name(folder), "status": "stale",
                                "reason": "written by an earlier sweep into this folder; not "
                                          "part of the sweep in multirun.yaml",
                                **read_overrides(folder)})
                continue
            jobs.append(Job(folder, read_overrides(folder), kind))
    jobs.sort(key=lambda j: name(j.folder))
    return jobs, skipped
