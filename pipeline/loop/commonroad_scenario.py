"""Scenario stage of ``scenario=commonroad``: a CommonRoad scenario XML as our scenario.

CommonRoad (commonroad-io, BSD-3-Clause) is the motion-planning community's scenario format.
:func:`read_commonroad` reads a file with commonroad-io's own reader and turns it into a
:class:`CommonRoadCase`:

* the planning problem's initial state gives the start, the heading and the speed (the
  scenario's own; no slower stand-in), its goal region the goal point (the centre of the goal's
  shape) and, with the file's time step, the sample time and the run length;
* every static and dynamic obstacle becomes a disc (circumscribing its shape, or of half its
  smaller side: ``scenario.commonroad.obstacle_disc``) that moves on its recorded track, present
  from its first to its last recorded time step; an obstacle on the ego's initial position at
  the initial time step is the ego's own recording and is dropped;
* the MPC fills its obstacle slots nearest first (``Scenario.nearest_first``).

:func:`ego_states` and :func:`ego_solution` turn our logged run back into CommonRoad states and
a CommonRoad solution (the kinematic single-track model's states, the trajectory a CommonRoad
tool reads). commonroad-io is an optional extra: every function here imports it lazily, and
:func:`require_commonroad` says in one line how to install it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pandas as pd

from pipeline.errors import ConfigError
from pipeline.loop.scenario import Extra, ObstacleSnapshot, Scenario, route_point_ahead
from pipeline.loop.settings import (
    MAX_RUN_STEPS,
    CommonRoadConfig,
    ScenarioConfig,
    ScenarioSourceConfig,
    VehicleConfig,
)

#: The one line that says how to get ``scenario=commonroad`` (the test skip reason too).
INSTALL_HINT = ("scenario=commonroad needs the optional extra: pip install '.[commonroad]' "
                "(its Polygon3 builds from source: a C compiler, e.g. apt-get install "
                "build-essential)")
PATH_KEY = "scenario.commonroad.path"
#: commonroad-io, the drivability checker and the vehicle models (``pip install
#: '.[commonroad]'``)
COMMONROAD_EXTRA = Extra("commonroad", ("commonroad", "commonroad_dc.pycrcc", "vehiclemodels"),
                         INSTALL_HINT)


def commonroad_missing() -> str | None:
    """None when commonroad-io, the drivability checker and the vehicle models import; else
    :data:`INSTALL_HINT`."""
    return COMMONROAD_EXTRA.missing()


def require_commonroad() -> None:
    """Raise :class:`~pipeline.errors.MissingExtraError` (the install line) without the
    extra."""
    COMMONROAD_EXTRA.require()


class CommonRoadSource:
    """A CommonRoad file's source (``conf/scenario/commonroad.yaml``): the scenario
    :func:`read_commonroad` makes of the file. A file is one scenario, not a family. Its run is
    :func:`pipeline.studies.commonroad.run_and_log` (``study``): the run at the file's own
    start, speed and goal, judged again by CommonRoad's drivability checker."""

    needs_extra: ClassVar[Extra | None] = COMMONROAD_EXTRA
    study = "pipeline.studies.commonroad.run_and_log"

    def __init__(self, scenario: ScenarioConfig, vehicle_radius_m: float = 1.0) -> None:
        if scenario.commonroad is None:
            raise ConfigError("scenario.source._target_", ScenarioSourceConfig.COMMONROAD,
                              "another source, or a scenario.commonroad block (scenario="
                              "commonroad), which this source reads")
        self.base = scenario

    def build(self, cfg: ScenarioConfig) -> Scenario:
        return read_commonroad(cfg).scenario

    def member(self, seed: int, index: int) -> ScenarioConfig:
        raise ConfigError("scenario.family", f"member {index} of seed {seed}",
                          "no family with a CommonRoad scenario (one file is one scenario; "
                          "run each file: make commonroad COMMONROAD=path)")


@dataclass(frozen=True)
class CommonRoadScenario(Scenario):
    """A :class:`Scenario` whose obstacles move on recorded tracks sampled every
    ``track_step_s`` from time 0 (arrays over obstacles and samples; positions of the disc
    centres, velocities by finite differences, ``track_present`` while the file has the
    obstacle). Between samples positions and velocities are interpolated linearly."""

    track_step_s: float = 0.1
    track_positions_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 1, 2)))
    track_velocities_mps: np.ndarray = field(default_factory=lambda: np.zeros((0, 1, 2)))
    track_present: np.ndarray = field(default_factory=lambda: np.zeros((0, 1), bool))
    #: the static obstacles' rectangles that hide what is behind them (k, 4, 2; corners
    #: counter-clockwise), and for each obstacle disc the rectangle that is its own (-1: none)
    occluders_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 2)))
    occluder_of: np.ndarray = field(default_factory=lambda: np.zeros(0, int))

    #: the route's lanelet centreline (P, 2; empty: none) and how far ahead along it the
    #: attraction pulls (``scenario.commonroad.route_lookahead_m``)
    route_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    route_lookahead_m: float = 0.0
    #: and how long ahead at the ego's speed (s; the farther of the two;
    #: ``scenario.commonroad.route_lookahead_s``, 0: the distance alone)
    route_lookahead_s: float = 0.0

    @property
    def follows_road(self) -> bool:
        return self.route_m.shape[0] >= 2

    @property
    def attraction_route(self) -> tuple[np.ndarray, float, float] | None:
        return (self.route_m, self.route_lookahead_m, self.route_lookahead_s) \
            if self.follows_road else None

    def attraction_goal_m(self, position_m: np.ndarray) -> np.ndarray:
        """The point :attr:`route_lookahead_m` along the route ahead of the ego's projection
        on it (:func:`~pipeline.loop.scenario.route_point_ahead`); past the route's end, the
        goal point."""
        if not self.follows_road:
            return self.goal_m
        goal = self.goal_m
        return np.array(route_point_ahead(self.route_m.tolist(), float(position_m[0]),
                                          float(position_m[1]), self.route_lookahead_m,
                                          float(goal[0]), float(goal[1])))

    @property
    def senses(self) -> bool:
        return self.sensor_range_m is not None or self.occluders_m.shape[0] > 0

    def sense(self, snapshot: ObstacleSnapshot, position_m: np.ndarray,
              reach_m: float) -> ObstacleSnapshot:
        """What the ego at ``position_m`` sees: within the sensor range, and not hidden behind
        a static obstacle (:func:`occluded`); a present obstacle within the ego's reach
        (``reach_m`` plus its radius) is always seen, whatever the range."""
        return sight_view(snapshot, position_m, reach_m,
                          Scenario.sense(self, snapshot, position_m, reach_m).visible,
                          self.occluders_m, self.occluder_of)

    def obstacles_at(self, time_s: float) -> ObstacleSnapshot:
        """The recorded obstacles at ``time_s``; outside its recording an obstacle is
        invisible (at the nearest recorded place)."""
        last = self.track_present.shape[1] - 1
        where = max(time_s / self.track_step_s, 0.0)
        i0 = min(int(math.floor(where + 1e-9)), last)
        share = min(max(where - i0, 0.0), 1.0) if i0 < last else 0.0
        if share < 1e-9:
            share = 0.0
        i1 = min(i0 + 1, last)
        positions = self.track_positions_m[:, i0] * (1.0 - share) \
            + self.track_positions_m[:, i1] * share
        velocities = self.track_velocities_mps[:, i0] * (1.0 - share) \
            + self.track_velocities_mps[:, i1] * share
        visible = self.track_present[:, i0] & (self.track_present[:, i1] | (share == 0.0))
        return ObstacleSnapshot(positions, velocities, self.obstacle_radius_m.copy(), visible)


def route_centreline(network: Any, start_m: np.ndarray, goal_m: np.ndarray | None,
                     straight_on_m: float = 300.0) -> np.ndarray:
    """The route's centreline (P, 2): the centre vertices of the shortest lanelet path
    (:func:`_shortest_lanelet_path`) from the start's lanelet to the goal point's, a lane
    change made at the start of the lanelet it leaves; without a
    goal point (a goal of time alone) the successors that turn least, for ``straight_on_m``
    (:func:`_straight_on`). Empty when the start is on no lanelet or no path leads to the goal.
    (commonroad-route-planner does this too, but needs osqp 0.6, which our cvxpy cannot take.)"""
    starts = network.find_lanelet_by_position([np.asarray(start_m, float)])[0]
    if not starts:
        return np.zeros((0, 2))
    if goal_m is None:
        path = _straight_on(network, starts[0], straight_on_m)
    else:
        goals = set(network.find_lanelet_by_position([np.asarray(goal_m, float)])[0])
        path = _shortest_lanelet_path(network, starts, goals)
    points: list[np.ndarray] = []
    for lanelet_id, lane_change in path:
        centre = np.asarray(network.find_lanelet_by_id(lanelet_id).center_vertices, float)
        if lane_change and points:
            # change lanes at once: keep the lanelet left only up to its first vertex and join
            # the neighbour where its centre is nearest to that vertex
            points[-1] = points[-1][:1]
            centre = centre[int(np.argmin(np.hypot(*(centre - points[-1][0]).T))):]
        elif points:
            centre = centre[1:]  # its first vertex is the predecessor's last
        if centre.shape[0]:
            points.append(centre)
    return np.concatenate(points) if points else np.zeros((0, 2))


def _shortest_lanelet_path(network: Any, starts: list[int], goals: set[int]
                           ) -> list[tuple[int, bool]]:
    """Dijkstra by length over successors; a change to a same-direction neighbour costs
    nothing (the route changes at the start of the lanelet it leaves, whose length the
    neighbour's then stands for). The lanelets of the path, each with whether it was entered
    by a lane change (empty: no path)."""
    import heapq

    queue: list[tuple[float, int, list[tuple[int, bool]]]] = \
        [(0.0, i, [(i, False)]) for i in starts]
    done: set[int] = set()
    while queue:
        cost, here, steps = heapq.heappop(queue)
        if here in goals:
            return steps
        if here in done:
            continue
        done.add(here)
        this = network.find_lanelet_by_id(here)
        length = float(this.distance[-1])
        for nxt in this.successor or []:
            heapq.heappush(queue, (cost + length, nxt, steps + [(nxt, False)]))
        for nxt, same in ((this.adj_left, this.adj_left_same_direction),
                          (this.adj_right, this.adj_right_same_direction)):
            if nxt is not None and same:
                heapq.heappush(queue, (cost, nxt, steps + [(nxt, True)]))
    return []


def _straight_on(network: Any, start: int, length_m: float) -> list[tuple[int, bool]]:
    """From ``start`` the successor whose first heading turns least from the lanelet's last,
    until ``length_m`` is covered or no successor is left."""
    here, total = start, 0.0
    path = [(here, False)]
    while total < length_m:
        this = network.find_lanelet_by_id(here)
        total += float(this.distance[-1])
        if not this.successor:
            break
        end = this.center_vertices[-1] - this.center_vertices[-2]
        heading = math.atan2(end[1], end[0])
        here = min(this.successor, key=lambda i: abs(math.remainder(
            _direction(network.find_lanelet_by_id(i).center_vertices) - heading, 2 * math.pi)))
        path.append((here, False))
    return path


def _direction(centre: np.ndarray) -> float:
    """The heading (rad) of a centreline's first segment."""
    d = np.asarray(centre[1], float) - np.asarray(centre[0], float)
    return math.atan2(d[1], d[0])


def sight_view(snapshot: ObstacleSnapshot, position_m: np.ndarray, reach_m: float,
               in_range: np.ndarray, occluders_m: np.ndarray, own: np.ndarray
               ) -> ObstacleSnapshot:
    """``snapshot`` as the ego at ``position_m`` sees it: present, ``in_range`` (the sensor
    range's mask) and not hidden behind an occluder (:func:`occluded`), or within the ego's
    reach (``reach_m`` plus the obstacle's radius: never hidden, so no contact escapes the
    check). Positions stay the true ones."""
    position = np.asarray(position_m, float)
    near = np.hypot(*(snapshot.positions_m - position).T) <= reach_m + snapshot.radii_m
    seen = in_range
    if occluders_m.shape[0] and seen.any():
        seen = seen & ~occluded(position, snapshot.positions_m, occluders_m, own)
    return ObstacleSnapshot(snapshot.positions_m, snapshot.velocities_mps, snapshot.radii_m,
                            snapshot.visible & (near | seen))


def occluded(viewer_m: np.ndarray, targets_m: np.ndarray, occluders_m: np.ndarray,
             own: np.ndarray) -> np.ndarray:
    """Whether the segment from ``viewer_m`` to each target (n, 2) crosses one of the convex
    ``occluders_m`` (k, 4, 2; corners counter-clockwise) other than the target's own
    (``own``: its index, -1 for none); an occluder holding the viewer hides nothing (the
    Cyrus-Beck clip of the segment against each occluder's four edge half-planes)."""
    corners = occluders_m                                   # (k, 4, 2)
    edges = np.roll(corners, -1, axis=1) - corners          # (k, 4, 2)
    normals = np.stack([edges[..., 1], -edges[..., 0]], axis=-1)   # outward for CCW
    start = np.einsum("ked,ked->ke", normals, viewer_m[None, None, :] - corners)   # (k, 4)
    direction = targets_m - viewer_m[None, :]               # (n, 2)
    rate = np.einsum("ked,nd->nke", normals, direction)     # (n, k, 4)
    with np.errstate(divide="ignore", invalid="ignore"):
        crossing = -start[None] / rate                      # where the segment meets each edge
    entering = np.where(rate < 0, crossing, -np.inf).max(axis=2)
    leaving = np.where(rate > 0, crossing, np.inf).min(axis=2)
    parallel_outside = ((rate == 0) & (start[None] > 0)).any(axis=2)
    low, high = np.maximum(entering, 0.0), np.minimum(leaving, 1.0)
    blocked = (low <= high) & ~parallel_outside             # (n, k)
    blocked &= ~(start <= 0).all(axis=1)[None, :]           # the viewer inside: hides nothing
    blocked[np.arange(targets_m.shape[0])[own >= 0], own[own >= 0]] = False
    return blocked.any(axis=1)


def occluder_rectangles(scenario: Any, t0: int, ids: tuple[int, ...]
                        ) -> tuple[np.ndarray, np.ndarray]:
    """The static obstacles' rectangles (their shapes' smallest bounding rectangles at time
    step ``t0``, corners counter-clockwise) and, for each obstacle disc of ``ids``, the index
    of its own rectangle (-1 when it is not a static obstacle's)."""
    rectangles: list[np.ndarray] = []
    index: dict[int, int] = {}
    for obstacle in sorted(scenario.static_obstacles, key=lambda o: o.obstacle_id):
        occupancy = obstacle.occupancy_at_time(t0)
        if occupancy is None:
            continue
        box = np.array(shape_geometry(occupancy.shape).minimum_rotated_rectangle
                       .exterior.coords)[:4]
        area = np.sum(box[:, 0] * np.roll(box[:, 1], -1) - np.roll(box[:, 0], -1) * box[:, 1])
        index[int(obstacle.obstacle_id)] = len(rectangles)
        rectangles.append(box if area > 0 else box[::-1])
    own = np.array([index.get(i, -1) for i in ids], int)
    return np.array(rectangles, float).reshape(-1, 4, 2), own


@dataclass(frozen=True)
class CommonRoadCase:
    """What :func:`read_commonroad` made of a file.

    Attributes
    ----------
    scenario_config : ScenarioConfig
        The configuration with start, heading, speed, goal, sample time and run length from the
        planning problem (what the run records in its ``config.yaml``).
    scenario : CommonRoadScenario
        Our scenario (obstacle ``j`` is CommonRoad obstacle ``obstacle_ids[j]``).
    commonroad_scenario, planning_problem : commonroad-io objects
    obstacle_ids : tuple of int
    ego_recording_ids : tuple of int
        Obstacles dropped as the ego's own recording.
    initial_time_step : int
        The CommonRoad time step of our time 0.
    file_sha256 : str
    """

    scenario_config: ScenarioConfig
    scenario: CommonRoadScenario
    commonroad_scenario: Any
    planning_problem: Any
    obstacle_ids: tuple[int, ...]
    ego_recording_ids: tuple[int, ...]
    initial_time_step: int
    file_sha256: str


def read_commonroad(cfg: ScenarioConfig) -> CommonRoadCase:
    """Read ``cfg.commonroad.path`` (a CommonRoad scenario XML) into a :class:`CommonRoadCase`.

    Raises
    ------
    MissingExtraError
        Without the ``commonroad`` extra.
    ConfigError
        A missing file, a file that is not a CommonRoad scenario, a scenario without a (or
        without the chosen) planning problem, or one whose ego stands still with no speed set.
    """
    require_commonroad()
    cr = cfg.commonroad
    if cr is None:
        raise ConfigError("scenario.commonroad", None, "a commonroad block (scenario=commonroad)")
    path = Path(cr.path)
    scenario, problems, digest = _open(path)
    problem = _planning_problem(problems, cr, path)
    t0 = int(problem.initial_state.time_step)
    start = np.asarray(problem.initial_state.position, float)
    # wrapped once, in closed form, where it enters: [-pi, pi] (a file may hold any turn)
    heading = math.remainder(float(problem.initial_state.orientation), 2.0 * math.pi)
    speed = _speed(problem, cr)
    dt = float(scenario.dt)
    n_steps = cr.n_steps if cr.n_steps is not None else _run_length(problem, scenario, t0)
    if n_steps > MAX_RUN_STEPS:  # the file's goal (or recording), not a key the user set
        raise ConfigError("scenario.commonroad.path", str(path),
                          f"a scenario whose goal ends within {MAX_RUN_STEPS} steps of its "
                          f"initial state ({path.name}'s goal or recording ends {n_steps} steps "
                          f"after time step {t0}), or scenario.commonroad.n_steps set to run "
                          "fewer")
    goal = _goal_point(problem, start, heading, speed, dt, t0)
    # named by the file (its benchmark id may be another file's: the result records it beside)
    name = _safe(path.stem) or "commonroad"
    resolved = replace(cfg, name=name, start_xy_m=[float(start[0]), float(start[1])],
                       start_heading_rad=heading, goal_xy_m=[float(goal[0]), float(goal[1])],
                       speed_mps=speed, initial_speed_mps=None, sample_time_s=dt,
                       n_steps=int(n_steps), obstacles=[])
    tracks, ids, ego_ids = _tracks(scenario, problem, cr, t0, int(n_steps) + 2)
    ours = build_commonroad_scenario(resolved, tracks)
    occluders, own = occluder_rectangles(scenario, t0, ids) if cr.occlusion \
        else (np.zeros((0, 4, 2)), np.full(len(ids), -1))
    route = np.zeros((0, 2))
    if cr.route_lookahead_m is not None:
        has_goal_point = any(getattr(g, "position", None) is not None
                             for g in problem.goal.state_list)
        route = route_centreline(scenario.lanelet_network, start,
                                 goal if has_goal_point else None)
    # the road as its lanelets' polygons: what the lateral MPC keeps the ego on with
    # controller.road_edge_weight, and what the off-road check measures against
    road = road_polygons(scenario.lanelet_network, float(cr.lanelet_gap_m))
    ours = replace(ours, sensor_range_m=cr.sensor_range_m, occluders_m=occluders,
                   occluder_of=own, route_m=route,
                   route_lookahead_m=float(cr.route_lookahead_m or 0.0),
                   route_lookahead_s=float(cr.route_lookahead_s or 0.0), road_polygons_m=road)
    return CommonRoadCase(resolved, ours, scenario, problem, ids, ego_ids, t0, digest)


def road_polygons(network: Any, gap_m: float = 0.0) -> tuple[np.ndarray, ...]:
    """The road as one polygon per lanelet (vertices (P, 2), closed implicitly): its left
    bound, then its right bound backwards; with ``gap_m`` > 0 each widened by ``gap_m / 2``
    to every side (a mitred buffer: straight edges stay straight), so that neighbours whose
    shared edges do not meet exactly overlap (``scenario.commonroad.lanelet_gap_m``)."""
    polygons = [np.vstack([np.asarray(lanelet.left_vertices, float),
                           np.asarray(lanelet.right_vertices, float)[::-1]])
                for lanelet in network.lanelets]
    if gap_m <= 0.0:
        return tuple(polygons)
    from shapely.geometry import Polygon

    widened = []
    for vertices in polygons:
        shape = Polygon(vertices)
        if not shape.is_valid:  # a bound that crosses itself: its valid area
            shape = shape.buffer(0)
        grown = shape.buffer(gap_m / 2.0, join_style="mitre", mitre_limit=2.0)
        if grown.geom_type != "Polygon":  # pieces: the largest (a valid lanelet has one)
            grown = max(grown.geoms, key=lambda piece: piece.area)
        widened.append(np.asarray(grown.exterior.coords, float)[:-1])
    return tuple(widened)


@dataclass(frozen=True)
class ObstacleTracks:
    """Disc tracks on the sample grid: centres (n, K, 2), presence (n, K), radii (n,)."""

    positions_m: np.ndarray
    present: np.ndarray
    radii_m: np.ndarray


def build_commonroad_scenario(cfg: ScenarioConfig, tracks: ObstacleTracks) -> CommonRoadScenario:
    """Our scenario from a resolved configuration and the obstacles' tracks (velocities by
    finite differences of the centres where both neighbours are recorded)."""
    n, k = tracks.present.shape
    dt = float(cfg.sample_time_s)
    velocities = _track_velocities(tracks, dt)
    first = np.argmax(tracks.present, axis=1) if n else np.zeros(0, int)
    rows = np.arange(n)
    return CommonRoadScenario(
        name=cfg.name, start_m=np.asarray(cfg.start_xy_m, float),
        start_heading_rad=math.remainder(float(cfg.start_heading_rad), 2.0 * math.pi), goal_m=np.asarray(cfg.goal_xy_m, float),
        goal_tolerance_m=float(cfg.goal_tolerance_m), speed_mps=float(cfg.speed_mps),
        initial_speed_mps=float(cfg.speed_mps), sample_time_s=dt, n_steps=int(cfg.n_steps),
        plant_substeps=int(cfg.plant_substeps),
        obstacle_start_m=tracks.positions_m[rows, first].reshape(-1, 2),
        obstacle_velocity_mps=velocities[rows, first].reshape(-1, 2),
        obstacle_radius_m=np.asarray(tracks.radii_m, float),
        obstacle_appear_s=first.astype(float) * dt, nearest_first=True,
        track_step_s=dt, track_positions_m=tracks.positions_m,
        track_velocities_mps=velocities, track_present=tracks.present)


def _track_velocities(tracks: ObstacleTracks, dt: float) -> np.ndarray:
    """Each sample's velocity (n, K, 2): the forward difference where the next sample is
    recorded too, else the backward one, else zero."""
    p, present = tracks.positions_m, tracks.present
    velocities = np.zeros(p.shape)
    if p.shape[1] < 2:
        return velocities
    steps = (p[:, 1:] - p[:, :-1]) / dt
    pairs = present[:, 1:] & present[:, :-1]
    forward, backward = np.zeros(p.shape), np.zeros(p.shape)
    forward[:, :-1] = np.where(pairs[..., None], steps, 0.0)
    backward[:, 1:] = np.where(pairs[..., None], steps, 0.0)
    has_forward = np.zeros(present.shape, bool)
    has_forward[:, :-1] = pairs
    velocities = np.where(has_forward[..., None], forward, backward)
    return velocities


def _safe(text: str) -> str:
    """``text`` with every character outside ``[A-Za-z0-9_.+=,-]`` replaced by ``_`` (a
    scenario name becomes a folder name), at most 100 characters."""
    import re

    return re.sub(r"[^A-Za-z0-9_.+=,-]", "_", text)[:100]


def _open(path: Path) -> tuple[Any, Any, str]:
    """The file's scenario, planning problem set and SHA-256; a one-line
    :class:`ConfigError` for a missing file or one that is not a CommonRoad scenario."""
    import hashlib
    import warnings
    import xml.etree.ElementTree as ET

    if not path.is_file():
        raise ConfigError(PATH_KEY, str(path), "an existing CommonRoad scenario XML file "
                          "(no such file)")
    data = path.read_bytes()
    try:
        root = ET.fromstring(data).tag
    except ET.ParseError as exc:
        raise ConfigError(PATH_KEY, str(path), "a CommonRoad scenario XML file (this one is "
                          f"not XML: {exc})") from None
    if root != "commonRoad":
        raise ConfigError(PATH_KEY, str(path), "a CommonRoad scenario XML file (its root "
                          f"element is <{root}>, not <commonRoad>)")
    from commonroad.common.file_reader import CommonRoadFileReader

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scenario, problems = CommonRoadFileReader(str(path)).open()
    except Exception as exc:  # any reader failure is the file's fault
        first = (str(exc).splitlines() or [""])[0][:200]
        raise ConfigError(PATH_KEY, str(path), "a CommonRoad scenario XML file (commonroad-io "
                          f"cannot read this one: {type(exc).__name__}: {first})") from None
    return scenario, problems, hashlib.sha256(data).hexdigest()


def _planning_problem(problems: Any, cr: CommonRoadConfig, path: Path) -> Any:
    """The chosen planning problem (the lowest id when none is chosen)."""
    found = dict(problems.planning_problem_dict) if problems is not None else {}
    if not found:
        raise ConfigError(PATH_KEY, str(path), "a CommonRoad scenario with a planning problem "
                          "(this file has none: nothing says where the ego starts and goes)")
    if cr.planning_problem_id is None:
        return found[min(found)]
    if cr.planning_problem_id not in found:
        raise ConfigError("scenario.commonroad.planning_problem_id", cr.planning_problem_id,
                          f"one of the file's planning problems {sorted(found)}")
    return found[cr.planning_problem_id]


def _speed(problem: Any, cr: CommonRoadConfig) -> float:
    """The run's speed: the configured one, else the initial state's."""
    if cr.speed_mps is not None:
        return float(cr.speed_mps)
    speed = float(getattr(problem.initial_state, "velocity", 0.0) or 0.0)
    if speed < 0.1:
        raise ConfigError("scenario.commonroad.speed_mps", None,
                          f"a speed in [0.1, 40] m/s: planning problem "
                          f"{problem.planning_problem_id} starts at {speed:g} m/s")
    return speed


def _goal_times(problem: Any) -> list[tuple[int, int]]:
    """The goal states' time-step intervals."""
    out = []
    for state in problem.goal.state_list:
        interval = getattr(state, "time_step", None)
        if interval is not None and hasattr(interval, "end"):
            out.append((int(interval.start), int(interval.end)))
    return out


def _run_length(problem: Any, scenario: Any, t0: int) -> int:
    """Steps to the goal's last time step (or to the file's last recorded obstacle step)."""
    times = _goal_times(problem)
    if times:
        return max(2, max(end for _, end in times) - t0)
    ends = [int(o.prediction.final_time_step) for o in scenario.dynamic_obstacles
            if o.prediction is not None]
    return max(2, (max(ends) if ends else t0 + 100) - t0)


def _shape_centre(shape: Any) -> np.ndarray:
    """A goal shape's centre (a shape group's: the mean of its shapes')."""
    if hasattr(shape, "shapes"):
        return np.mean([_shape_centre(s) for s in shape.shapes], axis=0)
    return np.asarray(shape.center, float)


def _goal_point(problem: Any, start: np.ndarray, heading: float, speed: float, dt: float,
                t0: int) -> np.ndarray:
    """The centre of the goal's position; a goal without one (a time or speed goal only):
    where the ego would be at the goal's last time step driving straight on."""
    for state in problem.goal.state_list:
        position = getattr(state, "position", None)
        if position is not None:
            return _shape_centre(position)
    times = _goal_times(problem)
    horizon_s = (max(end for _, end in times) - t0) * dt if times else 10.0
    return start + max(speed * horizon_s, 1.0) * np.array([math.cos(heading), math.sin(heading)])


def shape_geometry(shape: Any) -> Any:
    """A CommonRoad shape as a shapely geometry (in the frame its coordinates are in).

    A circle is drawn here at its radius: commonroad-io 2024.3's own ``Circle.shapely_object``
    is a disc of half the radius (``buffer(radius / 2)``), the one its drawings show."""
    from shapely.geometry import Point
    from shapely.ops import unary_union

    if hasattr(shape, "shapes"):
        return unary_union([shape_geometry(s) for s in shape.shapes])
    if hasattr(shape, "radius"):
        return Point(*np.asarray(shape.center, float)).buffer(float(shape.radius), 64)
    return shape.shapely_object


def disc_of_shape(shape: Any, reading: str) -> tuple[np.ndarray, float]:
    """The disc our methods see for a CommonRoad shape (in the obstacle's frame): its centre
    and radius; ``circumscribed`` holds the shape, ``half_width`` has half its smaller side.

    A circle is its own disc under both readings (commonroad-io's drawing shows circles at half
    their radius; its geometry does not)."""
    if hasattr(shape, "radius") and not hasattr(shape, "shapes"):
        return np.asarray(shape.center, float), float(shape.radius)
    geometry = shape_geometry(shape)
    centre = np.array(geometry.centroid.coords[0])
    if reading == "half_width":
        box = np.array(geometry.minimum_rotated_rectangle.exterior.coords)[:4]
        sides = np.hypot(*np.diff(np.vstack([box, box[:1]]), axis=0).T)
        return centre, float(sides.min() / 2.0)
    points = np.array(geometry.convex_hull.exterior.coords)
    return centre, float(np.max(np.hypot(*(points - centre).T)))


def discs_of_shape(shape: Any, reading: str, n_discs: int = 3
                   ) -> list[tuple[np.ndarray, float]]:
    """The discs our methods see for a CommonRoad shape (in the obstacle's frame), each a
    centre and a radius: under ``cover`` the shape's smallest bounding rectangle covered by
    ``n_discs`` discs along its long side (:func:`~pipeline.loop.cover.cover_centres`; a
    circle is its own disc), else the one disc of :func:`disc_of_shape`."""
    if reading != "cover":
        return [disc_of_shape(shape, reading)]
    if hasattr(shape, "radius") and not hasattr(shape, "shapes"):
        return [(np.asarray(shape.center, float), float(shape.radius))]
    from pipeline.loop.cover import cover_centres

    box = np.array(shape_geometry(shape).minimum_rotated_rectangle.exterior.coords)[:4]
    centre = box.mean(axis=0)
    sides = np.diff(np.vstack([box, box[:1]]), axis=0)[:2]     # two adjacent sides
    lengths = np.hypot(sides[:, 0], sides[:, 1])
    along = sides[0] / lengths[0] if lengths[0] > 0 else np.array([1.0, 0.0])
    across = np.array([-along[1], along[0]])
    local, radius = cover_centres(float(lengths[0]), float(lengths[1]), n_discs)
    return [(centre + x * along + y * across, radius) for x, y in local]


def _tracks(scenario: Any, problem: Any, cr: CommonRoadConfig, t0: int,
            n_samples: int) -> tuple[ObstacleTracks, tuple[int, ...], tuple[int, ...]]:
    """Every obstacle's disc tracks over ``n_samples`` time steps from ``t0`` (one per disc of
    :func:`discs_of_shape`); the CommonRoad id of each track and the ids dropped as the ego's
    recording (obstacles never recorded in the window are left out too)."""
    start = np.asarray(problem.initial_state.position, float)
    positions, presents, radii, ids, ego = [], [], [], [], []
    for obstacle in sorted(scenario.obstacles, key=lambda o: o.obstacle_id):
        at_start = _position(obstacle.state_at_time(t0))
        if at_start is not None and np.hypot(*(at_start - start)) <= cr.ego_match_tolerance_m:
            ego.append(int(obstacle.obstacle_id))
            continue
        discs = discs_of_shape(obstacle.obstacle_shape, cr.obstacle_disc, cr.cover_discs)
        centres = np.zeros((len(discs), n_samples, 2))
        present = np.zeros(n_samples, bool)
        for k in range(n_samples):
            state = obstacle.state_at_time(t0 + k)
            position = _position(state)
            if position is None:
                continue
            angle = _angle(getattr(state, "orientation", 0.0))
            c, s = math.cos(angle), math.sin(angle)
            for i, (centre, _) in enumerate(discs):
                centres[i, k] = position + [c * centre[0] - s * centre[1],
                                            s * centre[0] + c * centre[1]]
            present[k] = True
        if not present.any():
            continue
        for i, (_, radius) in enumerate(discs):
            _fill_absent(centres[i], present)
            positions.append(centres[i])
            presents.append(present.copy())
            radii.append(radius)
            ids.append(int(obstacle.obstacle_id))
    return ObstacleTracks(np.array(positions).reshape(-1, n_samples, 2),
                          np.array(presents, bool).reshape(-1, n_samples),
                          np.array(radii, float)), tuple(ids), tuple(ego)


def _position(state: Any) -> np.ndarray | None:
    """A state's position (an uncertain one, a shape: its centre), or None."""
    position = getattr(state, "position", None) if state is not None else None
    if position is None:
        return None
    if hasattr(position, "center") or hasattr(position, "shapes"):
        return _shape_centre(position)
    return np.asarray(position, float)


def _angle(orientation: Any) -> float:
    """A state's orientation (an uncertain one, an interval: its middle; none: 0)."""
    if orientation is None:
        return 0.0
    if hasattr(orientation, "start") and hasattr(orientation, "end"):
        return 0.5 * (float(orientation.start) + float(orientation.end))
    return float(orientation)


def _fill_absent(track: np.ndarray, present: np.ndarray) -> None:
    """Samples outside the recording take the nearest recorded place (in place)."""
    where = np.flatnonzero(present)
    nearest = where[np.clip(np.searchsorted(where, np.arange(present.size)), 0, where.size - 1)]
    before = where[np.clip(np.searchsorted(where, np.arange(present.size)) - 1, 0,
                           where.size - 1)]
    pick = np.where(np.abs(before - np.arange(present.size))
                    < np.abs(nearest - np.arange(present.size)), before, nearest)
    track[~present] = track[pick[~present]]


def ego_states(trajectory: pd.DataFrame, initial_time_step: int) -> list[Any]:
    """Our logged run as CommonRoad states of the kinematic single-track model (position,
    steering angle, speed, orientation, time step), one per logged step."""
    from commonroad.scenario.state import KSState

    columns = [trajectory[c].to_numpy(float) for c in ("X_m", "Y_m", "delta_rad", "vx_mps",
                                                      "psi_rad")]
    return [KSState(position=np.array([x, y]), steering_angle=float(delta),
                    velocity=float(v), orientation=float(psi), time_step=initial_time_step + k)
            for k, (x, y, delta, v, psi) in enumerate(zip(*columns, strict=True))]


def ego_solution(case: CommonRoadCase, trajectory: pd.DataFrame, vehicle_type: str) -> Any:
    """Our run as a CommonRoad solution (``commonroad.common.solution.Solution``): the
    kinematic single-track model's trajectory of the planning problem, ``vehicle_type``'s
    parameters."""
    from commonroad.common.solution import (
        CostFunction,
        PlanningProblemSolution,
        Solution,
        VehicleModel,
        VehicleType,
    )
    from commonroad.scenario.trajectory import Trajectory

    states = ego_states(trajectory, case.initial_time_step)
    solution = PlanningProblemSolution(
        planning_problem_id=case.planning_problem.planning_problem_id,
        vehicle_model=VehicleModel.KS, vehicle_type=VehicleType[vehicle_type],
        cost_function=CostFunction.JB1,
        trajectory=Trajectory(case.initial_time_step, states))
    return Solution(case.commonroad_scenario.scenario_id, [solution])


def write_solution(solution: Any, path: Path) -> Path:
    """Write a CommonRoad solution as its XML (commonroad-io's writer) to ``path``."""
    from commonroad.common.solution import CommonRoadSolutionWriter

    path = Path(path)
    CommonRoadSolutionWriter(solution).write_to_file(output_path=str(path.parent),
                                                     filename=path.name, overwrite=True)
    return path


def ego_cover_vehicle(vehicle: VehicleConfig, cr: CommonRoadConfig) -> VehicleConfig:
    """The vehicle as ``scenario.commonroad`` shapes the ego: under ``obstacle_disc=cover``
    ``vehicle_type``'s rectangle covered by ``cover_discs`` discs (``footprint_radius_m``,
    ``footprint_discs`` and ``footprint_span_m`` set from it, as the file sets the start and
    the speed); under the earlier readings the vehicle as configured."""
    if cr.obstacle_disc != "cover":
        return vehicle
    from pipeline.loop.cover import rectangle_cover

    length_m, width_m = vehicle_shape_m(cr.vehicle_type)
    offsets, radius = rectangle_cover(length_m, width_m, cr.cover_discs)
    return replace(vehicle, footprint_radius_m=round(radius, 9),
                   footprint_discs=cr.cover_discs,
                   footprint_span_m=round(float(offsets[-1] - offsets[0]), 9))


def vehicle_shape_m(vehicle_type: str) -> tuple[float, float]:
    """Length and width of a commonroad-vehicle-models parameter set (the ego's true
    shape)."""
    from vehiclemodels.parameters_vehicle1 import parameters_vehicle1
    from vehiclemodels.parameters_vehicle2 import parameters_vehicle2
    from vehiclemodels.parameters_vehicle3 import parameters_vehicle3

    make = {"FORD_ESCORT": parameters_vehicle1, "BMW_320i": parameters_vehicle2,
            "VW_VANAGON": parameters_vehicle3}[vehicle_type]
    params = make()
    return float(params.l), float(params.w)
