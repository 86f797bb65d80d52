"""Model validity from the logged columns (closed forms on planted tables), the family rows of
``model_validity.csv``, the verdicts on the scenarios where both models held (planted flags),
and the lateral nonlinear MPC against the QP."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from pipeline.analysis.metrics.criteria import validity_block
from pipeline.analysis.metrics.signals import TrajectoryContext
from pipeline.analysis.validity import (
    VALIDITY_COLUMNS,
    ValidityTable,
    valid_in_both,
    valid_scenario_ledgers,
    validity_row,
)


def planted(n=11, seed=0):
    rng = np.random.default_rng(seed)
    return pd.DataFrame({
        "time_s": 0.1 * np.arange(n),
        "model_heading_error_rad": np.r_[rng.uniform(0, 0.3, n - 2), 0.5, np.nan],
        "tyre_slip_norm": np.r_[np.full(n - 3, 0.1), 0.5, 0.6, 0.2],
        "path_beyond_limit": np.r_[np.ones(4, bool), np.zeros(n - 4, bool)],
        "solver_status": ["optimal"] * (n - 1) + ["end"],
        "model_error_05s_m": rng.uniform(0, 0.1, n),
        "model_error_1s_m": np.r_[rng.uniform(0, 0.2, n - 3), np.nan, np.nan, np.nan],
        "plan_error_1s_m": np.r_[rng.uniform(0, 0.3, n - 3), np.nan, np.nan, np.nan]})


def test_validity_block_closed_forms():
    tr = planted()
    context = TrajectoryContext((0.0, 0.0), (30.0, 0.0), 1.0, validity_heading_rad=0.35,
                                tyre_linear_limit=0.39)
    v = validity_block(tr, context)
    assert v.share_steps_beyond_bound == pytest.approx(1 / 10)   # one of the ten known
    assert v.share_steps_tyre_nonlinear == pytest.approx(2 / 11)
    assert v.share_steps_path_beyond_limit == pytest.approx(4 / 10)   # the end row has no step
    finite = tr["model_error_1s_m"].dropna().to_numpy()
    assert v.prediction_error_1s_p95_m == pytest.approx(np.percentile(finite, 95))
    assert v.prediction_error_1s_p50_m == pytest.approx(np.median(finite))
    assert v.model_heading_error_max_rad == pytest.approx(0.5)
    # a trajectory without the columns (a scored one) has no block
    assert validity_block(tr[["time_s"]], context) is None


def test_validity_row_pools_steps_and_averages_shares():
    members = []
    for seed in range(3):
        tr = planted(seed=seed)
        metrics = {"heading_validity_exceeded": seed == 1, "model_heading_error_max_rad": 0.5,
                   "share_steps_beyond_bound": 0.1 * seed, "share_steps_tyre_nonlinear": 0.2,
                   "share_steps_path_beyond_limit": 0.4}
        members.append((tr, metrics))
    row = validity_row("lateral", "path", "improved", members)
    assert row.runs == 3 and row.runs_beyond_bound == 1
    assert row.share_steps_beyond_bound == pytest.approx(0.1)
    pooled = np.concatenate([m[0]["model_error_1s_m"].dropna() for m in members])
    assert row.prediction_error_1s_p95_m == pytest.approx(np.percentile(pooled, 95))
    frame = ValidityTable((row,)).to_frame()
    assert tuple(frame.columns) == VALIDITY_COLUMNS
    # the kinematic track has no bound: an empty cell, not 0
    kin = validity_row("kinematic", "global (LTV)", "improved",
                       [(tr, {"model_heading_error_max_rad": None})
                        for tr, _ in members])
    assert pd.isna(ValidityTable((kin,)).to_frame()["runs_beyond_bound"].iloc[0])


def test_valid_scenarios_keep_only_pairs_where_both_models_held(make_config):
    """Planted: 40 scenarios, improved better on C1 by 0.2 s everywhere; the model left its
    bound in 5 scenarios of the treatment and 7 of the control (2 shared): 30 remain, and the
    ledger on them is judged on 30 pairs."""
    claims = make_config().claims
    n = 40
    rng = np.random.default_rng(3)

    def table(delay, flagged):
        from pipeline.analysis.claims.catalogue import ALL_CLAIMS

        frame = pd.DataFrame({c.primary_metric: rng.normal(1.0, 0.1, n) for c in ALL_CLAIMS})
        return frame.assign(scenario=[f"s{i}" for i in range(n)], member=np.arange(n),
                            collision=False, reaction_delay_s=delay + rng.normal(0, 0.01, n),
                            heading_validity_exceeded=[i in flagged for i in range(n)])

    treatment = table(0.3, set(range(5)))
    control = table(0.5, {3, 4, 5, 6, 7, 8, 9})
    assert valid_in_both(treatment, control) == {f"s{i}" for i in range(10, n)}
    ledgers = valid_scenario_ledgers({"improved": treatment, "baseline": control}, claims,
                                     "improved", ("baseline",))
    ledger, scenarios = ledgers["baseline"]
    assert scenarios == 30
    row = ledger.get(("C1", "baseline"))
    assert row.result.n_pairs == 30 and str(row.outcome) == "supported"
    assert row.result.estimate == pytest.approx(-0.2, abs=0.01)


def test_lateral_nmpc_agrees_with_the_qp_on_the_paper_scenario(make_config):
    """The same problem on the nonlinear single-track model (CasADi + IPOPT): on the paper
    scenario its path stays within 0.1 m of the QP's for both methods, with no fallback, and
    its prediction is the plant's (plan error 1 s ahead below 5 cm at the median)."""
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate

    for method in ("improved", "baseline"):
        cfg = make_config([f"method={method}"])
        nmpc_cfg = make_config([f"method={method}", "controller.backend=nmpc"])
        scenario = build_scenario(cfg.scenario)
        qp = simulate(cfg, scenario).trajectory
        nl = simulate(nmpc_cfg, scenario).trajectory
        n = min(len(qp), len(nl)) - 1
        gap = np.hypot(qp["X_m"].to_numpy()[:n] - nl["X_m"].to_numpy()[:n],
                       qp["Y_m"].to_numpy()[:n] - nl["Y_m"].to_numpy()[:n])
        assert gap.max() < 0.1, method
        assert not nl["fallback"].isin(["shifted_plan", "safe_input"]).any()
        assert set(nl["solver_status"].dropna()) <= {"optimal", "optimal_inaccurate", "end"}
        assert np.nanmedian(nl["plan_error_1s_m"]) < 0.05
    assert math.isfinite(gap.max())


@pytest.mark.parametrize("heading", [0.06, 0.2])
def test_where_the_model_holds_the_nonlinear_mpc_drives_within_a_centimetre_of_the_qp(
        make_config, heading):
    """No obstacle, a start heading inside the small-angle bound (the errors stay small, so
    the linear model is the plant's to first order): the QP and the nonlinear MPC (the plant's
    own model) drive the same path within 1 cm over 6 s, and neither leaves the bound."""
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate

    paths = {}
    for backend in ("clarabel_direct", "nmpc"):
        cfg = make_config(["method=improved", f"scenario.start_heading_rad={heading}",
                           "scenario.obstacles=[]", "scenario.allow_no_obstacles=true",
                           "scenario.n_steps=60", f"controller.backend={backend}"])
        trajectory = simulate(cfg, build_scenario(cfg.scenario)).trajectory
        assert np.nanmax(trajectory["model_heading_error_rad"]) <= 0.35
        paths[backend] = trajectory[["X_m", "Y_m"]].to_numpy()
    gap = np.hypot(*(paths["clarabel_direct"] - paths["nmpc"]).T)
    assert gap.max() < 0.01
    assert np.abs(paths["nmpc"][:, 1]).max() > 0.05  # it did steer back: not a trivial run
