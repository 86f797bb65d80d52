"""Compare fresh results with the committed reference (``python -m pipeline.verify RUNS REF``,
the command in :mod:`pipeline.verify`).

``reports/reference/`` holds the summary of the default ``make reproduce``:
``paper_metrics.csv`` (every method and track on the paper scenario) and, when the families
were run, ``claims_ledger.csv`` (the lateral family), ``claims_ledger_kinematic_family.csv``
(the Appendix-A track's family), ``claims_ledger_apf_alone.csv`` (the APF by itself) and
``model_validity.csv`` (does each MPC's model hold, per track, frame and method). Rows are
matched by their key (track and method; claim and comparison), whatever their order. Numbers
must agree within ``rel 1e-6 or abs 1e-6`` (deterministic code; the slack covers
floating-point differences between BLAS builds), labels and verdicts exactly. ``--update``
rewrites the reference (say why in the commit).

The ledgers are the report's own (the answer's family-wise rule applied): the caller hands
them in (:class:`Ledgers`, the command builds them from the report's verdicts); with
``seeds``, the answer's published outcomes are judged again under that many bootstrap seeds
(``claims.seed`` 0, 1, ...) and every row whose outcome changes is a difference.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
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
LEDGER_COLUMNS = ["claim", "comparison", "role", "metric", "outcome", "outcome_unadjusted",
                  "estimate", "ci_low", "ci_high", "p_holm", "p_holm_claim",
                  "prob_improvement", "n_better", "n_tied", "n_worse", "n_missing", "n_pairs",
                  "n_scenarios", "outcome_worst_rank", "paper_scenario"]

#: The report's ledgers under one bootstrap seed (None: the runs' own claims settings):
#: ``(published ledgers by file name, every row the answer publishes with its outcome)``.
Ledgers = Callable[[int | None], tuple[dict[str, pd.DataFrame], pd.DataFrame]]


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


def seed_differences(ledgers: Ledgers, seeds: int) -> list[str]:
    """Every published row whose outcome is not the same under ``claims.seed`` 0 ..
    ``seeds - 1`` (one line each, naming the outcomes and the seeds that gave them)."""
    outcomes: dict[tuple[str, str, str], dict[str, list[int]]] = {}
    for seed in range(seeds):
        _, table = ledgers(seed)
        for row in table.to_dict("records"):
            key = (str(row["ledger"]), str(row["claim"]), str(row["comparison"]))
            outcomes.setdefault(key, {}).setdefault(str(row["outcome"]), []).append(seed)
    return [f"bootstrap seeds: {ledger} {claim} vs {comparison}: " + "; ".join(
                f"{outcome} under seed {', '.join(map(str, found))}"
                for outcome, found in by_outcome.items())
            for (ledger, claim, comparison), by_outcome in outcomes.items()
            if len(by_outcome) > 1]


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


def verify(runs_root: Path, reference_dir: Path, update: bool = False,
           ledgers: Ledgers | None = None, seeds: int = 0) -> list[str]:
    """Compare (or, with ``update``, rewrite) the reference; returns the differences.
    ``ledgers``: the report's ledgers (see the module docstring; without them only the paper
    scenario and the model checks are compared); ``seeds``: how many bootstrap seeds the
    answer's outcomes must agree under (0: not checked)."""
    from pipeline.store.safe_load import read_table

    reference_dir = Path(reference_dir)
    paper = paper_metrics_table(runs_root, with_folders=True)
    fresh = {PAPER_FILE: paper.drop(columns=[RUN_FOLDER])}
    row_names = {PAPER_FILE: list(paper[RUN_FOLDER])}
    # the reference's tables are read (and refused, one line) before any ledger is computed
    references = {} if update else {
        name: read_table(reference_dir / name, f"a reference table ({name})", KEYS.get(name))
        for name in KEYS if (reference_dir / name).exists()}
    if ledgers is not None:
        published, _ = ledgers(None)
        for file, table in published.items():
            fresh[file] = table.reindex(columns=LEDGER_COLUMNS)
    from pipeline.store.collection import model_validity_table
    from pipeline.store.layout import OutputsLayout

    validity = model_validity_table(OutputsLayout.load(runs_root)).to_frame()
    if len(validity):
        fresh[VALIDITY_FILE] = validity
    if update:
        for name, table in fresh.items():
            write_csv_atomic(reference_dir / name, table)
        return []
    problems = seed_differences(ledgers, seeds) if ledgers is not None and seeds > 1 else []
    for name, table in fresh.items():
        path = reference_dir / name
        if name not in references:
            problems.append(f"{name}: no reference file {path}")
            continue
        # size, UTF-8, empty and duplicated rows were refused above (one line naming the file)
        reference = references[name]
        # round-trip through CSV so both sides have the same types
        problems += compare_tables(pd.read_csv(pd.io.common.StringIO(
            table.to_csv(index=False, float_format="%.10g"))), reference, name,
            KEYS.get(name), row_names.get(name))
    return problems
