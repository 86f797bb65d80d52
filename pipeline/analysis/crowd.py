"""The crowd-navigation metrics of a family among walkers, per method, each with an interval:
the field's usual summary (Francis et al. 2023, "Principles and Guidelines for Evaluating
Social Robot Navigation Algorithms"; CrowdNav's success, collision and timeout rates, time to
goal, path length, minimum distance and discomfort).

Read from a family's table (``family_metrics.csv``: one row per member, the run's metrics with
its :class:`~pipeline.analysis.metrics.results.Crowd` block). A rate's interval is the exact
(Clopper-Pearson) binomial interval (``scipy.stats.binomtest``); a median's the exact
distribution-free interval of the order statistics (``scipy.stats.quantile_test``); the
intrusion time share (each run's share of its logged steps inside a walker's personal space,
averaged over runs) a BCa bootstrap interval (``scipy.stats.bootstrap``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

#: The columns of ``tables/pedestrians_metrics.csv`` before the intervals (the issue's names).
METRIC_COLUMNS = ("crossings", "success_rate", "collision_rate", "timeout_rate",
                  "time_to_goal_median_s", "path_ratio_median", "min_distance_median_m",
                  "intrusion_time_share")


def flag_value(value: Any) -> bool | None:
    """A table cell as a flag: True or False as written (``True``, ``1``, ``1.0``; ``False``,
    ``0``, ``0.0``, any case), None where nothing was recorded (empty, NaN, anything else)."""
    word = str(value).lower()
    return True if word in ("true", "1", "1.0") else False if word in ("false", "0", "0.0") \
        else None


def _flags(table: pd.DataFrame, column: str) -> np.ndarray:
    return table[column].map(lambda v: flag_value(v) is True).to_numpy(bool) \
        if column in table else np.zeros(len(table), bool)


def _rate(hits: np.ndarray, level: float) -> tuple[float, float, float]:
    n = int(hits.size)
    if n == 0:
        return float("nan"), float("nan"), float("nan")
    ci = stats.binomtest(int(hits.sum()), n).proportion_ci(confidence_level=level,
                                                             method="exact")
    return float(hits.mean()), float(ci.low), float(ci.high)


def _median(values: np.ndarray, level: float) -> tuple[float, float, float]:
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float("nan"), float("nan"), float("nan")
    middle = float(np.median(v))
    if v.size < 2:
        return middle, float("nan"), float("nan")
    ci = stats.quantile_test(v, q=middle, p=0.5).confidence_interval(confidence_level=level)
    return middle, float(ci.low), float(ci.high)


def _mean(values: np.ndarray, level: float, seed: int) -> tuple[float, float, float]:
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float("nan"), float("nan"), float("nan")
    if v.size < 3 or np.ptp(v) == 0.0:
        return float(v.mean()), float(v.min()), float(v.max())
    ci = stats.bootstrap((v,), np.mean, confidence_level=level, n_resamples=9999,
                         method="BCa", random_state=np.random.default_rng(seed)
                         ).confidence_interval
    return float(v.mean()), float(ci.low), float(ci.high)


def crowd_metrics(table: pd.DataFrame, level: float = 0.95, seed: int = 0) -> dict[str, Any]:
    """One method's crowd metrics over a family's table, each ``<name>`` with
    ``<name>_low`` and ``<name>_high`` (its interval at ``level``).

    Success is reaching the goal without a contact; a timeout neither (the run's last step
    came first); an avoidable collision one whose ``collision_avoidable`` is true (the
    published label: :mod:`pipeline.analysis.unavoidable`; NaN without the column); a collision
    at appearance one whose ``contact_at_appearance`` is true (NaN without it); time to goal
    and the path ratio (path length over the straight start-goal
    line) are read on the successful runs; the minimum distance is the closest surface gap to
    any walker (m; negative: a contact)."""
    collided = _flags(table, "collision")
    # a contact that is not unavoidable (collision_avoidable: as the report's inputs publish
    # it, a manoeuvre from the walker's appearance or another method on the same crossing
    # avoided it; an unavoidable one is mostly a walker whose recorded track begins on or
    # against the platform, met by every method)
    avoidable = collided & _flags(table, "collision_avoidable")
    # a contact at the walker's appearance: its recorded track began on or against the
    # platform (the metrics' contact_at_appearance), seen by no planner before the contact
    appeared = collided & _flags(table, "contact_at_appearance")
    reached = _flags(table, "goal_reached")
    success = reached & ~collided
    timeout = ~reached & ~collided
    out: dict[str, Any] = {"crossings": int(len(table))}
    for name, value in (("success_rate", _rate(success, level)),
                        ("collision_rate", _rate(collided, level)),
                        ("collision_avoidable_rate", _rate(avoidable, level)
                         if "collision_avoidable" in table else (float("nan"),) * 3),
                        ("collision_at_appearance_rate", _rate(appeared, level)
                         if "contact_at_appearance" in table else (float("nan"),) * 3),
                        ("timeout_rate", _rate(timeout, level)),
                        ("time_to_goal_median_s", _median(
                            table["time_to_goal_s"].to_numpy(float)[success], level)),
                        ("path_ratio_median", _median(
                            table["path_ratio"].to_numpy(float)[success]
                            if "path_ratio" in table else np.array([]), level)),
                        ("min_distance_median_m", _median(
                            table["min_clearance_m"].to_numpy(float), level)),
                        ("intrusion_time_share", _mean(
                            table["personal_space_intrusion_share"].to_numpy(float)
                            if "personal_space_intrusion_share" in table else np.array([]),
                            level, seed))):
        out[name], out[f"{name}_low"], out[f"{name}_high"] = value
    # the steps with more walkers in sensor range than the MPC has obstacle slots (each run's
    # share, averaged: 0 when every walker in range constrained the plan)
    beyond = table["walkers_beyond_slots_share"].to_numpy(float) \
        if "walkers_beyond_slots_share" in table else np.array([])
    out["walkers_beyond_slots_share"] = float(np.nanmean(beyond)) \
        if np.isfinite(beyond).any() else float("nan")
    return out


def collision_rates(table: pd.DataFrame) -> tuple[float, float, float]:
    """A method's collision rate over the rows of ``table`` (a family table's crossings, e.g.
    those where standing still is safe): every contact; the avoidable ones
    (``collision_avoidable`` true); those with a walker seen before the contact (not
    ``contact_at_appearance``). NaN without rows, the last two NaN without their column."""
    if not len(table):
        return float("nan"), float("nan"), float("nan")
    hits = _flags(table, "collision")
    avoidable = float((hits & _flags(table, "collision_avoidable")).mean()) \
        if "collision_avoidable" in table else float("nan")
    seen = float((hits & ~_flags(table, "contact_at_appearance")).mean()) \
        if "contact_at_appearance" in table else float("nan")
    return float(hits.mean()), avoidable, seen


def crowd_metrics_table(families: list[tuple[dict[str, Any], dict[str, pd.DataFrame]]],
                        level: float = 0.95, seed: int = 0) -> pd.DataFrame:
    """``tables/pedestrians_metrics.csv``: one row per family and method; ``families`` holds,
    per family, its description (``family``, ``track`` and any other columns, first) and its
    tables by method."""
    rows = [{**about, "method": method, **crowd_metrics(table, level, seed)}
            for about, tables in families for method, table in tables.items()]
    return pd.DataFrame(rows)
