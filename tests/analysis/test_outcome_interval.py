"""Outcome and interval agree (issue 40, part 6): over hundreds of planted draws of continuous,
lattice and rate metrics, a ledger row gives a direction exactly when its interval (at the
ledger's level, 1 - alpha / 7; widened by its Monte-Carlo half-widths where a threshold lies
within them, ``decision_interval``) excludes zero, never at an estimate of 0, and is
inconclusive exactly when that interval contains zero and reaches past the margin. Planted
effects on lattice metrics and on rates are found; planted nulls are not given a direction."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from pipeline.analysis.claims.catalogue import ALL_CLAIMS, Outcome
from pipeline.analysis.claims.ledger import family_ledger
from pipeline.analysis.claims.statistics import compare, decision_interval, interval_level, judge
from pipeline.config import ClaimsConfig

BY_ID = {c.claim_id: c for c in ALL_CLAIMS}
CFG = ClaimsConfig(n_resamples=999, n_resamples_refine=3999)
LEVEL = interval_level(CFG, len(ALL_CLAIMS))
DIRECTIONS = {Outcome.SUPPORTED, Outcome.CONTRADICTED, Outcome.MIXED}


def paired_tables(improved: np.ndarray, control: np.ndarray, metric: str,
                  collided_i: np.ndarray | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    n = improved.size
    scen = [f"s{i}" for i in range(n)]
    if metric == "collision":
        return (pd.DataFrame({"scenario": scen, "collision": improved.astype(bool)}),
                pd.DataFrame({"scenario": scen, "collision": control.astype(bool)}))
    col_i = np.zeros(n, bool) if collided_i is None else collided_i
    return (pd.DataFrame({"scenario": scen, metric: improved, "collision": col_i}),
            pd.DataFrame({"scenario": scen, metric: control, "collision": np.zeros(n, bool)}))


def planted_draw(kind: str, rng: np.random.Generator) -> tuple[str, np.ndarray, np.ndarray]:
    """A claim and a pair of samples of one kind of metric with a random planted effect."""
    n = int(rng.integers(12, 120))
    if kind == "continuous":
        shift = rng.choice([0.0, 0.0, -0.04, 0.08, -0.3, 0.3])
        control = rng.normal(1.0, 0.3, n)
        return "C1", control + shift + rng.normal(0, rng.choice([0.01, 0.1, 0.5]), n), control
    if kind == "lattice_time":
        # recovery time on the 0.1 s sample lattice, many pairs tied, some moved one way
        control = np.round(rng.uniform(0.5, 3.0, n), 1)
        moves = rng.choice([-0.2, -0.1, 0.0, 0.1, 0.2], n,
                           p=rng.dirichlet(np.ones(5) * rng.choice([0.3, 3.0])))
        moved = rng.random(n) < rng.choice([0.05, 0.2, 0.6])
        return "C4", np.round(control + np.where(moved, moves, 0.0), 1), control
    if kind == "lattice_count":
        control = rng.poisson(rng.choice([0.2, 1.0, 3.0]), n).astype(float)
        steps = rng.choice([[-1.0, 0.0, 1.0], [0.0, 1.0, 1.0], [0.0, 0.0, 2.0]])
        moved = rng.random(n) < rng.choice([0.3, 0.8])
        return "C5", control + rng.choice(steps, n) * moved, control
    # a rate: collisions of each method, the treatment's rate planted apart
    n = int(rng.integers(100, 300))
    p_control = rng.choice([0.02, 0.1, 0.3])
    p_treat = float(np.clip(p_control + rng.choice([0.0, 0.0, -0.08, 0.1, 0.3]), 0.0, 1.0))
    return "C0", (rng.random(n) < p_treat).astype(float), (rng.random(n) < p_control).astype(float)


def check_agreement(outcome: Outcome, low: float, high: float, estimate: float, margin: float,
                    n_pairs: int) -> None:
    excludes = bool(high < 0.0 or low > 0.0)
    within_margin = -margin < low and high < margin
    if n_pairs < CFG.min_pairs:
        assert outcome == Outcome.INCONCLUSIVE
        return
    if within_margin:
        assert outcome == Outcome.EQUIVALENT
        return
    assert (outcome in DIRECTIONS) == excludes, (outcome, low, high)
    assert (outcome == Outcome.INCONCLUSIVE) == (not excludes), (outcome, low, high)
    if estimate == 0.0:
        assert outcome not in DIRECTIONS
    if outcome == Outcome.SUPPORTED:
        assert high < 0.0 and estimate < 0.0
    if outcome == Outcome.CONTRADICTED:
        assert low > 0.0 and estimate > 0.0


@pytest.mark.parametrize("kind", ["continuous", "lattice_time", "lattice_count", "rate"])
def test_outcome_never_disagrees_with_its_interval_over_planted_draws(kind):
    rng = np.random.default_rng({"continuous": 1, "lattice_time": 2, "lattice_count": 3,
                                 "rate": 4}[kind])
    seen = set()
    for _ in range(60):
        claim_id, treated, control = planted_draw(kind, rng)
        claim = BY_ID[claim_id]
        result = compare(*paired_tables(treated, control, claim.primary_metric), claim, CFG,
                         level=LEVEL)
        margin = float(CFG.margins[claim_id])
        outcome, _ = judge(result, margin, CFG, claim)
        assert result.ci_level == pytest.approx(1 - 0.05 / 7)
        check_agreement(outcome, *decision_interval(result), result.estimate, margin,
                        result.n_pairs)
        seen.add(outcome)
    # the draws reach both sides of the rule, so the agreement was tested, not assumed
    assert Outcome.INCONCLUSIVE in seen and seen & DIRECTIONS


def test_an_estimate_of_zero_on_a_lattice_gets_no_direction():
    """The issue's case: C4 'contradicted' at 0.000 [0.000, 0.125]: most pairs tie, a few are
    one sample worse. The interval ends at 0, the estimate is 0: inconclusive or equivalent."""
    control = np.round(np.linspace(0.5, 2.5, 160), 1)
    treated = control.copy()
    treated[:40] += 0.1
    treated[40:46] += 0.5
    claim = BY_ID["C4"]
    result = compare(*paired_tables(treated, control, claim.primary_metric), claim, CFG,
                     level=LEVEL)
    assert result.estimate == 0.0 and result.ci_low == 0.0 and result.ci_high > 0.0
    # with no margin (nothing is equivalent) the row can only be inconclusive
    outcome, _ = judge(result, 0.0, CFG, claim)
    assert outcome == Outcome.INCONCLUSIVE


def test_planted_effects_on_lattice_metrics_and_rates_are_found():
    rng = np.random.default_rng(11)
    n = 200
    # C4: recovery one to three samples faster in 70 % of the scenarios
    control = np.round(rng.uniform(1.0, 3.0, n), 1)
    faster = rng.random(n) < 0.7
    treated = np.round(control - faster * rng.choice([0.1, 0.2, 0.3], n), 1)
    c4 = compare(*paired_tables(treated, control, "recovery_time_s"), BY_ID["C4"], CFG,
                 level=LEVEL)
    assert judge(c4, 0.1, CFG, BY_ID["C4"])[0] == Outcome.SUPPORTED
    # C5: one reversal more in 70 % of the scenarios (with 40 % the Hodges-Lehmann interval
    # of this lattice ends at 0 and the rule gives no direction)
    control = rng.poisson(1.0, n).astype(float)
    treated = control + (rng.random(n) < 0.7)
    c5 = compare(*paired_tables(treated, control, "oscillation_count"), BY_ID["C5"], CFG,
                 level=LEVEL)
    assert c5.ci_low > 0 and judge(c5, 0.0, CFG, BY_ID["C5"])[0] == Outcome.CONTRADICTED
    # C0: 10 % against 35 % collisions
    treated, control = (rng.random(n) < 0.10).astype(float), (rng.random(n) < 0.35).astype(float)
    c0 = compare(*paired_tables(treated, control, "collision"), BY_ID["C0"], CFG, level=LEVEL)
    assert judge(c0, 0.02, CFG, BY_ID["C0"])[0] == Outcome.SUPPORTED
    # and equal rates give no direction
    same = (rng.random(n) < 0.2).astype(float)
    c0_null = compare(*paired_tables(same, same.copy(), "collision"), BY_ID["C0"], CFG,
                      level=LEVEL)
    assert c0_null.estimate == 0.0
    assert judge(c0_null, 0.02, CFG, BY_ID["C0"])[0] not in DIRECTIONS


def test_rate_interval_at_the_ledger_level_matches_its_closed_form():
    """No collision in either method: Newcombe's interval is [-u, u], u = z^2 / (n + z^2), z
    the normal quantile of the ledger's level (not of 95 %)."""
    n = 200
    zero = np.zeros(n)
    result = compare(*paired_tables(zero, zero.copy(), "collision"), BY_ID["C0"], CFG,
                     level=LEVEL)
    z = stats.norm.ppf(1 - 0.05 / 7 / 2)
    u = z * z / (n + z * z)
    assert result.ci_low == pytest.approx(-u, rel=1e-9)
    assert result.ci_high == pytest.approx(u, rel=1e-9)


def test_the_interval_adjustment_switch_sets_the_level_and_can_move_an_outcome():
    """With ``claims.interval_adjustment: none`` the ledger's interval is the 95 % one, so an
    effect whose 95 % interval clears zero but whose Bonferroni interval does not changes from
    inconclusive to supported (a switch that is ignored fails this)."""
    rng = np.random.default_rng(0)
    for _ in range(200):
        d = -0.12 + rng.normal(0.0, 0.35, 40)
        control = rng.normal(1.0, 0.2, 40)
        tables = dict(zip(("improved", "baseline"),
                          paired_tables(control + d, control, "reaction_delay_s"), strict=True))
        for claim in ALL_CLAIMS:
            for table in tables.values():
                if claim.primary_metric not in table:
                    table[claim.primary_metric] = 1.0
        strict = family_ledger(tables, CFG, comparisons=("baseline",), sensitivity=False)
        loose = family_ledger(tables, ClaimsConfig(n_resamples=999, n_resamples_refine=3999,
                                                   interval_adjustment="none"),
                              comparisons=("baseline",), sensitivity=False)
        row_s, row_l = strict[("C1", "baseline")], loose[("C1", "baseline")]
        assert row_s.result.ci_level == pytest.approx(1 - 0.05 / 7)
        assert row_l.result.ci_level == pytest.approx(0.95)
        assert row_s.result.ci_low <= row_l.result.ci_low
        if row_l.outcome == Outcome.SUPPORTED and row_s.outcome == Outcome.INCONCLUSIVE:
            return
    pytest.fail("no planted draw separated the two levels")
