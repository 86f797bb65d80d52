"""The CBF-QP safety filter peer (pipeline.peers.cbf_filter): the nominal input untouched where
no barrier row binds, the QP against an independent solve, the closed loop kept clear where the
nominal MPC alone collides, the side rule (pipeline.peers.side_rule) by hand and on an obstacle
dead ahead, both tracks through ``_target_``, bad params as one line."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

from pipeline.errors import ConfigError
from pipeline.loop.controller import LateralMpc, Observation, QpCache, make_controller
from pipeline.loop.planner import make_planner
from pipeline.loop.scenario import ObstacleSnapshot, build_scenario
from pipeline.loop.simulate import simulate
from pipeline.peers.cbf_filter import (
    CbfFilterSettings,
    CbfQpStructure,
    CbfRows,
    CbfSafetyFilter,
    KinematicCbfFilter,
    LateralCbfFilter,
)
from pipeline.peers.side_rule import pass_sides

#: A static obstacle dead ahead: on the start-goal line (the x axis), 14 m in front of the start.
DEAD_AHEAD = "scenario.obstacles=[{x_m: 14.0, y_m: 0.0, vx_mps: 0.0, vy_mps: 0.0, " \
             "radius_m: 0.5, appear_time_s: 0.0}]"


def observation(cfg, obstacles, y_m=0.5, speed_mps=3.0):
    """An observation as the loop makes it: the vehicle at ``(0, y_m)`` heading along the
    start-goal line at ``speed_mps``, ``obstacles`` rows ``(x, y, vx, vy, radius)`` all
    visible, the straight-to-goal planner's rollout."""
    scenario = build_scenario(cfg.scenario)
    frame = scenario.line_frame
    rows = np.asarray(obstacles, float).reshape(-1, 5)
    snapshot = ObstacleSnapshot(rows[:, :2], rows[:, 2:4], rows[:, 4],
                                np.ones(rows.shape[0], bool))
    state = np.array([0.0, y_m, 0.0, speed_mps, 0.0, 0.0, 0.0])
    planner = make_planner(cfg.planner, cfg.controller.horizon, scenario.sample_time_s)
    rollout = planner.rollout(state[:2].copy(), scenario.goal_m, snapshot,
                              np.array([speed_mps, 0.0]))
    return Observation(0.0, state, frame, frame.to_line(state[:2]), 0.0, rollout, snapshot,
                       speed_mps)


def clearance(trajectory):
    """True clearance per row: the smallest distance minus both radii over visible
    obstacles (inf where none is visible)."""
    out = np.full(len(trajectory), np.inf)
    j = 0
    while f"obs{j}_x_m" in trajectory:
        d = np.hypot(trajectory.X_m - trajectory[f"obs{j}_x_m"],
                     trajectory.Y_m - trajectory[f"obs{j}_y_m"]).to_numpy() \
            - trajectory[f"obs{j}_radius_m"].to_numpy() - 1.0   # vehicle.footprint_radius_m
        seen = trajectory[f"obs{j}_visible"].to_numpy().astype(bool)
        out = np.minimum(out, np.where(seen, d, np.inf))
        j += 1
    return out


def test_nominal_input_unchanged_without_an_active_row_and_changed_with_one(make_config):
    cfg = make_config(["method=cbf_filter"])
    ts = cfg.scenario.sample_time_s
    for obstacles in ([], [(60.0, 0.0, 0.0, 0.0, 0.5)]):   # none; one far ahead
        filtered = LateralCbfFilter(cfg.controller, cfg.vehicle, ts, QpCache())
        plain = LateralMpc(cfg.controller, cfg.vehicle, None, ts, QpCache())
        obs = observation(cfg, obstacles)
        step, nominal = filtered.step(obs), plain.step(obs)
        assert step.command.tolist() == nominal.command.tolist() != [0.0]   # bit for bit
        assert step.log["cbf_active"] is False and step.log["cbf_correction_rad_s"] == 0.0
    # planted 6.1 m ahead, just below the vehicle: the filter steers away (up), the nominal down
    filtered = LateralCbfFilter(cfg.controller, cfg.vehicle, ts, QpCache())
    plain = LateralMpc(cfg.controller, cfg.vehicle, None, ts, QpCache())
    obs = observation(cfg, [(6.1, 0.0, 0.0, 0.0, 0.5)])
    step, nominal = filtered.step(obs), plain.step(obs)
    assert nominal.command[0] < 0.0 < step.command[0]
    assert step.log["cbf_active"] is True and step.max_slack_m == 0.0
    assert step.planned[0, 1:].tolist() == nominal.planned[0, 1:].tolist()
    # a whole obstacle-free run is the nominal MPC's run, bit for bit
    free = ["scenario.obstacles=[]", "scenario.allow_no_obstacles=true", "scenario.n_steps=40"]
    runs = [simulate(c, build_scenario(c.scenario)).trajectory
            for c in (make_config(["method=cbf_filter", *free]),
                      make_config(["method=cbf_filter", "controller._target_=null", *free]))]
    for column in ("X_m", "Y_m", "psi_rad", "steering_rate_rad_s"):
        np.testing.assert_array_equal(runs[0][column], runs[1][column])  # NaN == NaN here
    assert not runs[0]["cbf_active"].any()


def slsqp(u_nom, gain, bound, structure):
    """The filter's QP by SciPy's SLSQP (inputs and slacks as one vector)."""
    n, m = u_nom.size, bound.size
    scale = np.asarray(structure.input_scale)
    w1, w2 = structure.slack_weights

    def cost(z):   # divided by w1: the same minimizer, better scaled for SLSQP
        u, s = z[:n], z[n:]
        return float(np.sum(((u - u_nom) / scale) ** 2) + w1 * s.sum() + w2 * s @ s) / w1

    rows = {"type": "ineq", "fun": lambda z: gain @ z[:n] + z[n:] - bound}
    bounds = list(zip(structure.input_low, structure.input_high, strict=True)) + [(0, None)] * m
    start = np.concatenate([u_nom, np.maximum(bound - gain @ u_nom, 0.0)])  # feasible
    found = minimize(cost, start, method="SLSQP",
                     constraints=[rows], bounds=bounds, options={"ftol": 1e-14, "maxiter": 500})
    assert found.success, found.message
    return found.x[:n]


def test_qp_equals_an_independent_solve_with_active_rows(make_config):
    cfg = make_config(["method=cbf_filter"])
    ts = cfg.scenario.sample_time_s
    # the lateral filter's own rows at the planted case: one active row, one input
    lateral = LateralCbfFilter(cfg.controller, cfg.vehicle, ts, QpCache())
    obs = observation(cfg, [(6.1, 0.0, 0.0, 0.0, 0.5)])
    inputs, log = lateral.nominal.frame.inputs(obs)
    u_nom = lateral.nominal.solve(inputs, log).command
    rows = lateral.rows(obs, u_nom)
    assert not rows.met_by(u_nom)
    result = lateral.filter.apply(u_nom, rows, 0.0)
    # closed form of one input: the rows (one per preview step) cut an interval out of the
    # bounds; the answer is u_nom moved into it
    g, b = rows.gain[:, 0], rows.bound
    assert np.all(b[g == 0.0] <= 0.0)
    low = max([-1.0] + [bi / gi for gi, bi in zip(g, b, strict=True) if gi > 0.0])
    high = min([1.0] + [bi / gi for gi, bi in zip(g, b, strict=True) if gi < 0.0])
    assert low <= high
    closed_form = float(np.clip(u_nom[0], low, high))
    assert closed_form != u_nom[0] and result.slack_m == 0.0
    assert result.command[0] == pytest.approx(closed_form, abs=1e-7)
    assert result.command[0] == pytest.approx(slsqp(u_nom, rows.gain, rows.bound,
                                                    lateral.filter.structure)[0], abs=1e-6)
    # two inputs, two active rows, one of them out of reach (slack) and a bound binding
    structure = CbfQpStructure((-3.0, -0.4), (3.0, 0.4), (3.0, 0.4), 3, (10.0, 100.0))
    two = CbfSafetyFilter(structure, "clarabel_direct", 200, QpCache())
    gain = np.array([[0.30, 0.80], [-0.05, 0.60], [0.0, 0.0]])
    bound = np.array([0.4, 0.45, -1.0])
    u_nom = np.array([0.5, -0.1])
    result = two.apply(u_nom, CbfRows(gain, bound, 2, np.zeros(2)), 0.0)
    reference = slsqp(u_nom, gain, bound, structure)
    assert result.active and result.status == "optimal" and result.slack_m > 0.0
    np.testing.assert_allclose(result.command, reference, atol=1e-6)
    assert result.command[1] == pytest.approx(0.4, abs=1e-8)
    # the same QP through CVXPY's own solve (controller.backend=cvxpy)
    through_cvxpy = CbfSafetyFilter(structure, "cvxpy", 200, QpCache())
    np.testing.assert_allclose(
        through_cvxpy.apply(u_nom, CbfRows(gain, bound, 2, np.zeros(2)), 0.0).command,
        result.command, atol=1e-7)


def test_filter_keeps_the_paper_run_clear_where_the_nominal_mpc_collides(make_config):
    cfg = make_config(["method=cbf_filter"])
    run = simulate(cfg, build_scenario(cfg.scenario))
    tr = run.trajectory
    h = clearance(tr)
    solved = (tr["solver_status"] != "end").to_numpy()
    slack = tr["max_slack_m"].to_numpy() > 0.0
    no_slack = solved & ~slack
    assert np.all(h[no_slack] >= 0.0), h.min()
    # slack only while the obstacle has just appeared (3 s) too close for the rows to be met
    appear_s = cfg.scenario.obstacles[0].appear_time_s
    assert np.all((tr["time_s"][slack] >= appear_s) & (tr["time_s"][slack] < appear_s + 0.5))
    assert tr["cbf_active"].any() and run.goal_reached
    nominal_cfg = make_config(["method=cbf_filter", "controller._target_=null"])
    nominal = simulate(nominal_cfg, build_scenario(nominal_cfg.scenario))
    assert clearance(nominal.trajectory).min() < 0.0 < h.min()   # alone, it collides


def test_both_tracks_compose_by_target_and_bad_params_are_one_line(make_config):
    cfg = make_config(["experiment=kinematic", "method=cbf_filter_kinematic"])
    assert cfg.controller.kind == "kinematic_mpc"
    assert cfg.controller._target_ == "pipeline.peers.cbf_filter.KinematicCbfFilter"
    assert isinstance(make_controller(cfg, 0.1, QpCache()), KinematicCbfFilter)
    run = simulate(cfg, build_scenario(cfg.scenario))
    tr = run.trajectory
    assert run.termination in ("goal_line", "max_steps") and tr["cbf_active"].any()
    no_slack = (tr["max_slack_m"].to_numpy() == 0.0)
    assert np.all(clearance(tr)[no_slack] >= 0.0)
    alone = make_config(["method=cbf_filter_kinematic"])   # as experiment=kinematic_peers has it
    assert alone.controller.kind == "kinematic_mpc" and alone.run.method == "cbf_filter"
    lateral = make_config(["method=cbf_filter"])
    assert isinstance(make_controller(lateral, 0.1, QpCache()), LateralCbfFilter)
    assert CbfFilterSettings.of(dict(lateral.controller.params)) == CbfFilterSettings()
    for override, key in (("controller.params.decay_rate=0.0", "decay_rate"),
                          ("controller.params.preview_steps=0", "preview_steps"),
                          ("+controller.params.horizon_s=2", "horizon_s"),
                          ("controller.params.min_lateral_offset_ratio=1.5",
                           "min_lateral_offset_ratio"),
                          # the lateral filter has one input: an acceleration weight is refused
                          ("+controller.params.accel_cost_ratio=10", "accel_cost_ratio")):
        bad = make_config(["method=cbf_filter", override])
        with pytest.raises(ValueError) as error:
            make_controller(bad, 0.1, QpCache())
        message = str(error.value)
        assert isinstance(error.value, ConfigError) and "\n" not in message
        assert f"controller.params.{key}" in message
    wrong_track = make_config(["method=cbf_filter",
                               "controller._target_=pipeline.peers.cbf_filter.KinematicCbfFilter"])
    with pytest.raises(ConfigError, match="controller.kind"):
        make_controller(wrong_track, 0.1, QpCache())


def test_side_choice_by_hand_mirror_symmetric_and_the_vehicles_side_dead_ahead():
    # a trajectory along the line (row 0: the vehicle now), three static obstacles at x = 6 m:
    # slightly left, slightly right, dead ahead. Closest points (6, 0): lateral offsets -0.1,
    # +0.1 and 0 (a tie): right, left, and the vehicle's side now (on the line: the left)
    points = np.column_stack([np.arange(11.0), np.zeros(11)])
    centres = np.broadcast_to(np.array([[6.0, 0.1], [6.0, -0.1], [6.0, 0.0]]), (11, 3, 2))
    assert pass_sides(points, centres, points[0]).tolist() == [-1.0, 1.0, 1.0]
    # dead ahead where the trajectory meets the obstacle's centre, the vehicle now 0.2 m to
    # one side of it: that side; mirrored, the other
    for y0, side in ((-0.2, -1.0), (0.2, 1.0)):
        converging = points.copy()
        converging[:, 1] = y0 * np.clip(1.0 - points[:, 0] / 6.0, 0.0, None)
        assert converging[6, 1] == 0.0
        assert pass_sides(converging, centres[:, 2:], converging[0]).tolist() == [side]


def test_filter_rows_follow_the_side_rule_by_hand(make_config):
    """The lateral filter's rows against the module docstring written out: the side on the
    preview under the input applied last step, the lateral offset raised to rho R on it, the
    row the tangent there."""
    cfg = make_config(["method=cbf_filter"])
    ts, params = cfg.scenario.sample_time_s, cfg.controller.params
    rho, m = params["min_lateral_offset_ratio"], params["preview_steps"]
    assert (rho, m) == (0.5, 10)
    R = 0.5 + cfg.vehicle.footprint_radius_m + cfg.controller.safety_margin_m
    signs = {}
    for oy, applied, side in ((0.05, 0.0, -1.0), (-0.05, 0.0, 1.0), (0.0, 0.0, 1.0),
                              (0.0, -1.0, -1.0), (0.0, 1.0, 1.0)):
        lateral = LateralCbfFilter(cfg.controller, cfg.vehicle, ts, QpCache())
        lateral.applied = np.array([applied])
        obs = observation(cfg, [(7.0, oy, 0.0, 0.0, 0.5)], y_m=0.0)
        inputs, log = lateral.nominal.frame.inputs(obs)
        u_nom = lateral.nominal.solve(inputs, log).command
        rows = lateral.rows(obs, u_nom)
        free, sens = lateral.preview(obs)
        J = sens[:, 1, 0]
        p = free + sens @ u_nom                       # the linearization points p_i(u_nom)
        dx, dy = p[:, 0] - 7.0, p[:, 1] - oy
        ny_raw = side * np.maximum(side * dy, rho * R)
        n_x, n_y = dx / np.hypot(dx, ny_raw), ny_raw / np.hypot(dx, ny_raw)
        target = (1.0 - params["decay_rate"]) ** m * (np.hypot(7.0, oy) - R)
        gain = n_y * J
        bound = target - (n_x * dx + n_y * dy - R) + gain * u_nom[0]
        np.testing.assert_allclose(rows.gain[:m, 0], gain, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(rows.bound[:m], bound, rtol=1e-12, atol=1e-12)
        signs[(oy, applied)] = np.sign(rows.gain[m - 1, 0])
    # mirror symmetry: slightly left -> steer right, slightly right -> steer left; dead ahead on
    # the line -> the left, or the side the last applied steering rate turns to
    assert signs == {(0.05, 0.0): -1.0, (-0.05, 0.0): 1.0, (0.0, 0.0): 1.0,
                     (0.0, -1.0): -1.0, (0.0, 1.0): 1.0}
    # the rule off: the plain gradient, purely longitudinal dead ahead (no steering gain)
    off = make_config(["method=cbf_filter", "controller.params.min_lateral_offset_ratio=0"])
    plain = LateralCbfFilter(off.controller, off.vehicle, ts, QpCache())
    obs = observation(off, [(7.0, 0.0, 0.0, 0.0, 0.5)], y_m=0.0)
    inputs, log = plain.nominal.frame.inputs(obs)
    assert np.all(np.abs(plain.rows(obs, plain.nominal.solve(inputs, log).command).gain)
                  < 1e-12)


@pytest.mark.parametrize("track", ["lateral", "kinematic"])
def test_dead_ahead_passes_with_the_side_rule_and_not_without(make_config, track):
    """A static obstacle on the start-goal line 14 m ahead: with the rule the filter steers
    round it and reaches the goal; without it the lateral filter collides (slack, no steering:
    the CBF-QP's undesired equilibrium) and the kinematic one brakes to a standstill in front of
    it. On the kinematic track the acceleration's cost weight is what lets the rule steer:
    alike weights stop too."""
    base = ["method=cbf_filter", DEAD_AHEAD] if track == "lateral" else \
        ["experiment=kinematic", "method=cbf_filter_kinematic", DEAD_AHEAD,
         "scenario.n_steps=160"]   # from rest, 100 steps do not reach the goal line
    runs = {}
    for name, extra in (("rule", []), ("off", ["controller.params.min_lateral_offset_ratio=0"]),
                        ("alike", ["controller.params.accel_cost_ratio=1"])):
        if track == "lateral" and name == "alike":
            continue
        cfg = make_config([*base, *extra])
        run = simulate(cfg, build_scenario(cfg.scenario))
        runs[name] = (run, clearance(run.trajectory))
    run, h = runs["rule"]
    assert np.isfinite(h.min()) and h.min() > 0.25 and run.goal_reached
    assert run.trajectory["cbf_active"].any()
    passed = np.argmin(np.abs(run.trajectory.X_m - 14.0))
    assert run.trajectory.Y_m.iloc[passed] > 1.0          # on the left (a tie: +1)
    off, h_off = runs["off"]
    if track == "lateral":
        assert h_off.min() < -0.5                           # collides
    else:
        assert not off.goal_reached and off.trajectory.vx_mps.iloc[-1] < 0.05
        assert off.trajectory.X_m.iloc[-1] < 14.0 and np.abs(off.trajectory.Y_m).max() < 0.01
        alike, _ = runs["alike"]
        assert not alike.goal_reached and alike.trajectory.vx_mps.iloc[-1] < 0.05
