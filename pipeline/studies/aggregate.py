"""Aggregate a Hydra sweep folder into one table: ``python -m pipeline.aggregate SWEEP_DIR``.

Every job folder (a single run with ``metrics.json``, or a family run with ``family.json`` and
``family_metrics.csv``) becomes one row of ``summary.csv`` with one column per override key
(``swept_keys.json`` says which of them vary) and the job's metrics (medians over the family for
family jobs, plus counts). When improved and baseline jobs can be paired (same values of every
swept key outside ``planner.*`` and the method), ``verdicts.csv`` holds the claim verdicts per
swept value. Figures of metric versus parameter land in ``figures/``. A Hydra callback
(:class:`AggregateCallback`) runs this at the end of every multirun.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml
from hydra.experimental.callback import Callback

from pipeline.store.runs import (check_derived_table, folder_kind, write_csv_atomic,
                                 write_derived_table, write_json_atomic)
from pipeline.analysis.claims import ALL_CLAIMS, family_ledger, single_scenario_outcome
from pipeline.config import ClaimsConfig

log = logging.getLogger(__name__)

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
    except Exception:  # noqa: BLE001 - another sweeper or an unreadable file: no stale check
        return None
    return {frozenset(job) for batch in batches for job in batch}


def job_sources(sweep_dir: Path, jobs: list[Job]) -> dict[str, Path]:
    """The record folders a summary is computed from, by their path in the sweep."""
    return {str(job.folder.relative_to(sweep_dir)): job.folder for job in jobs}


def summary_reason(sweep_dir: Path) -> str | None:
    """Why ``summary.csv`` of ``sweep_dir`` cannot be trusted as it is, or None (its manifest
    matches the table and the jobs now in the folder)."""
    jobs, _ = find_jobs(Path(sweep_dir))
    return check_derived_table(Path(sweep_dir) / "summary.csv", job_sources(sweep_dir, jobs))


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


def _job_row(job: Job, sweep_dir: Path) -> tuple[dict, pd.DataFrame | None, ClaimsConfig]:
    """A job's summary row, its per-member table (families) and the claims settings it was
    run with."""
    from pipeline.store.runs import read_family, read_run

    label = str(job.folder.relative_to(sweep_dir))
    if job.kind == "single":
        record = read_run(job.folder, trajectory=False)
        return ({"job": label, "kind": "single", "status": "ok", **job.overrides,
                 **record.flat_metrics()}, None, record.config.claims)
    family = read_family(job.folder)
    info, table = family.info, family.table
    numeric = table.select_dtypes(include=["number", "bool"]).drop(columns=["member"],
                                                                    errors="ignore")
    medians = {f"{k}": float(v) for k, v in numeric.astype(float).median().items()}
    row = {"job": label, "kind": "family", "status": "ok", **job.overrides, **medians,
           "method": info["method"], "scenario": info["scenario"], "family_seed": info["seed"],
           "family_size": info["size"], "collisions": info["collisions"],
           "not_recovered": info["not_recovered"], "config_hash": info["config_hash"]}
    return row, table, family.config.claims


def aggregate(sweep_dir: Path, baseline_dir: Path | None = None, progress: bool = True,
              figures: bool = True) -> pd.DataFrame:
    """Gather the sweep into ``summary.csv`` (and ``verdicts.csv``, figures) in ``sweep_dir``.

    Parameters
    ----------
    sweep_dir : Path
    baseline_dir : Path, optional
        A baseline job folder (single or family) used to pair improved jobs that have no baseline
        partner inside the sweep (e.g. a sweep over the improved APF's own parameters).
    progress : bool
        Show a tqdm progress bar.
    figures : bool
        Draw metric-vs-parameter figures.

    Returns
    -------
    pandas.DataFrame
        The summary table, one row per job.
    """
    from pipeline.studies.progress import Progress

    from pipeline.store.runs import RunFolderError

    sweep_dir = Path(sweep_dir)
    jobs, skipped = find_jobs(sweep_dir)
    for item in skipped:
        log.warning("aggregate: %s %s: %s", item["status"], item["job"], item["reason"])
    if not jobs:
        raise FileNotFoundError(f"no complete job folders in {sweep_dir}"
                                + (f" ({len(skipped)} passed over: see above)" if skipped
                                   else ""))
    rows, tables, settings = [], {}, {}
    bar = Progress(len(jobs), "aggregate", "job", disable=not progress)
    for job in _counted(jobs, bar):
        try:
            row, table, settings[str(job.folder.relative_to(sweep_dir))] = \
                _job_row(job, sweep_dir)
        except RunFolderError as exc:
            skipped.append({"job": str(job.folder.relative_to(sweep_dir)), "status": "skipped",
                            "reason": str(exc).split(": ", 1)[-1], **job.overrides})
            continue
        rows.append(row)
        if table is not None:
            tables[row["job"]] = table
    # the jobs passed over stand in the summary next to the good ones, with their reason
    summary = pd.DataFrame(rows + skipped)
    write_csv_atomic(sweep_dir / "skipped.csv",
                     pd.DataFrame(skipped, columns=["job", "status", "reason"]
                                  + sorted({k for r in skipped for k in r}
                                           - {"job", "status", "reason"})))
    override_keys = sorted({k for job in jobs for k in job.overrides})
    swept = [k for k in override_keys if k in summary and summary[k].astype(str).nunique() > 1]
    front = ["job", "kind", "status"] + override_keys + (["reason"] if "reason" in summary
                                                         else [])
    summary = summary[front + [c for c in summary.columns if c not in front]]
    write_csv_atomic(sweep_dir / "summary.csv", summary)
    write_json_atomic(sweep_dir / "swept_keys.json", {"override_keys": override_keys,
                                                      "swept_keys": swept})
    # a multirun over methods alone (make reproduce's families) has no swept value to judge
    # verdicts per; the report's claims ledger covers it
    parameter_keys = [k for k in swept if k not in METHOD_KEYS]
    good = summary[summary["status"] == "ok"]
    verdicts = sweep_verdicts(good, tables, swept, baseline_dir, settings) \
        if parameter_keys or baseline_dir is not None else None
    if verdicts is not None:
        write_csv_atomic(sweep_dir / "verdicts.csv", verdicts)
    if figures:
        from pipeline.reporting.figures import save_figure, sweep_figure

        for fig, stem in sweep_figure(good, swept):
            save_figure(fig, sweep_dir / "figures", stem)
    # last: the summary's manifest, tied to the jobs it was computed from (a reader re-aggregates
    # when a job changed, appeared or went, or when the summary was edited)
    write_derived_table(sweep_dir / "summary.csv", summary, job_sources(sweep_dir, jobs))
    return summary


def _group_keys(swept: list[str]) -> list[str]:
    return [k for k in swept if k not in METHOD_KEYS and not k.startswith("planner.")
            and k != "scenario.family.seed"]


def sweep_verdicts(summary: pd.DataFrame, tables: dict, swept: list[str],
                   baseline_dir: Path | None, settings: dict[str, ClaimsConfig]
                   ) -> pd.DataFrame | None:
    """Claim outcomes of each improved job against its baseline partner (the four-outcome rule
    of :mod:`pipeline.analysis.claims`; single scenarios: better / worse / within margin),
    each judged with the claims settings its improved job was run with (``settings``: job
    label -> ClaimsConfig).

    Partners share every swept key outside ``planner.*`` and the method; failing that, the job
    in ``baseline_dir``.
    """
    if "method" not in summary or not settings:
        return None
    # the treatment and its first control, as the jobs' claims settings name them
    first = next(iter(settings.values()))
    treatment, control = first.treatment, first.controls[0]
    improved = summary[summary["method"] == treatment]
    baseline = summary[summary["method"] == control]
    external_row, external_table = None, None
    if baseline_dir is not None and Path(baseline_dir).is_dir():
        kind = "family" if folder_kind(baseline_dir) == "family" else "single"
        external_row, external_table, _ = _job_row(Job(Path(baseline_dir), {}, kind),
                                                   Path(baseline_dir).parent)
    keys = _group_keys(swept) + (["scenario.family.seed"] if "scenario.family.seed" in swept
                                 else [])
    # index the baseline jobs by their values of the pairing keys (first job wins)
    partners: dict[tuple, dict] = {}
    for record in baseline.to_dict("records"):
        partners.setdefault(tuple(str(record.get(k)) for k in keys), record)
    rows = []
    for imp in improved.to_dict("records"):
        base_row = partners.get(tuple(str(imp.get(k)) for k in keys))
        if base_row is not None:
            base_table = tables.get(base_row["job"])
        elif external_row is not None:
            base_row, base_table = external_row, external_table
        else:
            continue
        imp_table = tables.get(imp["job"])
        cfg = settings[imp["job"]]
        swept_values = {k: imp[k] for k in swept if k not in METHOD_KEYS}
        if imp_table is not None and base_table is not None:
            ledger = family_ledger({treatment: imp_table, control: base_table}, cfg,
                                   improved=treatment, comparisons=(control,))
            for r in ledger:
                rows.append({**swept_values, "job": imp["job"], "claim": r.claim_id,
                             "metric": r.claim.primary_metric, "estimate": r.result.estimate,
                             "ci_low": r.result.ci_low, "ci_high": r.result.ci_high,
                             "p_holm": r.p_holm, "verdict": str(r.outcome),
                             "basis": f"family of {r.result.n_pairs}"})
        else:
            for claim in ALL_CLAIMS:
                rows.append({**swept_values, "job": imp["job"], "claim": claim.claim_id,
                             "metric": claim.primary_metric,
                             "estimate": _diff(imp, base_row, claim.primary_metric),
                             "ci_low": np.nan, "ci_high": np.nan, "p_holm": np.nan,
                             "verdict": single_scenario_outcome(claim, base_row, imp,
                                                                cfg.margins[claim.claim_id]),
                             "basis": "single scenario"})
    return pd.DataFrame(rows) if rows else None


def _diff(improved: dict, baseline: dict, key: str) -> float:
    try:
        return float(improved[key]) - float(baseline[key])
    except (TypeError, ValueError, KeyError):
        return float("nan")


class AggregateCallback(Callback):
    """Hydra callback: aggregate the sweep folder when a multirun ends.

    Configured in ``conf/config.yaml`` under ``hydra.callbacks.aggregate``.
    """

    def __init__(self, baseline_dir: str | None = None, figures: bool = True) -> None:
        self.baseline_dir = baseline_dir
        self.figures = figures

    def on_multirun_end(self, config, **kwargs) -> None:
        import logging

        sweep_dir = Path(config.hydra.sweep.dir)
        log = logging.getLogger(__name__)
        try:
            aggregate(sweep_dir, Path(self.baseline_dir) if self.baseline_dir else None,
                      progress=False, figures=self.figures)
            log.info("aggregated %s -> %s", sweep_dir, sweep_dir / "summary.csv")
        except FileNotFoundError as exc:
            log.warning("aggregate skipped: %s", exc)


def _counted(items, bar):
    """Yield ``items``, counting each on ``bar`` (closed at the end)."""
    with bar:
        for item in items:
            yield item
            bar.update()

