"""The lateral MPC in path coordinates (controller.frame=path) against oracles: the fixed frame
on a straight reference (the rollout itself as the path, and a straight path handed in), the
rollout resampled and time-indexed by hand, the model's equilibrium on a circle, closed forms of
the projection and of pure pursuit, the nonlinear plant for the prediction check, a second
solver's optimum; and every register switch of the frame, flipped so that the test fails when it
is ignored."""

from __future__ import annotations

import dataclasses
from math import cos, sin

import numpy as np
import pytest

from pipeline.loop.controller import LateralMpc, Observation
from pipeline.loop.controller.path import (
    ReferencePath,
    chase_path_arrays,
    rollout_path_arrays,
    steady_state_gains,
)
from pipeline.loop.controller.prediction_check import PredictionRecord, prediction_check
from pipeline.loop.model import build_lateral_model, step_plant
from pipeline.loop.planner import ApfRollout, apf_rollout, plan_speed
from pipeline.loop.scenario import LineFrame, ObstacleSnapshot

GOAL = np.array([30.0, 0.0])


def snap(points, velocities=None, radius=0.5):
    p = np.asarray(points, float).reshape(-1, 2)
    v = np.zeros_like(p) if velocities is None else np.asarray(velocities, float).reshape(-1, 2)
    return ObstacleSnapshot(p, v, np.full(len(p), radius), np.ones(len(p), bool))


def straight_rollout(start, n=10, step=0.5):
    """An APF rollout along the x axis from ``start`` (no forces)."""
    path = np.array([[start[0] + step * i, start[1]] for i in range(n)])
    zeros = np.zeros((n - 1, 2))
    return ApfRollout(path, zeros, zeros, np.zeros(n - 1, bool), np.zeros(n - 1, bool))


def observation(state, rollout, obstacles, speed_ref=3.0):
    frame = LineFrame(np.zeros(2), 0.0)
    return Observation(0.0, np.asarray(state, float), frame, frame.to_line(state[:2]),
                       float(state[2]), rollout, obstacles, speed_ref)


# --- the path's geometry ------------------------------------------------------------------------

def circle_path(radius, ds, n, start_heading=0.0):
    """A left-turning circle of ``radius`` through the origin as a ReferencePath (exact knots)."""
    kappa = 1.0 / radius
    s = ds * np.arange(n + 1)
    headings = start_heading + kappa * s
    centre = np.array([-radius * sin(start_heading), radius * cos(start_heading)])
    points = centre[None, :] + radius * np.column_stack([np.sin(headings), -np.cos(headings)])
    return ReferencePath(points, headings, np.full(n, kappa), np.zeros(n, bool), ds)


def test_projection_on_a_line_is_the_rotation():
    path = ReferencePath.straight(np.array([2.0, 1.0]), 0.3, 0.25, 12)
    rng = np.random.default_rng(0)
    points = rng.uniform(-5, 8, (50, 2))
    s, d = path.project(points)
    rel = points - np.array([2.0, 1.0])
    u = np.array([cos(0.3), sin(0.3)])
    np.testing.assert_allclose(s, rel @ u, atol=1e-12)
    np.testing.assert_allclose(d, rel @ np.array([-u[1], u[0]]), atol=1e-12)
    # and back
    np.testing.assert_allclose(path.to_global(s, d), points, atol=1e-12)


def test_projection_on_a_circle_is_arc_length_and_radial_offset():
    """On a circle of radius 6 m sampled every 0.3 m: s = R phi and d = R - |p - c| (left of
    the path is towards the centre), to the chord's sagitta (ds^2 / 8R = 1.9 mm)."""
    radius, ds = 6.0, 0.3
    path = circle_path(radius, ds, 20)
    centre = np.array([0.0, radius])
    phi = np.linspace(0.05, 0.95, 9)
    for offset in (-0.8, 0.0, 0.6):
        r = radius - offset
        points = centre + r * np.column_stack([np.sin(phi), -np.cos(phi)])
        s, d = path.project(points)
        np.testing.assert_allclose(s, radius * phi, atol=0.05)
        np.testing.assert_allclose(d, offset, atol=ds ** 2 / (8 * radius) + 1e-9)
    np.testing.assert_allclose(path.heading_at(radius * phi), phi, atol=1e-12)


def test_chase_is_pure_pursuit_and_clips_at_the_curvature_limit():
    """The first arc's curvature is pure pursuit's 2 sin(alpha) / |g - c| towards the point
    the look-ahead away along the rollout; past the limit it is clipped and flagged (without
    the clip: flagged, the pursuit's own curvature kept); a straight rollout ahead gives a
    straight path."""
    rollout = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]])
    lookahead = 2.0
    goal = np.array([lookahead / np.sqrt(2), lookahead / np.sqrt(2)])
    alpha = np.arctan2(goal[1], goal[0])
    pursuit = 2 * np.sin(alpha) / lookahead
    args = (0.0, 0.0, 0.0, rollout.tolist(), 1.0, 0.0, True, lookahead)
    points, headings, curvature, beyond = chase_path_arrays(*args, 5.0, 0.1, 4, True)
    assert curvature[0] == pytest.approx(pursuit, rel=1e-12)
    assert not beyond[0]
    _, _, limited, beyond = chase_path_arrays(*args, 0.1, 0.1, 4, True)
    assert limited[0] == 0.1 and beyond[0]
    _, _, unclipped, beyond = chase_path_arrays(*args, 0.1, 0.1, 4, False)
    assert unclipped[0] == pytest.approx(pursuit, rel=1e-12) and beyond[0]
    straight = chase_path_arrays(0.0, 0.0, 0.0, [[0.0, 0.0], [1.0, 0.0]], 0.0, 1.0, True,
                                 2.5, 0.2, 0.3, 6, True)
    assert np.all(straight[2] == 0.0) and np.allclose(straight[0][:, 1], 0.0)
    np.testing.assert_allclose(straight[0][:, 0], 0.3 * np.arange(7), atol=1e-12)


def test_rollout_path_is_the_rollout_resampled_and_never_clipped():
    """A rollout of 1 m along x, then 1 m at 60 degrees to the left: the knots every 0.25 m
    lie on it (by hand), the interior knots' headings bisect their chords, each arc's
    curvature is the heading's change over it (the corner's arcs far beyond a 0.2 1/m limit:
    flagged, kept as asked), and beyond the end the path goes on along the last segment."""
    turn = np.pi / 3
    corner = np.array([1.0, 0.0])
    u = np.array([np.cos(turn), np.sin(turn)])
    rollout = [[0.0, 0.0], [0.5, 0.0], corner.tolist(), (corner + 0.5 * u).tolist(),
               (corner + u).tolist()]
    points, headings, curvature, beyond = rollout_path_arrays(rollout, 1.0, 0.0, True, 0.2,
                                                              0.25, 12)
    s = 0.25 * np.arange(13)
    expected = np.where(s[:, None] <= 1.0, np.column_stack([s, np.zeros(13)]),
                        corner[None, :] + (s[:, None] - 1.0) * u[None, :])
    np.testing.assert_allclose(points, expected, atol=1e-12)
    # chords: 0 up to the corner (knot 4), turn after it
    np.testing.assert_allclose(headings[:4], 0.0, atol=1e-12)
    assert headings[4] == pytest.approx(turn / 2, abs=1e-12)   # the corner's knot bisects
    np.testing.assert_allclose(headings[5:], turn, atol=1e-12)
    np.testing.assert_allclose(curvature, np.diff(headings) / 0.25, atol=1e-12)
    assert curvature[3] == pytest.approx(turn / 2 / 0.25) and curvature[4] == curvature[3]
    np.testing.assert_array_equal(beyond, np.abs(curvature) > 0.2)
    assert beyond.sum() == 2 and curvature.max() > 10 * 0.2   # never clipped


def test_rollout_path_ends_where_the_rollout_folds_back():
    """A normalized-step rollout dithering about the goal (x = 30: 29.7, 30.2, 29.7 ...) ends
    at its first fold; the path goes on along its last advancing segment (extend) or along the
    start-goal line (hold)."""
    rollout = [[28.2, 0.0], [28.7, 0.0], [29.2, 0.0], [29.7, 0.0], [30.2, 0.0], [29.7, 0.0],
               [30.2, 0.0]]
    points, headings, _, beyond = rollout_path_arrays(rollout, 1.0, 0.0, True, 0.2, 0.3, 12)
    np.testing.assert_allclose(points[:, 0], 28.2 + 0.3 * np.arange(13), atol=1e-12)
    assert np.all(headings == 0.0) and not beyond.any()
    bent = [[0.0, 0.0], [0.0, 0.5], [0.0, 1.0], [0.0, 0.5]]   # heading up, then back down
    points, _, _, _ = rollout_path_arrays(bent, 1.0, 0.0, False, 0.2, 0.5, 4)
    np.testing.assert_allclose(points, [[0, 0], [0, 0.5], [0, 1.0], [0.5, 1.0], [1.0, 1.0]],
                               atol=1e-12)


@pytest.mark.parametrize("backend", ["clarabel_direct", "daqp"])
def test_the_rollout_as_reference_is_the_fixed_frame_on_a_straight_rollout(make_config,
                                                                           backend):
    """The default reference (the rollout itself) on a straight rollout from the vehicle,
    parallel to the start-goal line: the path frame's QP (built from the observation as a
    run builds it) is the fixed frame's, shifted by the rollout's offset, and both reach the
    same moves to 1e-9, an obstacle's half-planes included."""
    path_cfg = make_config([f"controller.backend={backend}"])
    assert path_cfg.controller.path_reference == "rollout"
    fixed_cfg = make_config([f"controller.backend={backend}", "controller.frame=fixed"])
    state = np.array([10.0, 0.4, 0.08, 3.0, 0.0, 0.0, 0.01])
    rollout = straight_rollout([10.0, 0.4])
    obstacles = snap([[13.0, 1.4]], [[0.0, -0.3]])
    obs = observation(state, rollout, obstacles)
    fixed = LateralMpc(fixed_cfg.controller, fixed_cfg.vehicle)
    fixed_inputs, _ = fixed.inputs_from(obs)
    mpc = LateralMpc(path_cfg.controller, path_cfg.vehicle)
    path_inputs, _ = mpc.inputs_from(obs)
    assert not np.count_nonzero(path_inputs.disturbance_rad_s)
    np.testing.assert_allclose(path_inputs.x0 + [0.4, 0, 0, 0, 0], fixed_inputs.x0, atol=1e-12)
    np.testing.assert_allclose(fixed_inputs.y_ref_m, 0.4, atol=1e-12)
    np.testing.assert_allclose(path_inputs.constraint_gain, fixed_inputs.constraint_gain,
                               atol=1e-12)
    np.testing.assert_allclose(path_inputs.constraint_bound
                               + 0.4 * path_inputs.constraint_gain,
                               fixed_inputs.constraint_bound, atol=1e-12)
    a, b = mpc.solve(path_inputs), fixed.solve(fixed_inputs)
    assert np.count_nonzero(fixed_inputs.constraint_gain)  # the half-planes are there
    np.testing.assert_allclose(a.planned_rates_rad_s, b.planned_rates_rad_s, atol=1e-9)


def test_the_rollout_is_read_at_the_time_the_vehicle_reaches_it(make_config):
    """Step k of the MPC is measured against the rollout's point at the arc length the vehicle
    covers in k steps (3 m/s, 0.1 s: 0.3 k m): on a rollout with a corner 1.3 m ahead, the
    frame's point at each station is that point of the polyline, computed by hand; the
    vehicle's heading error is its heading against the rollout's first chord."""
    cfg = make_config()
    turn = 0.4
    u = np.array([np.cos(turn), np.sin(turn)])
    corner = np.array([11.3, 0.0])
    rollout = straight_rollout([10.0, 0.0])
    rollout = dataclasses.replace(rollout, path_m=np.vstack(
        [[10.0, 0.0], [10.65, 0.0], corner, corner + 0.8 * u, corner + 1.6 * u,
         corner + 2.4 * u]))
    state = np.array([10.0, 0.0, 0.05, 3.0, 0.0, 0.0, 0.0])
    mpc, inputs, _ = path_step(cfg, state, rollout, snap(np.zeros((0, 2))))
    _, path, stations, dt = mpc.frame.record
    assert dt == pytest.approx(0.1)
    # v k dt up to the corner, then plus the speed a turn gains (vy r, the yaw rate at most the
    # vehicle's limit: 0.17 1/m x 3 m/s): a few cm over the second
    np.testing.assert_allclose(stations[:3], 0.3 * np.arange(3), atol=1e-12)
    gained = stations - 0.3 * np.arange(11)
    assert np.all(gained >= -1e-12) and gained.max() < 0.06
    by_hand = np.array([[10.0 + s, 0.0] if s <= 1.3 else corner + (s - 1.3) * u
                        for s in stations])
    # the chords cut the corner only on the arc that straddles it (s = 1.2 .. 1.5)
    frame_points = path.to_global(stations, np.zeros(11))
    off_corner = np.abs(stations - 1.35) > 0.2
    np.testing.assert_allclose(frame_points[off_corner], by_hand[off_corner], atol=1e-9)
    assert np.max(np.hypot(*(frame_points - by_hand).T)) < 0.3 * np.sin(turn) / 2 + 1e-9
    assert inputs.x0[0] == pytest.approx(0.0, abs=1e-12)
    assert inputs.x0[2] == pytest.approx(0.05, abs=1e-12)


def test_path_reference_switch_builds_the_pursuit_or_the_rollout(make_config):
    """The same observation, a rollout pointing 0.5 rad left of the vehicle: the rollout path
    starts along it (heading error 0 - 0.5), the pursuit path starts along the vehicle's
    course (heading error 0, no sideslip) and bends towards it."""
    state = np.array([10.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.0])
    rollout = straight_rollout([10.0, 0.0])
    rollout = dataclasses.replace(rollout, path_m=np.array(
        [[10.0, 0.0]]) + 0.5 * np.arange(10)[:, None] * np.array([[np.cos(0.5), np.sin(0.5)]]))
    _, along, log_along = path_step(make_config(), state, rollout, snap(np.zeros((0, 2))))
    _, chase, log_chase = path_step(make_config(["controller.path_reference=pursuit"]), state,
                                    rollout, snap(np.zeros((0, 2))))
    assert along.x0[2] == pytest.approx(-0.5, abs=1e-12)
    np.testing.assert_allclose(along.disturbance_rad_s, 0.0, atol=1e-12)   # straight: no curvature
    assert chase.x0[2] == pytest.approx(0.0, abs=1e-12)
    assert log_chase["path_curvature_1_per_m"] > 0.05 and np.count_nonzero(
        chase.disturbance_rad_s)


# --- the model on the path -----------------------------------------------------------------------

@pytest.mark.parametrize("speed", [1.5, 3.0, 6.0])
def test_a_circle_driven_at_zero_lateral_error_is_an_equilibrium(make_config, speed):
    """x* = g r_d (zero offset, r = r_d, the steering and sideslip that hold it) is a fixed
    point of the discrete model with the curvature fed forward, and the heading error there is
    the sideslip -vy / vx (Rajamani)."""
    cfg = make_config()
    model = build_lateral_model(cfg.vehicle, speed, 0.1)
    gains = steady_state_gains(model)
    r_d = speed * 0.1  # a circle of radius 10 m
    x_star = gains * r_d
    np.testing.assert_allclose(model.Ad @ x_star + model.Ed[:, 0] * r_d, x_star, atol=1e-12)
    assert x_star[0] == 0.0 and x_star[3] == r_d
    assert x_star[2] == pytest.approx(-x_star[1] / speed)
    # the continuous model's rows hold it too: A x* + B2 r_d = 0
    np.testing.assert_allclose(model.A @ x_star + model.B2[:, 0] * r_d, 0.0, atol=1e-12)


def test_on_the_equilibrium_the_qp_plans_no_steering(make_config):
    """With the previewed curvature constant and the vehicle at the equilibrium, zero moves
    cost nothing: the QP's optimum (Clarabel, and DAQP) is U = 0."""
    cfg = make_config()
    model = build_lateral_model(cfg.vehicle, 3.0, 0.1)
    N = cfg.controller.horizon
    r_d = np.full(N, 0.3)
    x_star = steady_state_gains(model) * 0.3
    from pipeline.loop.controller import MpcInputs

    refs = steady_state_gains(model)[:, None] * r_d[None, :]
    inputs = MpcInputs(x_star, model, np.zeros(N), refs[2], np.zeros((N, 3)),
                       np.zeros((N, 3)), r_d, refs[3], refs[4])
    for backend in ("clarabel_direct", "daqp"):
        mpc = LateralMpc(dataclasses.replace(cfg.controller, backend=backend), cfg.vehicle)
        step = mpc.solve(inputs)
        assert step.status == "optimal"
        assert np.max(np.abs(step.planned_rates_rad_s)) < 1e-6, backend


@pytest.mark.parametrize("backend", ["clarabel_direct", "daqp"])
def test_on_a_straight_reference_the_path_frame_is_the_fixed_frame(make_config, backend):
    """A straight path along the start-goal line (kappa = 0, psi_ref = 0), the vehicle off it
    with a heading error and an obstacle near: the path frame's QP data are the fixed frame's
    and both reach the same moves to 1e-9."""
    path_cfg = make_config([f"controller.backend={backend}"])
    fixed_cfg = make_config([f"controller.backend={backend}", "controller.frame=fixed"])
    state = np.array([10.0, 0.4, 0.08, 3.0, 0.05, 0.02, 0.01])
    rollout = straight_rollout([10.0, 0.0])
    obstacles = snap([[13.0, 1.0]], [[0.0, -0.3]])
    obs = observation(state, rollout, obstacles)
    fixed = LateralMpc(fixed_cfg.controller, fixed_cfg.vehicle)
    fixed_inputs, _ = fixed.inputs_from(obs)
    mpc = LateralMpc(path_cfg.controller, path_cfg.vehicle)
    line = ReferencePath.straight(np.array([0.0, 0.0]), 0.0, 0.3, 70)
    path_inputs, _ = mpc.frame.inputs_about(obs, line, 0.1)
    assert not np.count_nonzero(path_inputs.disturbance_rad_s)
    np.testing.assert_allclose(path_inputs.x0, fixed_inputs.x0, atol=1e-12)
    np.testing.assert_allclose(path_inputs.constraint_gain, fixed_inputs.constraint_gain,
                               atol=1e-12)
    np.testing.assert_allclose(path_inputs.constraint_bound, fixed_inputs.constraint_bound,
                               atol=1e-12)
    a, b = mpc.solve(path_inputs), fixed.solve(fixed_inputs)
    assert np.count_nonzero(fixed_inputs.constraint_gain)  # the half-planes are there
    np.testing.assert_allclose(a.planned_rates_rad_s, b.planned_rates_rad_s, atol=1e-9)


def test_the_prediction_check_against_the_nonlinear_plant(make_config):
    """The model replayed with the applied steering against the plant itself: within 2 cm
    1 s ahead for a small manoeuvre on the path, more than 10 cm when the vehicle drives at
    0.5 rad to the path (the along-track loss 1 - cos, second order, absent from the model)."""
    cfg = make_config()
    vehicle, ts = cfg.vehicle, 0.1
    model = build_lateral_model(vehicle, 3.0, ts)

    def run(heading, rate):
        state = np.array([0.0, 0.0, heading, 3.0, 0.0, 0.0, 0.0])
        rows = [state]
        for k in range(10):
            state = step_plant(state, rate if k < 3 else 0.0, 3.0, vehicle, ts, 10)
            rows.append(state)
        rows = np.array(rows)
        plant = rows[:, [0, 1, 2, 6]]
        path = ReferencePath.straight(np.zeros(2), 0.0, 0.3, 12)
        record = PredictionRecord(("path", path, 0.3 * np.arange(11), ts),
                                  np.array([0.0, 0.0, heading, 0.0, 0.0]), model, np.zeros(10),
                                  None)
        return prediction_check([record], ts * np.arange(11), plant, ts)

    small = run(0.0, 0.05)
    large = run(0.5, 0.0)
    assert small["model_error_1s_m"][0] < 0.02
    assert large["model_error_1s_m"][0] > 0.10
    assert large["model_heading_error_rad"][0] == pytest.approx(0.5, abs=1e-9)


def test_the_pursuit_path_keeps_the_model_inside_its_bound_the_rollout_itself_does_not(
        make_config):
    """The improved APF's detour on the paper scenario: the fixed frame's heading error
    leaves 0.35 rad and so does the path frame's about the rollout itself (the rollout turns
    faster than the vehicle can: the APF's demand, why the nonlinear MPC judges); the pursuit
    path, tangent to the vehicle and clipped at its curvature limit, keeps it inside, and its
    1-s prediction is closer than the fixed frame's."""
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate

    out = {}
    for name, overrides in (("fixed", ["controller.frame=fixed"]), ("rollout", []),
                            ("pursuit", ["controller.path_reference=pursuit"])):
        cfg = make_config(["method=improved", *overrides])
        out[name] = simulate(cfg, build_scenario(cfg.scenario)).trajectory
    heading = {k: np.nanmax(v["model_heading_error_rad"]) for k, v in out.items()}
    assert heading["fixed"] > 0.35 and heading["rollout"] > 0.35 > heading["pursuit"]
    assert out["rollout"]["path_beyond_limit"].mean() > 0.1
    assert np.nanpercentile(out["pursuit"]["model_error_1s_m"], 95) \
        < 0.5 * np.nanpercentile(out["fixed"]["model_error_1s_m"], 95)


# --- register switches: flip, and the number moves the way the alternative says -------------

def path_step(cfg, state, rollout, obstacles, speed_ref=3.0):
    mpc = LateralMpc(cfg.controller, cfg.vehicle)
    inputs, log = mpc.inputs_from(observation(state, rollout, obstacles, speed_ref))
    return mpc, inputs, log


def test_frame_switch_changes_what_the_state_is_measured_against(make_config):
    state = np.array([10.0, 1.0, 0.4, 3.0, 0.0, 0.0, 0.0])
    rollout = apf_rollout(state[:2], GOAL, snap([[14.0, 0.5]]), make_config().planner, 10, 0.1)
    _, path_inputs, _ = path_step(make_config(), state, rollout, snap([[14.0, 0.5]]))
    _, fixed_inputs, _ = path_step(make_config(["controller.frame=fixed"]), state, rollout,
                                   snap([[14.0, 0.5]]))
    assert fixed_inputs.x0[0] == pytest.approx(1.0) and fixed_inputs.x0[2] == 0.4
    assert path_inputs.x0[0] == pytest.approx(0.0, abs=1e-12)
    first = rollout.path_m[1] - rollout.path_m[0]
    assert np.hypot(*first) > 0.3   # the path's first chord lies on the rollout's first step
    assert path_inputs.x0[2] == pytest.approx(0.4 - np.arctan2(first[1], first[0]), abs=1e-12)
    assert np.count_nonzero(path_inputs.disturbance_rad_s)
    assert not np.count_nonzero(fixed_inputs.disturbance_rad_s)


def test_lookahead_sets_the_chase_curvature(make_config):
    """An offset rollout: the first arc's curvature is 2 sin(alpha) / |g - c| at each
    look-ahead (so a longer look-ahead bends less)."""
    state = np.array([0.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.0])
    rollout = straight_rollout([0.0, 1.0])
    rollout = dataclasses.replace(rollout, path_m=np.vstack([[0.0, 0.0], rollout.path_m[1:]]))
    kappa = {}
    for lookahead in (2.5, 4.0):
        cfg = make_config(["controller.path_reference=pursuit",
                           f"controller.path_lookahead_m={lookahead}",
                           "controller.path_curvature_max_1_per_m=5.0"])
        mpc, _, log = path_step(cfg, state, rollout, snap(np.zeros((0, 2))))
        kappa[lookahead] = log["path_curvature_1_per_m"]
    assert kappa[2.5] > kappa[4.0] > 0


def test_curvature_limit_clips_the_pursuit_path_and_only_flags_the_rollout(make_config):
    """A rollout straight to the left of a vehicle heading along x. Pursuit: a limit of 0.1
    1/m clips the chase's curvature and flags it, a limit of 5 does not bind, and without the
    clip (path_curvature_clip=false) the chase's own curvature is kept and flagged. The
    rollout itself: its first arc is straight (no curvature to clip), and the flag follows the
    corner's demand, never cut."""
    state = np.array([0.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.0])
    rollout = straight_rollout([0.0, 0.0])
    rollout = dataclasses.replace(rollout, path_m=np.column_stack(
        [np.zeros(10), 0.5 * np.arange(10)]))  # straight to the left
    empty = snap(np.zeros((0, 2)))
    pursuit = "controller.path_reference=pursuit"
    _, _, wide = path_step(make_config([pursuit, "controller.path_curvature_max_1_per_m=5.0"]),
                           state, rollout, empty)
    _, _, tight = path_step(make_config([pursuit, "controller.path_curvature_max_1_per_m=0.1"]),
                            state, rollout, empty)
    _, _, free = path_step(make_config([pursuit, "controller.path_curvature_max_1_per_m=0.1",
                                        "controller.path_curvature_clip=false"]),
                           state, rollout, empty)
    assert tight["path_beyond_limit"] and tight["path_curvature_1_per_m"] == pytest.approx(0.1)
    assert not wide["path_beyond_limit"] and wide["path_curvature_1_per_m"] > 0.1
    assert free["path_beyond_limit"] and free["path_curvature_1_per_m"] == pytest.approx(
        wide["path_curvature_1_per_m"])
    mpc, inputs, own = path_step(make_config(["controller.path_curvature_max_1_per_m=0.1"]),
                                 state, rollout, empty)
    assert own["path_curvature_1_per_m"] == 0.0 and not own["path_beyond_limit"]
    assert inputs.x0[2] == pytest.approx(-np.pi / 2)   # the vehicle at right angles to it


def test_path_state_reference_zero_drops_the_equilibrium(make_config):
    state = np.array([10.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.0])
    rollout = apf_rollout(state[:2], GOAL, snap([[13.0, 0.3]]), make_config().planner, 10, 0.1)
    _, steady, _ = path_step(make_config(), state, rollout, snap([[13.0, 0.3]]))
    _, zero, _ = path_step(make_config(["controller.path_state_reference=zero"]), state,
                           rollout, snap([[13.0, 0.3]]))
    gains = steady_state_gains(steady.model)
    np.testing.assert_allclose(steady.r_ref_rad_s, steady.disturbance_rad_s, atol=1e-15)
    np.testing.assert_allclose(steady.delta_ref_rad, gains[4] * steady.disturbance_rad_s)
    assert np.count_nonzero(steady.delta_ref_rad)
    assert not np.count_nonzero(zero.delta_ref_rad) and not np.count_nonzero(zero.psi_ref_rad)


def test_horizon_reach_stretches_the_prediction_step_at_low_speed(make_config):
    """At 1.5 m/s the horizon of 10 steps covers 3 m only with steps of 0.2 s: the model is
    discretized at 0.2 s (its Ad is c2d's at 0.2 s) and the stations reach 3 m; without the
    reach (null) the step stays 0.1 s and the horizon covers 1.5 m."""
    state = np.array([10.0, 0.0, 0.0, 1.5, 0.0, 0.0, 0.0])
    rollout = straight_rollout([10.0, 0.0])
    mpc, inputs, _ = path_step(make_config(), state, rollout, snap([[13.0, 0.3]]), 1.5)
    assert mpc.frame.record[-1] == pytest.approx(0.2)
    np.testing.assert_allclose(inputs.model.Ad, build_lateral_model(
        make_config().vehicle, 1.5, 0.2).Ad, atol=1e-12)
    assert mpc.frame.record[-2][-1] == pytest.approx(3.0, abs=1e-9)
    plain, _, _ = path_step(make_config(["controller.horizon_reach_m=null"]), state, rollout,
                            snap([[13.0, 0.3]]), 1.5)
    assert plain.frame.record[-1] == 0.1
    assert plain.frame.record[-2][-1] == pytest.approx(1.5, abs=1e-9)


def test_velocity_rule_predicted_clearance_does_not_slow_into_a_crossing_obstacle(make_config):
    """An obstacle 4 m ahead, 1.5 m to the right, crossing at 0.6 m/s towards the side the
    path swerves to (0.3 m left per 0.45 m): the stopping-distance rule slows to the speed that
    stops in the gap, sqrt(2 * 2 * (4 - 0.5 - 1 - 1)) = 2.449 m/s (it sees only the gap); the
    predicted-clearance rule keeps 3 m/s, at which the vehicle is 2.7 m left of the path's start
    when the obstacle has come 0.8 m nearer (at 1 m/s it would meet it). An obstacle parked on
    a straight path 5 m ahead: only the slowest candidate keeps the clearance within 3 s."""
    base = make_config(["planner.velocity_planning=true"]).planner
    stopping = dataclasses.replace(base, velocity_rule="stopping_distance")
    swerve = np.column_stack([10.0 + 0.45 * np.arange(10), 0.3 * np.arange(10)])
    crossing = snap([[14.0, -1.5]], [[0.0, 0.6]])
    args = (np.array([10.0, 0.0]), 0.0, crossing, 3.0, 1.0)
    assert plan_speed(*args, stopping) == pytest.approx(np.sqrt(6.0), rel=1e-12)
    assert plan_speed(*args, base, swerve, 3.0) == 3.0
    straight = np.column_stack([10.0 + 0.5 * np.arange(10), np.zeros(10)])
    parked = snap([[15.0, 0.3]])
    assert plan_speed(np.array([10.0, 0.0]), 0.0, parked, 3.0, 1.0, base, straight, 3.0) == 1.0
    # without velocity planning the rule is not asked
    off = dataclasses.replace(base, velocity_planning=False)
    assert plan_speed(np.array([10.0, 0.0]), 0.0, parked, 3.0, 1.0, off, straight, 3.0) == 3.0
