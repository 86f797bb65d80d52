"""Claims stage: the paper's claims C1-C5 mapped to metrics, and their verdicts on given runs.

Each claim names one primary metric (the verdict is taken on it) and secondary metrics shown
beside it. On a single scenario the verdict compares improved with baseline on the primary
metric with a stated tolerance; statistics over a scenario family build on the same table.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd


@dataclass(frozen=True)
class Claim:
    """One claim of the paper and the metric that stands for it."""

    claim_id: str
    text: str
    primary_metric: str
    lower_is_better: bool
    tolerance: float
    secondary_metrics: tuple[str, ...]
    criterion: str = ""
    paper_description: str = ""
    paper_indicator: str = ""
    paper_improved: str = ""
    paper_original: str = ""
    definition: str = ""


CLAIMS: tuple[Claim, ...] = (
    Claim("C1", "faster obstacle-avoidance response after a sudden obstacle appears",
          "reaction_delay_s", True, 0.05, ("reaction_delay_lateral_s",),
          criterion="Obstacle Avoidance Response",
          paper_description="How quickly and effectively the system reacts to a suddenly "
                            "appearing obstacle.",
          paper_indicator="Fast and smooth detour around the obstacle.",
          paper_improved="Fast and smooth avoidance",
          paper_original="Slow and aggressive curved avoidance",
          definition="Time (s) from the obstacle's appearance until the steering angle first "
                     "leaves a band of reaction_steering_band_rad around its value then."),
    Claim("C2", "smoother steering path (no sharp turns or jerks after avoidance)",
          "lateral_jerk_rms_mps3", True, 0.02,
          ("steering_rate_rms_rad_s", "curvature_rate_rms_1_per_ms", "lateral_jerk_max_mps3"),
          criterion="Smoothness of Steering Path",
          paper_description="How natural or jerky the steering path is.",
          paper_indicator="Smooth curvature and gradual turns.",
          paper_improved="Smooth and stable path after avoidance",
          paper_original="Sharp turns after avoidance (jerky)",
          definition="RMS over the run of the lateral jerk d(v r)/dt (m/s^3), v r = v^2 kappa "
                     "the lateral acceleration, by central differences."),
    Claim("C3", "repulsion applied only where needed (little force when far)",
          "repulsive_impulse_far_share", True, 0.01,
          ("repulsion_onset_clearance_m", "repulsive_force_peak", "repulsive_impulse"),
          criterion="Repulsive Force Modulation",
          paper_description="How well the repulsive force from the APF is applied.",
          paper_indicator="Adaptive, distance-based repulsion that avoids unnecessary forces.",
          paper_improved="H_k is activated smoothly based on distance; strong repulsion only "
                         "when needed",
          paper_original="exp((s - s0)^2) causes low sensitivity for far distances",
          definition="Share (0-1) of the repulsive impulse sum |F_rep| Ts at the vehicle that "
                     "is applied while the nearest obstacle's clearance exceeds "
                     "threat_clearance_m."),
    Claim("C4", "faster, smoother goal-direction recovery after avoidance",
          "recovery_time_s", True, 0.05, ("recovery_lateral_s", "recovery_heading_s",
                                          "overshoot_m"),
          criterion="Goal Direction Recovery",
          paper_description="Whether the system can return to the goal path after avoidance.",
          paper_indicator="Smooth convergence back to the original trajectory.",
          paper_improved="Returns smoothly to goal direction after avoiding obstacles",
          paper_original="Recovery is slow and inconsistent",
          definition="Settling time (s, python-control step_info convention, absolute band "
                     "recovery_lateral_band_m) of the lateral error to the start-goal line "
                     "after every obstacle is passed; missing if it never settles."),
    Claim("C5", "more stable path (no sharp drops, minimal oscillation)",
          "oscillation_count", True, 0.5, ("heading_step_max_rad", "overshoot_m",
                                           "max_lateral_deviation_m"),
          criterion="Path Stability",
          paper_description="The overall stability of the path (oscillations, abrupt dips, "
                            "etc.).",
          paper_indicator="Stable trajectory with no sharp drops or oscillations.",
          paper_improved="Globally stable with minimal oscillation",
          paper_original="Unstable - drops sharply and reacts suddenly",
          definition="Number of sign changes of the lateral error (outside "
                     "lateral_sign_band_m) plus those of the yaw rate (outside "
                     "yaw_rate_sign_band_rad_s)."),
)

VERDICT_RULE_SINGLE = (
    "single scenario: 'supported' if improved beats baseline on the primary metric by more than "
    "the tolerance, 'not supported' if it is worse by more than the tolerance, 'no difference' "
    "otherwise; a missing value (no reaction, not recovered) counts as the worst value")


def _value(metrics: dict, key: str) -> float:
    value = metrics.get(key)
    return float(value) if value is not None else math.nan


def single_scenario_verdict(claim: Claim, baseline: dict, improved: dict) -> str:
    """Verdict of one claim from two runs' metrics (see :data:`VERDICT_RULE_SINGLE`)."""
    b, i = _value(baseline, claim.primary_metric), _value(improved, claim.primary_metric)
    worst = math.inf if claim.lower_is_better else -math.inf
    b = worst if math.isnan(b) else b
    i = worst if math.isnan(i) else i
    if b == i:
        return "no difference"
    gain = (b - i) if claim.lower_is_better else (i - b)
    if math.isinf(gain):
        return "supported" if gain > 0 else "not supported"
    if gain > claim.tolerance:
        return "supported"
    if gain < -claim.tolerance:
        return "not supported"
    return "no difference"


def claims_table(metrics_by_method: dict[str, dict], baseline: str = "baseline",
                 improved: str = "improved") -> list[dict]:
    """One row per claim: primary metric, its value per method, the verdict."""
    rows = []
    for claim in CLAIMS:
        row = {"claim": claim.claim_id, "paper says": claim.text,
               "metric": claim.primary_metric,
               "better": "lower" if claim.lower_is_better else "higher",
               "tolerance": claim.tolerance}
        for method, metrics in metrics_by_method.items():
            row[method] = metrics.get(claim.primary_metric)
        if baseline in metrics_by_method and improved in metrics_by_method:
            row["verdict"] = single_scenario_verdict(claim, metrics_by_method[baseline],
                                                     metrics_by_method[improved])
        else:
            row["verdict"] = "n/a"
        rows.append(row)
    return rows


VERDICT_RULE_FAMILY = (
    "over the family, d = improved - baseline per scenario (sign flipped where higher is "
    "better, so d < 0 is an improvement; a missing value counts as the worst value, i.e. "
    "d = +inf if only improved lacks it and -inf if only baseline does); the median of d and its "
    "95 % percentile-bootstrap interval (2000 resamples, seeded): 'supported' if the whole "
    "interval lies below 0, 'not supported' if it lies at or above 0, 'mixed' if it contains 0. "
    "'holds in' is the share of scenarios with d < -tolerance")


def paired_differences(improved: pd.DataFrame, baseline: pd.DataFrame, claim: Claim
                       ) -> np.ndarray:
    """Per-scenario ``d = improved - baseline`` on the claim's primary metric (paired by the
    ``scenario`` column), signed so that ``d < 0`` is an improvement; NaN handled as worst."""
    key = claim.primary_metric
    merged = improved[["scenario", key]].merge(baseline[["scenario", key]], on="scenario",
                                               suffixes=("_i", "_b"))
    i = merged[f"{key}_i"].to_numpy(float)
    b = merged[f"{key}_b"].to_numpy(float)
    sign = 1.0 if claim.lower_is_better else -1.0
    with np.errstate(invalid="ignore"):
        d = sign * (i - b)
    d = np.where(np.isnan(i) & ~np.isnan(b), np.inf, d)
    d = np.where(~np.isnan(i) & np.isnan(b), -np.inf, d)
    d = np.where(np.isnan(i) & np.isnan(b), 0.0, d)
    return d


def median_of(values: np.ndarray, axis=None):
    """Median as an element of the data (``inverted_cdf``), well defined with infinities."""
    return np.quantile(values, 0.5, axis=axis, method="inverted_cdf")


def bootstrap_median_ci(values: np.ndarray, rng: np.random.Generator,
                        n_resamples: int = 2000, level: float = 0.95) -> tuple[float, float]:
    """Percentile-bootstrap interval of the median."""
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return float("nan"), float("nan")
    idx = rng.integers(0, values.size, size=(n_resamples, values.size))
    medians = median_of(values[idx], axis=1)
    tail = (1.0 - level) / 2.0
    return (float(np.quantile(medians, tail, method="inverted_cdf")),
            float(np.quantile(medians, 1.0 - tail, method="inverted_cdf")))


def family_verdict(low: float, high: float) -> str:
    """Verdict from the interval of the median paired difference (see VERDICT_RULE_FAMILY)."""
    if high < 0.0:
        return "supported"
    if low >= 0.0:
        return "not supported"
    return "mixed"


def family_ledger(tables: dict[str, pd.DataFrame], paper_metrics: dict[str, dict] | None = None,
                  baseline: str = "baseline", improved: str = "improved", seed: int = 0
                  ) -> tuple[list[dict], dict[str, np.ndarray]]:
    """Claims ledger over a scenario family.

    Parameters
    ----------
    tables : dict of method -> DataFrame
        Per-scenario metrics (``family_metrics.csv``) of each method, with a ``scenario`` column.
    paper_metrics : dict of method -> metrics, optional
        The paper scenario's values, shown beside the family statistics.
    seed : int
        Seed of the bootstrap.

    Returns
    -------
    rows : list of dict
    differences : dict of claim id -> ndarray
        The paired differences, for plotting.
    """
    rng = np.random.default_rng(seed)
    rows, differences = [], {}
    for claim in CLAIMS:
        d = paired_differences(tables[improved], tables[baseline], claim)
        low, high = bootstrap_median_ci(d, rng)
        row = {"claim": claim.claim_id, "paper says": claim.text, "metric": claim.primary_metric,
               "better": "lower" if claim.lower_is_better else "higher",
               "n_pairs": int(d.size), "median_difference": float(median_of(d)) if d.size else
               float("nan"), "ci_low": low, "ci_high": high,
               "holds_share": float(np.mean(d < -claim.tolerance)) if d.size else float("nan"),
               "verdict": family_verdict(low, high)}
        if paper_metrics:
            row["paper_scenario"] = {m: metrics.get(claim.primary_metric)
                                     for m, metrics in paper_metrics.items()}
            if baseline in paper_metrics and improved in paper_metrics:
                row["paper_verdict"] = single_scenario_verdict(claim, paper_metrics[baseline],
                                                               paper_metrics[improved])
        rows.append(row)
        differences[claim.claim_id] = d
    return rows, differences


def outcome_counts(tables: dict[str, pd.DataFrame]) -> list[dict]:
    """Collisions, failures and fallbacks per method; nothing is dropped from the statistics."""
    rows = []
    for method, t in tables.items():
        rows.append({
            "method": method, "scenarios": int(len(t)),
            "collisions": int(t["collision"].astype(bool).sum()),
            "not_recovered": int((~t["recovered"].astype(bool)).sum()),
            "no_reaction": int((~t["reacted"].astype(bool)).sum()),
            "goal_not_reached": int((~t["goal_reached"].astype(bool)).sum()),
            "heading_validity_exceeded": int(t["heading_validity_exceeded"].astype(bool).sum()),
            "fallback_steps": int(t["fallback_count"].fillna(0).sum())
            if "fallback_count" in t else 0,
            "min_clearance_median_m": float(t["min_clearance_m"].median()),
        })
    return rows
