"""The APF's attraction along a road's route (scenario.commonroad.route_lookahead_m): at every
rollout point it pulls towards the point the look-ahead along the route beyond that point's
projection, so the rollout follows the road through a bend."""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np
import pytest

from pipeline.loop.compiled import COMPILED_KERNELS
from pipeline.loop.planner import ApfPlanner
from pipeline.loop.python_kernels import PYTHON_KERNELS
from pipeline.loop.scenario import ObstacleSnapshot, route_point_ahead
from tests.loop.test_commonroad import needs_extra

NO_OBSTACLES = ObstacleSnapshot(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0),
                                np.zeros(0, bool))
L_ROUTE = np.array([[0.0, 0.0], [50.0, 0.0], [50.0, 50.0]])


def point_ahead_on(polyline_m: np.ndarray, position_m: np.ndarray, distance_m: float
                   ) -> np.ndarray | None:
    """The oracle: the point ``distance_m`` along ``polyline_m`` beyond the projection of
    ``position_m`` on it, vectorised in numpy (the pipeline's statement before the scalar one
    replaced it); None past its end."""
    starts, ends = polyline_m[:-1], polyline_m[1:]
    segments = ends - starts
    lengths = np.hypot(segments[:, 0], segments[:, 1])
    share = np.clip(np.einsum("sd,sd->s", position_m[None, :] - starts, segments)
                    / np.maximum(lengths ** 2, 1e-12), 0.0, 1.0)
    nearest = starts + share[:, None] * segments
    k = int(np.argmin(np.hypot(*(nearest - position_m[None, :]).T)))
    along = np.concatenate([[0.0], np.cumsum(lengths)])
    target = along[k] + share[k] * lengths[k] + distance_m
    if target > along[-1]:
        return None
    i = min(int(np.searchsorted(along, target, side="right")) - 1, lengths.size - 1)
    t = (target - along[i]) / lengths[i] if lengths[i] > 0 else 0.0
    return starts[i] + t * segments[i]


def test_the_point_ahead_is_the_vectorised_readings_and_the_goal_past_the_end():
    """Against the vectorised oracle on random polylines, points and distances, CPython and
    compiled; past the end the given end point."""
    from numba import njit

    compiled = njit(route_point_ahead)
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(400):
        n = int(rng.integers(2, 9))
        route = np.cumsum(rng.normal(0, 3, (n, 2)), axis=0)
        point, distance = rng.normal(0, 6, 2), float(rng.uniform(0, 15))
        expected = point_ahead_on(route, point, distance)
        got = route_point_ahead(route.tolist(), float(point[0]), float(point[1]), distance,
                                -99.0, -99.0)
        same_bits = compiled(route, float(point[0]), float(point[1]), distance, -99.0, -99.0)
        assert got == same_bits
        if expected is None:
            assert got == (-99.0, -99.0)
        else:
            assert got == pytest.approx(tuple(expected), abs=1e-9)
            checked += 1
    assert checked > 100


def _planner(make_config, kernels, route=None, lookahead=0.0, horizon=40):
    params = replace(make_config(["method=improved"]).planner, normalize_step=True,
                     step_size=1.0, step_min_m=0.0, step_max_m=None)
    planner = ApfPlanner(params, horizon, 0.1, kernels)
    if route is not None:
        planner.follow_route(route, lookahead)
    return planner


@pytest.mark.parametrize("kernels", [PYTHON_KERNELS, COMPILED_KERNELS], ids=["cpython", "numba"])
def test_on_a_straight_route_the_offset_decays_as_the_closed_form(make_config, kernels):
    """A straight route along x, the look-ahead L, unit steps towards the point L ahead:
    x' = x + L / r, y' = y - y / r with r = sqrt(L^2 + y^2) (no obstacles)."""
    look = 4.0
    route = np.array([[-100.0, 0.0], [500.0, 0.0]])
    rollout = _planner(make_config, kernels, route, look).rollout(
        np.array([0.0, 3.0]), np.array([400.0, 0.0]), NO_OBSTACLES)
    x, y, expected = 0.0, 3.0, [(0.0, 3.0)]
    for _ in range(39):
        r = np.hypot(look, y)
        x, y = x + look / r, y - y / r
        expected.append((x, y))
    assert rollout.path_m == pytest.approx(np.array(expected), abs=1e-12)


@pytest.mark.parametrize("kernels", [PYTHON_KERNELS, COMPILED_KERNELS], ids=["cpython", "numba"])
def test_through_a_bend_the_rollout_follows_the_route(make_config, kernels):
    """An L-shaped route: from (40, 0) with a 5 m look-ahead the rollout turns up the second
    leg and stays near the route; pulled at the one point 5 m ahead of the start instead (the
    earlier reading), it stops at that point."""
    start, goal = np.array([40.0, 0.0]), np.array([50.0, 50.0])
    follows = _planner(make_config, kernels, L_ROUTE, 5.0).rollout(start, goal, NO_OBSTACLES)
    path = follows.path_m
    assert path[-1, 1] > 20.0 and abs(path[-1, 0] - 50.0) < 2.0
    gap_to_route = np.minimum(np.where(path[:, 0] <= 50.0, np.abs(path[:, 1]), np.inf),
                              np.where(path[:, 1] >= 0.0, np.abs(path[:, 0] - 50.0), np.inf))
    assert gap_to_route.max() < 2.5  # cuts the corner by less than half the look-ahead
    carrot = point_ahead_on(L_ROUTE, start, 5.0)
    fixed = _planner(make_config, kernels).rollout(start, carrot, NO_OBSTACLES).path_m
    assert np.abs(fixed[-5:] - carrot).max() <= 1.0  # stuck at (45, 0)


#: sha256 (first 16 hex) of the path, attraction and repulsion bytes of the rollout below,
#: computed with the kernel before it took a route (commit 55ee88a), CPython and compiled alike
ROLLOUT_BEFORE_ROUTES = {"improved": "e26b300c6b742b3f", "baseline": "a0d2ffdc909f3df7"}


@pytest.mark.parametrize("method", sorted(ROLLOUT_BEFORE_ROUTES))
@pytest.mark.parametrize("kernels", [PYTHON_KERNELS, COMPILED_KERNELS], ids=["cpython", "numba"])
def test_without_a_route_the_rollout_is_the_kernels_before_routes_bit_for_bit(make_config,
                                                                              method, kernels):
    """Two moving obstacles, the closing-speed velocity: the same bytes as the kernel gave
    before it took a route (pinned), with no route and with an empty one."""
    import hashlib

    settings = make_config([f"method={method}"]).planner
    obstacles = ObstacleSnapshot(np.array([[8.0, 0.2], [14.0, -1.0]]),
                                 np.array([[0.0, -0.5], [-1.0, 0.3]]), np.array([0.5, 0.8]),
                                 np.ones(2, bool))
    for route in (None, np.zeros((0, 2)), np.array([[0.0, 0.0]])):
        planner = ApfPlanner(settings, 30, 0.1, kernels)
        if route is not None:
            planner.follow_route(route, 10.0, 2.0)
        rollout = planner.rollout(np.array([1.0, 0.4]), np.array([60.0, 0.0]), obstacles,
                                  np.array([5.0, 0.1]))
        digest = hashlib.sha256(b"".join(np.ascontiguousarray(getattr(rollout, name)).tobytes()
                                         for name in ("path_m", "attraction", "repulsion")))
        assert digest.hexdigest()[:16] == ROLLOUT_BEFORE_ROUTES[method]


def test_an_empty_route_is_no_route(make_config):
    """follow_route never called, or called with fewer than two points: the same bits."""
    start, goal = np.array([1.0, 0.4]), np.array([60.0, 0.0])
    obstacles = ObstacleSnapshot(np.array([[8.0, 0.2]]), np.array([[0.0, -0.5]]),
                                 np.array([0.5]), np.ones(1, bool))
    for kernels in (PYTHON_KERNELS, COMPILED_KERNELS):
        plain = _planner(make_config, kernels).rollout(start, goal, obstacles,
                                                       np.array([5.0, 0.0]))
        empty = _planner(make_config, kernels, np.zeros((0, 2)), 10.0).rollout(
            start, goal, obstacles, np.array([5.0, 0.0]))
        for field in fields(plain):
            assert np.array_equal(getattr(plain, field.name), getattr(empty, field.name))


class _SubclassWithItsOwnRollout(ApfPlanner):
    """A planner of one's own as docs/own_method.md shows it: a subclass whose rollout is its
    own (it would never read a route handed to the APF's)."""

    def rollout(self, position_m, goal_m, obstacles, vehicle_velocity_mps=None):
        return super().rollout(position_m, goal_m, obstacles, vehicle_velocity_mps)


def test_the_loop_hands_the_route_to_the_apf_and_the_point_ahead_to_any_other(make_config):
    from types import SimpleNamespace

    from pipeline.loop.engine import follows_route

    route = (L_ROUTE, 7.0)
    road = SimpleNamespace(attraction_route=route, follows_road=True)
    apf = _planner(make_config, PYTHON_KERNELS)
    assert follows_route(apf, road) is False
    assert apf._route_m.tolist() == L_ROUTE.tolist() and apf._route_lookahead_m == 7.0
    settings = make_config(["method=improved"]).planner
    other = _SubclassWithItsOwnRollout(settings, 10, 0.1)
    assert follows_route(other, road) is True and other._route_m.shape == (0, 2)
    from pipeline.peers.velocity_obstacles import VelocityObstaclePlanner

    vo = VelocityObstaclePlanner(make_config(["method=vo"]).planner, 10, 0.1)
    assert follows_route(vo, road) is True  # the VO peer is handed the point ahead each step
    assert follows_route(object(), road) is True
    assert follows_route(apf, SimpleNamespace(attraction_route=None, follows_road=False)) \
        is False


@pytest.mark.parametrize("speed, expected_m", [(0.0, 10.0), (4.0, 10.0), (5.0, 10.0),
                                               (8.0, 16.0), (17.0, 34.0)])
def test_the_look_ahead_is_the_farther_of_its_distance_and_its_time_at_the_speed(
        make_config, speed, expected_m):
    """route_lookahead_m = 10, route_lookahead_s = 2: max(10, 2 v), v the velocity's norm;
    and the rollout pulls to the point that far ahead (a straight route: the first step
    heads for (x + L, 0))."""
    planner = _planner(make_config, PYTHON_KERNELS)
    planner.follow_route(np.array([[-100.0, 0.0], [500.0, 0.0]]), 10.0, 2.0)
    velocity = np.array([0.6, 0.8]) * speed
    assert planner.route_lookahead_m(velocity) == pytest.approx(expected_m, rel=1e-12)
    rollout = planner.rollout(np.array([0.0, 3.0]), np.array([400.0, 0.0]), NO_OBSTACLES,
                              velocity)
    step = rollout.path_m[1] - rollout.path_m[0]
    assert step == pytest.approx(np.array([expected_m, -3.0]) / np.hypot(expected_m, 3.0),
                                 abs=1e-12)
    planner.follow_route(np.array([[-100.0, 0.0], [500.0, 0.0]]), 10.0)  # no time: 10 m
    assert planner.route_lookahead_m(velocity) == 10.0


@pytest.mark.parametrize("overrides, message", [
    (["scenario.commonroad.route_lookahead_s=0.05"], "route_lookahead_s"),
    (["scenario.commonroad.route_lookahead_s=11"], "route_lookahead_s"),
    (["scenario.commonroad.route_lookahead_s=-1"], "route_lookahead_s"),
])
def test_a_look_ahead_time_out_of_range_is_one_line_naming_the_key(make_config, overrides,
                                                                   message):
    from pipeline.errors import ConfigError

    with pytest.raises(ConfigError, match=message):
        make_config(["scenario=commonroad", "scenario.commonroad.path=x.xml", *overrides])


@needs_extra
def test_on_a_planted_road_the_engine_follows_the_route_as_the_oracle_loop(tmp_path,
                                                                          make_config):
    """The planted road of tests/loop/test_commonroad.py (the oncoming car in the other
    lane): the engine and the readable per-member loop give the same run bit for bit with the
    route default (10 m, 2 s) and straight to the goal, and the route changes the run (the
    switch is read)."""
    from pipeline.loop.commonroad_scenario import read_commonroad
    from pipeline.loop.controller import QpCache
    from pipeline.loop.engine import simulate_members
    from tests.loop.oracle_loop import oracle_simulate
    from tests.loop.test_commonroad import write_scenario

    path = write_scenario(tmp_path / "planted.xml", obstacles="oncoming")
    runs = {}
    for name, extra in (("route", []), ("straight", ["scenario.commonroad.route_lookahead_m=null"])):
        cfg = make_config(["scenario=commonroad", f"scenario.commonroad.path={path}",
                           "scenario.commonroad.n_steps=40", *extra])
        scenario = read_commonroad(cfg.scenario).scenario
        engine, = simulate_members([(cfg, scenario)], QpCache(compiled_kernels=True))
        oracle = oracle_simulate(cfg, scenario, QpCache(compiled_kernels=True))
        assert engine.trajectory.drop(columns=[c for c in engine.trajectory.columns
                                               if c.endswith("solve_time_s")]).equals(
            oracle.trajectory.drop(columns=[c for c in oracle.trajectory.columns
                                            if c.endswith("solve_time_s")]))
        runs[name] = engine.trajectory
    assert not np.array_equal(runs["route"]["apf_att_x"].to_numpy(),
                              runs["straight"]["apf_att_x"].to_numpy())
