"""A windowed claim read on a window common to both runs of a pair (``claims.c2_window =
common``): C2's RMS lateral jerk of each run over one window made of the two runs' own
avoidance windows.

Each run's own window (appearance of the threat to recovery, or run end) differs between the
two methods of a pair: the one that recovers later is measured over a longer span, most of it
quiet, which dilutes its RMS. The common window puts both runs on the same span. The default
rule is the *union* (from the earlier start to the later end): it keeps every sample either
run's own window holds, so neither method's late manoeuvre (C2's "no jerks after avoidance")
is cut off, and the run that settled earlier is charged for its quiet tail as the other is.
The *intersection* (the later start to the earlier end) would drop the tail of the slower
run's manoeuvre, the very jerks the claim is about; it is offered as the alternative.

The window's ends come from each run's metrics (``smoothness_window_start_s``,
``smoothness_window_end_s``), the jerk from its stored trajectory
(:func:`pipeline.analysis.metrics.lateral_jerk_signal`); a window that runs past a run's last
log row covers that run's samples up to its end.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping

import numpy as np
import pandas as pd

from pipeline.analysis.claims.catalogue import Claim
from pipeline.analysis.metrics.results import LateralJerk
from pipeline.analysis.settings import ClaimsConfig
from pipeline.errors import ConfigError

#: the rules that make one window of a pair's two (``claims.common_window``)
WINDOW_RULES = ("union", "intersection")
#: the columns of a run's own window in its metrics (``family_metrics.csv``)
WINDOW_START, WINDOW_END = "smoothness_window_start_s", "smoothness_window_end_s"
#: C2's primary metric on the common window (a column of the tables :func:`common_window_tables`
#: returns)
COMMON_C2_METRIC = "lateral_jerk_rms_common_mps3"


def require_own_window(cfg: ClaimsConfig, study: str) -> None:
    """Refuse ``claims.c2_window = common`` for a study that judges family tables without
    the runs' trajectories (before it starts its work, not after)."""
    if cfg.c2_window == "common":
        raise ConfigError("claims.c2_window", cfg.c2_window,
                          f"own for {study} (it judges C2 on each run's own window; the report "
                          "shows C2 on the common window beside it)")


def common_window(first: tuple[float, float], second: tuple[float, float],
                  rule: str = "union") -> tuple[float, float]:
    """One window (s) made of two runs' windows ``(start, end)``.

    Parameters
    ----------
    first, second : tuple of float
        Each run's own window; NaN ends: the run has none.
    rule : {"union", "intersection"}
        Union: the earlier start to the later end (the one window when only one run has
        one). Intersection: the later start to the earlier end (NaN when they do not overlap
        or a run has none).

    Returns
    -------
    tuple of float
        ``(start, end)``, ``(nan, nan)`` when there is none.
    """
    if rule not in WINDOW_RULES:
        raise ValueError(f"common window rule {rule!r}: one of {WINDOW_RULES}")
    windows = [(float(s), float(e)) for s, e in (first, second)
               if math.isfinite(s) and math.isfinite(e)]
    if rule == "union" and windows:
        return min(s for s, _ in windows), max(e for _, e in windows)
    if rule == "intersection" and len(windows) == 2:
        start, end = max(s for s, _ in windows), min(e for _, e in windows)
        if start <= end:
            return start, end
    return float("nan"), float("nan")


def _windows(table: pd.DataFrame, name: str) -> pd.DataFrame:
    """``scenario`` and the run's own window of each row (ValueError without the columns)."""
    missing = [c for c in (WINDOW_START, WINDOW_END) if c not in table]
    if missing:
        raise ValueError(f"{name}: no {', '.join(missing)} in its metrics (runs made before "
                         "the window was recorded): C2 on a common window needs them; "
                         "re-run or re-score the family")
    out = table[["scenario", WINDOW_START, WINDOW_END]].copy()
    for column in (WINDOW_START, WINDOW_END):
        out[column] = pd.to_numeric(out[column], errors="coerce")
    return out


def common_window_pairs(treatment: pd.DataFrame, control: pd.DataFrame,
                        jerk_treatment: Mapping[str, LateralJerk],
                        jerk_control: Mapping[str, LateralJerk],
                        rule: str = "union") -> pd.DataFrame:
    """Per pair (``scenario``): the common window and both runs' RMS jerk over it.

    Parameters
    ----------
    treatment, control : DataFrame
        Each method's per-scenario metrics with ``scenario`` and the own-window columns.
    jerk_treatment, jerk_control : mapping of scenario -> LateralJerk
        Each run's jerk signal (a scenario without one gives NaN: a missing pair).
    rule : {"union", "intersection"}

    Returns
    -------
    DataFrame
        ``scenario``, ``window_start_s``, ``window_end_s``, ``treatment_mps3``,
        ``control_mps3``.
    """
    merged = _windows(treatment, "treatment").merge(_windows(control, "control"),
                                                    on="scenario", suffixes=("_t", "_c"))
    by_scenario = [{str(k): v for k, v in jerks.items()}
                   for jerks in (jerk_treatment, jerk_control)]
    rows = []
    for r in merged.itertuples(index=False):
        scenario = str(r.scenario)
        start, end = common_window((getattr(r, f"{WINDOW_START}_t"),
                                    getattr(r, f"{WINDOW_END}_t")),
                                   (getattr(r, f"{WINDOW_START}_c"),
                                    getattr(r, f"{WINDOW_END}_c")), rule)
        values = [jerks[scenario].rms_over(start, end) if scenario in jerks else float("nan")
                  for jerks in by_scenario]
        rows.append({"scenario": r.scenario, "window_start_s": start, "window_end_s": end,
                     "treatment_mps3": values[0], "control_mps3": values[1]})
    return pd.DataFrame(rows, columns=["scenario", "window_start_s", "window_end_s",
                                       "treatment_mps3", "control_mps3"])


def common_window_tables(treatment: pd.DataFrame, control: pd.DataFrame,
                         jerk_treatment: Mapping[str, LateralJerk],
                         jerk_control: Mapping[str, LateralJerk],
                         rule: str = "union") -> tuple[pd.DataFrame, pd.DataFrame]:
    """Both methods' tables with :data:`COMMON_C2_METRIC`: each run's RMS jerk over the
    window common to it and its partner in this comparison (NaN where a pair has none)."""
    pairs = common_window_pairs(treatment, control, jerk_treatment, jerk_control, rule)
    key = pairs["scenario"].astype(str)
    out = []
    for table, column in ((treatment, "treatment_mps3"), (control, "control_mps3")):
        values = dict(zip(key, pairs[column], strict=True))
        table = table.copy()
        table[COMMON_C2_METRIC] = [values.get(str(s), np.nan) for s in table["scenario"]]
        out.append(table)
    return out[0], out[1]


def common_window_claim(claim: Claim, rule: str = "union") -> Claim:
    """C2 judged on :data:`COMMON_C2_METRIC` (its definition saying which window)."""
    return dataclasses.replace(
        claim, primary_metric=COMMON_C2_METRIC,
        definition=claim.definition.rstrip(".") + f"; read on the {rule} of the two runs' "
        "avoidance windows, so both runs of a pair are measured over the same window.")
