"""Solver faults in the closed loop and numerical edge cases (an interrupted sweep: tests/integration/test_processes.py)."""

from __future__ import annotations

import json

import cvxpy as cp
import numpy as np
import pandas as pd
import pytest

from pipeline.loop.controller import LateralMpc, MpcInputs, QpSolution
from pipeline.loop.model import build_lateral_model
from pipeline.loop.planner import apf_rollout
from pipeline.loop.scenario import ObstacleSnapshot
from pipeline.studies.experiment import run_experiment


def test_injected_solver_faults_fall_back_and_the_run_completes(make_config, tmp_path,
                                                               monkeypatch):
    """Steps 35-37 infeasible, 45 raising, 55 at the iteration limit: every one falls back,
    is logged in trajectory.csv and counted in metrics.json, and the run still ends at the goal."""
    from pipeline.loop.controller.qp import CvxpyQp

    original = CvxpyQp.solve
    calls = {"n": 0}

    def faulty(self, theta):
        k = calls["n"]
        calls["n"] += 1
        if k in (35, 36, 37):
            return QpSolution("infeasible", 7, 0.001, None)
        if k == 45:
            self.problem.solve = lambda *a, **kw: (_ for _ in ()).throw(
                cp.error.SolverError("injected"))
            try:
                return original(self, theta)
            finally:
                del self.problem.solve
        if k == 55:
            return QpSolution("user_limit", self.max_iter, 0.001, None)
        return original(self, theta)

    monkeypatch.setattr(CvxpyQp, "solve", faulty)
    m = run_experiment(make_config(["method=baseline", "controller.backend=cvxpy"]),
                       tmp_path).flat()
    tr = pd.read_csv(tmp_path / "trajectory.csv")
    assert m["fallback_count"] == 5 and m["goal_reached"]
    assert tr.loc[35:37, "fallback"].tolist() == ["shifted_plan"] * 3
    assert tr.loc[45, "solver_status"] == "error:SolverError"
    assert tr.loc[55, "fallback"] == "shifted_plan"
    assert tr[["X_m", "Y_m", "delta_rad"]].notna().all().all()


@pytest.mark.parametrize("backend", ["cvxpy", "clarabel_direct"])
def test_real_iteration_limit_is_a_recorded_fallback(make_config, backend):
    cfg = make_config(["controller.solver_max_iter=1", f"controller.backend={backend}"])
    model = build_lateral_model(cfg.vehicle, 3.0, 0.1)
    N, M = cfg.controller.horizon, cfg.controller.max_obstacles
    step = LateralMpc(cfg.controller, cfg.vehicle).solve(
        MpcInputs(np.array([0.5, 0.0, 0.1, 0.0, 0.0]), model, np.full(N, -1.0), np.zeros(N),
                  np.zeros((N, M)), np.zeros((N, M)), np.zeros(N)))
    assert step.fallback == "safe_input" and step.status != "optimal"
    if backend == "clarabel_direct":
        assert step.status == "user_limit"
    assert np.isfinite(step.steering_rate_rad_s)


@pytest.mark.parametrize("obstacle", [[30.0, 0.0], [0.0, 0.0], [29.9, 0.05]])
def test_apf_finite_with_obstacle_on_the_goal_or_the_vehicle(make_config, obstacle):
    for name in ("baseline", "improved"):
        params = make_config([f"planner={name}"]).planner
        snap = ObstacleSnapshot(np.array([obstacle]), np.zeros((1, 2)), np.array([0.5]),
                                np.array([True]))
        for start in ([0.0, 0.0], [29.95, 0.0], [30.0, 0.0]):
            rollout = apf_rollout(np.array(start), np.array([30.0, 0.0]), snap, params, 10, 0.1)
            assert np.all(np.isfinite(rollout.path_m))
            assert np.all(np.isfinite(rollout.repulsion))


@pytest.mark.parametrize("overrides", [
    ["scenario.goal_xy_m=[-30.0,0.0]"],                        # goal behind the vehicle
    ["scenario.obstacles.0.x_m=1000.0", "scenario.obstacles.0.y_m=1000.0"],  # far away
    ["scenario.speed_mps=0.1"],                                 # near-zero speed
])
def test_edge_case_runs_stay_finite(make_config, tmp_path, overrides):
    m = run_experiment(make_config(overrides), tmp_path).flat()
    tr = pd.read_csv(tmp_path / "trajectory.csv")
    numeric = tr.select_dtypes("number").drop(columns=["clearance_m"], errors="ignore")
    assert np.isfinite(numeric.fillna(0.0).to_numpy()).all()
    assert m["termination"] in ("goal_line", "max_steps")
    model = json.loads((tmp_path / "model.json").read_text())
    assert np.all(np.isfinite(model["discrete"]["Ad"]))


def test_far_obstacle_adds_no_constraint_and_no_repulsion(make_config, tmp_path):
    run_experiment(make_config(["scenario.obstacles.0.x_m=1000.0",
                                "scenario.obstacles.0.y_m=1000.0"]), tmp_path)
    tr = pd.read_csv(tmp_path / "trajectory.csv")
    assert (tr["apf_rep_norm"].fillna(0) == 0).all()
    assert tr["e_y_m"].abs().max() < 1e-6
