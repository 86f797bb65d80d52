"""MPC-DCBF (pipeline/peers/mpc_dcbf.py, Zeng, Zhang and Sreenath, ACC 2021) on both tracks:
the barrier holds where the QP needed no slack, the DCBF rows bind and are what their paper
says, both method configs compose and run through ``controller._target_``, bad params fail in
one line."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.loop.controller import LateralMpc, Observation, QpCache
from pipeline.loop.planner import make_planner
from pipeline.loop.scenario import ObstacleSnapshot, build_scenario
from pipeline.loop.simulate import simulate
from pipeline.peers.mpc_dcbf import DcbfParams, KinematicMpcDcbf, LateralMpcDcbf

HEAD_ON = "scenario.obstacles=[{x_m: 14.0, y_m: 0.0, vx_mps: -0.8, vy_mps: 0.0, " \
          "radius_m: 0.5, appear_time_s: 2.0}]"


@pytest.fixture(scope="module")
def qp_cache():
    """One cache for the module's runs (each QP structure compiled once)."""
    return QpCache()


def barrier(trajectory, cfg, margin: bool = True) -> np.ndarray:
    """The true (nonlinear) barrier of each logged step: the distance to the nearest visible
    obstacle minus its radius, the footprint and (``margin``) the safety margin; inf where
    none is visible."""
    reach = cfg.vehicle.footprint_radius_m + (cfg.controller.safety_margin_m if margin else 0.0)
    h = np.full(len(trajectory), np.inf)
    j = 0
    while f"obs{j}_x_m" in trajectory:
        d = np.hypot(trajectory.X_m - trajectory[f"obs{j}_x_m"],
                     trajectory.Y_m - trajectory[f"obs{j}_y_m"]).to_numpy() \
            - trajectory[f"obs{j}_radius_m"].to_numpy() - reach
        seen = trajectory[f"obs{j}_visible"].to_numpy().astype(bool)
        h = np.minimum(h, np.where(seen, d, np.inf))
        j += 1
    return h


def run(make_config, overrides, qp_cache):
    cfg = make_config(overrides)
    result = simulate(cfg, build_scenario(cfg.scenario), qp_cache)
    return cfg, result


@pytest.mark.parametrize("obstacles", [[HEAD_ON], []], ids=["head_on", "paper"])
def test_barrier_holds_where_no_slack_was_needed_and_the_run_comes_close(make_config, qp_cache,
                                                                          obstacles):
    cfg, result = run(make_config, ["method=mpc_dcbf", *obstacles], qp_cache)
    log = result.trajectory
    assert cfg.controller._target_ == "pipeline.peers.mpc_dcbf.LateralMpcDcbf"
    assert result.goal_reached and (log.fallback.iloc[:-1] == "none").all()
    h = barrier(log, cfg)
    solved = log.solver_status.iloc[:-1] != "end"
    no_slack = solved & (log.max_slack_m.iloc[:-1] <= 1e-9)
    seen = np.isfinite(h[:-1])
    # a run that comes close: the keep-out boundary within 0.7 m on a step without slack
    assert (h[:-1][no_slack & seen] < 0.7).any()
    assert (h[:-1][no_slack] >= 0.0).all(), h[:-1][no_slack].min()
    # the controller's own h(x_0) is the same barrier (the nearest visible obstacle)
    logged = log.cbf_min_h_m.to_numpy()[:-1]
    close = np.isfinite(logged)
    np.testing.assert_allclose(logged[close], h[:-1][close], atol=1e-9)
    if obstacles:
        # dead ahead on the line: the side rule passes on the left (+y)
        passing = np.argmin(np.abs(log.X_m - log.obs0_x_m))
        assert log.Y_m.iloc[passing] > 1.0


def test_a_smaller_gamma_keeps_a_larger_clearance(make_config, qp_cache):
    h_min = {}
    for gamma in (1.0, 0.05):
        cfg, result = run(make_config, ["method=mpc_dcbf", f"controller.params.gamma={gamma}"],
                          qp_cache)
        h_min[gamma] = float(np.min(barrier(result.trajectory, cfg)))
    # gamma = 1 only keeps h >= 0 at the next step: it skims the keep-out disk
    assert abs(h_min[1.0]) < 0.05
    assert h_min[0.05] > h_min[1.0] + 0.5


def observation(cfg, obstacles: list[tuple[float, float, float]],
                state: np.ndarray | None = None) -> Observation:
    """A step's observation at a fixed state (single-track by default: 3 m/s, slightly left of
    the line, turning)."""
    scenario = build_scenario(cfg.scenario)
    if state is None:
        state = np.array([2.0, 0.3, 0.05, 3.0, 0.0, 0.0, 0.02])
    snapshot = ObstacleSnapshot(np.array([[x, y] for x, y, _ in obstacles]).reshape(-1, 2),
                                np.zeros((len(obstacles), 2)),
                                np.array([r for _, _, r in obstacles], dtype=float),
                                np.ones(len(obstacles), dtype=bool))
    frame = scenario.line_frame
    planner = make_planner(cfg.planner, cfg.controller.horizon, scenario.sample_time_s)
    rollout = planner.rollout(state[:2], scenario.goal_m, snapshot,
                              3.0 * np.array([np.cos(state[2]), np.sin(state[2])]))
    return Observation(0.0, state, frame, frame.to_line(state[:2]),
                       float(state[2] - frame.heading_rad), rollout, snapshot, 3.0)


def test_one_qp_meets_the_linearized_dcbf_rows_and_without_obstacles_is_the_plain_mpc(
        make_config, qp_cache):
    cfg = make_config(["method=mpc_dcbf"])
    ctrl, vehicle, ts = cfg.controller, cfg.vehicle, 0.1
    gamma, rho = ctrl.params["gamma"], ctrl.params["min_lateral_offset_ratio"]
    ox, oy, radius = 7.5, 1.0, 0.5
    obs = observation(cfg, [(ox, oy, radius)])
    dcbf = LateralMpcDcbf(ctrl, vehicle, ts, qp_cache)
    inputs, _ = dcbf.frame.inputs(obs)
    step = dcbf.step(obs)
    assert step.fallback == "none" and step.max_slack_m == 0.0
    # the linearized DCBF rows, written out independently from the module docstring: the
    # first step linearizes about the reference, the obstacle is passed on the side the
    # reference is on (right: y_ref < o_y), the point's lateral offset at least rho R
    N = ctrl.horizon
    R = radius + vehicle.footprint_radius_m + ctrl.safety_margin_m
    s = obs.position_line_m[0] + 3.0 * ts * np.arange(N + 1)
    y = step.predicted_states[0]
    ybar = np.concatenate([[obs.position_line_m[1]], inputs.y_ref_m])
    sigma = -1.0
    lateral = sigma * np.maximum(sigma * (ybar - oy), rho * R)
    norm = np.hypot(s - ox, lateral)
    nx, ny = (s - ox) / norm, lateral / norm
    tangent = nx * (s - ox) + ny * (y - oy) - R
    h0 = np.hypot(obs.position_line_m[0] - ox, obs.position_line_m[1] - oy) - R
    residual = np.concatenate([[tangent[1] - (1 - gamma) * h0],
                               tangent[2:] - (1 - gamma) * tangent[1:-1]])
    assert residual.min() >= -1e-6
    assert residual.min() < 1e-4          # a row binds: the obstacle shapes the plan
    # the tangent never exceeds the true barrier (h is convex): the plan keeps h > 0
    assert (np.hypot(s - ox, y - oy) - R >= tangent - 1e-9).all()
    # without the obstacle, the rows are idle: the built-in MPC's plan in the same frame
    free = make_config(["method=mpc_no_apf", "controller.frame=fixed"])
    plain = LateralMpc(free.controller, vehicle, sample_time_s=ts,
                       qp_cache=qp_cache).step(observation(cfg, []))
    clear = LateralMpcDcbf(ctrl, vehicle, ts, qp_cache).step(observation(cfg, []))
    np.testing.assert_allclose(clear.planned, plain.planned, atol=1e-6)
    np.testing.assert_allclose(clear.predicted_states, plain.predicted_states, atol=1e-6)
    # and the obstacle moved the plan away from it (to the right)
    assert y[-1] < clear.predicted_states[0, -1] - 0.05


def test_one_kinematic_qp_meets_the_linearized_dcbf_rows(make_config, qp_cache):
    cfg = make_config(["experiment=kinematic", "method=mpc_dcbf_kinematic"])
    ctrl, vehicle = cfg.controller, cfg.vehicle
    gamma, rho = ctrl.params["gamma"], ctrl.params["min_lateral_offset_ratio"]
    ox, oy, radius = 6.0, 1.0, 0.5
    state = np.array([1.0, 0.2, 0.0, 3.0])
    step = KinematicMpcDcbf(ctrl, vehicle, 0.1, qp_cache).step(
        observation(cfg, [(ox, oy, radius)], state))
    assert step.fallback == "none" and step.max_slack_m == 0.0
    # first step: linearized about the measured state rolled out with zero inputs (straight
    # on at 3 m/s), passed on the right (the rollout is below the obstacle), the point's
    # lateral offset at least rho R (the start-goal line is the x axis here)
    N = ctrl.horizon
    R = radius + vehicle.footprint_radius_m + ctrl.safety_margin_m
    xbar = 1.0 + 0.3 * np.arange(N + 1)
    lateral = -np.maximum(oy - 0.2, rho * R)
    norm = np.hypot(xbar - ox, lateral)
    nx, ny = (xbar - ox) / norm, lateral / norm
    X = step.predicted_states
    tangent = nx * (X[0] - ox) + ny * (X[1] - oy) - R
    h0 = np.hypot(ox - 1.0, oy - 0.2) - R
    residual = np.concatenate([[tangent[1] - (1 - gamma) * h0],
                               tangent[2:] - (1 - gamma) * tangent[1:-1]])
    assert residual.min() >= -1e-6
    assert residual.min() < 1e-4          # a row binds
    free = KinematicMpcDcbf(ctrl, vehicle, 0.1, qp_cache).step(observation(cfg, [], state))
    assert X[1, -1] < free.predicted_states[1, -1] - 0.05   # away from the obstacle (right)


def test_kinematic_track_composes_runs_and_keeps_clear_where_the_halfplane_mpc_collides(
        make_config):
    cache = QpCache()
    cfg, result = run(make_config, ["experiment=kinematic", "method=mpc_dcbf_kinematic"], cache)
    assert cfg.controller.kind == "kinematic_mpc" and cfg.planner.name == "straight_to_goal"
    assert cfg.controller._target_ == "pipeline.peers.mpc_dcbf.KinematicMpcDcbf"
    assert cfg.method_name == "mpc_dcbf"
    log = result.trajectory
    assert result.termination == "max_steps" and len(log) == cfg.scenario.n_steps + 1
    assert (log.fallback.iloc[:-1] == "none").all() and "cbf_min_h_m" in log
    assert result.compile_count == 1
    assert np.min(barrier(log, cfg, margin=False)) > 0.1
    # the built-in LTV-MPC on the same goal-line reference (its half-planes) hits the chair
    cfg_hp, result_hp = run(make_config, ["experiment=kinematic", "planner=mpc_no_apf"], cache)
    assert np.min(barrier(result_hp.trajectory, cfg_hp, margin=False)) < 0.0
    # a second run on the same cache compiles nothing
    again = simulate(cfg, build_scenario(cfg.scenario), cache)
    assert again.compile_count == 0
    np.testing.assert_array_equal(again.trajectory.X_m, log.X_m)


@pytest.mark.parametrize("overrides, key, allowed", [
    (["method=mpc_dcbf", "controller.params.gamma=0"], "controller.params.gamma", "(0, 1]"),
    (["method=mpc_dcbf", "controller.params.min_lateral_offset_ratio=1.5"],
     "controller.params.min_lateral_offset_ratio", "(0, 1]"),
    (["method=mpc_dcbf", "+controller.params.gama=0.3"], "controller.params.gama", "gamma"),
    (["experiment=kinematic", "method=mpc_dcbf_kinematic", "controller.params.gamma=1.5"],
     "controller.params.gamma", "(0, 1]"),
])
def test_bad_params_give_one_line_naming_the_key(make_config, overrides, key, allowed):
    cfg = make_config(overrides)
    cls = KinematicMpcDcbf if cfg.controller.kind == "kinematic_mpc" else LateralMpcDcbf
    with pytest.raises(ValueError) as error:
        cls(cfg.controller, cfg.vehicle, 0.1, None)
    message = str(error.value)
    assert isinstance(error.value, ConfigError) and "\n" not in message
    assert f"{key}=" in message and allowed in message


def test_params_defaults_and_a_frame_it_cannot_use(make_config):
    assert DcbfParams.of({}) == DcbfParams(0.2, 0.5)
    assert DcbfParams.of({"gamma": 1}).gamma == 1.0
    cfg = make_config(["method=mpc_dcbf", "controller.frame=path"])
    with pytest.raises(ConfigError, match=r"controller\.frame=.*fixed"):
        LateralMpcDcbf(cfg.controller, cfg.vehicle, 0.1, None)
