"""The dynamic window approach (pipeline.peers.dwa) on the Appendix-A track: the window, the time
to the goal on an empty course against the closed form for its speed limit, a wall it must stop
short of, and bad params."""

from __future__ import annotations

from math import tan

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.loop.scenario import build_scenario
from pipeline.loop.simulate import simulate
from pipeline.peers.dwa import (
    DwaSettings,
    DynamicWindow,
    arc_points,
    distance_to_collision_m,
    dynamic_window,
)

KINEMATIC = ["experiment=kinematic", "method=dwa_kinematic"]


def test_config_composes_on_the_kinematic_track(make_config):
    cfg = make_config(KINEMATIC)
    assert cfg.controller.kind == "kinematic_mpc" and cfg.run.method == "dwa"
    assert cfg.controller._target_ == "pipeline.peers.dwa.DynamicWindow"
    assert cfg.planner.name == "straight_to_goal"
    assert cfg.scenario.initial_speed_mps == 0.0 and cfg.scenario.n_steps == 100


def test_window_is_one_sample_of_the_bounds_and_the_steerable_yaw_rates(make_config):
    cfg = make_config(KINEMATIC)
    L, delta_max = cfg.vehicle.wheelbase_m, cfg.vehicle.steering_max_rad
    speeds, yaw_rates = dynamic_window(2.0, DwaSettings(), (-3.0, 3.0), tan(delta_max) / L, 0.1)
    assert speeds.max() == pytest.approx(2.3) and speeds.min() == pytest.approx(1.7)
    assert np.all(np.abs(yaw_rates) <= speeds * tan(delta_max) / L + 1e-12)
    assert np.any(yaw_rates == 0.0) and speeds.size == 7 * 21
    # at rest: no reversing; at the speed limit: no faster
    speeds, _ = dynamic_window(0.0, DwaSettings(), (-3.0, 3.0), 0.1, 0.1)
    assert speeds.min() == 0.0 and speeds.max() == pytest.approx(0.3)
    speeds, _ = dynamic_window(3.0, DwaSettings(), (-3.0, 3.0), 0.1, 0.1)
    assert speeds.max() == pytest.approx(3.0) and speeds.min() == pytest.approx(2.7)


def test_arcs_are_exact_and_dist_stops_at_the_last_free_sample():
    times = 0.1 * np.arange(1, 31)
    points, headings = arc_points(np.array([0.0, 0.0, 0.0]), np.array([2.0, 2.0]),
                                  np.array([0.0, 0.5]), times)
    np.testing.assert_allclose(points[0, :, 0], 2.0 * times)
    radius = 2.0 / 0.5  # circle of radius v / omega, centre (0, 4)
    np.testing.assert_allclose(np.hypot(points[1, :, 0], points[1, :, 1] - radius), radius)
    np.testing.assert_allclose(headings[1], 0.5 * times)
    # an obstacle 5 m ahead, combined radius 1 m: the straight arc is in contact from x > 4 m,
    # i.e. from t = 2.1 s (4.2 m); the last free sample is t = 2.0 s, 4.0 m along it
    dist = distance_to_collision_m(points, np.array([2.0, 2.0]), times, np.array([[5.0, 0.0]]),
                                   np.zeros((1, 2)), np.array([1.0]), False)
    assert dist[0] == pytest.approx(4.0) and dist[1] == np.inf


def _run(make_config, overrides):
    cfg = make_config(KINEMATIC + overrides)
    scenario = build_scenario(cfg.scenario)
    return cfg, scenario, simulate(cfg, scenario)


def test_empty_course_reaches_the_goal_in_the_closed_form_time(make_config):
    """From rest with a = 3 m/s^2 to v = 3 m/s, then at 3 m/s: the run ends at the goal line,
    goal_tolerance_m = 0.5 short of the goal 30 m away, d = 29.5 m, crossed at
    t = v / a + (d - v^2 / (2 a)) / v = 1 + 28 / 3 = 10.33 s: the first sample after it is
    10.4 s."""
    cfg, _, result = _run(make_config, ["scenario.obstacles=[]",
                                        "scenario.allow_no_obstacles=true",
                                        "scenario.n_steps=130"])
    v, a = cfg.controller.params["max_speed_mps"], cfg.controller.accel_bounds_mps2[1]
    start, goal = np.asarray(cfg.scenario.start_xy_m), np.asarray(cfg.scenario.goal_xy_m)
    d = float(np.hypot(*(goal - start))) - cfg.scenario.goal_tolerance_m
    expected = v / a + (d - v**2 / (2 * a)) / v
    assert expected == pytest.approx(1.0 + 28.0 / 3.0)
    tr = result.trajectory
    end = float(tr.time_s.iloc[-1])
    assert result.termination == "goal_line"
    assert expected - 1e-9 <= end <= expected + cfg.scenario.sample_time_s + 1e-9
    assert tr.Y_m.abs().max() < 1e-9 and tr.vx_mps.max() <= v + 1e-9
    np.testing.assert_allclose(tr.accel_mps2.iloc[:10], 3.0)  # full acceleration from rest


def test_stops_short_of_a_wall_and_never_enters_it(make_config):
    """A row of static obstacles across the way at x = 15 m (radius 0.5 m, 1 m apart, y from
    -20 to 20 m: no gap the vehicle fits through): the vehicle never comes within an
    obstacle's radius plus its footprint, stays short of the row, and stops."""
    wall_x, radius = 15.0, 0.5
    row = ",".join(f"{{x_m:{wall_x},y_m:{y:.1f},radius_m:{radius}}}" for y in range(-20, 21))
    cfg, scenario, result = _run(make_config, [f"scenario.obstacles=[{row}]",
                                               "scenario.n_steps=120",
                                               "controller.max_obstacles=41"])  # unused by DWA
    tr = result.trajectory
    footprint = cfg.vehicle.footprint_radius_m
    for j in range(scenario.n_obstacles):
        gap = np.hypot(tr.X_m - tr[f"obs{j}_x_m"], tr.Y_m - tr[f"obs{j}_y_m"]) \
            - tr[f"obs{j}_radius_m"] - footprint
        assert gap.min() > 0.0, f"entered obstacle {j}"
        # and it kept (nearly all of) its 0.2 m margin: the one-sample hold is accounted for
        assert gap.min() > 0.15, f"came {gap.min():.3f} m from obstacle {j}"
    assert tr.X_m.max() < wall_x - radius - footprint
    assert tr.X_m.max() > 10.0            # it drove up to the wall, not stopped far away
    assert tr.vx_mps.iloc[-1] < 0.05      # and stands in front of it at the end


@pytest.mark.parametrize("key, value, allowed", [
    ("speed_samples", 0, "an integer in [1, 201]"),
    ("prediction_time_s", -1.0, "a number in (0.0, 60.0]"),
    ("alpha_heading", "high", "a number in [0.0, 1000000.0]"),
    ("max_speed_mps", 0.0, "a number in (0.0, 40.0]"),
])
def test_bad_param_is_a_one_line_error_naming_the_key(make_config, key, value, allowed):
    cfg = make_config(KINEMATIC + [f"controller.params.{key}={value}"])
    with pytest.raises(ValueError) as info:
        DynamicWindow(cfg.controller, cfg.vehicle, 0.1)
    message = str(info.value)
    assert isinstance(info.value, ConfigError) and "\n" not in message
    assert f"controller.params.{key}=" in message and allowed in message


def test_unknown_param_is_refused(make_config):
    cfg = make_config(KINEMATIC + ["+controller.params.horizon_s=2.0"])
    with pytest.raises(ConfigError, match=r"controller\.params\.horizon_s=2\.0 is invalid"):
        DynamicWindow(cfg.controller, cfg.vehicle, 0.1)
