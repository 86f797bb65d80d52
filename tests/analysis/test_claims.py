"""Statistics v2 against planted effects and closed forms: four outcomes, Holm, McNemar, the
probability of improvement, Hodges-Lehmann, and the four-word outcomes on one scenario."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from pipeline.analysis.claims.catalogue import ALL_CLAIMS, CLAIMS, SAFETY
from pipeline.analysis.claims.ledger import claims_table, family_ledger, single_scenario_outcome
from pipeline.analysis.claims.statistics import (
    compare,
    decide,
    hodges_lehmann,
    holm,
    probability_of_improvement,
)
from pipeline.config import ClaimsConfig

CFG = ClaimsConfig(n_resamples=999)
C1 = CLAIMS[0]
BY_ID = {c.claim_id: c for c in ALL_CLAIMS}


def tables_with(d: np.ndarray, metric: str = "reaction_delay_s", collided=None):
    """Improved and baseline tables whose paired differences on ``metric`` are ``d``."""
    n = d.size
    base = np.full(n, 1.0)
    collided = np.zeros(n, bool) if collided is None else collided
    scen = [f"s{i}" for i in range(n)]
    improved = pd.DataFrame({"scenario": scen, metric: base + d, "collision": collided})
    baseline = pd.DataFrame({"scenario": scen, metric: base, "collision": np.zeros(n, bool)})
    return improved, baseline


@pytest.mark.parametrize("shift, expected", [(-0.3, "supported"), (0.3, "contradicted"),
                                             (0.0, "equivalent")])
def test_planted_shift_gives_the_planted_outcome(shift, expected):
    rng = np.random.default_rng(5)
    d = shift + rng.normal(0.0, 0.005 if shift == 0.0 else 0.1, 200)
    improved, baseline = tables_with(d)
    row = compare(improved, baseline, C1, CFG)
    outcome, _ = decide(row.ci_low, row.ci_high, 0.05, row.n_pairs, CFG,
                         row.pi_low, row.pi_high)
    assert outcome == expected
    assert row.ci_low < shift + 0.05 and row.ci_high > shift - 0.05


def test_noise_without_effect_wider_than_the_margin_is_inconclusive():
    d = np.random.default_rng(2).normal(0.0, 1.0, 60)
    row = compare(*tables_with(d), C1, CFG)
    assert decide(row.ci_low, row.ci_high, 0.05, row.n_pairs,
                  CFG, row.pi_low, row.pi_high)[0] == "inconclusive"


def test_real_effect_inside_the_margin_is_equivalent_and_says_so():
    d = -0.02 + np.random.default_rng(3).normal(0.0, 0.002, 200)
    row = compare(*tables_with(d), C1, CFG)
    outcome, note = decide(row.ci_low, row.ci_high, 0.05, row.n_pairs,
                           CFG, row.pi_low, row.pi_high)
    assert outcome == "equivalent" and "less than the margin" in note


def test_discrete_split_with_many_ties_moves_the_estimate_but_an_interval_at_zero_decides():
    """68 worse, 117 tied, 15 better (the C5 split of an earlier issue): Hodges-Lehmann moves
    off zero, the signed-rank test and the probability of improvement see it; but the
    estimate's interval on this lattice ends at 0, and the interval is the test (issue 40):
    no direction, and the ledger's note says the paired test disagrees."""
    d = np.concatenate([np.ones(68), np.zeros(117), -np.ones(15)])
    row = compare(*tables_with(d, "oscillation_count"), BY_ID["C5"], CFG)
    assert (row.n_better, row.n_tied, row.n_worse) == (15, 117, 68)
    assert row.estimate == 0.5 and row.p_value < 1e-6
    assert row.prob_improvement == pytest.approx((15 + 117 / 2) / 200)
    assert row.pi_high < 0.5
    assert row.ci_low == 0.0 and row.ci_high >= 0.5
    outcome, _ = decide(row.ci_low, row.ci_high, 0.25, row.n_pairs, CFG,
                        row.pi_low, row.pi_high)
    assert outcome == "inconclusive"
    # one more worse step off the lattice's floor and the direction is given
    shifted = decide(row.ci_low + 0.5, row.ci_high, 0.25, row.n_pairs, CFG, row.pi_low,
                     row.pi_high)[0]
    assert shifted == "contradicted"


def test_hodges_lehmann_equals_the_walsh_median_by_brute_force():
    x = np.random.default_rng(4).normal(size=31)
    walsh = [(x[i] + x[j]) / 2 for i in range(31) for j in range(i, 31)]
    assert hodges_lehmann(x) == pytest.approx(np.median(walsh))
    batch = np.stack([x, -x])
    np.testing.assert_allclose(hodges_lehmann(batch), [np.median(walsh), -np.median(walsh)])


def test_fast_hodges_lehmann_on_resamples_equals_the_direct_one():
    from pipeline.analysis.claims.statistics import hodges_lehmann_on

    rng = np.random.default_rng(8)
    sample = np.round(rng.normal(size=57), 1)  # ties, as metrics on a lattice have
    resamples = rng.choice(sample, size=(40, 57))
    np.testing.assert_array_equal(hodges_lehmann_on(sample)(resamples), hodges_lehmann(resamples))
    leave_one_out = np.delete(sample, 3)
    assert hodges_lehmann_on(sample)(leave_one_out) == hodges_lehmann(leave_one_out)
    other = rng.normal(size=(3, 10))  # not drawn from the sample: the direct computation
    np.testing.assert_array_equal(hodges_lehmann_on(sample)(other), hodges_lehmann(other))


@pytest.mark.parametrize("seed", [1, 2])
def test_the_walsh_medians_bootstrap_on_positions_is_the_one_on_values(monkeypatch, seed):
    """The paired bootstrap of the Hodges-Lehmann estimate resamples the sample's positions
    and looks their values up: the same interval, method and Monte-Carlo bands, bit for bit, as
    the bootstrap of the values themselves (scipy.stats.bootstrap, BCa and percentile), on
    samples with ties and with one value far out."""
    from pipeline.analysis.claims import statistics
    from pipeline.analysis.claims.statistics import bootstrap_interval, hodges_lehmann_on

    rng = np.random.default_rng(seed)
    sample = np.round(rng.normal(size=83), 1)
    sample[5] = 40.0
    cfg = ClaimsConfig(n_resamples=999)
    statistic = hodges_lehmann_on(sample)
    positions, of_positions = statistics.on_positions(statistic, sample)
    np.testing.assert_array_equal(of_positions(positions), statistic(sample))
    by_positions = bootstrap_interval(sample, statistic, cfg, 0.95)
    monkeypatch.setattr(statistics, "on_positions", lambda statistic, sample: None)
    by_values = bootstrap_interval(sample, statistic, cfg, 0.95)
    assert by_positions == by_values and by_values.method == "BCa"
    # a statistic that is not the Walsh median of this sample resamples the values
    monkeypatch.undo()
    assert statistics.on_positions(hodges_lehmann_on(sample[:-1] + 0.05), sample) is None
    assert statistics.on_positions(np.median, sample) is None


def test_wilcoxon_pvalue_is_scipys_own_and_enumerates_all_at_once(monkeypatch):
    """Oracle: ``scipy.stats.wilcoxon(zero_method="pratt")``, equal to the last bit, on small
    samples with zeros and ties (where SciPy enumerates every sign flip one by one), without
    them (its exact distribution) and beyond 13 pairs (its normal approximation); the first
    kind goes through one vectorized ``permutation_test``."""
    import warnings

    from pipeline.analysis.claims import statistics

    calls = []
    original = stats.permutation_test

    def counted(*args, **kwargs):
        calls.append(kwargs.get("vectorized"))
        return original(*args, **kwargs)

    monkeypatch.setattr(stats, "permutation_test", counted)
    rng = np.random.default_rng(3)
    samples = [np.array([0.0, 0.3]), np.array([0.2, -0.2, 0.2]), np.zeros(4) + [0, 0, 0, 1.0],
               np.round(rng.normal(0.4, 1, size=13), 1)]  # 13: SciPy's last enumerated size
    samples += [rng.integers(-3, 4, n) * 0.5 for n in range(2, 10)]  # zeros and ties
    samples += [rng.normal(size=n) for n in (3, 9, 13)]  # no ties: SciPy's exact distribution
    samples += [np.round(rng.normal(size=n), 1) for n in (14, 30)]  # ties, approximated
    for d in samples:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            expected = stats.wilcoxon(d, zero_method="pratt").pvalue
        calls.clear()
        got = statistics.wilcoxon_pratt_pvalue(d)
        assert got == expected or (np.isnan(got) and np.isnan(expected)), d
        ties = np.any(d == 0) or np.unique(np.abs(d)).size < d.size
        assert calls == ([True] if ties and d.size <= 13 else []), d


def test_holm_matches_the_step_down_formula():
    p = [0.01, 0.04, 0.03, 0.5]
    # sorted 0.01, 0.03, 0.04, 0.5 -> 4*0.01, max(., 3*0.03), max(., 2*0.04), max(., 0.5)
    assert holm(p) == pytest.approx([0.04, 0.09, 0.09, 0.5])
    assert np.isnan(holm([np.nan, 0.2])[0]) and holm([np.nan, 0.2])[1] == pytest.approx(0.2)


def test_mcnemar_on_discordant_collision_pairs():
    n = 200
    base = np.zeros(n, bool)
    imp = np.zeros(n, bool)
    base[:20] = True          # 20 baseline-only collisions
    imp[20:24] = True         # 4 improved-only
    improved = pd.DataFrame({"scenario": range(n), "collision": imp})
    baseline = pd.DataFrame({"scenario": range(n), "collision": base})
    row = compare(improved, baseline, SAFETY, CFG)
    assert (row.n_better, row.n_worse) == (20, 4)
    assert row.p_value == pytest.approx(stats.binomtest(4, 24, 0.5).pvalue)
    assert row.estimate == pytest.approx((4 - 20) / n)


def test_probability_of_improvement_counts_ties_as_half():
    value, low, high = probability_of_improvement(np.array([-1.0, 0.0, 1.0, -2.0]), CFG)
    assert value == pytest.approx(0.625) and low <= value <= high


def test_colliding_pairs_leave_c1_to_c5_but_stay_in_the_sensitivity():
    d = np.full(40, -0.3)
    d[:10] = 5.0  # the colliding pairs are much worse
    collided = np.zeros(40, bool)
    collided[:10] = True
    improved, baseline = tables_with(d, collided=collided)
    filtered = compare(improved, baseline, C1, CFG)
    every = compare(improved, baseline, C1, CFG, pairs="all")
    assert filtered.n_pairs == 30 and every.n_pairs == 40
    assert filtered.estimate == pytest.approx(-0.3) and filtered.n_worse == 0
    assert every.n_worse == 10 and every.prob_improvement == pytest.approx(0.75)


def test_ledger_has_c0_first_and_both_comparisons():
    d = -0.3 + np.random.default_rng(9).normal(0.0, 0.05, 50)
    improved, baseline = tables_with(d)
    matched = baseline.copy()
    rows = family_ledger({"improved": improved.assign(
        **{c.primary_metric: improved["reaction_delay_s"] for c in CLAIMS[1:]}),
        "baseline": baseline.assign(**{c.primary_metric: 1.0 for c in CLAIMS[1:]}),
        "baseline_matched": matched.assign(**{c.primary_metric: 1.0 for c in CLAIMS[1:]})},
        CFG).records()
    assert [(r["claim"], r["comparison"]) for r in rows][:2] == [("C0", "baseline"),
                                                                 ("C1", "baseline")]
    assert len(rows) == 14 and rows[7]["comparison"] == "baseline_matched"
    # a 0.3 gain beats C1-C4's margins; C5's margin is half a reversal: within it
    assert all(r["outcome"] == "supported" for r in rows if r["claim"] in ("C1", "C2", "C3a",
                                                                          "C4"))
    # C3b is higher-is-better: the same 0.3 lower value is a contradiction there
    assert all(r["outcome"] == "contradicted" for r in rows if r["claim"] == "C3b")
    assert all(r["outcome"] == "equivalent" for r in rows if r["claim"] == "C5")


@pytest.mark.parametrize("improved, expected", [(0.3, "better"), (0.98, "within margin"),
                                                (1.2, "worse"), (None, "missing")])
def test_single_scenario_words(improved, expected):
    assert single_scenario_outcome(C1, {"reaction_delay_s": 1.0},
                                   {"reaction_delay_s": improved}, 0.05) == expected
    rows = claims_table({"baseline": {"reaction_delay_s": 1.0},
                         "improved": {"reaction_delay_s": improved}}, CFG.margins,
                        ("baseline",))
    assert [r["claim"] for r in rows] == [c.claim_id for c in ALL_CLAIMS]
    assert rows[1]["vs baseline"] == expected


@pytest.mark.parametrize("small, large, pi_side", [(-0.05, +1.0, "better"),
                                                   (+0.05, -1.0, "worse")])
def test_estimate_and_probability_of_improvement_disagreeing_is_mixed(small, large, pi_side):
    """60 % of pairs slightly one way, 40 % much the other: the typical difference and the
    share of better pairs point opposite ways; never 'supported' or 'contradicted'."""
    rng = np.random.default_rng(3)
    d = np.concatenate([small + rng.normal(0, 0.005, 120), large + rng.normal(0, 0.05, 80)])
    row = compare(*tables_with(d), C1, CFG)
    assert (row.prob_improvement > 0.5) == (pi_side == "better")
    assert (row.estimate > 0) == (pi_side == "better")
    outcome, note = decide(row.ci_low, row.ci_high, 0.05, row.n_pairs, CFG,
                           row.pi_low, row.pi_high, row.estimate, row.prob_improvement)
    assert outcome == "mixed"
    assert f"most pairs {pi_side}" in note and f"{row.prob_improvement:.2f}" in note


def test_significant_estimate_beyond_the_margin_with_pi_at_one_half_is_a_direction():
    """The family case: estimate +0.35 [0.23, 0.47], p tiny, PI's upper bound exactly 0.5:
    both point worse, so it is a contradiction, not 'inconclusive'."""
    outcome, _ = decide(0.23, 0.47, 0.1, 160, CFG, 0.40, 0.50, 0.35, 0.45)
    assert outcome == "contradicted"


def wilson(k: int, n: int, z: float = stats.norm.ppf(0.975)) -> tuple[float, float]:
    """Wilson's score interval written out (an oracle independent of scipy's)."""
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


@pytest.mark.parametrize("a, b, c, n", [(0, 0, 0, 12), (0, 0, 0, 2000), (2, 5, 1, 40),
                                        (10, 3, 9, 200)])
def test_newcombe_paired_interval_matches_its_formula(a, b, c, n):
    from pipeline.analysis.claims.statistics import newcombe_paired_interval

    low, high = newcombe_paired_interval(a, b, c, n)
    d = n - a - b - c
    p1, p2 = (a + b) / n, (a + c) / n
    (l1, u1), (l2, u2) = wilson(a + b, n), wilson(a + c, n)
    den = (a + b) * (c + d) * (a + c) * (b + d)
    phi = (a * d - b * c) / np.sqrt(den) if den else 0.0
    delta = np.sqrt((p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2)
    eps = np.sqrt((u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2)
    assert (low, high) == pytest.approx((p1 - p2 - delta, p1 - p2 + eps), abs=1e-12)
    if a + b + c == 0:  # no events: [-u, u], u = z^2 / (n + z^2)
        z2 = stats.norm.ppf(0.975) ** 2
        assert high == pytest.approx(z2 / (n + z2)) and low == pytest.approx(-high)


@pytest.mark.parametrize("n, expected", [(12, "inconclusive"), (2000, "equivalent")])
def test_zero_collisions_are_equivalent_only_with_enough_scenarios(n, expected):
    """No collision in either method: 12 pairs cannot bound the rate difference within two
    points (the interval is about +-0.24); 2,000 can (about +-0.002)."""
    improved = pd.DataFrame({"scenario": range(n), "collision": np.zeros(n, bool)})
    baseline = pd.DataFrame({"scenario": range(n), "collision": np.zeros(n, bool)})
    cfg = ClaimsConfig(n_resamples=199, min_pairs=10)
    ledger = family_ledger({"improved": improved.assign(**{c.primary_metric: 1.0
                                                           for c in CLAIMS}),
                            "baseline": baseline.assign(**{c.primary_metric: 1.0
                                                           for c in CLAIMS})},
                           cfg, comparisons=("baseline",))
    row = ledger[("C0", "baseline")]
    assert row.result.interval_method == "newcombe_paired_score"
    assert row.outcome == expected


def test_almost_every_pair_at_the_floor_says_neither_method_shows_it():
    n = 100
    values = np.zeros(n)
    values[:3] = 1.0
    improved = pd.DataFrame({"scenario": range(n), "oscillation_count": values,
                             "collision": False})
    baseline = pd.DataFrame({"scenario": range(n), "oscillation_count": np.zeros(n),
                             "collision": False})
    tables = {"improved": improved.assign(**{c.primary_metric: 0.0 for c in CLAIMS
                                             if c.primary_metric != "oscillation_count"}),
              "baseline": baseline.assign(**{c.primary_metric: 0.0 for c in CLAIMS
                                             if c.primary_metric != "oscillation_count"})}
    ledger = family_ledger(tables, ClaimsConfig(n_resamples=199), comparisons=("baseline",))
    assert "neither method shows the behaviour in 97 of 100 pairs" in \
        ledger[("C5", "baseline")].note
    looser = family_ledger(tables, ClaimsConfig(n_resamples=199, floor_tie_share=0.99),
                           comparisons=("baseline",))
    assert "neither method" not in looser[("C5", "baseline")].note
