"""Claims stage: the paper's claims C1-C5 mapped to metrics, and their verdicts on given runs.

Each claim names one primary metric (the verdict is taken on it) and secondary metrics shown
beside it. On a single scenario the verdict compares improved with baseline on the primary
metric with a stated tolerance; statistics over a scenario family build on the same table.
"""

from __future__ import annotations

from dataclasses import dataclass

import math


@dataclass(frozen=True)
class Claim:
    """One claim of the paper and the metric that stands for it."""

    claim_id: str
    text: str
    primary_metric: str
    lower_is_better: bool
    tolerance: float
    secondary_metrics: tuple[str, ...]


CLAIMS: tuple[Claim, ...] = (
    Claim("C1", "faster obstacle-avoidance response after a sudden obstacle appears",
          "reaction_delay_s", True, 0.05, ("reaction_delay_lateral_s",)),
    Claim("C2", "smoother steering path (no sharp turns or jerks after avoidance)",
          "lateral_jerk_rms_mps3", True, 0.02,
          ("steering_rate_rms_rad_s", "curvature_rate_rms_1_per_ms", "lateral_jerk_max_mps3")),
    Claim("C3", "repulsion applied only where needed (little force when far)",
          "repulsive_impulse_far_share", True, 0.01,
          ("repulsion_onset_clearance_m", "repulsive_force_peak", "repulsive_impulse")),
    Claim("C4", "faster, smoother goal-direction recovery after avoidance",
          "recovery_time_s", True, 0.05, ("recovery_lateral_s", "recovery_heading_s",
                                          "overshoot_m")),
    Claim("C5", "more stable path (no sharp drops, minimal oscillation)",
          "oscillation_count", True, 0.5, ("heading_step_max_rad", "overshoot_m",
                                           "max_lateral_deviation_m")),
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
