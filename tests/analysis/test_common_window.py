"""C2 on a window common to both runs of a pair (``claims.c2_window``, ``claims.common_window``):
the window from closed forms, both runs' RMS jerk over it computed by hand, and the switch
moving the ledger's C2 row the way the reading says (a longer own window dilutes the RMS)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from pipeline.analysis.claims import (
    ALL_CLAIMS,
    COMMON_C2_METRIC,
    common_window,
    common_window_pairs,
    family_ledger,
)
from pipeline.analysis.metrics import LateralJerk
from pipeline.config import ClaimsConfig
from pipeline.errors import ConfigError
from pipeline.studies.multiverse import CONF_DIR

#: a log of 0.1 s rows over 10 s (101 rows)
TIME_S = np.round(np.arange(101) * 0.1, 10)


def burst(amplitude: float, start_s: float, end_s: float) -> LateralJerk:
    """A jerk of ``amplitude`` on ``[start_s, end_s]`` and 0 elsewhere."""
    times = TIME_S
    on = (times >= start_s - 1e-9) & (times <= end_s + 1e-9)
    return LateralJerk(times, np.where(on, amplitude, 0.0))


def rows_in(start_s: float, end_s: float) -> int:
    """Log rows in ``[start_s, end_s]`` at 0.1 s."""
    return round((end_s - start_s) / 0.1) + 1


@pytest.mark.parametrize("rule, first, second, expected", [
    ("union", (3.0, 5.0), (2.5, 8.0), (2.5, 8.0)),
    ("union", (3.0, 5.0), (math.nan, math.nan), (3.0, 5.0)),
    ("intersection", (3.0, 5.0), (2.5, 8.0), (3.0, 5.0)),
    ("intersection", (3.0, 4.0), (5.0, 8.0), (math.nan, math.nan)),
    ("intersection", (3.0, 5.0), (math.nan, math.nan), (math.nan, math.nan)),
])
def test_common_window_of_two_windows(rule, first, second, expected):
    got = common_window(first, second, rule)
    assert np.allclose(got, expected, equal_nan=True)


def test_planted_pair_rms_over_the_common_window_by_hand():
    # treatment: a jerk of 2 over [3, 5], its own window [3, 5]; control: a jerk of 1 over
    # [3, 8], its own window [3, 8]. Own windows: RMS 2 and 1. Union [3, 8] (51 rows): the
    # treatment's 21 rows of 2 among 51 give sqrt(21 * 4 / 51), the control stays at 1.
    # Intersection [3, 5]: 2 and 1 again.
    treatment = pd.DataFrame({"scenario": ["s0"], "smoothness_window_start_s": [3.0],
                              "smoothness_window_end_s": [5.0]})
    control = pd.DataFrame({"scenario": ["s0"], "smoothness_window_start_s": [3.0],
                            "smoothness_window_end_s": [8.0]})
    jerk_t, jerk_c = {"s0": burst(2.0, 3.0, 5.0)}, {"s0": burst(1.0, 3.0, 8.0)}
    assert jerk_t["s0"].rms_over(3.0, 5.0) == pytest.approx(2.0)
    union = common_window_pairs(treatment, control, jerk_t, jerk_c, "union").iloc[0]
    assert (union["window_start_s"], union["window_end_s"]) == (3.0, 8.0)
    assert union["treatment_mps3"] == pytest.approx(math.sqrt(21 * 4 / 51), rel=1e-12)
    assert union["control_mps3"] == pytest.approx(1.0, rel=1e-12)
    inter = common_window_pairs(treatment, control, jerk_t, jerk_c, "intersection").iloc[0]
    assert inter["treatment_mps3"] == pytest.approx(2.0)
    assert inter["control_mps3"] == pytest.approx(1.0)


def test_a_pair_without_a_jerk_signal_is_missing():
    table = pd.DataFrame({"scenario": ["s0", "s1"], "smoothness_window_start_s": [3.0, 3.0],
                          "smoothness_window_end_s": [5.0, 5.0]})
    pairs = common_window_pairs(table, table, {"s0": burst(1.0, 3.0, 5.0)},
                                {"s0": burst(1.0, 3.0, 5.0), "s1": burst(1.0, 3.0, 5.0)})
    assert pairs["treatment_mps3"].iloc[0] == pytest.approx(1.0)
    assert np.isnan(pairs["treatment_mps3"].iloc[1])


N = 12
#: each treatment run's burst of amplitude AMPLITUDE[i] on [3, 5] inside its own window [3, 9]
#: (quiet from 5 s: the dilution); each control run's burst of 1 on [3, 5], own window [3, 5]
AMPLITUDE = 1.2 + 0.01 * np.arange(N)
DILUTION = math.sqrt(rows_in(3.0, 5.0) / rows_in(3.0, 9.0))


def planted_family() -> tuple[dict[str, pd.DataFrame], dict[str, dict[str, LateralJerk]]]:
    """Treatment and control tables (every claim's primary metric, C2's own-window RMS and
    windows) and their jerk signals, as :func:`family_ledger` reads them."""
    scenarios = [f"s{i}" for i in range(N)]
    jerks = {"improved": {s: burst(a, 3.0, 5.0) for s, a in zip(scenarios, AMPLITUDE,
                                                                 strict=True)},
             "baseline": {s: burst(1.0, 3.0, 5.0) for s in scenarios}}
    tables = {}
    for method, end in (("improved", 9.0), ("baseline", 5.0)):
        table = pd.DataFrame({"scenario": scenarios, "collision": False})
        for claim in ALL_CLAIMS[1:]:
            table[claim.primary_metric] = 1.0 + 0.01 * np.arange(N)
        table["smoothness_window_start_s"], table["smoothness_window_end_s"] = 3.0, end
        table["lateral_jerk_rms_mps3"] = [jerks[method][s].rms_over(3.0, end)
                                          for s in scenarios]
        tables[method] = table
    return tables, jerks


def test_the_switch_moves_c2_the_way_the_common_window_says():
    tables, jerks = planted_family()
    own = family_ledger(tables, ClaimsConfig(), comparisons=("baseline",), jerks=jerks)
    common = family_ledger(tables, ClaimsConfig(c2_window="common"), comparisons=("baseline",),
                           jerks=jerks)
    own_row, common_row = own[("C2", "baseline")], common[("C2", "baseline")]
    # the differences form an arithmetic sequence: the Hodges-Lehmann estimate is its mean
    assert own_row.result.estimate == pytest.approx(AMPLITUDE.mean() * DILUTION - 1.0, rel=1e-9)
    assert common_row.result.estimate == pytest.approx((AMPLITUDE.mean() - 1.0) * DILUTION,
                                                       rel=1e-9)
    # diluted over its own longer window the treatment looks smoother; on the common window
    # it is not
    assert str(own_row.outcome) == "supported"
    assert str(common_row.outcome) == "contradicted"
    assert common_row.to_dict()["metric"] == COMMON_C2_METRIC
    # every other claim is read as before
    for claim in ("C0", "C1", "C3a", "C3b", "C4", "C5"):
        assert common[(claim, "baseline")].result.estimate == \
            own[(claim, "baseline")].result.estimate


def test_common_window_without_the_runs_jerk_says_so():
    tables, _ = planted_family()
    with pytest.raises(ValueError, match="c2_window=common"):
        family_ledger(tables, ClaimsConfig(c2_window="common"), comparisons=("baseline",))


def test_unknown_readings_are_refused():
    with pytest.raises(ConfigError):
        ClaimsConfig(c2_window="shared")
    with pytest.raises(ConfigError):
        ClaimsConfig(common_window="overlap")


def test_a_runs_own_window_and_jerk_give_back_its_own_rms():
    """The recorded window and the jerk signal rebuild the run's own C2 value exactly: what
    the common window is made of is what the metrics used."""
    from builders import out_and_back

    from pipeline.analysis.metrics import TrajectoryContext, compute_metrics, lateral_jerk_signal
    from pipeline.config import MetricsConfig

    frame = out_and_back(0.4)
    ctx = TrajectoryContext((0.0, 0.0), (30.0, 0.0), 1.0)
    for reading in ("vy_dot_plus_vx_r", "vx_r"):
        cfg = MetricsConfig(lateral_accel=reading)
        m = compute_metrics(frame, ctx, cfg).to_json()
        jerk = lateral_jerk_signal(frame, ctx, cfg)
        start, end = m["smoothness_window_start_s"], m["smoothness_window_end_s"]
        assert 0.0 < start < end
        assert jerk.rms_over(start, end) == m["lateral_jerk_rms_window_mps3"]
        assert jerk.rms_over(-1.0, 1e6) == m["lateral_jerk_rms_run_mps3"]


def test_report_shows_c2_on_the_common_window_beside_the_default(tmp_path, make_config):
    """On a small family the report writes both readings; the common window's estimate is
    rebuilt here from the stored trajectories with numpy alone (jerk by central differences
    of vy_dot + vx r, the union of the two recorded windows, the Walsh-average median)."""
    import json

    from pipeline.report import build_report
    from pipeline.run import run_experiment
    from pipeline.studies.experiment import run_family

    runs = tmp_path / "outputs"
    for method in ("baseline", "improved"):
        run_experiment(make_config([f"method={method}"]), runs / "paper" / method)
        run_family(make_config([f"method={method}", "scenario=family",
                                "scenario.family.size=12", "scenario.family.n_jobs=1"]),
                   runs / "family" / method, progress=False)
    page = build_report(runs, tmp_path / "report", "pytest").read_text()
    assert 'id="c2-common-window"' in page
    table = pd.read_csv(tmp_path / "report" / "tables" / "claims_c2_common_window.csv")
    ledger = pd.read_csv(tmp_path / "report" / "tables" / "claims_ledger.csv")
    assert set(table["reading"]) == {"own", "common"}
    own = table[table["reading"] == "own"].iloc[0]
    assert bool(own["in_ledger"])
    c2 = ledger[(ledger["claim"] == "C2") & (ledger["comparison"] == "baseline")].iloc[0]
    assert own["estimate"] == pytest.approx(c2["estimate"], rel=1e-12)

    def member(method: str, i: int) -> tuple[pd.DataFrame, dict]:
        folder = runs / "family" / method / f"member_{i:04d}"
        return (pd.read_csv(folder / "trajectory.csv"),
                json.loads((folder / "metrics.json").read_text()))

    d = []
    for i in range(12):
        (tr_i, m_i), (tr_b, m_b) = member("improved", i), member("baseline", i)
        if m_i["collision"] or m_b["collision"] or m_i["smoothness_window_start_s"] is None:
            continue
        start = min(m_i["smoothness_window_start_s"], m_b["smoothness_window_start_s"])
        end = max(m_i["smoothness_window_end_s"], m_b["smoothness_window_end_s"])
        values = []
        for tr in (tr_i, tr_b):
            t = tr["time_s"].to_numpy()
            a_y = np.gradient(tr["vy_mps"].to_numpy(), t) + tr["vx_mps"].to_numpy() * \
                tr["r_rad_s"].to_numpy()
            jerk = np.gradient(a_y, t)
            inside = (t >= start - 1e-9) & (t <= end + 1e-9)
            values.append(np.sqrt(np.mean(jerk[inside] ** 2)))
        d.append(values[0] - values[1])
    d = np.asarray(d)
    walsh = [(d[a] + d[b]) / 2 for a in range(d.size) for b in range(a, d.size)]
    common = table[(table["reading"] == "common") & (table["comparison"] == "baseline")].iloc[0]
    assert int(common["n_pairs"]) == d.size
    assert common["estimate"] == pytest.approx(float(np.median(walsh)), rel=1e-6)


def test_the_multiverse_refuses_the_common_window_before_it_runs(tmp_path):
    from pipeline.studies.multiverse import load_space, run_multiverse

    space = load_space(CONF_DIR / "multiverse" / "quick.yaml")
    with pytest.raises(ConfigError, match="claims.c2_window"):
        run_multiverse(space, tmp_path / "mv", ["claims.c2_window=common"])
    assert not (tmp_path / "mv" / "runs").exists()


def test_the_jerk_read_from_the_signal_columns_alone_is_the_jerk():
    """The report reads each member's trajectory for C2's common window with only the columns
    the signals read (metrics.signals.SIGNAL_COLUMNS): the same jerk as from the whole table,
    under both readings of the lateral acceleration; a column left out would change it."""
    from builders import out_and_back

    from pipeline.analysis.metrics import TrajectoryContext, lateral_jerk_signal
    from pipeline.analysis.metrics.signals import SIGNAL_COLUMNS
    from pipeline.config import MetricsConfig

    frame = out_and_back(0.4)
    frame["unread_column"] = np.arange(len(frame), dtype=float)
    ctx = TrajectoryContext((0.0, 0.0), (30.0, 0.0), 1.0)
    read = frame[[c for c in frame.columns if c in SIGNAL_COLUMNS]]
    assert "unread_column" not in read and "vx_mps" in read
    for reading in ("vy_dot_plus_vx_r", "vx_r"):
        cfg = MetricsConfig(lateral_accel=reading)
        whole, part = lateral_jerk_signal(frame, ctx, cfg), lateral_jerk_signal(read, ctx, cfg)
        assert np.array_equal(whole.jerk_mps3, part.jerk_mps3)
    without_vx = lateral_jerk_signal(read.drop(columns="vx_mps"), ctx, MetricsConfig())
    assert not np.array_equal(without_vx.jerk_mps3, lateral_jerk_signal(frame, ctx,
                                                                         MetricsConfig()).jerk_mps3)
