"""Aggregate a Hydra sweep folder into one table: ``python -m pipeline.aggregate SWEEP_DIR``.

Every job folder (a single run with ``metrics.json``, or a family run with ``family.json`` and
``family_metrics.csv``) becomes one row of ``summary.csv`` with one column per override key
(``swept_keys.json`` says which of them vary) and the job's metrics (medians over the family for
family jobs, plus counts). When improved and baseline jobs can be paired (same values of every
swept key outside ``planner.*`` and the method), ``verdicts.csv`` holds the claim verdicts per
swept value (:class:`pipeline.studies.results.SweepSummary`). The command
(:mod:`pipeline.aggregate`) and the sweep's Hydra callback draw the figures of metric versus
parameter.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.analysis.claims import ALL_CLAIMS, family_ledger, single_scenario_outcome
from pipeline.config import ClaimsConfig
from pipeline.store.runs import folder_kind
from pipeline.studies.results.sweep import SweepSummary
from pipeline.studies.sweep_jobs import METHOD_KEYS, Job, find_jobs

log = logging.getLogger(__name__)

def _job_row(job: Job, sweep_dir: Path) -> tuple[dict, pd.DataFrame | None, ClaimsConfig]:
    """A job's summary row, its per-member table (families) and the claims settings it was
    run with."""
    from pipeline.store.runs import RunFolderError, read_family, read_run

    label = str(job.folder.relative_to(sweep_dir))
    if job.kind == "single":
        record = read_run(job.folder, trajectory=False)
        return ({"job": label, "kind": "single", "status": "ok", **job.overrides,
                 **record.flat_metrics()}, None, record.config.claims)
    family = read_family(job.folder)
    if family.config is None:  # read with its settings: there, or RunFolderError
        raise RunFolderError(f"{job.folder}: the family's settings cannot be read")
    info, table = family.info, family.table
    numeric = table.select_dtypes(include=["number", "bool"]).drop(columns=["member"],
                                                                    errors="ignore")
    medians = {f"{k}": float(v) for k, v in numeric.astype(float).median().items()}
    row = {"job": label, "kind": "family", "status": "ok", **job.overrides, **medians,
           "method": info["method"], "scenario": info["scenario"], "family_seed": info["seed"],
           "family_size": info["size"], "collisions": info["collisions"],
           "not_recovered": info["not_recovered"], "config_hash": info["config_hash"]}
    return row, table, family.config.claims


def aggregate(sweep_dir: Path, baseline_dir: Path | None = None, progress: bool = True
              ) -> SweepSummary:
    """Gather the sweep in ``sweep_dir`` into its summary (and verdicts), written there.

    Parameters
    ----------
    sweep_dir : Path
    baseline_dir : Path, optional
        A baseline job folder (single or family) used to pair improved jobs that have no baseline
        partner inside the sweep (e.g. a sweep over the improved APF's own parameters).
    progress : bool
        Show a progress bar.

    Returns
    -------
    SweepSummary
        As written (the figures of metric versus parameter are the command's:
        :func:`pipeline.reporting.figures.sweep_figure`).
    """
    sweep_dir = Path(sweep_dir)
    jobs, skipped = find_jobs(sweep_dir)
    for item in skipped:
        log.warning("aggregate: %s %s: %s", item["status"], item["job"], item["reason"])
    if not jobs:
        raise FileNotFoundError(f"no complete job folders in {sweep_dir}"
                                + (f" ({len(skipped)} passed over: see above)" if skipped
                                   else ""))
    rows, tables, settings = _read_jobs(jobs, sweep_dir, skipped, progress)
    # the jobs passed over stand in the summary next to the good ones, with their reason
    summary = pd.DataFrame(rows + skipped)
    skipped_table = pd.DataFrame(skipped, columns=["job", "status", "reason"]
                                 + sorted({k for r in skipped for k in r}
                                          - {"job", "status", "reason"}))
    override_keys = sorted({k for job in jobs for k in job.overrides})
    swept = [k for k in override_keys if k in summary and summary[k].astype(str).nunique() > 1]
    front = ["job", "kind", "status"] + override_keys + (["reason"] if "reason" in summary
                                                         else [])
    summary = summary[front + [c for c in summary.columns if c not in front]]
    # a multirun over methods alone (make reproduce's families) has no swept value to judge
    # verdicts per; the report's claims ledger covers it
    parameter_keys = [k for k in swept if k not in METHOD_KEYS]
    good = summary[summary["status"] == "ok"]
    verdicts = sweep_verdicts(good, tables, swept, baseline_dir, settings) \
        if parameter_keys or baseline_dir is not None else None
    # last: the summary with its manifest, tied to the jobs it was computed from (a reader
    # refuses it when a job changed, appeared or went, or when the summary was edited)
    return SweepSummary(summary, tuple(override_keys), tuple(swept), verdicts,
                        skipped_table).write(sweep_dir, jobs)


def _read_jobs(jobs: list[Job], sweep_dir: Path, skipped: list[dict], progress: bool
               ) -> tuple[list[dict], dict[str, pd.DataFrame], dict[str, ClaimsConfig]]:
    """Every job's summary row, the per-member tables of the family jobs and the claims
    settings of each job, by job label; a job that cannot be read is appended to
    ``skipped``."""
    from pipeline.store.runs import RunFolderError
    from pipeline.studies.progress import Progress

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
    return rows, tables, settings


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


def _counted(items, bar):
    """Yield ``items``, counting each on ``bar`` (closed at the end)."""
    with bar:
        for item in items:
            yield item
            bar.update()

