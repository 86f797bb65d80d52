"""The lateral track brakes to a stop (issue 59, item 1; issue 60, item 3): below
``vehicle.kinematic_below_mps`` the plant and the lateral MPC's model are the kinematic
single-track. The plant against the closed form of a steady turn, compiled against CPython bit
for bit; the kinematic model's matrices and its equilibrium; the speed floor's refusal; and a car
that stops short of a wall it cannot pass, where without the hand-over it could not slow below
its model's floor and drove through."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.loop.controller.path import steady_state_gains
from pipeline.loop.model import build_lateral_model, single_track_constants, single_track_rk4


@pytest.fixture(scope="module")
def car(make_config):
    return make_config([]).vehicle


def _run(state, vehicle, target_mps, steps, rate=0.0, compiled=False):
    constants = single_track_constants(vehicle)
    if compiled:
        from pipeline.loop.compiled import single_track_rk4 as kernel
        state, constants = np.asarray(state, float), np.asarray(constants)
    else:
        kernel = single_track_rk4
    for _ in range(steps):
        state = kernel(state if compiled else list(state), constants, rate, target_mps, 0.1, 10)
    return np.asarray(state, float)


def test_below_the_hand_over_the_plant_turns_as_the_kinematic_single_track(car):
    """Speed held at 0.8 m/s, steering held at 0.2 rad: the centre of gravity turns at
    ``v tan(delta) / L`` with side slip ``beta = atan(b tan(delta) / L)`` on a circle of radius
    ``L / (cos(beta) tan(delta))`` (closed form), and vy, r are the kinematic ones."""
    vehicle = replace(car, kinematic_below_mps=1.5)
    v, delta, L, b = 0.8, 0.2, car.wheelbase_m, car.cg_to_rear_m
    beta = math.atan(b * math.tan(delta) / L)
    start = [0.0, 0.0, 0.0, v, v * math.tan(beta), v * math.tan(delta) / L, delta]
    end = _run(start, vehicle, v, 30)
    omega, radius = v * math.tan(delta) / L, L / (math.cos(beta) * math.tan(delta))
    T = 3.0
    assert end[2] == pytest.approx(omega * T, abs=1e-12)
    assert end[0] == pytest.approx(radius * (math.sin(omega * T + beta) - math.sin(beta)),
                                   abs=1e-9)
    assert end[1] == pytest.approx(radius * (math.cos(beta) - math.cos(omega * T + beta)),
                                   abs=1e-9)
    assert end[3] == pytest.approx(v, abs=1e-15)
    assert end[4] == pytest.approx(v * b * math.tan(delta) / L, abs=1e-15)
    assert end[5] == pytest.approx(omega, abs=1e-15)


def test_braking_to_a_stop_leaves_no_yaw_and_the_compiled_plant_agrees(car):
    """From 2 m/s with 0.2 rad of steering to a speed target of 0: with the hand-over the car
    stops with vy = r = 0 (the kinematic single-track); without it the tyre law leaves a yaw
    rate at standstill (it creeps round). Compiled and CPython give the same bits."""
    start = [0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.2]
    kinematic = replace(car, kinematic_below_mps=1.5)
    stopped = _run(start, kinematic, 0.0, 100)
    assert np.isfinite(stopped).all() and 0.0 <= stopped[3] < 1e-3
    assert abs(stopped[4]) < 1e-6 and abs(stopped[5]) < 1e-6
    dynamic = _run(start, car, 0.0, 100)
    assert dynamic[3] < 1e-3 and abs(dynamic[5]) > 1e-3   # a yaw rate with the car stopped
    compiled = _run(start, kinematic, 0.0, 100, compiled=True)
    assert compiled.tolist() == stopped.tolist()
    # above the hand-over speed nothing changes, to the bit
    fast = [0.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.1]
    assert _run(fast, kinematic, 3.0, 20, rate=0.3).tolist() == \
        _run(fast, car, 3.0, 20, rate=0.3).tolist()


def test_below_the_hand_over_the_mpc_predicts_with_the_kinematic_model(car):
    """The model at 1.2 m/s (below a 1.5 m/s hand-over) is the kinematic single-track:
    ``vy = b v delta / L`` and ``r = v delta / L`` driven by the steering rate, no 1/v term; its
    equilibrium on a curve (``delta = L r / v``, ``vy = b r``) is a fixed point of
    ``Ad x + Ed r_d``. At 2 m/s the dynamic model is unchanged."""
    vehicle = replace(car, kinematic_below_mps=1.5)
    model = build_lateral_model(vehicle, 1.2, 0.1)
    L, b = car.wheelbase_m, car.cg_to_rear_m
    assert model.kinematic
    assert model.B1[:, 0].tolist() == pytest.approx([0.0, b * 1.2 / L, 0.0, 1.2 / L, 1.0])
    assert model.A[0].tolist() == [0.0, 1.0, 1.2, 0.0, 0.0] and not model.A[1].any()
    gains = steady_state_gains(model)
    assert gains.tolist() == pytest.approx([0.0, b, -b / 1.2, 1.0, L / 1.2])
    x = gains * 0.3
    assert (model.Ad @ x + model.Ed[:, 0] * 0.3) == pytest.approx(x, abs=1e-12)
    fast, before = build_lateral_model(vehicle, 2.0, 0.1), build_lateral_model(car, 2.0, 0.1)
    assert not fast.kinematic and np.array_equal(fast.Ad, before.Ad)
    assert "model" not in before.to_json() and model.to_json()["model"].startswith("kinematic")


def test_a_speed_floor_below_the_model_needs_the_hand_over(make_config):
    with pytest.raises(ConfigError, match="vehicle.kinematic_below_mps"):
        make_config(["planner.speed_floor_mps=0.0"])
    assert make_config(["planner.speed_floor_mps=0.0",
                        "vehicle.kinematic_below_mps=1.5"]).planner.speed_floor_mps == 0.0
    with pytest.raises(ConfigError, match="vehicle.kinematic_below_mps"):
        make_config(["vehicle.kinematic_below_mps=0.5"])   # below min_model_speed_mps (1.0)


def test_the_lateral_track_stops_short_of_a_wall_it_cannot_pass(make_config):
    """Ten discs across the road at x = 14 (no way round): with velocity planning to a floor of
    0 and the hand-over at 1.5 m/s the car stops about 1 m short and never touches; with the
    model's floor of 1 m/s it cannot slow enough and drives through."""
    from pipeline.analysis.metrics.geometry import clearance_series
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate

    disc = "{{x_m: 14.0, y_m: {}, vx_mps: 0.0, vy_mps: 0.0, radius_m: 0.5, appear_time_s: 0.0}}"
    wall = "[" + ",".join(disc.format(y) for y in np.arange(-4.5, 4.6, 1.0)) + "]"
    base = ["method=improved", f"scenario.obstacles={wall}", "controller.max_obstacles=10",
            "planner.velocity_planning=true", "planner.velocity_rule=stopping_distance",
            "planner.stop_margin_m=2.0", "scenario.n_steps=150"]
    gaps = {}
    for name, extra in (("floor", ["planner.speed_floor_mps=1.0"]),
                        ("stop", ["planner.speed_floor_mps=0.0",
                                  "vehicle.kinematic_below_mps=1.5"])):
        cfg = make_config(base + extra)
        trajectory = simulate(cfg, build_scenario(cfg.scenario)).trajectory
        gaps[name] = float(np.nanmin(clearance_series(trajectory, 1.0)))
        if name == "stop":
            assert trajectory["vx_mps"].iloc[-1] < 1e-2
            assert np.isfinite(trajectory[["X_m", "Y_m", "psi_rad"]].to_numpy()).all()
    assert gaps["stop"] > 0.5 and gaps["floor"] < 0.0
