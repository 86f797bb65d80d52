"""Closed loop on the paper scenario: goal reached, complete log, run folder, determinism."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from pipeline.studies.experiment import run_experiment

STATE_COLUMNS = ["time_s", "X_m", "Y_m", "psi_rad", "vx_mps", "vy_mps", "r_rad_s", "delta_rad"]


@pytest.fixture(scope="module")
def paper_runs(tmp_path_factory, make_config):
    out = {}
    for method in ("baseline", "improved"):
        folder = tmp_path_factory.mktemp(method)
        out[method] = (run_experiment(make_config([f"planner={method}"]), folder), folder)
    return out


def cfg_slots(make_config) -> int:
    """The default lateral MPC's obstacle slots."""
    return int(make_config().controller.max_obstacles)


@pytest.mark.parametrize("method", ["baseline", "improved"])
def test_paper_scenario_reaches_goal_with_complete_log(paper_runs, make_config, method):
    summary, folder = paper_runs[method]
    for name in ("model.json", "trajectory.csv", "metrics.json", "config.yaml", "timing.json"):
        assert (folder / name).is_file(), name
    m = json.loads((folder / "metrics.json").read_text())
    assert m["goal_reached"] and m["termination"] == "goal_line"
    assert not m["collision"] and m["min_clearance_m"] > 0.0
    # one statement per number of obstacle slots (0 to max_obstacles)
    assert m["fallback_count"] == 0 and m["compile_count"] == cfg_slots(make_config) + 1
    tr = pd.read_csv(folder / "trajectory.csv")
    cfg = make_config([f"planner={method}"])
    # one row per step until the goal line, evenly spaced, every state finite
    assert np.allclose(np.diff(tr["time_s"]), cfg.scenario.sample_time_s)
    assert tr[STATE_COLUMNS].notna().all().all()
    assert len(tr) <= cfg.scenario.n_steps + 1
    final = tr.iloc[-1]
    goal = np.array(cfg.scenario.goal_xy_m)
    assert final["X_m"] >= goal[0] - cfg.scenario.goal_tolerance_m
    assert abs(final["Y_m"] - goal[1]) < 0.5
    # the controller did react to the obstacle
    assert m["reacted"] and tr["e_y_m"].abs().max() > 0.5
    model = json.loads((folder / "model.json").read_text())
    assert np.array(model["discrete"]["Ad"]).shape == (5, 5)
    assert model["speed_mps"] == cfg.scenario.speed_mps


def test_same_config_twice_is_byte_identical(paper_runs, make_config, tmp_path):
    _, folder = paper_runs["improved"]
    again = tmp_path / "again"
    run_experiment(make_config(["planner=improved"]), again)
    for name in ("trajectory.csv", "metrics.json", "model.json", "config.yaml"):
        assert (again / name).read_bytes() == (folder / name).read_bytes(), name


def test_resume_skips_complete_run_with_same_hash(paper_runs, make_config):
    _, folder = paper_runs["baseline"]
    summary = run_experiment(make_config(["planner=baseline"]), folder)
    assert summary.skipped


def test_invisible_obstacle_is_ignored_before_it_appears(paper_runs):
    _, folder = paper_runs["baseline"]
    tr = pd.read_csv(folder / "trajectory.csv")
    before = tr[tr["time_s"] < 3.0 - 1e-9]
    assert not before["obs0_visible"].any()
    assert (before["apf_rep_norm"] == 0).all()
    assert np.allclose(before["delta_rad"], 0.0)
