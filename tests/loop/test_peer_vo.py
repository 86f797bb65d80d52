"""Velocity obstacles (pipeline.peers.velocity_obstacles): a planted cone computed by hand, many
random planted cases against an independent geometric check (closest approach over the time
horizon), the goal direction when nothing is near, bad params, and whole runs on both tracks."""

from __future__ import annotations

from math import asin

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.loop.scenario import ObstacleSnapshot, build_scenario
from pipeline.loop.simulate import simulate
from pipeline.peers.velocity_obstacles import (
    VelocityObstaclePlanner,
    VoSettings,
    choose_velocity,
    time_to_collision_s,
)


def snapshot(positions, velocities, radii) -> ObstacleSnapshot:
    positions = np.asarray(positions, float).reshape(-1, 2)
    return ObstacleSnapshot(positions, np.asarray(velocities, float).reshape(-1, 2),
                            np.asarray(radii, float), np.ones(positions.shape[0], bool))


def closest_approach_hits(d: np.ndarray, w: np.ndarray, radius: float, tau: float) -> bool:
    """Independent check: does the vehicle, moving at ``w`` relative to the obstacle at ``d``,
    come within ``radius`` of it for some ``t`` in ``[0, tau]``?"""
    ww = float(w @ w)
    t = 0.0 if ww == 0.0 else min(max(float(w @ d) / ww, 0.0), tau)
    return float(np.linalg.norm(d - t * w)) <= radius


def is_free(velocity: np.ndarray, position: np.ndarray, centres: np.ndarray,
            velocities: np.ndarray, combined: np.ndarray, tau: float) -> bool:
    """Whether ``velocity`` misses every enlarged disc within ``tau`` (independent check)."""
    return not any(closest_approach_hits(c - position, velocity - u, r, tau)
                   for c, u, r in zip(centres, velocities, combined, strict=True))


def is_reachable(heading: float, vehicle_velocity: np.ndarray | None, reach: float) -> bool:
    """Whether ``heading`` is within ``reach`` of the vehicle's velocity heading."""
    if vehicle_velocity is None:
        return True
    current = np.arctan2(vehicle_velocity[1], vehicle_velocity[0])
    return abs(np.angle(np.exp(1j * (heading - current)))) <= reach + 1e-9


def test_planted_static_obstacle_cone_by_hand():
    """Obstacle 5 m ahead, radius 0.5: combined radius 0.5 + 1.0 + 0.3 = 1.8 m, so the cone's
    half-angle is asin(1.8 / 5) = 0.3683 rad. Headings are 0.05 rad apart: 0.35 lies inside,
    0.40 is the admissible heading nearest the goal direction; the tie between +-0.40 goes to
    the side of the vehicle's current velocity."""
    settings = VoSettings()
    half_angle = asin(1.8 / 5.0)
    assert 0.35 < half_angle < 0.40
    obstacles = snapshot([[5.0, 0.0]], [[0.0, 0.0]], [0.5])
    for sign in (1.0, -1.0):
        velocity, admissible, candidates, inside = choose_velocity(
            np.zeros(2), np.array([20.0, 0.0]), obstacles, settings, 3.0,
            np.array([3.0, sign * 0.1]))
        heading = np.arctan2(velocity[1], velocity[0])
        assert admissible and heading == pytest.approx(sign * 0.40, abs=1e-12)
        assert np.linalg.norm(velocity) == pytest.approx(3.0)
        angles = np.arctan2(candidates[:, 1], candidates[:, 0])
        # inside the cone exactly where |angle| <= asin(R / d) (3 m/s reaches it within tau)
        np.testing.assert_array_equal(inside, np.abs(angles) <= half_angle)


def test_planted_head_on_obstacle_cone_in_relative_velocity():
    """An oncoming obstacle (1 m/s towards the vehicle) 10 m ahead: the relative velocity is
    ``v + (1, 0)``; at 3 m/s the vehicle meets it within tau = 3 s only when that ray points
    into the disc (angle of ``v + (1, 0)`` within asin(1.8 / 10) of the x axis)."""
    settings = VoSettings()
    obstacles = snapshot([[10.0, 0.0]], [[-1.0, 0.0]], [0.5])
    velocity, admissible, candidates, inside = choose_velocity(
        np.zeros(2), np.array([30.0, 0.0]), obstacles, settings, 3.0)
    relative = candidates + np.array([1.0, 0.0])
    angle = np.abs(np.arctan2(relative[:, 1], relative[:, 0]))
    # ... and reaches the disc's near edge in time: first contact t_1 <= 3 s
    ttc = time_to_collision_s(np.array([[10.0, 0.0]]), relative[:, None, :], np.array([1.8]))[:, 0]
    np.testing.assert_array_equal(inside, (angle <= asin(1.8 / 10.0)) & (ttc <= 3.0))
    assert inside.any() and admissible and not inside[
        np.flatnonzero((candidates == velocity).all(axis=1))[0]]


def test_random_planted_cases_never_pick_a_velocity_inside_a_cone():
    """Many random obstacles (1-3, moving, all outside their enlarged discs) and vehicle
    velocities: whenever the independent check finds an admissible candidate, the chosen
    velocity is admissible by that check, reachable if any admissible one is (within
    ``reachable_turn_rad`` of the vehicle's velocity), and no such candidate is nearer the goal
    direction; when it finds none, the planner says so."""
    rng = np.random.default_rng(12345)
    settings = VoSettings()
    tau, reach = settings.time_horizon_s, settings.reachable_turn_rad
    count, half = settings.heading_count, settings.fan_half_angle_rad
    tallies = {"reachable": 0, "unreachable": 0, "fallback": 0}
    for case in range(800):
        position = rng.uniform(-5, 5, 2)
        a = rng.uniform(-np.pi, np.pi)
        goal = position + rng.uniform(5, 30) * np.array([np.cos(a), np.sin(a)])
        n = int(rng.integers(1, 4))
        radii = rng.uniform(0.3, 1.5, n)
        combined = radii + settings.vehicle_radius_m + settings.margin_m
        distance = combined + rng.uniform(0.1, 10.0, n)
        bearing = rng.uniform(-np.pi, np.pi, n)
        unit = np.column_stack([np.cos(bearing), np.sin(bearing)])
        centres = position + distance[:, None] * unit
        velocities = rng.uniform(-2, 2, (n, 2))
        speed = float(rng.uniform(1.0, 4.0))
        vehicle_velocity = rng.uniform(-3, 3, 2) if case % 4 else None
        velocity, admissible, _, _ = choose_velocity(
            position, goal, snapshot(centres, velocities, radii), settings, speed,
            vehicle_velocity)
        obstacles = (position, centres, velocities, combined, tau)

        def free(v: np.ndarray, obstacles=obstacles) -> bool:
            return is_free(v, *obstacles)

        def reachable(heading: float, vehicle=vehicle_velocity) -> bool:
            return is_reachable(heading, vehicle, reach)

        # the candidates, built independently of the planner
        goal_heading = np.arctan2(*(goal - position)[::-1])
        headings = goal_heading + np.linspace(-half, half, count)
        offsets = headings - goal_heading
        ok = np.array([free(speed * np.array([np.cos(h), np.sin(h)])) for h in headings])
        near = np.array([reachable(h) for h in headings])
        chosen = np.arctan2(velocity[1], velocity[0])
        chosen_offset = abs(np.angle(np.exp(1j * (chosen - goal_heading))))
        if ok.any():
            assert admissible and free(velocity)
            if (ok & near).any():
                assert reachable(chosen)
                assert chosen_offset <= np.abs(offsets[ok & near]).min() + 1e-9
                tallies["reachable"] += 1
            else:
                assert chosen_offset <= np.abs(offsets[ok]).min() + 1e-9
                tallies["unreachable"] += 1
        else:
            assert not admissible
            tallies["fallback"] += 1
    assert tallies["reachable"] > 300 and min(tallies.values()) > 0, tallies  # every branch


def test_reachable_velocities_choose_the_side_the_vehicle_can_turn_to():
    """Obstacle 4 m ahead, the goal direction 0.04 rad left of it: the cone's half-angle is
    asin(1.8 / 4) = 0.467 rad, so the admissible headings nearest the goal direction are 0.49
    (left, 0.45 off it) and -0.51 (right, 0.55 off). The plain fan sends the vehicle left; a
    vehicle heading -0.3 rad reaches -0.51 (0.21 rad away), not 0.49 (0.79 rad): the
    reachable set sends it right."""
    obstacles = snapshot([[4.0, 0.0]], [[0.0, 0.0]], [0.5])
    heading = -0.3
    vehicle = 3.0 * np.array([np.cos(heading), np.sin(heading)])
    goal = np.array([20.0, 20.0 * np.tan(0.04)])  # goal direction 0.04 rad left of the obstacle
    plain = VoSettings(reachable_turn_rad=None)
    v_plain, ok_plain, _, _ = choose_velocity(np.zeros(2), goal, obstacles, plain, 3.0, vehicle)
    v_reach, ok_reach, _, _ = choose_velocity(np.zeros(2), goal, obstacles, VoSettings(), 3.0,
                                              vehicle)
    assert ok_plain and ok_reach
    assert np.arctan2(v_plain[1], v_plain[0]) > 0.4      # left: nearest the goal direction
    assert np.arctan2(v_reach[1], v_reach[0]) < -0.4     # right: the side it can turn to


def test_inside_an_enlarged_disc_only_velocities_moving_away_are_admissible():
    ttc = time_to_collision_s(np.array([[1.0, 0.0]]),
                              np.array([[[1.0, 0.0]], [[-1.0, 0.0]], [[0.0, 1.0]]]),
                              np.array([1.8]))[:, 0]
    assert ttc[0] == 0.0 and ttc[1] == np.inf and ttc[2] == np.inf


def test_goal_direction_when_nothing_is_near(make_config):
    cfg = make_config(["method=vo"])
    planner = VelocityObstaclePlanner(cfg.planner, 10, 0.1)
    goal = np.array([12.0, 9.0])
    far = snapshot([[-20.0, 0.0], [40.0, -40.0]], [[0.0, 0.0], [0.0, 0.5]], [0.5, 0.5])
    empty = snapshot(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0))
    # a vehicle heading 0.4 rad off the goal direction (within reach), or at rest
    for obstacles, vehicle in ((far, 3.0 * np.array([np.cos(1.0), np.sin(1.0)])),
                               (empty, None), (far, np.zeros(2))):
        rollout = planner.rollout(np.zeros(2), goal, obstacles, vehicle)
        assert rollout.path_m.shape == (10, 2)
        np.testing.assert_allclose(rollout.path_m[0], 0.0)
        # straight towards the goal, 0.3 m (3 m/s x 0.1 s) per point
        np.testing.assert_allclose(rollout.path_m[1], 0.3 * goal / np.linalg.norm(goal),
                                   atol=1e-12)
        np.testing.assert_allclose(np.diff(rollout.path_m, axis=0),
                                   np.repeat(rollout.path_m[1:2], 9, axis=0), atol=1e-12)


@pytest.mark.parametrize("key, value, allowed", [
    ("heading_count", 0, "an integer in [1, 1001]"),
    ("time_horizon_s", -1.0, "a number in (0.0, 600.0]"),
    ("fan_half_angle_rad", 4.0, "a number in [0.0, 3.14"),
    ("speed_mps", "fast", "a number in [0.1, 40.0]"),
    ("reachable_turn_rad", 0.0, "a number in (0.0, 3.14"),
    ("tau_s", 3.0, "a key of the velocity-obstacle planner"),
])
def test_bad_param_is_a_one_line_error_naming_the_key(make_config, key, value, allowed):
    cfg = make_config(["method=vo", f"+planner.params.{key}={value}"] if key == "tau_s"
                      else ["method=vo", f"planner.params.{key}={value}"])
    with pytest.raises(ValueError) as info:
        VelocityObstaclePlanner(cfg.planner, 10, 0.1)
    message = str(info.value)
    assert isinstance(info.value, ConfigError) and "\n" not in message
    assert f"planner.params.{key}=" in message and allowed in message


def test_configs_compose_on_both_tracks(make_config):
    lateral = make_config(["method=vo"])
    assert lateral.controller.kind == "mpc" and lateral.run.method == "vo"
    assert lateral.planner._target_ == "pipeline.peers.velocity_obstacles.VelocityObstaclePlanner"
    kinematic = make_config(["experiment=kinematic", "method=vo_kinematic"])
    assert kinematic.controller.kind == "kinematic_mpc" and kinematic.run.method == "vo"
    assert kinematic.scenario.initial_speed_mps == 0.0 and kinematic.scenario.n_steps == 100
    assert kinematic.planner._target_ == lateral.planner._target_


def _min_clearance_m(result, scenario, footprint_m: float) -> float:
    tr = result.trajectory
    gaps = []
    for j in range(scenario.n_obstacles):
        seen = tr[f"obs{j}_visible"].astype(bool)
        gap = np.hypot(tr.X_m - tr[f"obs{j}_x_m"], tr.Y_m - tr[f"obs{j}_y_m"]) \
            - tr[f"obs{j}_radius_m"] - footprint_m
        gaps.append(gap[seen].min() if seen.any() else np.inf)
    return float(min(gaps))


def test_full_lateral_run_with_vo_completes_without_collision(make_config):
    cfg = make_config(["method=vo"])
    scenario = build_scenario(cfg.scenario)
    result = simulate(cfg, scenario)
    assert result.termination == "goal_line"
    assert _min_clearance_m(result, scenario, cfg.vehicle.footprint_radius_m) > 0.0
    # the reference swung out: the vehicle left the line to pass the obstacle
    assert result.trajectory.Y_m.abs().max() > 0.5


def test_kinematic_track_run_with_vo_completes_without_collision(make_config):
    cfg = make_config(["experiment=kinematic", "method=vo_kinematic"])
    scenario = build_scenario(cfg.scenario)
    result = simulate(cfg, scenario)
    # 100 steps from rest: it runs them all (at 3 m/s the goal line is 10.5 s away)
    assert result.termination in ("goal_line", "max_steps")
    assert np.isfinite(result.trajectory[["X_m", "Y_m"]].to_numpy()).all()
    assert _min_clearance_m(result, scenario, cfg.vehicle.footprint_radius_m) > 0.0
