"""Compare fresh results with the committed reference (``python -m pipeline.verify RUNS REF``,
the command in :mod:`pipeline.verify`).

``reports/reference/`` holds the summary of the default ``make reproduce``:
``paper_metrics.csv`` (every method and track on the paper scenario) and, when the families
were run, ``claims_ledger.csv`` (the lateral family), ``claims_ledger_kinematic_family.csv``
(the Appendix-A track's family), ``claims_ledger_apf_alone.csv`` (the APF by itself) and ``model_validity.csv`` (does each MPC's model hold, per
track, frame and method). Rows are matched by their key (track and method; claim and
comparison), whatever their order. Numbers must agree within ``rel 1e-6 or abs 1e-6``
(deterministic code; the slack covers floating-point differences between BLAS builds), labels
and verdicts exactly. ``--update`` rewrites the reference (say why in the commit).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import pandas as pd

from pipeline.store.files import write_csv_atomic
from pipeline.store.runs import RunFolderError, discover, read_run

log = logging.getLogger(__name__)

REL_TOL = 1e-6
ABS_TOL = 1e-6
PAPER_FILE = "paper_metrics.csv"
LEDGER_FILE = "claims_ledger.csv"
KINEMATIC_LEDGER_FILE = "claims_ledger_kinematic_family.csv"
APF_ALONE_LEDGER_FILE = "claims_ledger_apf_alone.csv"
VALIDITY_FILE = "model_validity.csv"
#: the column :func:`paper_metrics_table` names each run's folder in (never compared)
RUN_FOLDER = "run_folder"
#: the columns that name a row of each file
KEYS = {PAPER_FILE: ("track", "method"), LEDGER_FILE: ("claim", "comparison"),
        KINEMATIC_LEDGER_FILE: ("claim", "comparison"),
        APF_ALONE_LEDGER_FILE: ("claim", "comparison"),
        VALIDITY_FILE: ("track", "frame", "method")}
LEDGER_COLUMNS = ["claim", "comparison", "metric", "outcome", "estimate", "ci_low", "ci_high",
                  "p_holm", "prob_improvement", "n_better", "n_tied", "n_worse", "n_missing",
                  "n_pairs", "outcome_all_pairs", "paper_scenario"]


def paper_metrics_table(runs_root: Path, with_folders: bool = False) -> pd.DataFrame:
    """One row per (track, method) on the paper scenario, from the trusted runs under
    ``runs_root`` (family members and the study sections the report reads apart excluded:
    sweeps, ablation, multiverse, tuning, the Appendix-A readings); ``with_folders``: a last
    column ``run_folder``, each row's folder relative to ``runs_root`` (the name of an extra
    run)."""
    from pipeline.store.layout import OutputsLayout

    rows = []
    found = discover(runs_root, exclude=OutputsLayout.load(runs_root).not_main_runs)
    for item in found.skipped:
        log.warning("verify: skipped %s: %s", item.folder, item.reason)
    for folder in found.runs:
        try:
            metrics = read_run(folder, trajectory=False).flat_metrics()
        except RunFolderError as exc:
            log.warning("verify: skipped %s", exc)
            continue
        if metrics.get("scenario") != "paper_sudden_obstacle":
            continue
        # the config hash is provenance (it changes with any new config key), not a result
        row = {k: v for k, v in metrics.items() if k not in ("compile_count", "config_hash",
                                                                 "label")}
        if with_folders:
            row[RUN_FOLDER] = _relative(folder, runs_root)
        rows.append(row)
    if not rows:
        raise FileNotFoundError(f"no paper-scenario runs under {runs_root}")
    table = pd.DataFrame(rows).sort_values(["track", "method"]).reset_index(drop=True)
    return table[["track", "method"] + sorted(c for c in table.columns
                                              if c not in ("track", "method", RUN_FOLDER))
                 + ([RUN_FOLDER] if with_folders else [])]


def _relative(folder: Path, root: Path) -> str:
    try:
        return str(Path(folder).relative_to(root))
    except ValueError:
        return str(folder)


def ledger_table(runs_root: Path, kinematic: bool = False, apf_alone: bool = False
                 ) -> pd.DataFrame | None:
    """The family claims ledger, if the family was run (``kinematic``: the Appendix-A
    track's family under ``runs_root/kinematic_family``, without the paper-scenario column;
    ``apf_alone``: the families without the MPC's collision constraints, improved against
    baseline, baseline_matched and no APF)."""
    from pipeline.analysis.claims import family_ledger
    from pipeline.analysis.settings import ClaimsConfig
    from pipeline.store.collection import load_runs
    from pipeline.store.layout import OutputsLayout

    if kinematic or apf_alone:
        runs_root = OutputsLayout.load(runs_root).folder(
            "kinematic_family" if kinematic else "apf_alone")
        if not runs_root.is_dir():
            return None
    collection = load_runs(runs_root)
    tables = collection.family_tables
    if "baseline" not in tables or "improved" not in tables:
        return None
    paper = {}
    try:
        if not kinematic and not apf_alone:
            frame = paper_metrics_table(runs_root)
            paper = {r["method"]: r
                     for r in frame[frame["track"] == "lateral"].to_dict("records")}
    except FileNotFoundError:
        pass
    # the claims settings the runs were made with
    cfg = collection.claims_settings("improved") or ClaimsConfig()
    comparisons = ("baseline", "baseline_matched") + (("mpc_no_apf",) if apf_alone else ())
    return family_ledger(tables, cfg, paper or None, comparisons=comparisons).to_frame() \
        .reindex(columns=LEDGER_COLUMNS)


def compare_tables(fresh: pd.DataFrame, reference: pd.DataFrame, name: str,
                   key: tuple[str, ...] | None = None,
                   row_names: list[str] | None = None) -> list[str]:
    """Differences between two tables (numbers within tolerance, the rest exactly), rows
    matched by ``key`` (default: the first two columns) in any order.

    A key the reference holds twice is a difference (it cannot say which row it means). A key
    the fresh table holds twice (another run of the same track and method in the outputs) is
    compared through the row closest to the reference; each other row is one line on the log,
    "extra run NAME (KEY) not in the reference" (``row_names``: the fresh rows' names, their
    folders), not a list of false differences."""
    problems = []
    if list(fresh.columns) != list(reference.columns):
        missing = sorted(set(reference.columns) - set(fresh.columns))
        extra = sorted(set(fresh.columns) - set(reference.columns))
        problems.append(f"{name}: columns differ (missing {missing}, new {extra})")
    key = tuple(key or reference.columns[:2])
    if not set(key) <= set(fresh.columns) & set(reference.columns):
        return problems + [f"{name}: no key columns {list(key)}"]
    names = list(row_names) if row_names is not None else [f"row {i + 1}"
                                                          for i in range(len(fresh))]
    shared = [c for c in reference.columns if c in fresh.columns]

    def rows_by_key(table: pd.DataFrame) -> dict:
        out: dict = {}
        for i, (_, row) in enumerate(table.iterrows()):
            out.setdefault(tuple(str(v) for v in row[list(key)]), []).append((i, row))
        return out

    def differences(a, b) -> list[str]:
        return [c for c in shared if not _same(a[c], b[c])]

    ours, theirs = rows_by_key(fresh), rows_by_key(reference)
    problems += [f"{name}: row {', '.join(k)} is in the reference {len(rows)} times (a "
                 "duplicated row)" for k, rows in theirs.items() if len(rows) > 1]
    for k in theirs.keys() - ours.keys():
        problems.append(f"{name}: row {', '.join(k)} is in the reference, not in the rerun")
    for k in ours.keys() - theirs.keys():
        problems.append(f"{name}: row {', '.join(k)} is new (not in the reference)")
    for k in [k for k in theirs if k in ours]:
        reference_row = theirs[k][0][1]
        candidates = sorted(ours[k], key=lambda item: len(differences(item[1],
                                                                       reference_row)))
        for i, _ in candidates[1:]:
            log.warning("%s: extra run %s (%s) not in the reference: another run with the "
                        "same %s; not compared", name, names[i], ", ".join(k), ", ".join(key))
        row = candidates[0][1]
        for column in differences(row, reference_row):
            problems.append(f"{name}: row {', '.join(k)} {column}: {row[column]!r} vs "
                            f"reference {reference_row[column]!r}")
    return problems


def _same(a, b) -> bool:
    try:
        fa, fb = float(a), float(b)
    except (TypeError, ValueError):
        return str(a) == str(b) or (pd.isna(a) and pd.isna(b))
    if math.isnan(fa) and math.isnan(fb):
        return True
    return math.isclose(fa, fb, rel_tol=REL_TOL, abs_tol=ABS_TOL)


def verify(runs_root: Path, reference_dir: Path, update: bool = False) -> list[str]:
    """Compare (or, with ``update``, rewrite) the reference; returns the differences."""
    reference_dir = Path(reference_dir)
    paper = paper_metrics_table(runs_root, with_folders=True)
    fresh = {PAPER_FILE: paper.drop(columns=[RUN_FOLDER])}
    row_names = {PAPER_FILE: list(paper[RUN_FOLDER])}
    for file, kinematic, alone in ((LEDGER_FILE, False, False),
                                   (KINEMATIC_LEDGER_FILE, True, False),
                                   (APF_ALONE_LEDGER_FILE, False, True)):
        ledger = ledger_table(runs_root, kinematic=kinematic, apf_alone=alone)
        if ledger is not None:
            fresh[file] = ledger
    from pipeline.store.collection import model_validity_table
    from pipeline.store.layout import OutputsLayout

    validity = model_validity_table(OutputsLayout.load(runs_root)).to_frame()
    if len(validity):
        fresh[VALIDITY_FILE] = validity
    if update:
        for name, table in fresh.items():
            write_csv_atomic(reference_dir / name, table)
        return []
    from pipeline.store.safe_load import read_table

    problems = []
    for name, table in fresh.items():
        path = reference_dir / name
        if not path.exists():
            problems.append(f"{name}: no reference file {path}")
            continue
        # size, UTF-8, empty and duplicated rows: one line naming the file (exit 2)
        reference = read_table(path, f"a reference table ({name})", KEYS.get(name))
        # round-trip through CSV so both sides have the same types
        problems += compare_tables(pd.read_csv(pd.io.common.StringIO(
            table.to_csv(index=False, float_format="%.10g"))), reference, name,
            KEYS.get(name), row_names.get(name))
    return problems
