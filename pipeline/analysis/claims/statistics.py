"""The statistics of one claim against one comparison: paired differences, the Hodges-Lehmann
estimate with its paired bootstrap interval, the paired tests (Wilcoxon, sign, McNemar),
Newcombe's interval for a rate, the probability of improvement, Holm's adjustment, and the
outcome (:func:`decide`, :func:`judge`; :data:`pipeline.analysis.claims.catalogue.OUTCOME_RULE`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from pipeline.analysis.claims.catalogue import Claim, Outcome
from pipeline.analysis.claims.memo import IntervalMemo
from pipeline.analysis.objectives import CENSORED_AT_RUN_END
from pipeline.analysis.settings import ClaimsConfig


def hodges_lehmann(values: np.ndarray, axis: int = -1) -> np.ndarray:
    """One-sample Hodges-Lehmann estimate: the median of the Walsh averages
    ``(d_i + d_j) / 2, i <= j`` along ``axis`` (vectorized over the other axes)."""
    x = np.moveaxis(np.asarray(values, dtype=float), axis, -1)
    i, j = np.triu_indices(x.shape[-1])
    return np.median((x[..., i] + x[..., j]) / 2.0, axis=-1)


#: A statistic of paired differences along an axis (what the bootstrap resamples).
Statistic = Callable[..., Any]


@dataclass(frozen=True)
class WalshMedian:
    """:func:`hodges_lehmann` specialised to resamples of one sample (as a bootstrap draws
    them): a statistic over values, ``statistic(x, axis=-1)``.

    A resample holds the sample's distinct values with counts; its estimate is a weighted
    median of the sample's Walsh averages, found by the compiled
    :func:`pipeline.analysis.claims.compiled.walsh_medians` (a search over the sorted Walsh
    averages, O(u log u) per resample: the same numbers as the direct median, bit for bit);
    values outside the sample fall back to the direct computation. ``values``: the distinct
    values, sorted; ``walsh``: every ``(values[a] + values[b]) / 2``, ``a <= b``, sorted, with
    its ``first`` and ``second`` indices.
    """

    values: np.ndarray
    walsh: np.ndarray
    first: np.ndarray
    second: np.ndarray

    @classmethod
    def of(cls, sample: np.ndarray) -> WalshMedian:
        values = np.unique(np.asarray(sample, dtype=float))
        first, second = np.triu_indices(values.size)
        walsh = (values[first] + values[second]) / 2.0
        order = np.argsort(walsh, kind="stable")
        return cls(values, walsh[order], first[order], second[order])

    def __call__(self, x: Any, axis: int = -1) -> Any:
        from pipeline.analysis.claims.compiled import walsh_medians

        x = np.moveaxis(np.asarray(x, dtype=float), axis, -1)
        if self.values.size == 0 or x.shape[-1] == 0:
            return hodges_lehmann(x, axis=-1)
        index = np.clip(np.searchsorted(self.values, x), 0, self.values.size - 1)
        if not np.array_equal(self.values[index], x):
            return hodges_lehmann(x, axis=-1)
        batch_shape, n = index.shape[:-1], index.shape[-1]
        flat = np.ascontiguousarray(index.reshape(-1, n), dtype=np.int64)
        return walsh_medians(flat, self.values, self.walsh, self.first,
                             self.second).reshape(batch_shape)


@dataclass(frozen=True)
class WalshMedianOfPositions:
    """A :class:`WalshMedian` read on the positions of its sample instead of its values: a
    resample of positions ``i`` (floats, as a bootstrap hands data) is the resample
    ``sample[i]`` of values. The bootstrap of the positions draws the same indices from the
    same generator as the bootstrap of the values (they depend only on the sample's size), so
    every resample's estimate, the jackknife's and the interval are the same numbers; each
    position's distinct value is looked up instead of searched for."""

    median: WalshMedian
    codes: np.ndarray

    def __call__(self, positions: Any, axis: int = -1) -> Any:
        from pipeline.analysis.claims.compiled import walsh_medians

        index = self.codes[np.moveaxis(np.asarray(positions), axis, -1).astype(np.intp)]
        batch_shape, n = index.shape[:-1], index.shape[-1]
        if n == 0:
            return hodges_lehmann(np.zeros(batch_shape + (0,)), axis=-1)
        m = self.median
        return walsh_medians(np.ascontiguousarray(index.reshape(-1, n), dtype=np.int64),
                             m.values, m.walsh, m.first, m.second).reshape(batch_shape)


def on_positions(statistic: Statistic, sample: np.ndarray
                 ) -> tuple[np.ndarray, Statistic] | None:
    """``(positions, statistic of positions)`` when ``statistic`` is the :class:`WalshMedian`
    of ``sample`` (the bootstrap then resamples positions), else None."""
    if not isinstance(statistic, WalshMedian) or statistic.values.size == 0:
        return None
    codes = np.searchsorted(statistic.values, sample)
    if codes.size and (codes.max() >= statistic.values.size
                       or not np.array_equal(statistic.values[codes], sample)):
        return None
    return np.arange(sample.size, dtype=float), WalshMedianOfPositions(statistic, codes)


def hodges_lehmann_on(sample: np.ndarray) -> WalshMedian:
    """:func:`hodges_lehmann` specialised to resamples of ``sample`` (:class:`WalshMedian`):
    the same numbers, about ten times faster than a cumulative sum over every Walsh average
    on 170 distinct values."""
    return WalshMedian.of(sample)


def _estimator(name: str, sample: np.ndarray | None = None) -> Statistic:
    if name == "median":
        return lambda x, axis=-1: np.median(x, axis=axis)
    return hodges_lehmann_on(sample) if sample is not None else hodges_lehmann


@dataclass(frozen=True)
class BootstrapInterval:
    """A paired bootstrap interval and its Monte-Carlo resolution: each end's half-width of
    the distribution-free band of the bootstrap quantile it is (the order statistics at
    ranks ``B q +- z sqrt(B q (1 - q))``, ``q`` the end's level: BCa's adjusted level, or the
    percentile's; ``z = claims.mc_band_z``): another seed's end lies within it about as often
    as ``z`` says. On a lattice metric the band is 0 wide unless the level's rank lies near
    the edge of an atom of the bootstrap distribution."""

    low: float
    high: float
    method: str
    n_resamples: int = 0
    low_mc: float = 0.0
    high_mc: float = 0.0


def quantile_band(sorted_values: np.ndarray, level: float, z: float) -> tuple[float, float]:
    """The order statistics that bound the ``level`` quantile of ``sorted_values`` (the
    resamples' statistic, sorted) at ``z`` binomial standard errors of its rank: a
    distribution-free band for a bootstrap quantile."""
    count = int(sorted_values.size)
    if count == 0 or not 0.0 <= level <= 1.0:
        return float("nan"), float("nan")
    spread = z * math.sqrt(count * level * (1.0 - level))
    low_rank = int(np.clip(math.floor(count * level - spread) - 1, 0, count - 1))
    high_rank = int(np.clip(math.ceil(count * level + spread) - 1, 0, count - 1))
    return float(sorted_values[low_rank]), float(sorted_values[high_rank])


def interval_levels(d: np.ndarray, statistic: Statistic, resampled: np.ndarray, level: float,
                    method: str) -> tuple[float, float]:
    """The quantile levels of the bootstrap distribution ``resampled`` that a ``method``
    interval at ``level`` reads: ``(1 -+ level) / 2`` for the percentile interval; BCa's
    adjusted levels (Efron and Tibshirani 1993, 14.3: the bias ``z0`` from the share of
    resamples below the estimate, ties counted half, as ``scipy.stats.bootstrap`` counts them,
    and the acceleration from the jackknife)."""
    from scipy.special import ndtr, ndtri

    alpha = (1.0 - level) / 2.0
    if method != "BCa":
        return alpha, 1.0 - alpha
    estimate = float(np.asarray(statistic(d[None, :], axis=-1)).ravel()[0])
    below = (np.count_nonzero(resampled < estimate) + np.count_nonzero(resampled <= estimate))
    z0 = float(ndtri(below / (2.0 * resampled.size)))
    n = d.size
    others = np.broadcast_to(d, (n, n))[~np.eye(n, dtype=bool)].reshape(n, n - 1)
    leave_one_out = np.asarray(statistic(others, axis=-1), dtype=float).ravel()
    spread = (n - 1) * (leave_one_out.mean() - leave_one_out)
    denominator = float(np.sum(spread ** 2) / n ** 2) ** 1.5
    acceleration = float(np.sum(spread ** 3) / n ** 3) / denominator / 6.0 \
        if denominator > 0 else 0.0
    levels = []
    for z_alpha in (float(ndtri(alpha)), -float(ndtri(alpha))):
        shifted = z0 + z_alpha
        levels.append(float(ndtr(z0 + shifted / (1.0 - acceleration * shifted))))
    return levels[0], levels[1]


def bootstrap_interval(d: np.ndarray, statistic: Statistic, cfg: ClaimsConfig,
                       level: float = 0.95, n_resamples: int | None = None
                       ) -> BootstrapInterval:
    """Paired bootstrap interval of ``statistic`` over the differences (BCa where defined,
    percentile otherwise) with ``n_resamples`` (``claims.n_resamples`` when omitted) and each
    end's Monte-Carlo half-width (:class:`BootstrapInterval`); a constant sample has the
    degenerate interval at its value."""
    from scipy import stats

    d = np.asarray(d, dtype=float)
    resamples = int(cfg.n_resamples if n_resamples is None else n_resamples)
    if d.size == 0:
        return BootstrapInterval(float("nan"), float("nan"), "none")
    if np.ptp(d) == 0.0:
        return BootstrapInterval(float(d[0]), float(d[0]), "degenerate", resamples)
    # the Walsh median resamples the sample's positions (the same draws, looked up, not
    # searched for: the same numbers)
    data, resampled_statistic = on_positions(statistic, d) or (d, statistic)
    for method in ("BCa", "percentile"):
        with np.errstate(all="ignore"):
            import warnings

            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result = stats.bootstrap((data,), resampled_statistic, n_resamples=resamples,
                                         confidence_level=level, method=method, vectorized=True,
                                         axis=-1, batch=200,
                                         random_state=np.random.default_rng(cfg.seed))
                low, high = (float(v) for v in result.confidence_interval)
                if not (np.isfinite(low) and np.isfinite(high)):
                    continue
                values = np.sort(np.asarray(result.bootstrap_distribution, dtype=float).ravel())
                levels = interval_levels(d, statistic, values, level, method)
        bands = [quantile_band(values, q, cfg.mc_band_z) for q in levels]
        low_mc = max(low - bands[0][0], bands[0][1] - low, 0.0)
        high_mc = max(high - bands[1][0], bands[1][1] - high, 0.0)
        return BootstrapInterval(low, high, method, resamples, float(low_mc), float(high_mc))
    return BootstrapInterval(float("nan"), float("nan"), "failed", resamples)


def within_resolution(interval: BootstrapInterval, margin: float) -> bool:
    """Whether a threshold of the outcome rule lies within an end's Monte-Carlo band: the low
    end near ``-margin`` or 0, the high end near 0 or ``+margin`` (another bootstrap seed
    could then give another outcome)."""
    return any(abs(end - threshold) <= mc for end, mc, thresholds in (
        (interval.low, interval.low_mc, (-margin, 0.0)),
        (interval.high, interval.high_mc, (0.0, margin))) for threshold in thresholds
        if np.isfinite(end) and mc > 0.0)


def probability_of_improvement(d: np.ndarray, cfg: ClaimsConfig, level: float = 0.95
                               ) -> tuple[float, float, float]:
    """``P(d < 0) + P(d = 0) / 2`` (ties within ``tie_tolerance``) and its percentile bootstrap
    interval at ``level``."""
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
                             confidence_level=level, vectorized=True, axis=-1,
                             random_state=np.random.default_rng(cfg.seed + 1))
    low, high = result.confidence_interval
    return value, float(low), float(high)


def paired_test(d: np.ndarray, cfg: ClaimsConfig) -> float:
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


def interval_level(cfg: ClaimsConfig, n_claims: int) -> float:
    """The confidence level of a ledger row's interval: ``1 - alpha / n_claims`` with
    ``claims.interval_adjustment: bonferroni`` (the claims against one comparison share the
    family-wise error rate ``alpha``), ``1 - alpha`` with ``none``.

    The interval *is* the test (:data:`OUTCOME_RULE`): a direction exactly when it excludes 0.
    Holm's step-down, which adjusts the p-values shown beside it, has no interval it is dual to
    (Strassburger and Bretz, Stat. Med. 2008), so the intervals carry Bonferroni's level.
    """
    if cfg.interval_adjustment == "none":
        return 1.0 - cfg.alpha
    return 1.0 - cfg.alpha / max(int(n_claims), 1)


def decide(low: float, high: float, margin: float, n_pairs: int, cfg: ClaimsConfig,
           pi_low: float = float("nan"), pi_high: float = float("nan"),
           estimate: float = float("nan"), pi: float = float("nan")) -> tuple[Outcome, str]:
    """Outcome and note (:data:`OUTCOME_RULE`) from the estimate's interval at the ledger's
    level (:func:`interval_level`).

    Equivalence is read off the interval and the margin. A direction exactly when the interval
    excludes 0 (strictly: an interval ending at 0, as lattice metrics give, has none) and the
    estimate is not 0; it needs the probability of improvement (its point ``pi``, or its
    interval's middle) to agree, and is "mixed" when they point opposite ways. Without a
    probability of improvement (rates) the interval alone gives the direction. Everything else
    is inconclusive: a row is inconclusive exactly when its interval contains 0 and reaches
    beyond the margin.
    """
    if n_pairs < cfg.min_pairs or not (np.isfinite(low) and np.isfinite(high)):
        return Outcome.INCONCLUSIVE, f"too few pairs ({n_pairs} < {cfg.min_pairs})"
    has_estimate = np.isfinite(estimate)
    est_better = high < 0.0 and (estimate < 0.0 if has_estimate else True)
    est_worse = low > 0.0 and (estimate > 0.0 if has_estimate else True)
    if not np.isfinite(pi) and np.isfinite(pi_low) and np.isfinite(pi_high):
        pi = (pi_low + pi_high) / 2.0
    if np.isfinite(pi):
        pi_better, pi_worse = pi > 0.5, pi < 0.5
    else:
        pi_better, pi_worse = est_better, est_worse
    if -margin < low and high < margin:
        if est_better and pi_better:
            return Outcome.EQUIVALENT, "improved better, by less than the margin"
        if est_worse and pi_worse:
            return Outcome.EQUIVALENT, "improved worse, by less than the margin"
        return Outcome.EQUIVALENT, ""
    if est_better and not pi_worse:
        return Outcome.SUPPORTED, ""
    if est_worse and not pi_better:
        return Outcome.CONTRADICTED, ""
    if est_better or est_worse:
        value = estimate if has_estimate else (low + high) / 2.0
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


PAIRS = ("neither_collided", "all", "worst_rank", "unsettled_last")


def paired_differences(improved: pd.DataFrame, comparison: pd.DataFrame, claim: Claim,
                       pairs: str = "all") -> pd.DataFrame:
    """Pairs by ``scenario``: the claim's primary metric of both, ``d`` (NaN when either is
    missing, signed so that ``d < 0`` is the claimed improvement) and both collision flags.

    ``pairs="neither_collided"`` keeps, for a paired claim, the pairs where neither method
    collided (a rate claim always keeps every pair): the one place this filter is applied.
    ``pairs="worst_rank"`` keeps every pair and ranks a collision worse than any run without
    one: a collided run's value becomes one that is worse than every value of both methods
    in the comparison by their range (at least 1 in the metric's units), so a pair where one
    method collided counts for the other and a pair where both did ties (the ranking of
    composite outcomes in clinical trials, where the worst event ranks last). Its ``d`` is a
    rank-preserving stand-in: its sign and its pairs' order mean something, its size does not.
    ``pairs="unsettled_last"`` keeps the pairs where neither collided and, for a metric of
    :data:`~pipeline.analysis.objectives.CENSORED_AT_RUN_END` (C1's reaction, C4's recovery: the
    columns the tune's censoring reads), ranks a run whose clock started and
    whose event never came before the run ended (never settled after the pass) worse than
    every run whose event came, the same stand-in (two such runs tie); a run whose clock never
    started stays missing.
    """
    key = claim.primary_metric
    cols = ["scenario", key] + (["collision"] if key != "collision" else [])
    clocked = CENSORED_AT_RUN_END.get(key) if pairs == "unsettled_last" else None
    if clocked is not None and not set(clocked) <= set(improved) & set(comparison):
        clocked = None  # tables without the clock's columns: nothing to rank
    cols += list(clocked or ())
    merged = improved[cols].merge(comparison[cols], on="scenario", suffixes=("_i", "_c"))
    i = pd.to_numeric(merged[f"{key}_i"], errors="coerce").to_numpy(float)
    c = pd.to_numeric(merged[f"{key}_c"], errors="coerce").to_numpy(float)
    sign = 1.0 if claim.lower_is_better else -1.0
    if key == "collision":
        merged["collision_i"], merged["collision_c"] = i.astype(bool), c.astype(bool)
    else:
        merged["collision_i"] = merged["collision_i"].astype(bool)
        merged["collision_c"] = merged["collision_c"].astype(bool)
    last_i = last_c = None
    if pairs == "worst_rank" and not claim.is_rate:
        last_i = merged["collision_i"].to_numpy(bool)
        last_c = merged["collision_c"].to_numpy(bool)
    if clocked is not None:
        start, flag = clocked
        last_i, last_c = (
            np.isnan(values) & np.isfinite(pd.to_numeric(merged[f"{start}_{side}"],
                                                         errors="coerce").to_numpy(float))
            & ~merged[f"{flag}_{side}"].astype(bool).to_numpy()
            for values, side in ((i, "i"), (c, "c")))
    if last_i is not None and last_c is not None:
        worst = _worse_than_every(i, c, claim.lower_is_better)
        i, c = np.where(last_i, worst, i), np.where(last_c, worst, c)
        merged[f"{key}_i"], merged[f"{key}_c"] = i, c
    merged["d"] = sign * (i - c)
    if pairs in ("neither_collided", "unsettled_last") and not claim.is_rate:
        merged = merged[~(merged["collision_i"] | merged["collision_c"])]
    return merged


def _worse_than_every(i: np.ndarray, c: np.ndarray, lower_is_better: bool) -> float:
    """A value worse than every finite value of both methods by their range (at least 1 in
    the metric's units): the stand-in of a run ranked last."""
    seen = np.concatenate([i[np.isfinite(i)], c[np.isfinite(c)]])
    if not seen.size:
        return 1.0 if lower_is_better else -1.0
    span = max(float(np.ptp(seen)), 1.0)
    return float(seen.max()) + span if lower_is_better else float(seen.min()) - span


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
    differences: np.ndarray | None = field(repr=False, compare=False, default=None)
    #: the confidence level of ``ci_low, ci_high`` and ``pi_low, pi_high``
    ci_level: float = 0.95
    #: bootstrap resamples behind the interval (0: none, a rate's closed-form interval) and
    #: each end's Monte-Carlo half-width (:class:`BootstrapInterval`)
    n_resamples: int = 0
    ci_low_mc: float = 0.0
    ci_high_mc: float = 0.0
    #: a threshold of the outcome rule still lies within an end's Monte-Carlo band after
    #: ``claims.n_resamples_refine`` resamples: the outcome is read off the interval widened
    #: by its bands (the conservative reading)
    at_resolution: bool = False

    @property
    def resolvable_effect(self) -> float:
        """The smallest effect this interval's width can resolve at 80 % power: ``(z_{1 -
        a/2} + z_{0.8}) SE`` with ``SE`` the interval's half-width over ``z_{1 - a/2}`` and
        ``a = 1 - ci_level`` (a normal approximation: an effect this large puts the interval
        clear of zero four times in five)."""
        from scipy import stats

        width = self.ci_high - self.ci_low
        if not np.isfinite(width):
            return float("nan")
        z_level = float(stats.norm.ppf(0.5 + self.ci_level / 2.0))
        return float((z_level + stats.norm.ppf(0.8)) * width / (2.0 * z_level))


def compare(improved: pd.DataFrame, comparison: pd.DataFrame, claim: Claim, cfg: ClaimsConfig,
            pairs: str | None = None, level: float | None = None,
            margin: float | None = None, memo: IntervalMemo | None = None) -> PairedResult:
    """One claim, one comparison: estimate, interval (at ``level``, by default
    ``1 - claims.alpha``; a ledger passes :func:`interval_level`), test, probability of
    improvement, counts (before the Holm adjustment and the outcome).

    A bootstrap interval with a threshold of the outcome rule (0 and +-``margin``, the
    claim's margin by default) within an end's Monte-Carlo band is drawn again with
    ``claims.n_resamples_refine`` resamples; if a threshold is still within a band the result
    is marked ``at_resolution`` (:func:`judge` then reads the interval widened by its bands).
    With ``memo`` the bootstrap results come from it where it holds them for the same
    differences and settings (:class:`~pipeline.analysis.claims.memo.IntervalMemo`; the same
    numbers), and what is computed is kept in it.
    """
    from scipy import stats

    level = 1.0 - cfg.alpha if level is None else float(level)
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
                                             int(np.sum(~events_i & events_c)), int(d.size),
                                             level)
        method = "newcombe_paired_score"
        discordant = better + worse
        p_value = float(stats.binomtest(worse, discordant, 0.5).pvalue) if discordant else 1.0
    else:
        estimate = float(_estimator(cfg.estimator)(d)) if d.size else float("nan")
        statistic = _estimator(cfg.estimator, d)
        threshold = float(cfg.margins[claim.claim_id]) if margin is None else float(margin)
        interval = _recalled_interval(memo, d, statistic, cfg, level, cfg.n_resamples)
        if within_resolution(interval, threshold) \
                and cfg.n_resamples_refine > interval.n_resamples:
            interval = _recalled_interval(memo, d, statistic, cfg, level,
                                          cfg.n_resamples_refine)
        low, high, method = interval.low, interval.high, interval.method
        p_value = paired_test(d, cfg) if d.size else float("nan")
        resolution = (interval.n_resamples, interval.low_mc, interval.high_mc,
                      within_resolution(interval, threshold))
    pi, pi_low, pi_high = _recalled_improvement(memo, d, cfg, level)
    if claim.is_rate:
        resolution = (0, 0.0, 0.0, False)
    return PairedResult(int(d.size), int(d_all.size - d.size), better, tied, worse, estimate,
                        low, high, method, p_value, pi, pi_low, pi_high, n_floor, floor, d,
                        level, *resolution)


def _recalled_interval(memo: IntervalMemo | None, d: np.ndarray, statistic: Statistic,
                       cfg: ClaimsConfig, level: float, n_resamples: int) -> BootstrapInterval:
    """:func:`bootstrap_interval`, from ``memo`` where it holds it (kept there otherwise)."""
    if memo is None:
        return bootstrap_interval(d, statistic, cfg, level, n_resamples)
    key = memo.key("bootstrap_interval", d, cfg, level, n_resamples)
    values = memo.recall(key)
    if values is not None:  # of the kind's types (checked): the same numbers
        low, high, method, resamples, low_mc, high_mc = values
        return BootstrapInterval(float(low), float(high), str(method), int(resamples),
                                 float(low_mc), float(high_mc))
    interval = bootstrap_interval(d, statistic, cfg, level, n_resamples)
    memo.keep(key, [float(interval.low), float(interval.high), str(interval.method),
                    int(interval.n_resamples), float(interval.low_mc),
                    float(interval.high_mc)])
    return interval


def _recalled_improvement(memo: IntervalMemo | None, d: np.ndarray, cfg: ClaimsConfig,
                          level: float) -> tuple[float, float, float]:
    """:func:`probability_of_improvement`, from ``memo`` where it holds it."""
    if memo is None:
        return probability_of_improvement(d, cfg, level)
    key = memo.key("probability_of_improvement", d, cfg, level)
    values = memo.recall(key)
    if values is not None:
        return float(values[0]), float(values[1]), float(values[2])
    result = probability_of_improvement(d, cfg, level)
    memo.keep(key, [float(v) for v in result])
    return result


def decision_interval(result: PairedResult) -> tuple[float, float]:
    """The interval the outcome is read off: the reported one, widened by each end's
    Monte-Carlo half-width where the result is ``at_resolution``."""
    if result.at_resolution:
        return result.ci_low - result.ci_low_mc, result.ci_high + result.ci_high_mc
    return result.ci_low, result.ci_high


def judge(result: PairedResult, margin: float, cfg: ClaimsConfig, claim: Claim
          ) -> tuple[Outcome, str]:
    """:func:`decide` on one comparison's result (a rate's direction from its interval); a
    result ``at_resolution`` is read off its interval widened by each end's Monte-Carlo band
    (what no other bootstrap seed is likely to overturn), and its note says so."""
    if claim.is_rate:
        return decide(result.ci_low, result.ci_high, margin, result.n_pairs, cfg,
                      estimate=result.estimate)
    low, high = decision_interval(result)
    outcome, note = decide(low, high, margin, result.n_pairs, cfg, result.pi_low,
                           result.pi_high, result.estimate, result.prob_improvement)
    if result.at_resolution:
        words = (f"at the bootstrap's resolution: after {result.n_resamples} resamples an end "
                 f"lies within its Monte-Carlo error (+-{max(result.ci_low_mc, result.ci_high_mc):.2g}) "
                 f"of 0 or the margin; read off [{low:.3g}, {high:.3g}]")
        note = f"{note}; {words}" if note else words
    return outcome, note
