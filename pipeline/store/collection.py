"""A set of run folders read together: every trusted run and family under a root, labelled by
what differs between runs of one method, and the settings they were made with.

Reads only through :mod:`pipeline.store.runs`; folders that cannot be trusted (or whose settings
cannot be read) are listed as :class:`~pipeline.store.runs.Skipped` with their reason.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from pipeline.analysis.settings import ClaimsConfig
from pipeline.analysis.validity import VALIDITY_READS, ValidityTable, validity_row
from pipeline.config import ExperimentConfig
from pipeline.errors import RunFolderError
from pipeline.store.layout import OutputsLayout
from pipeline.store.runs import (
    FamilyRecord,
    RunRecord,
    Skipped,
    discover,
    member_trajectories,
    read_family,
    read_run,
)

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class LabelledRun:
    """A trusted run folder (:class:`~pipeline.store.runs.RunRecord`) and its label: the
    method, plus what differs from the other runs of that method and track."""

    label: str
    record: RunRecord

    @property
    def method(self) -> str:
        return self.record.info.method

    @property
    def scenario(self) -> str:
        return self.record.info.scenario

    @property
    def track(self) -> str:
        return self.record.info.track

    @property
    def folder(self) -> Path:
        return self.record.folder

    @property
    def config(self) -> dict:
        """The settings as ``config.yaml`` holds them (for labels, the register, the page)."""
        return self.record.config_data

    @property
    def claims(self) -> ClaimsConfig:
        """The claims settings the run was made with."""
        return self.record.config.claims

    @property
    def trajectory(self) -> pd.DataFrame:
        return self.record.trajectory

    @property
    def timing(self) -> dict:
        return self.record.timing

    def metrics(self) -> dict:
        """Every metric and the run's bookkeeping by name (``metrics.json`` as written), with
        its ``label``."""
        return {**self.record.flat_metrics(), "label": self.label}


@dataclass
class RunCollection:
    """What :func:`load_runs` found.

    Attributes
    ----------
    runs : list of LabelledRun
        Each trusted single-run folder, labelled.
    family_tables : dict of label -> DataFrame
        ``family_metrics.csv`` of each trusted family folder.
    family_info : dict of label -> dict
        ``family.json`` of each family folder (with ``dir``).
    family_settings : dict of label -> ExperimentConfig
        The settings each family was made with.
    """

    runs: list[LabelledRun] = field(default_factory=list)
    family_tables: dict[str, pd.DataFrame] = field(default_factory=dict)
    family_info: dict[str, dict] = field(default_factory=dict)
    family_settings: dict[str, ExperimentConfig] = field(default_factory=dict)

    def claims_settings(self, treatment: str = "improved") -> ClaimsConfig | None:
        """The claims settings the runs were made with: the treatment's family, else its
        paper-scenario run, else the first run or family; None when there is nothing."""
        if treatment in self.family_settings:
            return self.family_settings[treatment].claims
        for run in self.runs:
            if run.method == treatment:
                return run.claims
        if self.family_settings:
            return next(iter(self.family_settings.values())).claims
        return self.runs[0].claims if self.runs else None


def _flatten(config: dict, prefix: str = "") -> dict:
    flat = {}
    for key, value in (config or {}).items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(_flatten(value, name + "."))
        else:
            flat[name] = value
    return flat


def label_by_difference(configs: list[dict], method: str, skip: tuple[str, ...] = (
        "run.", "scenario.name")) -> list[str]:
    """Labels for several runs of one method: the method plus the config values that differ
    between them (at most three, the rest counted)."""
    if len(configs) < 2:
        return [method] * len(configs)
    flats = [_flatten(c) for c in configs]
    keys = sorted({k for f in flats for k in f})
    differing = [k for k in keys if not k.startswith(skip)
                 and len({repr(f.get(k)) for f in flats}) > 1]
    labels = []
    for f in flats:
        parts = [f"{k}={f.get(k)}" for k in differing[:3]]
        more = f", +{len(differing) - 3} more" if len(differing) > 3 else ""
        labels.append(f"{method} ({', '.join(parts)}{more})" if parts else method)
    # identical configs: number them so that no run hides another
    seen: dict[str, int] = {}
    for i, label in enumerate(labels):
        if labels.count(label) > 1:
            seen[label] = seen.get(label, 0) + 1
            labels[i] = f"{label} #{seen[label]}"
    return labels


def load_runs(run_root: Path, skipped: list[Skipped] | None = None) -> RunCollection:
    """Single runs (outside family folders) and per-method family tables under ``run_root``.

    Every folder is read through :mod:`pipeline.store.runs`; folders that cannot be trusted are
    appended to ``skipped`` with their reason. Several runs of one method on one track are all
    kept, labelled by what differs between them (``metrics["label"]``).

    Returns
    -------
    RunCollection
    """
    run_root = Path(run_root)
    skipped = skipped if skipped is not None else []
    if not run_root.is_dir():
        raise FileNotFoundError(f"no complete run folders under {run_root} (no such folder)")
    # the studies and the families of other sections are read by their own sections
    found = discover(run_root, exclude=OutputsLayout.load(run_root).not_main_runs)
    skipped.extend(found.skipped)
    families = []
    for folder in found.families:
        try:
            families.append(read_family(folder))
        except RunFolderError as exc:
            skipped.append(Skipped(folder, str(exc).split(": ", 1)[-1]))
    records = []
    for folder in found.runs:
        try:
            records.append(read_run(folder))
        except RunFolderError as exc:
            skipped.append(Skipped(folder, str(exc).split(": ", 1)[-1]))
    if not records and not families:
        if skipped:
            raise FileNotFoundError(f"no trusted run folders under {run_root} ("
                                    f"{len(skipped)} skipped, e.g. {skipped[0].folder}: "
                                    f"{skipped[0].reason})")
        raise FileNotFoundError(f"no complete run folders (with metrics.json) under {run_root}")
    return RunCollection(_labelled_runs(records), *_labelled_families(families))


def _labelled_runs(records: list[RunRecord]) -> list[LabelledRun]:
    """Runs of the same method and track labelled by what differs between them."""
    groups: dict[tuple[str, str], list[RunRecord]] = {}
    for record in records:
        groups.setdefault((record.info.track, record.info.method), []).append(record)
    labels = {}
    for (_, method), group in groups.items():
        for record, label in zip(group, label_by_difference([r.config_data for r in group],
                                                            method), strict=True):
            labels[id(record)] = label
    return [LabelledRun(labels[id(r)], r) for r in records]


def _labelled_families(families: list[FamilyRecord]
                       ) -> tuple[dict[str, pd.DataFrame], dict[str, dict[str, Any]],
                                  dict[str, ExperimentConfig]]:
    """Each family's table, ``family.json`` (with ``dir``) and settings, by label (families of
    one method labelled by what differs between them)."""
    family_tables: dict[str, pd.DataFrame] = {}
    family_info: dict[str, dict[str, Any]] = {}
    by_method: dict[str, list[FamilyRecord]] = {}
    for family in families:
        by_method.setdefault(family.info.get("method", ""), []).append(family)
    family_settings: dict[str, ExperimentConfig] = {}
    for method, same_method in by_method.items():
        configs = [family.config_data or {} for family in same_method]
        for family, label in zip(same_method, label_by_difference(configs, method), strict=True):
            family_tables[label] = family.table
            family_info[label] = {**family.info, "dir": str(family.folder)}
            if family.config is not None:  # read with its settings: always there
                family_settings[label] = family.config
    return family_tables, family_info, family_settings


#: The methods whose MPC models are checked (the controls and the treatment of the ledger).
VALIDITY_METHODS = ("baseline", "baseline_matched", "improved")


def trusted_families(root: Path) -> list[FamilyRecord]:
    """Every trusted family folder under ``root`` with readable settings (none when ``root``
    is missing; the report's sections list what they skip)."""
    if not Path(root).is_dir():
        return []
    out = []
    for folder in discover(Path(root)).families:
        try:
            family = read_family(folder)
        except RunFolderError:
            continue
        if family.config is not None:
            out.append(family)
    return out


def model_validity_table(layout: OutputsLayout) -> ValidityTable:
    """:class:`~pipeline.analysis.validity.ValidityTable` of ``make reproduce``'s families
    (the layout's :attr:`~pipeline.store.layout.OutputsLayout.validity_sections`, the methods
    of :data:`VALIDITY_METHODS`): each family's member trajectories pooled into one row,
    lateral rows first (path frame first), then the Appendix-A track's."""
    rows = []
    for section in layout.validity_sections:
        for family in trusted_families(layout.folder(section)):
            cfg = family.config
            if cfg is None:  # trusted_families keeps only families with their settings
                continue
            method = family.info.get("method", cfg.method_name)
            if method not in VALIDITY_METHODS or cfg.controller.kind == "pure_pursuit":
                continue
            track = "kinematic" if cfg.controller.kind == "kinematic_mpc" else "lateral"
            frame = cfg.controller.frame if track == "lateral" else "global (LTV)"
            members = ((trajectory, metrics) for _, trajectory, metrics
                       in member_trajectories(family.folder, VALIDITY_READS))
            rows.append(validity_row(track, frame, method, members))
    order = {"lateral": 0, "kinematic": 1}
    rows.sort(key=lambda r: (order.get(r.track, 2), r.frame != "path",
                             VALIDITY_METHODS.index(r.method)))
    return ValidityTable(tuple(rows))


def family_tables_by_method(root: Path, skipped: list[Skipped] | None = None
                            ) -> dict[str, pd.DataFrame]:
    """``{method: family_metrics}`` of every trusted family folder below ``root`` (an
    ablation's or an interpretation variant's); folders that cannot be trusted are logged and
    appended to ``skipped``, and left out. The tables are judged with the claims settings the
    caller passes (the report's: those of its main runs)."""
    skipped = skipped if skipped is not None else []
    tables: dict[str, pd.DataFrame] = {}
    if not Path(root).is_dir():
        return tables
    found = discover(Path(root))
    for item in found.skipped:
        log.warning("ablation: skipped %s: %s", item.folder, item.reason)
        skipped.append(item)
    for folder in found.families:
        try:
            family = read_family(folder, settings=False)
        except RunFolderError as exc:
            log.warning("ablation: skipped %s", exc)
            skipped.append(Skipped(folder, str(exc).split(": ", 1)[-1]))
            continue
        tables[family.info["method"]] = family.table
    return tables


def interpretation_tables(root: Path, skipped: list[Skipped] | None = None
                          ) -> dict[str, dict[str, pd.DataFrame]]:
    """Per interpretation variant (each a folder under ``root``, in name order) its family
    tables by method (:func:`family_tables_by_method`)."""
    root = Path(root)
    variants = sorted(p.name for p in root.iterdir() if p.is_dir()) if root.is_dir() else []
    return {v: family_tables_by_method(root / v, skipped) for v in variants}
