"""Every alternative of the interpretation register, tested so that the test fails when the
switch is ignored: flip it, and the number moves the way the alternative says.

``SWITCH_TESTS`` names the config keys covered here or in the module named beside them; a
register entry whose key is covered nowhere fails ``test_every_register_key_has_a_switch_test``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from pipeline.analysis.metrics.criteria import compute_metrics
from pipeline.config import INTERPRETATION_REGISTER
from pipeline.loop.controller import (
    LateralMpc,
    Observation,
    blocking_matrix,
    collision_halfplanes,
    force_heading_reference,
    lateral_reference,
)
from pipeline.loop.controller.kinematic import KinematicLtvMpc
from pipeline.loop.model import build_lateral_model, step_plant
from pipeline.loop.planner import adaptive_coefficient, apf_rollout, apf_step, repulsive_force
from pipeline.loop.scenario import LineFrame, ObstacleSnapshot


def metrics_json(*args):
    """The flat ``metrics.json`` mapping of :func:`compute_metrics`."""
    return compute_metrics(*args).to_json()

GOAL = np.array([30.0, 0.0])

SWITCH_TESTS = {
    "model.b2_heading_entry": "here", "planner.k_rep_source": "here",
    "planner.step_size": "here", "planner.alpha_e": "here", "planner.step_max_m": "here",
    "planner.step_min_m": "here", "planner.beta": "here", "planner.rho_floor_m": "here",
    "planner.obstacle_prediction": "here", "planner.closing_speed_gain_s_per_m": "here",
    "controller.heading_reference": "here", "controller.path_beyond_end": "here",
    "controller.input_hold": "here", "controller.halfplane_normal": "here",
    "controller.reference_alignment": "here", "scenario.plant_substeps": "here",
    "scenario.n_steps": "here",
    "metrics.near_field_m": "test_metrics", "metrics.repulsion_onset_force": "test_metrics",
    "metrics.recovery_reading": "test_metrics", "metrics.recovery_lateral_band_m": "test_metrics",
    "metrics.pass_reading": "test_metrics",
    "metrics.reaction_obstacle": "test_metrics", "metrics.reaction_interpolation":
    "test_metrics", "metrics.threat_margin_m": "here", "metrics.threat_horizon_s": "here",
    "metrics.lateral_accel": "test_metrics", "metrics.smoothness_window": "here",
    "metrics.repulsion_need": "test_metrics", "metrics.oscillation": "test_metrics",
    "metrics.collision_check": "test_metrics", "metrics.attribution_steering_samples": "here",
    "metrics.attribution_switch_samples": "test_unavoidable",
    "claims.c2_window": "test_common_window", "claims.common_window": "test_common_window",
    "claims.estimator": "here", "claims.test": "here", "claims.pairs": "test_claims",
    "claims.catalogue": "here", "claims.comparable_clearance_m": "here",
    "controller.backend": "test_kinematic", "planner.normalize_step": "test_kinematic",
    "scenario.obstacle_anchor": "here",
    "controller.frame": "test_path_frame", "controller.path_lookahead_m": "test_path_frame",
    "controller.path_curvature_max_1_per_m": "test_path_frame",
    "controller.path_reference": "test_path_frame",
    "controller.path_curvature_clip": "test_path_frame",
    "controller.path_state_reference": "test_path_frame",
    "controller.horizon_reach_m": "test_path_frame", "planner.velocity_rule": "test_path_frame",
    "planner.velocity_planning": "test_planner",
    "claims.interval_adjustment": "test_outcome_interval",
    "tune.convergence_tolerance": "test_tune_convergence",
    "tune.convergence_window": "test_tune_convergence",
    "tune.hypervolume_bounds": "test_tune_convergence", "tune.replicates": "test_tune",
    "tune.settled_test": "test_tune_convergence", "tune.censoring": "test_tune_convergence",
    "controller.collision_constraints": "test_apf_alone",
    # among recorded pedestrians (choices we add): tests/analysis/test_crowd.py
    "vehicle": "test_crowd", "controller": "test_crowd", "controller.max_obstacles": "test_crowd",
    "scenario.pedestrians.end_at_contact": "test_crowd", "scenario.pedestrians.draw": "test_crowd",
    "scenario.pedestrians.walkable_radius_m": "test_crowd",
    "scenario.pedestrians.walkers": "test_crowd", "scenario.pedestrians.social_*": "test_crowd",
    "scenario.pedestrians.track_extension_s": "test_pedestrians",
    "controller.solver_refinement": "test_kinematic",
    # on CommonRoad's roads (choices we add): tests/loop/test_cover.py, test_commonroad.py
    "scenario.commonroad.obstacle_disc": "test_commonroad",
    "scenario.commonroad.cover_discs": "test_commonroad", "vehicle.footprint_discs": "test_cover",
    "vehicle.footprint_span_m": "test_cover", "scenario.commonroad.n_steps": "test_commonroad",
    "vehicle.kinematic_below_mps": "test_handover",
    "scenario.commonroad.sensor_range_m": "test_commonroad",
    "scenario.commonroad.occlusion": "test_commonroad",
    "scenario.commonroad.route_lookahead_m": "test_commonroad",
    "scenario.commonroad.route_lookahead_s": "test_route_attraction",
    "scenario.commonroad.lanelet_gap_m": "test_commonroad",
    "controller.road_edge_weight": "test_road",
    "controller.steering_friction_share": "test_steering_friction",
    "vehicle.brake_max_mps2": "test_brake_limit",
    "controller.speed_bounds_mps": "test_kinematic",
    **{f"scenario.source.params.{key}": "test_euro_ncap" for key in (
        "cases", "ego_speeds_kmh", "speed_tolerance_kmh", "child_speed_kmh",
        "adult_far_speed_kmh", "cyclist_speed_kmh", "near_start_m", "lead_time_s",
        "parked_lateral_gap_m", "occlusion", "lane_width_m", "oncoming_lane",
        "end_at_contact")},


}


def test_every_register_key_has_a_switch_test():
    # "(none: ...)": a reading that changes no computation (e.g. which figure is which)
    keys = {k.strip() for entry in INTERPRETATION_REGISTER for k in entry.config_key.split(",")
            if not k.strip().startswith("(")}
    assert keys <= set(SWITCH_TESTS), sorted(keys - set(SWITCH_TESTS))


def snap(points, velocities=None, radius=0.5):
    p = np.asarray(points, float).reshape(-1, 2)
    v = np.zeros_like(p) if velocities is None else np.asarray(velocities, float).reshape(-1, 2)
    return ObstacleSnapshot(p, v, np.full(len(p), radius), np.ones(len(p), bool))


def test_b2_entry_flips_the_disturbance_column(make_config):
    minus = make_config()
    plus = make_config(["model.b2_heading_entry=1.0"])
    ed = {}
    for cfg in (minus, plus):
        mpc = LateralMpc(cfg.controller, cfg.vehicle, cfg.model, 0.1)
        ed[cfg.model.b2_heading_entry] = mpc.models.at_speed(3.0).Ed[2, 0]
    assert ed[-1.0] == pytest.approx(-0.1) and ed[1.0] == pytest.approx(0.1)


def test_k_rep_constant_replaces_the_adaptive_gain(make_config):
    adaptive = make_config(["planner=improved"]).planner
    constant = dataclasses.replace(adaptive, k_rep_source="constant", k_rep_constant=25.0)
    p, o = np.array([10.0, 0.0]), np.array([[12.0, 1.0]])
    h = adaptive_coefficient(p, o, adaptive.h_max, adaptive.beta, adaptive.rho_p_m)[0]
    f_a = np.linalg.norm(repulsive_force(p, GOAL, o, adaptive))
    f_c = np.linalg.norm(repulsive_force(p, GOAL, o, constant))
    assert f_c / f_a == pytest.approx(25.0 / h)


def test_step_size_alpha_e_beta_and_floor_enter_the_apf(make_config):
    base = make_config(["planner=baseline"]).planner
    p, o = np.array([10.0, 0.0]), np.array([[12.0, 1.0]])
    for step in (0.1, 0.3):
        nxt = apf_step(p, GOAL, o, dataclasses.replace(base, step_size=step))[0]
        assert np.linalg.norm(nxt - p) == pytest.approx(step)
    improved = make_config(["planner=improved"]).planner
    f1 = np.linalg.norm(repulsive_force(p, GOAL, o, improved))
    f2 = np.linalg.norm(repulsive_force(p, GOAL, o, dataclasses.replace(improved, alpha_e=4.0)))
    rho = np.linalg.norm(p - o[0])
    assert f2 / f1 == pytest.approx(np.exp(2.0 * (1.0 - rho / improved.rho0_m)))
    h1 = adaptive_coefficient(p, o, 50.0, 0.25, 6.0)[0]
    h2 = adaptive_coefficient(p, o, 50.0, 1.0, 6.0)[0]
    assert h1 == pytest.approx(50.0 / (1.0 + np.exp(0.25 * 4.0)))
    assert h2 == pytest.approx(50.0 / (1.0 + np.exp(4.0)))
    on_top = np.array([[10.0, 0.01]])
    small = np.linalg.norm(repulsive_force(p, GOAL, on_top, dataclasses.replace(improved,
                                                                                rho_floor_m=0.5)))
    large = np.linalg.norm(repulsive_force(p, GOAL, on_top, dataclasses.replace(improved,
                                                                                rho_floor_m=0.05)))
    assert small < large


def test_step_cap_and_minimum_step(make_config):
    improved = make_config(["planner=improved"]).planner
    p = np.array([0.0, 0.0])
    capped = apf_step(p, GOAL, np.zeros((0, 2)), improved)
    uncapped = apf_step(p, GOAL, np.zeros((0, 2)), dataclasses.replace(improved,
                                                                       step_max_m=None))
    assert np.linalg.norm(capped[0] - p) == pytest.approx(0.5) and capped[3]
    assert np.linalg.norm(uncapped[0] - p) == pytest.approx(0.2 * 30.0)
    near_goal = np.array([29.9, 0.0])
    lengthened = apf_step(near_goal, GOAL, np.zeros((0, 2)), improved)
    plain = apf_step(near_goal, GOAL, np.zeros((0, 2)), dataclasses.replace(improved,
                                                                          step_min_m=0.0))
    assert np.linalg.norm(lengthened[0] - near_goal) == pytest.approx(0.05) and lengthened[4]
    assert np.linalg.norm(plain[0] - near_goal) == pytest.approx(0.02)


def test_obstacle_prediction_and_closing_speed(make_config):
    params = make_config(["planner=improved"]).planner
    moving = snap([[12.0, 2.0]], [[0.0, -3.0]])
    held = apf_rollout(np.array([10.0, 0.0]), GOAL, moving, params, 10, 0.1)
    predicted = apf_rollout(np.array([10.0, 0.0]), GOAL, moving,
                            dataclasses.replace(params, obstacle_prediction="constant_velocity"),
                            10, 0.1)
    assert not np.allclose(held.path_m, predicted.path_m)
    p, o = np.array([10.0, 0.0]), np.array([[12.0, 1.0]])
    plain = repulsive_force(p, GOAL, o, params, np.array([2.0]))
    scaled = repulsive_force(p, GOAL, o, dataclasses.replace(params,
                                                             closing_speed_gain_s_per_m=0.5),
                             np.array([2.0]))
    np.testing.assert_allclose(scaled, plain * 2.0)


def observation(cfg, rollout):
    frame = LineFrame(np.zeros(2), 0.0)
    state = np.array([10.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.0])
    return Observation(3.0, state, frame, np.array([10.0, 0.0]), 0.0, rollout, snap([[14.0,
                                                                                      0.5]]), 3.0)


def test_heading_reference_from_the_apf_force(make_config):
    slope = make_config(["planner=improved", "controller.frame=fixed"])
    force = make_config(["planner=improved", "controller.heading_reference=apf_force",
                         "controller.frame=fixed"])
    rollout = apf_rollout(np.array([10.0, 0.0]), GOAL, snap([[14.0, 0.5]]), slope.planner, 10,
                          0.1)
    psi_slope = LateralMpc(slope.controller, slope.vehicle).inputs_from(
        observation(slope, rollout))[0].psi_ref_rad
    psi_force = LateralMpc(force.controller, force.vehicle).inputs_from(
        observation(force, rollout))[0].psi_ref_rad
    total = rollout.attraction[0] + rollout.repulsion[0]
    np.testing.assert_allclose(psi_force, force_heading_reference(total, 0.0, 10, 0.1,
                                                                  force.controller))
    assert not np.allclose(psi_slope, psi_force)


def test_heading_reference_from_the_apf_force_in_the_path_frame(make_config):
    """In the path frame the reading's heading ramp is the path's heading: knot k's heading
    (line frame, course 0 here) is the fixed frame's psi_ref at step k (the curvature limit
    lifted, so nothing clips the ramp), and the path differs from the rollout's chase."""
    lifted = ["planner=improved", "controller.path_curvature_max_1_per_m=5.0"]
    slope = make_config(lifted)
    force = make_config(lifted + ["controller.heading_reference=apf_force"])
    rollout = apf_rollout(np.array([10.0, 0.0]), GOAL, snap([[14.0, 0.5]]), slope.planner, 10,
                          0.1)
    chase = LateralMpc(slope.controller, slope.vehicle)
    ramp = LateralMpc(force.controller, force.vehicle)
    chase.inputs_from(observation(slope, rollout))
    ramp.inputs_from(observation(force, rollout))
    path = ramp.frame.record[1]
    total = rollout.attraction[0] + rollout.repulsion[0]
    np.testing.assert_allclose(path.headings_rad[1:11], force_heading_reference(
        total, 0.0, 10, 0.1, force.controller), atol=1e-12)
    assert not np.allclose(chase.frame.record[1].headings_rad[1:11], path.headings_rad[1:11])


def test_path_beyond_end_hold_keeps_the_last_lateral_position(make_config):
    extend = make_config().controller
    hold = make_config(["controller.path_beyond_end=hold"]).controller
    path = np.array([[0.0, 0.0], [1.0, 0.1], [2.0, 0.3]])
    stations = np.array([1.5, 3.0, 4.0])
    y_e, psi_e = lateral_reference(path, stations, extend)
    y_h, psi_h = lateral_reference(path, stations, hold)
    assert y_h[1:].tolist() == [0.3, 0.3] and psi_h[1:].tolist() == [0.0, 0.0]
    assert y_e[1:] == pytest.approx([0.5, 0.7]) and psi_e[2] == pytest.approx(np.arctan(0.2))


def test_input_hold_zero_rate_zeroes_the_inputs_after_nc(make_config):
    assert blocking_matrix(5, 2, "zero_rate")[:, 2:].sum() == 0
    assert blocking_matrix(5, 2, "hold_last")[1, 2:].tolist() == [1.0, 1.0, 1.0]
    cfg = make_config(["controller.input_hold=zero_rate"])
    from builders import make_inputs

    model = build_lateral_model(cfg.vehicle, 3.0, 0.1)
    step = LateralMpc(cfg.controller, cfg.vehicle).solve(
        make_inputs(model, cfg.controller, np.zeros(5), np.full(10, 0.5), np.zeros(10)))
    assert np.all(step.planned[0, 3:] == 0.0) and abs(step.planned[0, 0]) > 1e-3


def test_radial_halfplanes_have_the_tangent_plane_closed_form(make_config):
    cfg = make_config(["controller.halfplane_normal=radial"])
    stations, y_ref = np.array([3.0]), np.array([1.0])
    obstacle = np.array([[[3.0, -1.0]]])  # directly below the reference point, 2 m away
    G, h = collision_halfplanes(stations, y_ref, np.zeros(2), obstacle, np.array([0.5]),
                                cfg.vehicle, cfg.controller)
    reach = 0.5 + cfg.vehicle.footprint_radius_m + cfg.controller.safety_margin_m
    # normal (0, 1): y - (-1) >= R
    assert G[0, 0] == pytest.approx(1.0) and h[0, 0] == pytest.approx(reach - 1.0)
    side = make_config()
    obstacle = np.array([[[3.5, -1.0]]])
    G_r, h_r = collision_halfplanes(stations, y_ref, np.zeros(2), obstacle, np.array([0.5]),
                                    cfg.vehicle, cfg.controller)
    G_s, h_s = collision_halfplanes(stations, y_ref, np.zeros(2), obstacle, np.array([0.5]),
                                    side.vehicle, side.controller)
    n = np.array([-0.5, 2.0]) / np.hypot(0.5, 2.0)
    assert G_r[0, 0] == pytest.approx(n[1]) and G_s[0, 0] == 1.0
    assert h_r[0, 0] == pytest.approx(reach - n[0] * (3.0 - 3.5) + n[1] * -1.0)
    assert h_s[0, 0] == pytest.approx(-1.0 + np.sqrt(reach**2 - 0.25))


def test_reference_alignment_shifts_the_kinematic_reference(make_config):
    refs = {}
    for alignment in ("literal", "shifted"):
        cfg = make_config(["controller=kinematic", f"controller.reference_alignment={alignment}"])
        mpc = KinematicLtvMpc(cfg.controller, cfg.vehicle, 0.1)
        rollout = apf_rollout(np.zeros(2), GOAL, snap(np.zeros((0, 2))), cfg.planner, 10, 0.1)
        state = np.array([0.0, 0.0, 0.0, 1.0])
        obs = Observation(0.0, state, LineFrame(np.zeros(2), 0.0), np.zeros(2), 0.0, rollout,
                          snap(np.zeros((0, 2))), np.nan)
        refs[alignment] = (mpc.step(obs).log["y_ref_m"], rollout.path_m)
    path = refs["literal"][1]
    np.testing.assert_allclose([refs["literal"][0], refs["shifted"][0]], [path[0, 1],
                                                                        path[1, 1]])


def test_plant_substeps_and_run_length(make_config, tmp_path):
    cfg = make_config()
    state = np.array([0.0, 0.0, 0.0, 3.0, 0.3, 0.5, 0.2])
    assert not np.allclose(step_plant(state, 1.0, 3.0, cfg.vehicle, 0.1, 1),
                           step_plant(state, 1.0, 3.0, cfg.vehicle, 0.1, 10), atol=1e-6)
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate

    short = make_config(["scenario.n_steps=20"])
    assert len(simulate(short, build_scenario(short.scenario)).trajectory) == 21


def test_threat_margin_and_horizon_decide_what_threatens():
    from builders import synthetic

    from pipeline.analysis.metrics.signals import TrajectoryContext
    from pipeline.config import MetricsConfig

    t = np.round(np.arange(0.0, 8.0 + 1e-9, 0.1), 10)
    # an obstacle 2.3 m beside the path (reach 2.0 with the default margin) appearing at 3 s
    frame = synthetic(t, 3.0 * t, np.zeros(t.size), delta=np.maximum(t - 3.2, 0.0),
                      obstacle=(16.0, 2.3, 0.5), appear=3.0)
    ctx = TrajectoryContext((0.0, 0.0), (30.0, 0.0), 1.0)
    assert metrics_json(frame, ctx, MetricsConfig())["threatened"] is False
    assert metrics_json(frame, ctx, MetricsConfig(threat_margin_m=1.0))["threatened"]
    # 7 m ahead at 3 m/s, passed at 1.8 m (no contact): a threat before the run ends (the
    # default) and within 3 s, not within a 1 s horizon
    ahead = synthetic(t, 3.0 * t, np.zeros(t.size), obstacle=(16.0, 1.8, 0.5), appear=3.0)
    assert metrics_json(ahead, ctx, MetricsConfig())["threatened"]
    assert metrics_json(ahead, ctx, MetricsConfig(threat_horizon_s=3.0))["threatened"]
    assert not metrics_json(ahead, ctx, MetricsConfig(threat_horizon_s=1.0))["threatened"]


def test_an_obstacle_that_collides_threatened_even_beyond_the_horizon():
    """A threat later than the look-ahead that then collides: never "nothing threatened" with
    a collision; the reaction clock starts at its appearance."""
    from builders import synthetic

    from pipeline.analysis.metrics.signals import TrajectoryContext
    from pipeline.config import MetricsConfig

    t = np.round(np.arange(0.0, 8.0 + 1e-9, 0.1), 10)
    frame = synthetic(t, 3.0 * t, np.zeros(t.size), delta=np.maximum(t - 3.5, 0.0),
                      obstacle=(16.0, 0.5, 0.5), appear=3.0)
    ctx = TrajectoryContext((0.0, 0.0), (30.0, 0.0), 1.0)
    m = metrics_json(frame, ctx, MetricsConfig(threat_horizon_s=1.0))
    assert m["collision"] and m["threatened"]
    assert m["threat_appear_time_s"] == pytest.approx(3.0)
    assert m["reaction_delay_s"] == pytest.approx(0.5 + 0.01, abs=1e-6)


def test_smoothness_window_selects_the_primary_jerk():
    from builders import out_and_back

    from pipeline.analysis.metrics.signals import TrajectoryContext
    from pipeline.config import MetricsConfig

    frame = out_and_back(0.4)
    ctx = TrajectoryContext((0.0, 0.0), (30.0, 0.0), 1.0)
    window = metrics_json(frame, ctx, MetricsConfig())
    run = metrics_json(frame, ctx, MetricsConfig(smoothness_window="whole_run"))
    assert window["lateral_jerk_rms_mps3"] == window["lateral_jerk_rms_window_mps3"]
    assert run["lateral_jerk_rms_mps3"] == run["lateral_jerk_rms_run_mps3"]
    assert window["lateral_jerk_rms_mps3"] != run["lateral_jerk_rms_mps3"]


def test_attribution_samples_decide_between_a_narrow_gap_and_none():
    """An obstacle half a lane ahead: with two steering samples (hard left, hard right) the
    swerve clears it, so the count of samples is what the check depends on; with the default
    nine it is avoidable too, and an obstacle appearing on the vehicle never is."""
    from builders import synthetic

    from pipeline.analysis.metrics.signals import TrajectoryContext
    from pipeline.config import MetricsConfig

    t = np.round(np.arange(0.0, 8.0 + 1e-9, 0.1), 10)
    ctx = TrajectoryContext((0.0, 0.0), (30.0, 0.0), 1.0)
    frame = synthetic(t, 3.0 * t, np.zeros(t.size), obstacle=(17.0, 0.0, 0.5), appear=3.0)
    assert metrics_json(frame, ctx, MetricsConfig(attribution_steering_samples=2))[
        "collision_avoidable"] is True
    # a straight-only set (both samples at zero steering is impossible: the range is symmetric)
    # -> with a steering limit of zero nothing can swerve: unavoidable
    stiff = TrajectoryContext((0.0, 0.0), (30.0, 0.0), 1.0, steering_max_rad=1e-6,
                              braking_mps2=1e-6)
    assert metrics_json(frame, stiff, MetricsConfig())["collision_avoidable"] is False


def test_estimator_test_and_margins_change_the_outcome():
    from pipeline.analysis.claims.catalogue import CLAIMS
    from pipeline.analysis.claims.statistics import compare, decide
    from pipeline.config import ClaimsConfig

    rng = np.random.default_rng(0)
    d = np.concatenate([np.full(30, -0.2), rng.exponential(1.0, 20)])  # skewed
    n = d.size
    improved = pd.DataFrame({"scenario": range(n), "reaction_delay_s": 1.0 + d,
                             "collision": False})
    baseline = pd.DataFrame({"scenario": range(n), "reaction_delay_s": 1.0, "collision": False})
    hl = compare(improved, baseline, CLAIMS[0], ClaimsConfig(n_resamples=199))
    med = compare(improved, baseline, CLAIMS[0], ClaimsConfig(n_resamples=199,
                                                              estimator="median"))
    assert med.estimate == pytest.approx(np.median(d)) and hl.estimate != med.estimate
    sign = compare(improved, baseline, CLAIMS[0], ClaimsConfig(n_resamples=199, test="sign"))
    assert sign.p_value != hl.p_value
    row = compare(improved, baseline, CLAIMS[0], ClaimsConfig(n_resamples=199))
    args = (row.ci_low, row.ci_high, None, row.n_pairs,
            ClaimsConfig(n_resamples=199), row.pi_low, row.pi_high)
    wide = decide(args[0], args[1], 10.0, *args[3:])[0]
    narrow = decide(args[0], args[1], 1e-3, *args[3:])[0]
    assert wide == "equivalent" and narrow != "equivalent"


def test_comparable_clearance_marks_the_kinematic_comparison():
    from pipeline.config import ClaimsConfig
    from pipeline.reporting.inputs import TrackRuns
    from pipeline.reporting.verdicts import track_claims

    class Run:
        def __init__(self, method: str, clearance: float) -> None:
            self.method = method
            self._metrics = {"method": method, "scenario": "s", "track": "kinematic",
                             "min_clearance_m": clearance, "reaction_delay_s": 0.5,
                             "collision": False}

        def metrics(self) -> dict:
            return self._metrics

    runs = TrackRuns("s", {m: Run(m, c) for m, c in (("baseline", 4.5), ("improved", 0.5))},
                     (), ())
    strict = track_claims(runs, ClaimsConfig(), comparable_only=True)
    loose = track_claims(runs, ClaimsConfig(comparable_clearance_m=5.0), comparable_only=True)
    assert strict.rows[1]["vs baseline"] == "not comparable"
    assert strict.comparability[0].startswith("vs baseline: not comparable (baseline")
    assert loose.rows[1]["vs baseline"] == "within margin"
    # C0 is a rate: judged even where the methods never met the obstacle
    assert strict.rows[0]["vs baseline"] != "not comparable"


def test_obstacle_anchor_places_the_obstacle_relative_to_the_vehicle(make_config):
    """Under obstacle_anchor=vehicle an obstacle appears shifted by the vehicle's offset from
    its nominal place (start + speed * appear time along the line) at that instant; before it
    appears and under "world" it is where the config puts it."""
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate

    overrides = ["controller=kinematic", "scenario.initial_speed_mps=0.0", "scenario.n_steps=40",
                 "planner=baseline"]
    world = make_config(overrides)
    anchored = make_config(overrides + ["scenario.obstacle_anchor=vehicle"])
    assert world.config_hash() != anchored.config_hash()
    t_world = simulate(world, build_scenario(world.scenario)).trajectory
    t_anch = simulate(anchored, build_scenario(anchored.scenario)).trajectory
    obstacle = world.scenario.obstacles[0]
    k = int(round(obstacle.appear_time_s / world.scenario.sample_time_s))
    # where the vehicle is at the appearance step, against where 3 m/s would have put it
    vehicle = t_anch[["X_m", "Y_m"]].to_numpy()[k]
    nominal = np.array([world.scenario.speed_mps * obstacle.appear_time_s, 0.0])
    assert vehicle[0] < nominal[0] - 2.0  # started at rest: well behind its nominal place
    expected = np.array([obstacle.x_m, obstacle.y_m]) + vehicle - nominal
    got = t_anch[["obs0_x_m", "obs0_y_m"]].to_numpy()
    np.testing.assert_allclose(got[k], expected, atol=1e-9)
    # it then moves at its own velocity from there
    np.testing.assert_allclose(got[k + 5], expected + 0.5 * np.array(
        [obstacle.vx_mps, obstacle.vy_mps]), atol=1e-9)
    np.testing.assert_allclose(t_world[["obs0_x_m", "obs0_y_m"]].to_numpy()[k],
                               [obstacle.x_m, obstacle.y_m], atol=1e-9)
    np.testing.assert_allclose(got[k - 1], [obstacle.x_m, obstacle.y_m], atol=1e-9)
