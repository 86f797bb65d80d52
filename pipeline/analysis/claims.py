"""Claims stage: the paper's claims mapped to metrics, and four-outcome verdicts on given runs.

Each claim names one primary metric (the outcome is taken on it) and secondary metrics shown
beside it; C0 (safety: collisions) comes first. Over a scenario family a claim is judged on the
paired differences ``d = improved - comparison`` (``d < 0`` is the claimed improvement) as
*supported*, *contradicted*, *equivalent* or *inconclusive* (:data:`OUTCOME_RULE`); on the single
paper scenario the words are *better*, *worse* or *within margin*. Statistics come from
``scipy.stats``: the paired bootstrap interval (``bootstrap``, BCa where defined), the Wilcoxon
signed-rank or sign test (``wilcoxon``, ``binomtest``), McNemar's exact test on discordant
collision pairs (``binomtest``); Holm's adjustment over the six claims is written out (SciPy has
none).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np
import pandas as pd

from pipeline.analysis.tally import Tally


@dataclass(frozen=True)
class Claim:
    """One claim of the paper and the metric that stands for it."""

    claim_id: str
    text: str
    primary_metric: str
    lower_is_better: bool
    secondary_metrics: tuple[str, ...]
    criterion: str = ""
    paper_description: str = ""
    paper_indicator: str = ""
    paper_improved: str = ""
    paper_original: str = ""
    definition: str = ""
    #: "paired" (a paired difference of a metric) or "rate" (a rate of events, e.g. C0)
    kind: str = "paired"

    @property
    def is_rate(self) -> bool:
        return self.kind == "rate"


CLAIMS: tuple[Claim, ...] = (
    Claim("C1", "faster obstacle-avoidance response after a sudden obstacle appears",
          "reaction_delay_s", True, ("reaction_delay_lateral_s",
                                     "reaction_delay_first_visible_s"),
          criterion="Obstacle Avoidance Response",
          paper_description="How quickly and effectively the system reacts to a suddenly "
                            "appearing obstacle.",
          paper_indicator="Fast and smooth detour around the obstacle.",
          paper_improved="Fast and smooth avoidance",
          paper_original="Slow and aggressive curved avoidance",
          definition="Time (s) from the appearance of the first obstacle that threatens the "
                     "vehicle's straight continuation (within both radii + threat_margin_m, "
                     "threat_horizon_s ahead) until the steering angle first leaves a band of "
                     "reaction_steering_band_rad around its value then, the crossing "
                     "interpolated between samples; missing when nothing threatens."),
    Claim("C2", "smoother steering path (no sharp turns or jerks after avoidance)",
          "lateral_jerk_rms_mps3", True,
          ("lateral_jerk_rms_run_mps3", "lateral_jerk_max_window_mps3",
           "steering_rate_rms_window_rad_s", "curvature_rate_rms_1_per_ms"),
          criterion="Smoothness of Steering Path",
          paper_description="How natural or jerky the steering path is.",
          paper_indicator="Smooth curvature and gradual turns.",
          paper_improved="Smooth and stable path after avoidance",
          paper_original="Sharp turns after avoidance (jerky)",
          definition="RMS of the lateral jerk d(a_y)/dt (m/s^3) with a_y = vy_dot + vx r, by "
                     "central differences, over the avoidance window (appearance of the threat "
                     "to recovery, or run end)."),
    Claim("C3a", "no repulsion while nothing is near (low sensitivity far away)",
          "repulsion_unneeded_share", True,
          ("repulsion_unneeded_share_threat", "repulsive_impulse_far_share",
           "repulsion_unneeded_impulse", "repulsive_force_peak"),
          criterion="Repulsive Force Modulation (first half: only when needed)",
          paper_description="How well the repulsive force from the APF is applied.",
          paper_indicator="Adaptive, distance-based repulsion that avoids unnecessary forces.",
          paper_improved="H_k is activated smoothly based on distance; strong repulsion only "
                         "when needed",
          paper_original="exp((s - s0)^2) causes low sensitivity for far distances",
          definition="Share (0-1) of the repulsive impulse sum |F_rep| Ts at the vehicle that "
                     "is applied while no obstacle threatens the straight continuation of the "
                     "current motion and none is within near_field_m (0 when no repulsion was "
                     "applied): force spent holding the vehicle off a near obstacle is needed."),
    Claim("C3b", "early repulsion when a threat appears",
          "repulsion_onset_ttc_s", False,
          ("repulsion_onset_clearance_m", "repulsive_force_peak"),
          criterion="Repulsive Force Modulation (second half: strong when needed)",
          paper_description="How well the repulsive force from the APF is applied.",
          paper_indicator="Adaptive, distance-based repulsion that avoids unnecessary forces.",
          paper_improved="strong repulsion only when needed",
          paper_original="low sensitivity for far distances",
          definition="Time to contact (s) of the straight continuation at the first step on "
                     "which the repulsion exceeds repulsion_onset_force while an obstacle "
                     "threatens (higher = earlier); missing when the repulsion never becomes "
                     "significant during a threat."),
    Claim("C4", "faster, smoother goal-direction recovery after avoidance",
          "recovery_time_s", True, ("recovery_lateral_s", "recovery_heading_s",
                                    "overshoot_m"),
          criterion="Goal Direction Recovery",
          paper_description="Whether the system can return to the goal path after avoidance.",
          paper_indicator="Smooth convergence back to the original trajectory.",
          paper_improved="Returns smoothly to goal direction after avoiding obstacles",
          paper_original="Recovery is slow and inconsistent",
          definition="Settling time (s, python-control step_info convention, absolute band "
                     "recovery_lateral_band_m) of the lateral error to the start-goal line "
                     "after every threatening obstacle is passed; missing if it never "
                     "settles."),
    Claim("C5", "more stable path (no sharp drops, minimal oscillation)",
          "oscillation_count", True, ("oscillation_whole_run_count", "heading_step_max_rad",
                                      "overshoot_m", "max_lateral_deviation_m"),
          criterion="Path Stability",
          paper_description="The overall stability of the path (oscillations, abrupt dips, "
                            "etc.).",
          paper_indicator="Stable trajectory with no sharp drops or oscillations.",
          paper_improved="Globally stable with minimal oscillation",
          paper_original="Unstable - drops sharply and reacts suddenly",
          definition="After the obstacle is passed, reversals of the lateral error's "
                     "direction (hysteresis lateral_sign_band_m), net of the manoeuvre: an apex "
                     "of the detour after the pass is not counted, so one out-and-back scores "
                     "0 and an overshoot with its return 1."),
)

SAFETY = Claim(
    "C0", "no less safe (collision rate)", "collision", True,
    ("collision_avoidable", "min_clearance_m"),
    criterion="Safety (not a row of Table 1; judged first)",
    paper_description="Implied throughout: avoidance must avoid.",
    paper_indicator="No collision.",
    definition="Collision from a continuous check (vehicle and obstacles interpolated between "
               "log rows, closest approach in closed form); each collision labelled avoidable "
               "or unavoidable by a sampled reachability check from the state at the obstacle's "
               "appearance.",
    kind="rate")

#: Every claim in the order the report shows them: safety first.
ALL_CLAIMS: tuple[Claim, ...] = (SAFETY,) + CLAIMS


class Outcome(StrEnum):
    """The four outcomes of a claim over a family (:data:`OUTCOME_RULE`)."""

    SUPPORTED = "supported"
    CONTRADICTED = "contradicted"
    EQUIVALENT = "equivalent"
    INCONCLUSIVE = "inconclusive"
    #: the estimate and the probability of improvement point opposite ways
    MIXED = "mixed"


OUTCOMES = tuple(o.value for o in Outcome)

OUTCOME_RULE = (
    "per claim, d = improved - comparison on each scenario (d < 0 is the claimed improvement); "
    "C1-C5 on pairs where neither method collided (all pairs as a sensitivity), pairs with a "
    "missing value counted apart. Estimate: Hodges-Lehmann of d (claims.estimator) with a paired "
    "bootstrap interval (scipy.stats.bootstrap, BCa where defined, claims.n_resamples, seeded); "
    "C0 (a rate): the difference of collision rates with Newcombe's hybrid score interval for "
    "paired proportions (Wilson limits from scipy.stats, honest at zero events). Test: Wilcoxon "
    "signed-rank (Pratt's zeros) or sign test, C0 McNemar's exact test on discordant pairs, "
    "Holm-adjusted over the claims; probability of improvement PI = P(d < 0) + P(d = 0)/2 with "
    "a percentile bootstrap interval. 'equivalent' when the estimate's whole interval lies "
    "inside (-margin, +margin); otherwise, with the adjusted p < alpha: 'supported' when the "
    "estimate's interval holds no worsening (at or below zero, not only zero) and PI is above "
    "1/2 (both say improved is better), 'contradicted' when the interval holds no improvement "
    "and PI is below 1/2, 'mixed' when they point "
    "opposite ways (most pairs better but the typical difference worse, or the reverse; both "
    "numbers in the note); 'inconclusive' else (also with fewer than claims.min_pairs pairs). "
    "For C0 the interval alone gives the direction. A significant difference inside the margin "
    "is a real but small effect: the note says so; a claim on which claims.floor_tie_share of "
    "the pairs tie at the metric's floor notes that neither method shows the behaviour")

SINGLE_RULE = (
    "paper scenario: 'better' if improved beats the comparison on the primary metric by at "
    "least the claim's margin, 'worse' if it trails by at least the margin, 'within margin' "
    "otherwise, 'missing' when either value is missing")


def _value(metrics: dict, key: str) -> float:
    value = metrics.get(key)
    if isinstance(value, (bool, np.bool_)):
        return float(value)
    return float(value) if value is not None else math.nan


def single_scenario_outcome(claim: Claim, comparison: dict, improved: dict,
                            margin: float) -> str:
    """Outcome of one claim on one scenario (see :data:`SINGLE_RULE`)."""
    b, i = _value(comparison, claim.primary_metric), _value(improved, claim.primary_metric)
    if math.isnan(b) or math.isnan(i):
        return "missing"
    d = (i - b) if claim.lower_is_better else (b - i)
    if d <= -margin and d < 0:
        return "better"
    if d >= margin and d > 0:
        return "worse"
    return "within margin"


def claims_table(metrics_by_method: dict[str, dict], margins: dict[str, float],
                 comparisons: tuple[str, ...] = ("baseline", "baseline_matched"),
                 improved: str = "improved") -> list[dict]:
    """One row per claim on one scenario: primary metric per method, outcome per comparison."""
    rows = []
    for claim in ALL_CLAIMS:
        row = {"claim": claim.claim_id, "paper says": claim.text,
               "metric": claim.primary_metric,
               "better": "lower" if claim.lower_is_better else "higher",
               "margin": margins[claim.claim_id]}
        for method, metrics in metrics_by_method.items():
            row[method] = metrics.get(claim.primary_metric)
        for comparison in comparisons:
            if comparison in metrics_by_method and improved in metrics_by_method:
                row[f"vs {comparison}"] = single_scenario_outcome(
                    claim, metrics_by_method[comparison], metrics_by_method[improved],
                    margins[claim.claim_id])
        rows.append(row)
    return rows


def hodges_lehmann(values: np.ndarray, axis: int = -1) -> np.ndarray:
    """One-sample Hodges-Lehmann estimate: the median of the Walsh averages
    ``(d_i + d_j) / 2, i <= j`` along ``axis`` (vectorized over the other axes)."""
    x = np.moveaxis(np.asarray(values, dtype=float), axis, -1)
    i, j = np.triu_indices(x.shape[-1])
    return np.median((x[..., i] + x[..., j]) / 2.0, axis=-1)


def hodges_lehmann_on(sample: np.ndarray):
    """:func:`hodges_lehmann` specialised to resamples of ``sample`` (as a bootstrap draws them).

    A resample holds the sample's distinct values ``u`` with counts ``c``; its Walsh averages
    are the sorted Walsh averages of ``u`` with weights ``c_a c_b`` (``c_a (c_a + 1) / 2`` on the
    diagonal), so its median is a weighted median found by a cumulative sum instead of a
    partition of ``n (n + 1) / 2`` numbers per resample. Same numbers, several times faster;
    values outside ``sample`` fall back to the direct computation.
    """
    u = np.unique(np.asarray(sample, dtype=float))
    a, b = np.triu_indices(u.size)
    walsh = (u[a] + u[b]) / 2.0
    order = np.argsort(walsh, kind="stable")
    walsh, a, b = walsh[order], a[order], b[order]
    diagonal = a == b

    def statistic(x, axis=-1):
        x = np.moveaxis(np.asarray(x, dtype=float), axis, -1)
        batch_shape, n = x.shape[:-1], x.shape[-1]
        flat = x.reshape(-1, n)
        index = np.clip(np.searchsorted(u, flat), 0, u.size - 1)
        if u.size == 0 or not np.array_equal(u[index], flat):
            return hodges_lehmann(x, axis=-1)
        rows = flat.shape[0]
        # every partial sum is at most n (n + 1) / 2: 32-bit integers whenever that fits (half
        # the memory traffic of the weights and their cumulative sum, the same integers)
        dtype = np.int32 if n * (n + 1) // 2 < 2**31 else np.int64
        counts = np.bincount((index + u.size * np.arange(rows)[:, None]).ravel(),
                             minlength=rows * u.size).reshape(rows, u.size).astype(dtype)
        total = n * (n + 1) // 2
        low, high = np.empty(rows, dtype=np.intp), np.empty(rows, dtype=np.intp)
        # a few resamples at a time: their weights stay in the CPU's cache between the passes
        # (a quarter less time than whole batches; the same integers)
        step = max(1, 2**18 // max(walsh.size, 1))
        for start in range(0, rows, step):
            part = counts[start:start + step]
            weights = part[:, a] * part[:, b]
            on_diagonal = part[:, a[diagonal]]
            weights[:, diagonal] = on_diagonal * (on_diagonal + 1) // 2
            cumulative = np.cumsum(weights, axis=1, dtype=dtype)
            low[start:start + step] = np.argmax(cumulative > (total - 1) // 2, axis=1)
            high[start:start + step] = np.argmax(cumulative > total // 2, axis=1)
        return ((walsh[low] + walsh[high]) / 2.0).reshape(batch_shape)

    return statistic


def _estimator(name: str, sample: np.ndarray | None = None):
    if name == "median":
        return lambda x, axis=-1: np.median(x, axis=axis)
    return hodges_lehmann_on(sample) if sample is not None else hodges_lehmann


def bootstrap_interval(d: np.ndarray, statistic, cfg, level: float = 0.95
                       ) -> tuple[float, float, str]:
    """Paired bootstrap interval of ``statistic`` over the differences (BCa where defined,
    percentile otherwise); a constant sample has the degenerate interval at its value."""
    from scipy import stats

    d = np.asarray(d, dtype=float)
    if d.size == 0:
        return float("nan"), float("nan"), "none"
    if np.ptp(d) == 0.0:
        return float(d[0]), float(d[0]), "degenerate"
    for method in ("BCa", "percentile"):
        with np.errstate(all="ignore"):
            import warnings

            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result = stats.bootstrap((d,), statistic, n_resamples=cfg.n_resamples,
                                         confidence_level=level, method=method, vectorized=True,
                                         axis=-1, batch=200,
                                         random_state=np.random.default_rng(cfg.seed))
        low, high = result.confidence_interval
        if np.isfinite(low) and np.isfinite(high):
            return float(low), float(high), method
    return float("nan"), float("nan"), "failed"


def probability_of_improvement(d: np.ndarray, cfg) -> tuple[float, float, float]:
    """``P(d < 0) + P(d = 0) / 2`` (ties within ``tie_tolerance``) and its percentile bootstrap
    interval."""
    from scipy import stats

    d = np.asarray(d, dtype=float)
    if d.size == 0:
        return float("nan"), float("nan"), float("nan")
    tie = cfg.tie_tolerance
    score = np.where(d < -tie, 1.0, np.where(d > tie, 0.0, 0.5))
    value = float(score.mean())
    if np.ptp(score) == 0.0:
        return value, value, value
    result = stats.bootstrap((score,), np.mean, n_resamples=cfg.n_resamples, method="percentile",
                             vectorized=True, axis=-1,
                             random_state=np.random.default_rng(cfg.seed + 1))
    low, high = result.confidence_interval
    return value, float(low), float(high)


def paired_test(d: np.ndarray, cfg) -> float:
    """Two-sided p-value of the paired test on ``d`` (1 when every pair ties)."""
    from scipy import stats

    d = np.asarray(d, dtype=float)
    tie = cfg.tie_tolerance
    better, worse = int(np.sum(d < -tie)), int(np.sum(d > tie))
    if better + worse == 0:
        return 1.0
    if cfg.test == "sign":
        return float(stats.binomtest(better, better + worse, 0.5).pvalue)
    cleaned = np.where(np.abs(d) <= tie, 0.0, d)
    return wilcoxon_pratt_pvalue(cleaned)


#: SciPy's ``wilcoxon(method="auto")`` enumerates every sign flip up to this many pairs when
#: zeros or ties make its exact distribution inexact (2**13 < its 9999 resamples)
WILCOXON_ENUMERATED_MAX_PAIRS = 13


def wilcoxon_pratt_pvalue(d: np.ndarray) -> float:
    """``scipy.stats.wilcoxon(d, zero_method="pratt").pvalue``, the same number, faster where
    SciPy enumerates.

    With zeros or tied ``|d|`` and at most 13 pairs SciPy runs ``permutation_test`` over all
    ``2**n`` sign flips, calling its statistic once per flip in Python (about 0.15 s for 12
    pairs, most of a small family's ledger). Every flip keeps ``|d|`` and so its ranks; ``R+``
    is the sum of the ranks of the positive entries. Here the same ``permutation_test`` gets
    that sum over all flips at once (``vectorized=True``): the same null distribution, the same
    comparisons, the same p-value. Everything else is SciPy's own call.
    """
    from scipy import stats

    d = np.asarray(d, dtype=float)
    magnitude = np.abs(d)
    n = d.size
    enumerated = 2 <= n <= WILCOXON_ENUMERATED_MAX_PAIRS and np.all(np.isfinite(d)) and (
        np.count_nonzero(d == 0.0) > 0 or np.unique(magnitude).size < n)
    if not enumerated:
        return float(stats.wilcoxon(d, zero_method="pratt").pvalue)
    ranks = stats.rankdata(magnitude)  # average ranks, as SciPy's statistic takes them

    def positive_rank_sum(flipped: np.ndarray, axis: int = -1) -> np.ndarray:
        return np.sum((flipped > 0) * ranks, axis=axis)

    return float(stats.permutation_test((d,), positive_rank_sum, permutation_type="samples",
                                        vectorized=True, alternative="two-sided",
                                        axis=-1).pvalue)


def holm(p_values: list[float]) -> list[float]:
    """Holm's step-down adjustment (monotone, capped at 1); NaN stays NaN."""
    p = np.asarray(p_values, dtype=float)
    finite = np.nonzero(np.isfinite(p))[0]
    adjusted = np.full(p.shape, np.nan)
    order = finite[np.argsort(p[finite], kind="stable")]
    m, running = len(order), 0.0
    for rank, index in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[index]))
        adjusted[index] = running
    return adjusted.tolist()


def decide(low: float, high: float, p_adjusted: float, margin: float, n_pairs: int, cfg,
           pi_low: float = float("nan"), pi_high: float = float("nan"),
           estimate: float = float("nan"), pi: float = float("nan")) -> tuple[Outcome, str]:
    """Outcome and note (:data:`OUTCOME_RULE`).

    Equivalence is read off the estimate's interval and the margin; significance off the
    adjusted p. A direction needs the estimate's interval (clear of zero) and the probability of
    improvement (its point ``pi``, or its interval's middle) to agree; when they point opposite
    ways the outcome is "mixed". Without a probability of improvement (rates) the interval alone
    gives the direction.
    """
    if n_pairs < cfg.min_pairs or not (np.isfinite(low) and np.isfinite(high)):
        return Outcome.INCONCLUSIVE, f"too few pairs ({n_pairs} < {cfg.min_pairs})"
    significant = bool(np.isfinite(p_adjusted) and p_adjusted < cfg.alpha)
    # the interval contains no improvement (or no worsening); a lattice interval may end at 0
    est_better, est_worse = high <= 0 < -low, low >= 0 < high
    if not np.isfinite(pi) and np.isfinite(pi_low) and np.isfinite(pi_high):
        pi = (pi_low + pi_high) / 2.0
    if np.isfinite(pi):
        pi_better, pi_worse = pi > 0.5, pi < 0.5
    else:
        pi_better, pi_worse = est_better, est_worse
    if -margin < low and high < margin:
        if significant and est_better and pi_better:
            return Outcome.EQUIVALENT, "improved better, by less than the margin"
        if significant and est_worse and pi_worse:
            return Outcome.EQUIVALENT, "improved worse, by less than the margin"
        return Outcome.EQUIVALENT, ""
    if significant and est_better and pi_better:
        return Outcome.SUPPORTED, ""
    if significant and est_worse and pi_worse:
        return Outcome.CONTRADICTED, ""
    if significant and ((est_better and pi_worse) or (est_worse and pi_better)):
        value = estimate if np.isfinite(estimate) else (low + high) / 2.0
        if pi_better:
            words = (f"most pairs better (P(improvement) {pi:.2f}) but the typical difference "
                     f"worse ({value:+.3g} [{low:.3g}, {high:.3g}])")
        else:
            words = (f"most pairs worse (P(improvement) {pi:.2f}) but the typical difference "
                     f"better ({value:+.3g} [{low:.3g}, {high:.3g}])")
        return Outcome.MIXED, words
    return Outcome.INCONCLUSIVE, ""


def newcombe_paired_interval(n_both: int, n_first_only: int, n_second_only: int, n: int,
                             level: float = 0.95) -> tuple[float, float]:
    """Newcombe's hybrid score interval (his method 10, Stat. Med. 1998, 17: 2635-2650) for the
    difference of two paired proportions ``p1 - p2``, ``p1 = (a + b) / n``, ``p2 = (a + c) / n``.

    Built from the two Wilson score intervals (``scipy.stats.binomtest(...).proportion_ci``)
    and the correlation ``phi`` of the paired table; unlike a bootstrap it is not degenerate at
    zero events (with none in either, it is ``[-u, u]``, ``u = z^2 / (n + z^2)``).
    """
    from scipy import stats

    a, b, c = n_both, n_first_only, n_second_only
    d = n - a - b - c
    if n <= 0 or d < 0:
        return float("nan"), float("nan")
    p1, p2 = (a + b) / n, (a + c) / n
    ci1 = stats.binomtest(a + b, n).proportion_ci(confidence_level=level, method="wilson")
    ci2 = stats.binomtest(a + c, n).proportion_ci(confidence_level=level, method="wilson")
    l1, u1, l2, u2 = ci1.low, ci1.high, ci2.low, ci2.high
    denominator = (a + b) * (c + d) * (a + c) * (b + d)
    phi = (a * d - b * c) / math.sqrt(denominator) if denominator > 0 else 0.0
    delta = math.sqrt(max((p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2, 0.0))
    epsilon = math.sqrt(max((u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2,
                            0.0))
    return float(p1 - p2 - delta), float(p1 - p2 + epsilon)


PAIRS = ("neither_collided", "all")


def paired_differences(improved: pd.DataFrame, comparison: pd.DataFrame, claim: Claim,
                       pairs: str = "all") -> pd.DataFrame:
    """Pairs by ``scenario``: the claim's primary metric of both, ``d`` (NaN when either is
    missing, signed so that ``d < 0`` is the claimed improvement) and both collision flags.

    ``pairs="neither_collided"`` keeps, for a paired claim, the pairs where neither method
    collided (a rate claim always keeps every pair): the one place this filter is applied.
    """
    key = claim.primary_metric
    cols = ["scenario", key] + (["collision"] if key != "collision" else [])
    merged = improved[cols].merge(comparison[cols], on="scenario", suffixes=("_i", "_c"))
    i = pd.to_numeric(merged[f"{key}_i"], errors="coerce").to_numpy(float)
    c = pd.to_numeric(merged[f"{key}_c"], errors="coerce").to_numpy(float)
    sign = 1.0 if claim.lower_is_better else -1.0
    merged["d"] = sign * (i - c)
    if key == "collision":
        merged["collision_i"], merged["collision_c"] = i.astype(bool), c.astype(bool)
    else:
        merged["collision_i"] = merged["collision_i"].astype(bool)
        merged["collision_c"] = merged["collision_c"].astype(bool)
    if pairs == "neither_collided" and not claim.is_rate:
        merged = merged[~(merged["collision_i"] | merged["collision_c"])]
    return merged


@dataclass(frozen=True)
class PairedResult:
    """One claim, one comparison, before the Holm adjustment and the outcome."""

    n_pairs: int
    n_missing: int
    n_better: int
    n_tied: int
    n_worse: int
    estimate: float
    ci_low: float
    ci_high: float
    interval_method: str
    p_value: float
    prob_improvement: float
    pi_low: float
    pi_high: float
    #: pairs where both methods sit at the metric's floor (the smallest value seen)
    n_floor_ties: int = 0
    floor_value: float = float("nan")
    #: the finite paired differences the estimate was taken on (for plots)
    differences: np.ndarray = field(repr=False, compare=False, default=None)


def compare(improved: pd.DataFrame, comparison: pd.DataFrame, claim: Claim, cfg,
            pairs: str | None = None) -> PairedResult:
    """One claim, one comparison: estimate, interval, test, probability of improvement,
    counts (before the Holm adjustment and the outcome)."""
    from scipy import stats

    merged = paired_differences(improved, comparison, claim, cfg.pairs if pairs is None
                                else pairs)
    d_all = merged["d"].to_numpy(float)
    d = d_all[np.isfinite(d_all)]
    tie = cfg.tie_tolerance
    better, tied, worse = int(np.sum(d < -tie)), int(np.sum(np.abs(d) <= tie)), \
        int(np.sum(d > tie))
    key = claim.primary_metric
    ok = np.isfinite(d_all)
    values_i = pd.to_numeric(merged[f"{key}_i"], errors="coerce").to_numpy(float)[ok]
    values_c = pd.to_numeric(merged[f"{key}_c"], errors="coerce").to_numpy(float)[ok]
    floor = float(min(values_i.min(), values_c.min())) if d.size else float("nan")
    n_floor = int(np.sum((np.abs(values_i - floor) <= tie) & (np.abs(values_c - floor) <= tie))) \
        if d.size else 0
    if claim.is_rate:
        # rates: the difference of the two rates with Newcombe's paired score interval (honest
        # at zero events); McNemar's exact test on the discordant pairs
        estimate = float(d.mean()) if d.size else float("nan")
        events_i, events_c = values_i.astype(bool), values_c.astype(bool)
        low, high = newcombe_paired_interval(int(np.sum(events_i & events_c)),
                                             int(np.sum(events_i & ~events_c)),
                                             int(np.sum(~events_i & events_c)), int(d.size))
        method = "newcombe_paired_score"
        discordant = better + worse
        p_value = float(stats.binomtest(worse, discordant, 0.5).pvalue) if discordant else 1.0
    else:
        estimate = float(_estimator(cfg.estimator)(d)) if d.size else float("nan")
        low, high, method = bootstrap_interval(d, _estimator(cfg.estimator, d), cfg)
        p_value = paired_test(d, cfg) if d.size else float("nan")
    pi, pi_low, pi_high = probability_of_improvement(d, cfg)
    return PairedResult(int(d.size), int(d_all.size - d.size), better, tied, worse, estimate,
                        low, high, method, p_value, pi, pi_low, pi_high, n_floor, floor, d)


LEDGER_COLUMNS = ["claim", "comparison", "metric", "outcome", "estimate", "ci_low", "ci_high",
                  "p_value", "p_holm", "prob_improvement", "pi_low", "pi_high", "n_better",
                  "n_tied", "n_worse", "n_missing", "n_pairs", "margin", "note",
                  "outcome_all_pairs", "estimate_all_pairs", "paper_scenario"]


@dataclass(frozen=True)
class LedgerRow:
    """The verdict on one claim against one comparison."""

    claim: Claim
    comparison: str
    outcome: Outcome
    result: PairedResult
    p_holm: float
    margin: float
    note: str
    margin_reason: str
    outcome_all_pairs: Outcome | None = None
    estimate_all_pairs: float | None = None
    paper_scenario: str | None = None

    @property
    def claim_id(self) -> str:
        return self.claim.claim_id

    @property
    def key(self) -> tuple[str, str]:
        return (self.claim.claim_id, self.comparison)

    def to_dict(self) -> dict:
        """The row as the ledger table writes it (:data:`LEDGER_COLUMNS` and more)."""
        r = self.result
        return {"claim": self.claim.claim_id, "comparison": self.comparison,
                "metric": self.claim.primary_metric, "outcome": str(self.outcome),
                "n_pairs": r.n_pairs, "n_missing": r.n_missing, "n_better": r.n_better,
                "n_tied": r.n_tied, "n_worse": r.n_worse, "estimate": r.estimate,
                "ci_low": r.ci_low, "ci_high": r.ci_high, "interval_method": r.interval_method,
                "p_value": r.p_value, "prob_improvement": r.prob_improvement,
                "pi_low": r.pi_low, "pi_high": r.pi_high, "p_holm": self.p_holm,
                "margin": self.margin, "note": self.note, "margin_reason": self.margin_reason,
                "paper says": self.claim.text,
                "outcome_all_pairs": None if self.outcome_all_pairs is None
                else str(self.outcome_all_pairs),
                "estimate_all_pairs": self.estimate_all_pairs,
                "paper_scenario": self.paper_scenario}


@dataclass(frozen=True)
class Ledger:
    """Verdicts on every claim against every comparison, keyed by ``(claim_id, comparison)``."""

    rows: tuple[LedgerRow, ...] = ()
    treatment: str = "improved"

    def __iter__(self):
        return iter(self.rows)

    def __len__(self) -> int:
        return len(self.rows)

    def __getitem__(self, key: tuple[str, str]) -> LedgerRow:
        for row in self.rows:
            if row.key == key:
                return row
        raise KeyError(key)

    def get(self, key: tuple[str, str]) -> LedgerRow | None:
        return next((row for row in self.rows if row.key == key), None)

    @property
    def comparisons(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(row.comparison for row in self.rows))

    @property
    def differences(self) -> dict[tuple[str, str], np.ndarray]:
        """The paired differences each outcome was taken on, for plotting."""
        return {row.key: row.result.differences for row in self.rows}

    def records(self) -> list[dict]:
        return [row.to_dict() for row in self.rows]

    def to_frame(self) -> pd.DataFrame:
        """The ledger table (``claims_ledger.csv``)."""
        return pd.DataFrame(self.records()).reindex(
            columns=LEDGER_COLUMNS + ["interval_method", "margin_reason"])


def family_ledger(tables: dict[str, pd.DataFrame], cfg, paper_metrics: dict[str, dict] | None
                  = None, improved: str = "improved",
                  comparisons: tuple[str, ...] = ("baseline", "baseline_matched"),
                  sensitivity: bool = True) -> Ledger:
    """Claims ledger over a scenario family: C0-C5 against each comparison present.

    Parameters
    ----------
    tables : dict of method -> DataFrame
        Per-scenario metrics (``family_metrics.csv``) of each method, with a ``scenario`` column.
    cfg : ClaimsConfig
    paper_metrics : dict of method -> metrics, optional
        The paper scenario's values: its better / worse / within-margin word per claim.
    improved : str
        The treatment; ``comparisons`` are its controls.
    sensitivity : bool
        Also judge C1-C5 on the other set of pairs (all pairs when the ledger uses those where
        neither collided).

    Returns
    -------
    Ledger
    """
    rows: list[LedgerRow] = []
    if improved not in tables:
        return Ledger((), improved)
    for comparison in [c for c in comparisons if c in tables]:
        block = [(claim, compare(tables[improved], tables[comparison], claim, cfg))
                 for claim in ALL_CLAIMS]
        adjusted = holm([r.p_value for _, r in block])
        for (claim, result), p_holm in zip(block, adjusted):
            rows.append(_ledger_row(claim, comparison, result, p_holm, tables, cfg,
                                    paper_metrics, improved, sensitivity))
    return Ledger(tuple(rows), improved)


def judge(result: PairedResult, p_value: float, margin: float, cfg, claim: Claim
          ) -> tuple[Outcome, str]:
    """:func:`decide` on one comparison's result (a rate's direction from its interval)."""
    if claim.is_rate:
        return decide(result.ci_low, result.ci_high, p_value, margin, result.n_pairs, cfg,
                      estimate=result.estimate)
    return decide(result.ci_low, result.ci_high, p_value, margin, result.n_pairs, cfg,
                  result.pi_low, result.pi_high, result.estimate, result.prob_improvement)


def _ledger_row(claim: Claim, comparison: str, result: PairedResult, p_holm: float,
                tables: dict[str, pd.DataFrame], cfg, paper_metrics: dict | None,
                improved: str, sensitivity: bool) -> LedgerRow:
    margin = float(cfg.margins[claim.claim_id])
    outcome, note = judge(result, p_holm, margin, cfg, claim)
    if not claim.is_rate and result.n_pairs and \
            result.n_floor_ties >= cfg.floor_tie_share * result.n_pairs:
        floor_note = (f"neither method shows the behaviour in {result.n_floor_ties} of "
                      f"{result.n_pairs} pairs (both at {result.floor_value:.3g})")
        note = f"{note}; {floor_note}" if note else floor_note
    all_pairs, estimate_all = None, None
    if claim.is_rate:
        all_pairs, estimate_all = outcome, result.estimate
    elif sensitivity:
        other = "all" if cfg.pairs == "neither_collided" else "neither_collided"
        sens = compare(tables[improved], tables[comparison], claim, cfg, pairs=other)
        # the sensitivity keeps its own unadjusted test: it is a check, not a claim
        all_pairs, _ = judge(sens, sens.p_value, margin, cfg, claim)
        estimate_all = sens.estimate
    paper = None
    if paper_metrics and comparison in paper_metrics and improved in paper_metrics:
        paper = single_scenario_outcome(claim, paper_metrics[comparison],
                                        paper_metrics[improved], margin)
    return LedgerRow(claim, comparison, outcome, result, p_holm, margin, note,
                     cfg.margin_reasons[claim.claim_id], all_pairs, estimate_all, paper)


def outcome_counts(tables: dict[str, pd.DataFrame]) -> list[dict]:
    """Collisions (avoidable / unavoidable), failures and fallbacks per method; how often the
    APF's step cap binds (:class:`pipeline.analysis.tally.Tally`)."""
    return [{"method": method, **Tally.of(t).to_dict()} for method, t in tables.items()]
