"""APF planner: step rules, repulsion laws, safeguards, finite differences of the potential."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pipeline.loop.planner import (
    adaptive_coefficient,
    apf_rollout,
    apf_step,
    plan_speed,
    repulsive_force,
)
from pipeline.loop.scenario import ObstacleSnapshot

GOAL = np.array([30.0, 0.0])


def snapshot(points, radius=0.5, velocities=None):
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    vel = np.zeros_like(pts) if velocities is None else np.asarray(velocities, float).reshape(-1, 2)
    return ObstacleSnapshot(pts, vel, np.full(len(pts), radius), np.ones(len(pts), bool))


@pytest.fixture()
def planners(make_config):
    return {name: make_config([f"planner={name}"]).planner for name in ("baseline", "improved")}


@pytest.mark.parametrize("position", [[0.0, 0.0], [12.0, -0.8], [13.6, 1.2], [29.0, 0.3]])
def test_baseline_step_length_is_exactly_alpha(planners, position):
    p = np.array(position)
    nxt, *_ = apf_step(p, GOAL, np.array([[14.0, 1.5]]), planners["baseline"])
    assert np.linalg.norm(nxt - p) == pytest.approx(planners["baseline"].step_size, abs=1e-12)


def test_improved_step_is_alpha_times_force_when_no_safeguard_acts(planners):
    params = planners["improved"]
    p = np.array([29.0, 0.5])  # near the goal: |alpha F| = 0.2 * 1.12 m is between min and cap
    nxt, att, rep, cap, low = apf_step(p, GOAL, np.zeros((0, 2)), params)
    np.testing.assert_allclose(nxt - p, params.step_size * (att + rep))
    assert not cap and not low


def test_step_cap_is_what_keeps_the_improved_rollout_bounded(planners):
    capped = planners["improved"]
    literal = dataclasses.replace(capped, step_max_m=None)
    obstacles = snapshot([[6.3, 0.05]])  # out of range at p0, right where the first step lands
    p0 = np.array([0.0, 0.0])
    bounded = apf_rollout(p0, GOAL, obstacles, capped, 10, 0.1)
    wild = apf_rollout(p0, GOAL, obstacles, literal, 10, 0.1)
    steps_bounded = np.linalg.norm(np.diff(bounded.path_m, axis=0), axis=1)
    steps_wild = np.linalg.norm(np.diff(wild.path_m, axis=0), axis=1)
    assert steps_bounded.max() <= capped.step_max_m + 1e-12
    assert bounded.step_cap_active.any()
    # without the cap the first step is alpha * |g - p| = 6 m, metres per step
    assert steps_wild[0] == pytest.approx(capped.step_size * 30.0, rel=1e-3)
    assert steps_wild.max() > 10 * capped.step_max_m


def test_minimum_movement_threshold_pushes_small_steps(planners):
    params = planners["improved"]
    p = GOAL - np.array([0.1, 0.0])  # |alpha F| = 0.02 m < step_min 0.05 m
    nxt, _, _, cap, low = apf_step(p, GOAL, np.zeros((0, 2)), params)
    assert low and not cap
    assert np.linalg.norm(nxt - p) == pytest.approx(params.step_min_m)
    off = dataclasses.replace(params, step_min_m=0.0)
    nxt_off, *_ = apf_step(p, GOAL, np.zeros((0, 2)), off)
    assert np.linalg.norm(nxt_off - p) == pytest.approx(0.02)


@pytest.mark.parametrize("law", ["baseline", "improved"])
def test_repulsion_zero_beyond_rho0_and_monotone_as_distance_shrinks(planners, law):
    params = planners[law]
    obstacle = np.array([[14.0, 0.0]])
    # move straight away from the obstacle laterally, so s - s_o = 0 and H_i is constant
    distances = np.linspace(0.1, params.rho0_m * 1.5, 200)
    magnitudes = np.array([np.linalg.norm(repulsive_force(np.array([14.0, d]), GOAL, obstacle,
                                                          params)) for d in distances])
    assert np.all(magnitudes[distances >= params.rho0_m] == 0.0)
    inside = magnitudes[distances < params.rho0_m]
    assert np.all(np.diff(inside) < 0.0)
    # points away from the obstacle
    force = repulsive_force(np.array([14.0, 1.0]), GOAL, obstacle, params)
    assert force[1] > 0 and abs(force[0]) < 1e-12


@pytest.mark.parametrize("law", ["baseline", "improved"])
def test_repulsion_finite_with_obstacle_at_vehicle_position(planners, law):
    params = planners[law]
    p = np.array([14.0, 1.5])
    force = repulsive_force(p, GOAL, p[None, :], params)
    assert np.all(np.isfinite(force)) and np.linalg.norm(force) > 0
    rollout = apf_rollout(p, GOAL, snapshot([p]), params, 10, 0.1)
    assert np.all(np.isfinite(rollout.path_m))


def test_polynomial_repulsion_is_minus_gradient_of_its_potential(planners):
    """With beta = 0 the coefficient is constant, H = H_max/2, and the baseline repulsion is
    -grad U with U = H/2 (1/rho - 1/rho0)^2 (Khatib's potential); checked by central differences."""
    params = dataclasses.replace(planners["baseline"], beta=0.0)
    obstacle = np.array([[14.0, 1.5]])
    H = params.h_max / 2.0

    def potential(p):
        rho = np.linalg.norm(p - obstacle[0])
        return 0.5 * H * (1 / rho - 1 / params.rho0_m) ** 2 if rho < params.rho0_m else 0.0

    for p in (np.array([13.0, 0.2]), np.array([15.1, 2.9]), np.array([12.5, 1.4])):
        eps = 1e-6
        grad = np.array([(potential(p + e) - potential(p - e)) / (2 * eps)
                         for e in (np.array([eps, 0]), np.array([0, eps]))])
        np.testing.assert_allclose(repulsive_force(p, GOAL, obstacle, params), -grad, rtol=1e-6)


def test_adaptive_coefficient_closed_form():
    obstacles = np.array([[14.0, 1.5], [40.0, 0.0]])
    h = adaptive_coefficient(np.array([13.0, 0.0]), obstacles, 50.0, 0.25, 6.0)
    assert h[0] == pytest.approx(50.0 / (1.0 + np.exp(0.25)))
    assert h[1] == 0.0  # beyond rho_p


def test_velocity_planning_slows_for_obstacle_ahead_and_respects_floor(make_config):
    cfg = make_config(["planner.velocity_planning=true"])
    ctrl, radius = cfg.planner, cfg.vehicle.footprint_radius_m
    far = plan_speed(np.zeros(2), 0.0, snapshot([[30.0, 0.0]]), 3.0, radius, ctrl)
    assert far == 3.0
    gap_obstacle = 0.5 + radius + cfg.planner.stop_margin_m + 1.0  # free gap beyond the margin: 1 m
    near = plan_speed(np.zeros(2), 0.0, snapshot([[gap_obstacle, 0.0]]), 3.0, radius, ctrl)
    assert near == pytest.approx(np.sqrt(2 * cfg.planner.braking_decel_mps2 * 1.0))
    touching = plan_speed(np.zeros(2), 0.0, snapshot([[1.6, 0.0]]), 3.0, radius, ctrl)
    assert touching == cfg.planner.speed_floor_mps
    off = make_config().planner
    assert plan_speed(np.zeros(2), 0.0, snapshot([[1.6, 0.0]]), 3.0, radius, off) == 3.0
