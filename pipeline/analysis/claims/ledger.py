"""The claims ledger: every claim against every comparison over a family
(:func:`family_ledger` -> :class:`Ledger` of :class:`LedgerRow`), the single paper scenario's
table (:func:`claims_table`, :data:`pipeline.analysis.claims.catalogue.SINGLE_RULE`) and the
outcome counts per method (:func:`outcome_counts`)."""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd

from pipeline.analysis.claims.catalogue import ALL_CLAIMS, Claim, Outcome, claims_of
from pipeline.analysis.claims.memo import IntervalMemo
from pipeline.analysis.claims.statistics import PairedResult, compare, holm, interval_level, judge
from pipeline.analysis.claims.windows import common_window_claim, common_window_tables
from pipeline.analysis.metrics.results import LateralJerk
from pipeline.analysis.settings import ClaimsConfig
from pipeline.analysis.tally import Tally


def _value(metrics: dict[str, Any], key: str) -> float:
    value = metrics.get(key)
    if isinstance(value, (bool, np.bool_)):
        return float(value)
    return float(value) if value is not None else math.nan


def single_scenario_outcome(claim: Claim, comparison: dict[str, Any], improved: dict[str, Any],
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


def claims_table(metrics_by_method: dict[str, dict[str, Any]], margins: dict[str, float],
                 comparisons: tuple[str, ...] = ("baseline", "baseline_matched"),
                 improved: str = "improved", claims: tuple[Claim, ...] = ALL_CLAIMS
                 ) -> list[dict[str, Any]]:
    """One row per claim (``claims``: by default the package's catalogue) on one scenario:
    primary metric per method, outcome per comparison."""
    rows = []
    for claim in claims:
        row: dict[str, Any] = {"claim": claim.claim_id, "paper says": claim.text,
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


LEDGER_COLUMNS = ["claim", "comparison", "role", "metric", "outcome", "outcome_unadjusted",
                  "estimate", "ci_low", "ci_high", "ci_level", "n_resamples", "ci_low_mc",
                  "ci_high_mc", "p_value", "p_holm", "p_holm_claim", "holm_family_size",
                  "prob_improvement", "pi_low", "pi_high", "n_better", "n_tied", "n_worse",
                  "n_missing", "n_pairs", "n_scenarios", "margin", "resolvable_effect", "note",
                  "outcome_worst_rank", "estimate_worst_rank", "paper_scenario"]


@dataclass(frozen=True)
class LedgerRow:
    """The verdict on one claim against one comparison.

    ``outcome`` is what the answer publishes: after the family-wise rule across the answer's
    rows of the claim (:mod:`pipeline.analysis.claims.multiplicity`) where that was applied,
    ``outcome_unadjusted`` before it (the same where it was not). ``role``: ``primary`` (the
    declared comparison that carries the headline) or ``secondary``."""

    claim: Claim
    comparison: str
    outcome: Outcome
    result: PairedResult
    p_holm: float
    margin: float
    note: str
    margin_reason: str
    outcome_worst_rank: Outcome | None = None
    estimate_worst_rank: float | None = None
    paper_scenario: str | None = None
    #: scenarios in the comparison (every pair, collided or not)
    n_scenarios: int = 0
    role: str = "secondary"
    outcome_unadjusted: Outcome | None = None
    #: Holm over every row of this claim in the answer, and how many rows that is
    p_holm_claim: float = math.nan
    holm_family_size: int = 0

    @property
    def claim_id(self) -> str:
        return self.claim.claim_id

    @property
    def key(self) -> tuple[str, str]:
        return (self.claim.claim_id, self.comparison)

    def to_dict(self) -> dict[str, Any]:
        """The row as the ledger table writes it (:data:`LEDGER_COLUMNS` and more)."""
        r = self.result
        return {"claim": self.claim.claim_id, "comparison": self.comparison,
                "role": self.role, "metric": self.claim.primary_metric,
                "outcome": str(self.outcome),
                "outcome_unadjusted": str(self.outcome_unadjusted or self.outcome),
                "n_pairs": r.n_pairs, "n_scenarios": self.n_scenarios,
                "n_missing": r.n_missing, "n_better": r.n_better,
                "n_tied": r.n_tied, "n_worse": r.n_worse, "estimate": r.estimate,
                "ci_low": r.ci_low, "ci_high": r.ci_high, "ci_level": r.ci_level,
                "n_resamples": r.n_resamples, "ci_low_mc": r.ci_low_mc,
                "ci_high_mc": r.ci_high_mc, "interval_method": r.interval_method,
                "p_value": r.p_value, "prob_improvement": r.prob_improvement,
                "pi_low": r.pi_low, "pi_high": r.pi_high, "p_holm": self.p_holm,
                "p_holm_claim": self.p_holm_claim, "holm_family_size": self.holm_family_size,
                "margin": self.margin, "resolvable_effect": r.resolvable_effect,
                "note": self.note, "margin_reason": self.margin_reason,
                "paper says": self.claim.text,
                "outcome_worst_rank": None if self.outcome_worst_rank is None
                else str(self.outcome_worst_rank),
                "estimate_worst_rank": self.estimate_worst_rank,
                "paper_scenario": self.paper_scenario}


@dataclass(frozen=True)
class Ledger:
    """Verdicts on every claim against every comparison, keyed by ``(claim_id, comparison)``."""

    rows: tuple[LedgerRow, ...] = ()
    treatment: str = "improved"

    def __iter__(self) -> Iterator[LedgerRow]:
        return iter(self.rows)

    def __len__(self) -> int:
        return len(self.rows)

    def without_claims(self, claim_ids: tuple[str, ...]) -> Ledger:
        """This ledger without the rows of ``claim_ids`` (the intervals keep their level and
        Holm its count: conservative)."""
        return Ledger(tuple(row for row in self.rows if row.claim_id not in claim_ids),
                      self.treatment)

    def with_rows(self, rows: tuple[LedgerRow, ...]) -> Ledger:
        """This ledger with ``rows`` (the same claims and comparisons, rejudged)."""
        return Ledger(rows, self.treatment)

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
    def differences(self) -> dict[tuple[str, str], np.ndarray | None]:
        """The paired differences each outcome was taken on, for plotting."""
        return {row.key: row.result.differences for row in self.rows}

    def records(self) -> list[dict[str, Any]]:
        return [row.to_dict() for row in self.rows]

    def to_frame(self) -> pd.DataFrame:
        """The ledger table (``claims_ledger.csv``)."""
        return pd.DataFrame(self.records()).reindex(
            columns=LEDGER_COLUMNS + ["interval_method", "margin_reason"])


#: A run's lateral jerk by method and scenario (what C2 on a common window reads).
Jerks = Mapping[str, Mapping[str, LateralJerk]]


def family_ledger(tables: dict[str, pd.DataFrame], cfg: ClaimsConfig,
                  paper_metrics: dict[str, dict[str, Any]] | None = None,
                  improved: str = "improved",
                  comparisons: tuple[str, ...] = ("baseline", "baseline_matched"),
                  sensitivity: bool = True, jerks: Jerks | None = None,
                  memo: IntervalMemo | None = None) -> Ledger:
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
        Also judge C1-C5 on the other set of pairs: every pair with a collision ranked worst
        (``worst_rank``, :func:`~pipeline.analysis.claims.statistics.paired_differences`) when
        the ledger uses the pairs where neither collided, else those.
    jerks : mapping of method -> scenario -> LateralJerk, optional
        Each run's lateral jerk: with ``cfg.c2_window = "common"`` C2 is judged on a window
        common to both runs of each pair (:mod:`pipeline.analysis.claims.windows`), which
        needs them.
    memo : IntervalMemo, optional
        Bootstrap results by their inputs (:func:`~pipeline.analysis.claims.statistics.
        compare`): the same ledger, its intervals recalled where the memo holds them.

    Returns
    -------
    Ledger

    Raises
    ------
    ValueError
        ``cfg.c2_window = "common"`` without the jerk of the treatment or of a comparison.
    """
    rows: list[LedgerRow] = []
    if improved not in tables:
        return Ledger((), improved)
    level = interval_level(cfg, len(cfg.entries))
    for comparison in [c for c in comparisons if c in tables]:
        pair = _pair_tables(tables, improved, comparison, cfg, jerks)
        block = [(claim, compare(*pair[claim.claim_id], claim, cfg, level=level, memo=memo))
                 for claim in _claims_read(cfg)]
        adjusted = holm([r.p_value for _, r in block])
        for (claim, result), p_holm in zip(block, adjusted, strict=True):
            rows.append(_ledger_row(claim, comparison, result, p_holm, pair[claim.claim_id],
                                    cfg, paper_metrics, improved, sensitivity, memo))
    return Ledger(tuple(rows), improved)


def _claims_read(cfg: ClaimsConfig) -> tuple[Claim, ...]:
    """Every claim of ``cfg``'s catalogue as it reads it (C2 on a common window with
    ``c2_window = common``)."""
    if cfg.c2_window != "common":
        return claims_of(cfg)
    return tuple(common_window_claim(c, cfg.common_window) if c.claim_id == "C2" else c
                 for c in claims_of(cfg))


def _pair_tables(tables: dict[str, pd.DataFrame], improved: str, comparison: str,
                 cfg: ClaimsConfig, jerks: Jerks | None
                 ) -> dict[str, tuple[pd.DataFrame, pd.DataFrame]]:
    """Per claim, the treatment's and the comparison's tables it is judged on: the family
    tables, C2's with its common-window column when ``cfg.c2_window = common``."""
    pair = (tables[improved], tables[comparison])
    out = {claim_id: pair for claim_id in cfg.entries}
    if cfg.c2_window == "common":
        absent = [m for m in (improved, comparison) if jerks is None or m not in jerks]
        if absent:
            raise ValueError(f"claims.c2_window=common: no lateral jerk of {', '.join(absent)} "
                             "(C2 on a window common to both runs of a pair reads the runs' "
                             "trajectories)")
        assert jerks is not None
        out["C2"] = common_window_tables(*pair, jerks[improved], jerks[comparison],
                                         cfg.common_window)
    return out


def _ledger_row(claim: Claim, comparison: str, result: PairedResult, p_holm: float,
                pair: tuple[pd.DataFrame, pd.DataFrame], cfg: ClaimsConfig,
                paper_metrics: dict[str, Any] | None,
                improved: str, sensitivity: bool, memo: IntervalMemo | None = None
                ) -> LedgerRow:
    margin = float(cfg.margins[claim.claim_id])
    if result.n_pairs < cfg.min_pairs:
        # too few pairs: no interval is reported, so none can seem to disagree with the outcome
        result = replace(result, ci_low=math.nan, ci_high=math.nan, pi_low=math.nan,
                         pi_high=math.nan, interval_method="too few pairs",
                         at_resolution=False)
    outcome, note = judge(result, margin, cfg, claim)
    excludes_zero = bool(result.ci_high < 0.0 or result.ci_low > 0.0)
    if np.isfinite(p_holm) and result.n_pairs >= cfg.min_pairs \
            and (p_holm < cfg.alpha) != excludes_zero:
        test_note = f"Holm p {p_holm:.2g} disagrees; the interval decides"
        note = f"{note}; {test_note}" if note else test_note
    if not claim.is_rate and result.n_pairs and \
            result.n_floor_ties >= cfg.floor_tie_share * result.n_pairs:
        floor_note = (f"neither method shows the behaviour in {result.n_floor_ties} of "
                      f"{result.n_pairs} pairs (both at {result.floor_value:.3g})")
        note = f"{note}; {floor_note}" if note else floor_note
    worst, estimate_worst = None, None
    if claim.is_rate:
        worst, estimate_worst = outcome, result.estimate
    elif sensitivity:
        other = "worst_rank" if cfg.pairs == "neither_collided" else "neither_collided"
        sens = compare(*pair, claim, cfg, pairs=other, level=result.ci_level, margin=margin,
                       memo=memo)
        # the sensitivity reads its interval at the row's level: a check, not a claim
        worst, _ = judge(sens, margin, cfg, claim)
        estimate_worst = sens.estimate
    paper = None
    if paper_metrics and comparison in paper_metrics and improved in paper_metrics:
        paper = single_scenario_outcome(claim, paper_metrics[comparison],
                                        paper_metrics[improved], margin)
    scenarios = int(len(pair[0][["scenario"]].merge(pair[1][["scenario"]], on="scenario")))
    return LedgerRow(claim, comparison, outcome, result, p_holm, margin, note,
                     cfg.margin_reasons[claim.claim_id], worst, estimate_worst, paper,
                     scenarios, outcome_unadjusted=outcome)


def outcome_counts(tables: dict[str, pd.DataFrame]) -> list[dict[str, Any]]:
    """Collisions (avoidable / unavoidable), failures and fallbacks per method; how often the
    APF's step cap binds (:class:`pipeline.analysis.tally.Tally`)."""
    return [{"method": method, **Tally.of(t).to_dict()} for method, t in tables.items()]
