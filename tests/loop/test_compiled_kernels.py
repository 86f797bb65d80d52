"""The compiled kernels (numba) against the same functions run by CPython, bit for bit: the
single-track plant's RK4 step against ``step_plant`` and the APF rollout against
``apf_rollout`` over every switch of the planner (an overflowing ``exp`` included); the closed
loop with the kernels against the loop without; and the family runner's rule for turning them
on."""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest

from pipeline.loop.compiled import COMPILED_KERNELS, apf_rollout_kernel, single_track_rk4
from pipeline.loop.controller import QpCache, lateral_reference
from pipeline.loop.model import SINGLE_TRACK_CONSTANT_NAMES, single_track_constants, step_plant
from pipeline.loop.planner import ApfPlanner, ApfSettings, apf_kernel_settings, apf_rollout
from pipeline.loop.python_kernels import PYTHON_KERNELS
from pipeline.loop.scenario import ObstacleSnapshot, build_scenario, family_members
from pipeline.loop.simulate import SingleTrackPlant, simulate


@pytest.mark.parametrize("overrides", [[], ["vehicle.brake_max_mps2=8",
                                              "vehicle.kinematic_below_mps=2"]])
def test_compiled_plant_gives_step_plants_bits(make_config, overrides):
    vehicle = make_config(overrides).vehicle
    constants = np.array(single_track_constants(vehicle))
    assert constants.shape == (len(SINGLE_TRACK_CONSTANT_NAMES),)
    rng = np.random.default_rng(7)
    rate_max, d_max = vehicle.steering_rate_max_rad_s, vehicle.steering_max_rad
    cases = 0
    for _ in range(400):
        state = np.array([rng.normal(0, 20), rng.normal(0, 3), rng.normal(0, 0.5),
                          rng.uniform(-1.0, 25.0), rng.normal(0, 0.8), rng.normal(0, 0.5),
                          rng.uniform(-1.05, 1.05) * d_max])
        rate = float(rng.normal(0, 1.5 * rate_max))  # beyond the limit too
        target = float(rng.uniform(0.0, 25.0))
        substeps = int(rng.integers(1, 12))
        expected = step_plant(state, rate, target, vehicle, 0.1, substeps)
        clipped = min(max(rate, -rate_max), rate_max)
        got = single_track_rk4(state, constants, clipped, target, 0.1, substeps)
        assert np.array_equal(got, expected), (state, rate, target, substeps)
        cases += 1
    assert cases == 400


def test_compiled_plant_is_what_the_plant_object_steps(make_config):
    """Both plant objects step as step_plant does (the rate saturated)."""
    cfg = make_config()
    scenario = build_scenario(cfg.scenario)
    python = SingleTrackPlant(cfg, scenario)
    compiled = SingleTrackPlant(cfg, scenario, COMPILED_KERNELS)
    assert compiled._kernel is single_track_rk4 and python._kernel is not single_track_rk4
    state = python.initial_state(scenario)
    for rate in (0.0, 0.2, -5.0, 5.0):
        expected = step_plant(state, rate, 2.5, cfg.vehicle, scenario.sample_time_s,
                              scenario.plant_substeps)
        assert np.array_equal(compiled.step(state, np.array([rate]), 2.5), expected)
        assert np.array_equal(python.step(state, np.array([rate]), 2.5), expected)


PLANNER_SWITCHES = {
    "repulsion_law": ["polynomial", "exponential", "none"],
    "k_rep_source": ["adaptive_h", "constant"],
    "obstacle_prediction": ["current", "constant_velocity"],
    "normalize_step": [True, False],
    "steps": [(0.0, None), (0.35, None), (0.0, 0.12), (0.05, 0.3)],
    "closing_speed_gain_s_per_m": [0.0, 0.4],
}


@pytest.mark.parametrize("obstacles", [[], [[12.0, 1.0]], [[12.0, 1.0], [13.0, -1.0],
                                                           [10.0, 0.3], [10.2, 0.3]]])
def test_compiled_rollout_gives_apf_rollouts_bits_for_every_switch(make_config, obstacles):
    base = make_config(["method=improved"]).planner
    positions = np.array(obstacles, float).reshape(-1, 2)
    n = positions.shape[0]
    snap = ObstacleSnapshot(positions, np.tile([[0.4, -0.3]], (n, 1)), np.full(n, 0.5),
                            np.ones(n, bool))
    goal = np.array([30.0, 0.0])
    combos = 0
    for law, source, prediction, normalize, (step_min, step_max), gain in itertools.product(
            *PLANNER_SWITCHES.values()):
        params = replace(base, repulsion_law=law, k_rep_source=source,
                         obstacle_prediction=prediction, normalize_step=normalize,
                         step_min_m=step_min, step_max_m=step_max,
                         closing_speed_gain_s_per_m=gain)
        settings = apf_kernel_settings(params)
        assert isinstance(settings, ApfSettings) and settings.h_max == params.h_max
        # on the obstacle, beside it, far away; with and without the vehicle's velocity
        for start, velocity in (([10.0, 0.3], [3.0, 0.1]), ([11.5, 0.9], None),
                                ([0.0, 0.0], [1.0, 0.0])):
            start = np.array(start)
            velocity = None if velocity is None else np.array(velocity)
            for horizon in (0, 1, 10):
                expected = apf_rollout(start, goal, snap, params, horizon, 0.1, velocity)
                got = ApfPlanner(params, horizon, 0.1, COMPILED_KERNELS).rollout(
                    start, goal, snap, velocity)
                for field in ("path_m", "attraction", "repulsion", "step_cap_active",
                              "step_min_active"):
                    a, b = getattr(got, field), getattr(expected, field)
                    assert a.dtype == b.dtype and np.array_equal(a, b), (field, params, start)
        combos += 1
    assert combos == 3 * 2 * 2 * 2 * 4 * 2


def test_overflowing_gaussian_gives_no_repulsion_in_both(make_config):
    """``exp(beta dx^2)`` overflows far along the track: Python raises (the rollout takes
    ``h = 0``), the kernel gets ``inf`` and ``H / (1 + inf) = 0``."""
    params = replace(make_config(["method=improved"]).planner, beta=1e308, rho0_m=50.0,
                     rho_p_m=50.0)
    snap = ObstacleSnapshot(np.array([[12.0, 1.0]]), np.zeros((1, 2)), np.array([0.5]),
                            np.ones(1, bool))
    start, goal = np.array([10.0, 0.3]), np.array([30.0, 0.0])
    expected = apf_rollout(start, goal, snap, params, 10, 0.1)
    got = apf_rollout_kernel(10.0, 0.3, 30.0, 0.0, snap.positions_m, snap.velocities_mps,
                             apf_kernel_settings(params), 10, 0.1, 0.0, 0.0,
                             np.zeros((0, 2)), 0.0)
    assert np.array_equal(got[0], expected.path_m) and np.array_equal(got[2],
                                                                       expected.repulsion)
    assert not expected.repulsion.any()


@pytest.mark.parametrize("beyond", ["extend", "hold"])
def test_compiled_reference_gives_the_references_bits(make_config, beyond):
    """Paths that advance, stall (repeated and backward points) or do not advance at all;
    stations before, on, between and beyond the knots, ascending or not."""
    ctrl = make_config([f"controller.path_beyond_end={beyond}"]).controller
    rng = np.random.default_rng(11)
    for case in range(300):
        n = int(rng.integers(1, 12))
        xs = np.cumsum(rng.choice([0.0, 1e-10, -0.2, 0.3, 0.5], n)) + rng.normal(0, 2)
        path = np.column_stack([xs, rng.normal(0, 1.5, n)])
        stations = np.sort(rng.uniform(xs.min() - 1, xs.max() + 2, 10))
        if case % 3 == 0:
            stations[:4] = xs[:4] if n >= 4 else stations[:4]  # on knots
        if case % 7 == 0:
            stations = stations[::-1].copy()
        plain = lateral_reference(path, stations, ctrl)
        fast = lateral_reference(path, stations, ctrl, COMPILED_KERNELS)
        assert np.array_equal(plain[0], fast[0]) and np.array_equal(plain[1], fast[1]), case
        # where the path advances, the interpolation is np.interp's
        if np.all(np.diff(xs) > 1e-9) and n > 1:
            inside = (stations >= xs[0]) & (stations <= xs[-1])
            np.testing.assert_array_equal(plain[0][inside],
                                          np.interp(stations[inside], xs, path[:, 1]))


def test_compiled_chase_gives_the_paths_bits():
    """The drivable path (frame=path) compiled and in CPython: rollouts that advance, stall
    (repeated and backward points), do not advance at all, and bend past the curvature
    limit; look-aheads beyond the rollout's end."""
    from pipeline.loop.compiled import chase_path_kernel
    from pipeline.loop.controller.path import chase_path_arrays

    rng = np.random.default_rng(5)
    clipped_seen = 0
    for case in range(300):
        n = int(rng.integers(1, 12))
        steps = rng.normal(0.3, 0.3, (n, 2)) * rng.choice([0.0, 1.0, 1e-11], (n, 1))
        rollout = np.cumsum(steps, axis=0) + rng.normal(0, 2, 2)
        angle = rng.uniform(-np.pi, np.pi)
        args = (float(rollout[0, 0]), float(rollout[0, 1]), float(rng.uniform(-3, 3)),
                rollout, float(np.cos(angle)), float(np.sin(angle)), bool(case % 3),
                float(rng.uniform(0.5, 5.0)), float(rng.uniform(0.05, 0.5)),
                float(rng.uniform(0.05, 0.5)), int(rng.integers(1, 14)), bool(case % 2))
        plain = chase_path_arrays(*args[:3], rollout.tolist(), *args[4:])
        fast = chase_path_kernel(*args)
        for a, b in zip(plain, fast, strict=True):
            assert np.array_equal(a, b), case
        clipped_seen += int(plain[3].any())
    assert clipped_seen > 30  # the curvature limit bound in many cases


def test_compiled_rollout_path_gives_the_paths_bits():
    """The rollout path (path_reference=rollout) compiled and in CPython: rollouts that
    advance, stall (repeated points), fold back (dithering at the goal), do not advance at
    all, and bend past the curvature limit; paths reaching beyond the rollout's end."""
    from pipeline.loop.compiled import rollout_path_kernel
    from pipeline.loop.controller.path import rollout_path_arrays

    rng = np.random.default_rng(6)
    beyond_seen = folded_seen = 0
    for case in range(300):
        n = int(rng.integers(1, 12))
        steps = rng.normal(0.3, 0.3, (n, 2)) * rng.choice([0.0, 1.0, 1e-11], (n, 1))
        if case % 5 == 0 and n > 3:
            steps[n // 2:] *= np.where(np.arange(n - n // 2) % 2 == 0, -1.0, 1.0)[:, None]
        rollout = np.cumsum(steps, axis=0) + rng.normal(0, 2, 2)
        angle = rng.uniform(-np.pi, np.pi)
        args = (rollout, float(np.cos(angle)), float(np.sin(angle)), bool(case % 3),
                float(rng.uniform(0.05, 0.5)), float(rng.uniform(0.05, 0.5)),
                int(rng.integers(1, 14)))
        plain = rollout_path_arrays(rollout.tolist(), *args[1:])
        fast = rollout_path_kernel(*args)
        for a, b in zip(plain, fast, strict=True):
            assert np.array_equal(a, b), case
        beyond_seen += int(plain[3].any())
        folded_seen += int(case % 5 == 0 and n > 3)
    assert beyond_seen > 30 and folded_seen > 30


def test_compiled_frame_step_and_check_give_the_same_bits():
    """One step's path-frame data, a plan's poses and one record's prediction check, compiled
    and in CPython:
    paths that bend and clip, stations with and without a previous plan, obstacles on both
    sides and behind, records whose window ends early, prediction steps longer than the
    sample time."""
    from pipeline.loop.compiled import (
        chase_path_kernel,
        check_record_kernel,
        frame_step_kernel,
        plan_poses_kernel,
    )
    from pipeline.loop.controller.path import frame_step_arrays, plan_poses_arrays
    from pipeline.loop.controller.prediction_check import check_record_arrays

    rng = np.random.default_rng(9)
    for case in range(120):
        rollout = np.cumsum(rng.normal(0.3, 0.3, (8, 2)), axis=0)
        ds = float(rng.uniform(0.1, 0.4))
        path = chase_path_kernel(0.0, 0.0, float(rng.uniform(-1, 1)), rollout, 1.0, 0.0,
                                 True, 2.5, 0.2, ds, 14, True)
        points, headings, curvature, _ = path
        m = int(rng.choice([0, 11]))
        plan_xy = rng.normal(0, 1, (m, 2)) + np.column_stack([np.arange(m) * ds, np.zeros(m)])
        plan_course = rng.normal(0, 0.3, m)
        obstacles = rng.uniform(-3, 5, (int(rng.integers(0, 7)), 2))
        settings = (ds, 14, float(rng.normal(0, 0.1)), float(rng.normal(0, 0.1)),
                    float(rng.uniform(1, 4)), float(rng.uniform(1, 4)),
                    float(rng.normal(1, 0.2)), float(rng.choice([0.1, 0.2])), 10, 0.5, 3.0,
                    float(rng.choice([3.0, 8.0])), float(rng.choice([0.05, 0.2, 5.0])))
        fast = frame_step_kernel(points, headings, curvature, *settings, plan_xy, plan_course,
                                 obstacles)
        plain = frame_step_arrays(points.tolist(), headings.tolist(), curvature.tolist(),
                                  *settings, plan_xy.tolist(), plan_course.tolist(),
                                  obstacles.tolist())
        for a, b in zip(plain, fast, strict=True):
            assert np.array_equal(a, b), case
        stations = fast[3]
        poses = (stations, rng.normal(0, 0.5, 11), rng.normal(0, 0.2, 11),
                 rng.normal(0, 0.3, 11), rng.uniform(-0.5, 4, 11))
        fast_poses = plan_poses_kernel(points, headings, curvature, ds, 14, *poses)
        plain_poses = plan_poses_arrays(points.tolist(), headings.tolist(), curvature.tolist(),
                                        ds, 14, *(p.tolist() for p in poses))
        for a, b in zip(plain_poses, fast_poses, strict=True):
            assert np.array_equal(a, b), case
        rows = 14
        xy = np.cumsum(rng.normal(0.3, 0.05, (rows, 2)), axis=0)
        psi, delta = rng.normal(0, 0.3, rows), rng.normal(0, 0.2, rows)
        Ad, Bd, Ed = rng.normal(0, 0.3, (5, 5)), rng.normal(0, 0.1, 5), rng.normal(0, 0.1, 5)
        x0 = rng.normal(0, 0.2, 5)
        plan = rng.normal(0, 0.2, 11) if case % 2 else np.zeros(0)
        first = int(rng.integers(0, 8))
        last = min(rows - 1, first + 10)
        args = (ds, 14, stations, float(settings[7]), x0, Ad, Bd, Ed, plan, xy, psi, delta,
                first, last, 5, 10, 0.1)
        fast = check_record_kernel(points, headings, curvature, *args)
        plain = check_record_arrays(points.tolist(), headings.tolist(), curvature.tolist(),
                                    *[a.tolist() if isinstance(a, np.ndarray) else a
                                      for a in args])
        assert np.array_equal(np.array(plain), np.array(fast), equal_nan=True), case


@pytest.mark.parametrize("frame", ["path", "fixed"])
@pytest.mark.parametrize("method", ["improved", "baseline"])
def test_closed_loop_with_kernels_is_the_closed_loop_without(make_config, method, frame):
    """A run with the compiled kernels, counted, against the run with CPython's: every step
    through the compiled plant, rollout and references (the fixed frame's interpolation), or,
    in the path frame (the default statement), through the compiled calls of the engine's
    group (pipeline/loop/lateral_group.py: its rollout, path and plant inside them), the same
    trajectory bit for bit; the cache's flag chooses them."""
    calls = {"plant": 0, "rollout": 0, "references": 0, "rollout_path": 0, "observed": 0,
             "applied": 0}

    def counting(name, kernel):
        def wrapped(*args):
            calls[name] += 1
            return kernel(*args)
        return wrapped

    def counting_rows(states, *args):
        # the lockstep engine steps the compiled plants of all its members in one call
        calls["plant"] += states.shape[0]
        return COMPILED_KERNELS.plant_rk4_rows(states, *args)

    def counting_members(name, kernel):
        def wrapped(k, members, *args):
            calls[name] += members.shape[0]
            return kernel(k, members, *args)
        return wrapped

    counted = COMPILED_KERNELS._replace(
        observe_plan_rows=counting_members("observed", COMPILED_KERNELS.observe_plan_rows),
        apply_rows=counting_members("applied", COMPILED_KERNELS.apply_rows),
        plant_rk4=counting("plant", COMPILED_KERNELS.plant_rk4), plant_rk4_rows=counting_rows,
        apf_rollout=counting("rollout", COMPILED_KERNELS.apf_rollout),
        references=counting("references", COMPILED_KERNELS.references),
        rollout_path=counting("rollout_path", COMPILED_KERNELS.rollout_path))
    cfg = make_config([f"method={method}", "scenario=family", "scenario.family.size=3",
                       f"controller.frame={frame}"])
    references = "rollout_path" if frame == "path" else "references"
    for member in family_members(cfg.scenario, cfg.vehicle.footprint_radius_m):
        member_cfg = replace(cfg, scenario=member)
        scenario = build_scenario(member)
        before = dict(calls)
        plain = simulate(member_cfg, scenario, QpCache())
        assert calls == before  # the default: CPython's
        fast = simulate(member_cfg, scenario, QpCache(), counted)
        steps = len(fast.trajectory) - 1
        grouped = frame == "path"
        assert calls["observed"] - before["observed"] == (steps + 1 if grouped else 0)
        assert calls["applied"] - before["applied"] == (steps if grouped else 0)
        assert calls["plant"] - before["plant"] == (0 if grouped else steps)
        assert calls["rollout"] - before["rollout"] == (0 if grouped else steps)
        assert calls[references] - before[references] == (0 if grouped else steps)
        assert fast.trajectory.equals(plain.trajectory)
        # the flag a family runner sets chooses the compiled set
        flagged = simulate(member_cfg, scenario, QpCache(compiled_kernels=True))
        assert flagged.trajectory.equals(plain.trajectory)
    from pipeline.loop.simulate import run_kernels

    assert run_kernels(QpCache(compiled_kernels=True)) is COMPILED_KERNELS
    assert run_kernels(QpCache()) is PYTHON_KERNELS and run_kernels(None) is PYTHON_KERNELS


def test_family_runner_turns_the_kernels_on_after_enough_members(make_config, tmp_path,
                                                                 monkeypatch):
    import pipeline.studies.experiment as experiment

    cfg = make_config(["method=improved", "scenario=family", "scenario.family.size=3",
                       "scenario.family.n_jobs=1"])
    cache = QpCache()
    plain = experiment.run_family(cfg, tmp_path / "small", progress=False, qp_cache=cache)
    assert cache.members_planned == 3 and not cache.compiled_kernels
    monkeypatch.setattr(experiment, "COMPILED_KERNELS_MIN_MEMBERS", 5)
    fast = experiment.run_family(cfg, tmp_path / "second", progress=False, qp_cache=cache)
    assert cache.members_planned == 6 and cache.compiled_kernels
    # the same members, the same numbers, with and without the kernels (times aside)
    timing = [c for c in plain if "time" in c or "compile" in c]
    assert len(plain) == 3 and plain.drop(columns=timing).equals(fast.drop(columns=timing))


@pytest.mark.parametrize("constrained", [True, False])
def test_halfplane_kernel_is_collision_halfplanes(make_config, constrained):
    """The path frame's half-planes by the kernels' statement (CPython's and numba's) against
    :func:`collision_halfplanes` (lateral_side, one disc), bit for bit: obstacles beyond the
    slots, beyond the activation distance, at a NaN distance, straddling the station's reach,
    a reference exactly on an obstacle's centre (the fallback side), a vehicle level with
    one."""
    from pipeline.loop.compiled import halfplane_kernel
    from pipeline.loop.controller.references import (
        collision_halfplanes,
        lateral_side_halfplane_arrays,
    )

    cfg = make_config(["method=improved"])
    ctrl = replace(cfg.controller, collision_constraints=constrained)
    vehicle = cfg.vehicle
    rng = np.random.default_rng(11)
    N = ctrl.horizon
    cases = 0
    for trial in range(300):
        n_obs = int(rng.integers(0, 6))
        stations = np.sort(rng.uniform(0.0, 12.0, N))
        s_o = rng.uniform(-2.0, 16.0, N * n_obs)
        d_o = rng.normal(0.0, 1.5, N * n_obs)
        if n_obs and trial % 7 == 0:
            d_o[::2] = 0.0                       # on the reference: the fallback side
        if n_obs and trial % 11 == 0:
            s_o[0] = np.nan                      # a NaN distance: constrained
        radii = rng.uniform(0.2, 1.0, n_obs)
        s0, d0 = 0.0, (0.0 if trial % 5 == 0 else float(rng.normal(0, 0.5)))
        projected = np.stack([s_o.reshape(N, n_obs), d_o.reshape(N, n_obs)], axis=2)
        G, h = collision_halfplanes(stations, np.zeros(N), np.array([s0, d0]), projected,
                                    radii, vehicle, ctrl)
        args = (np.zeros(N), s0, d0)
        settings = (ctrl.max_obstacles, vehicle.footprint_radius_m, ctrl.safety_margin_m,
                    ctrl.constraint_activation_m, ctrl.collision_constraints)
        fast = halfplane_kernel(stations, *args, s_o, d_o, n_obs, radii, *settings)
        plain = lateral_side_halfplane_arrays(stations.tolist(), args[0].tolist(), s0, d0,
                                              s_o.tolist(), d_o.tolist(), n_obs,
                                              radii.tolist(), *settings)
        for ours in (fast, plain):
            assert np.array_equal(ours[0], G, equal_nan=True), trial
            assert np.array_equal(ours[1], h, equal_nan=True), trial
            assert np.array_equal(np.signbit(ours[1]), np.signbit(h)), trial
        cases += bool(np.count_nonzero(G))
    assert cases > (100 if constrained else -1) and (constrained or cases == 0)
