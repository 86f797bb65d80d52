"""Scenario stage: start, goal, obstacles over time, and the straight start-to-goal line frame.

Obstacles are circles. How they move is the scenario's :class:`ObstacleMotion`: by default
(the scripted scenarios) they are invisible until their appearance time and then move at
constant velocity from the position at which they appear; recorded pedestrians
(:mod:`pipeline.loop.pedestrians`) move on their recorded tracks, and the vehicle sees them only
within a sensor range (:meth:`ObstacleSnapshot.sensed_from`).

Where a scenario comes from is its *source* (:class:`ScenarioSource`), chosen by
``scenario.source._target_`` in the scenario's YAML as a planner of one's own is chosen: the
scripted scenario and its family (:class:`ScriptedSource`, here), the recorded pedestrians
(:class:`pipeline.loop.pedestrians.PedestrianSource`), a CommonRoad file
(:class:`pipeline.loop.commonroad_scenario.CommonRoadSource`), or a class of one's own.
:func:`build_scenario` and :func:`family_members` ask the source; nothing after this stage asks
which source a scenario came from.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from math import inf, sqrt
from typing import Any, ClassVar, Protocol

import numpy as np

from pipeline.errors import ConfigError, MissingExtraError
from pipeline.loop.arrays import KernelValues
from pipeline.loop.settings import (
    FamilyConfig,
    ObstacleConfig,
    ScenarioConfig,
    ScenarioSourceConfig,
)
from pipeline.validation import build_target, resolve_target


@dataclass(frozen=True)
class ObstacleSnapshot:
    """Obstacle states at one instant (arrays over obstacles, global frame).

    Attributes
    ----------
    positions_m : ndarray, shape (n, 2)
    velocities_mps : ndarray, shape (n, 2)
    radii_m : ndarray, shape (n,)
    visible : ndarray of bool, shape (n,)
    """

    positions_m: np.ndarray
    velocities_mps: np.ndarray
    radii_m: np.ndarray
    visible: np.ndarray

    def only_visible(self) -> ObstacleSnapshot:
        keep = self.visible
        if np.count_nonzero(keep) == keep.size:  # all seen (the common case): nothing to drop
            return self
        return ObstacleSnapshot(self.positions_m[keep], self.velocities_mps[keep],
                                self.radii_m[keep], self.visible[keep])

    def predicted_positions(self, times_ahead_s: np.ndarray) -> np.ndarray:
        """Constant-velocity prediction, shape (len(times_ahead_s), n, 2)."""
        t = np.asarray(times_ahead_s, dtype=float)[:, None, None]
        return self.positions_m[None, :, :] + t * self.velocities_mps[None, :, :]

    def sensed_from(self, position_m: np.ndarray, sensor_range_m: float) -> ObstacleSnapshot:
        """The snapshot as a sensor at ``position_m`` sees it: visible only where also within
        ``sensor_range_m`` (centre distance, m); positions stay the true ones."""
        d = self.positions_m - np.asarray(position_m, dtype=float)[None, :]
        near = np.hypot(d[:, 0], d[:, 1]) <= sensor_range_m
        return ObstacleSnapshot(self.positions_m, self.velocities_mps, self.radii_m,
                                self.visible & near)

    def nearest_first(self, position_m: np.ndarray) -> ObstacleSnapshot:
        """The obstacles ordered by centre distance from ``position_m`` (the MPC fills its
        ``max_obstacles`` slots in this order; ties keep their index order)."""
        d = self.positions_m - np.asarray(position_m, dtype=float)[None, :2]
        order = np.argsort(np.hypot(d[:, 0], d[:, 1]), kind="stable")
        return ObstacleSnapshot(self.positions_m[order], self.velocities_mps[order],
                                self.radii_m[order], self.visible[order])


class ObstacleMotion(Protocol):
    """How a scenario's obstacles move: their true positions (n, 2), velocities (n, 2) and
    presence (n,) at a time (s). The scripted scenarios need none (their constant-velocity
    arrays, :meth:`Scenario.obstacles_at`); recorded pedestrians use
    :class:`pipeline.loop.pedestrians.RecordedTrackMotion`."""

    def states_at(self, time_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...


@dataclass(frozen=True)
class LineFrame:
    """Frame whose x axis runs from the start to the goal (the lateral model's reference line)."""

    origin_m: np.ndarray
    heading_rad: float

    @cached_property
    def cos_sin(self) -> tuple[Any, ...]:
        """``cos`` and ``sin`` of the heading (numpy's, computed once per frame)."""
        return np.cos(self.heading_rad), np.sin(self.heading_rad)

    def to_line(self, points_m: np.ndarray) -> np.ndarray:
        d = np.asarray(points_m, dtype=float) - self.origin_m
        if self.heading_rad == 0.0:
            # cos 0 = 1 and sin 0 = 0 exactly: the rotation below gives these values (for
            # finite points), without its six small-array operations
            return d
        c, s = self.cos_sin
        out = np.empty(d.shape)
        out[..., 0] = c * d[..., 0] + s * d[..., 1]
        out[..., 1] = -s * d[..., 0] + c * d[..., 1]
        return out

    def vectors_to_line(self, vectors: np.ndarray) -> np.ndarray:
        v = np.asarray(vectors, dtype=float)
        if self.heading_rad == 0.0:
            return v.copy()  # the rotation by 0 (see to_line)
        c, s = self.cos_sin
        return np.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1]], axis=-1)

    def to_global(self, points_line_m: np.ndarray) -> np.ndarray:
        c, s = self.cos_sin
        p = np.asarray(points_line_m, dtype=float)
        return np.stack([c * p[..., 0] - s * p[..., 1], s * p[..., 0] + c * p[..., 1]],
                        axis=-1) + self.origin_m


@dataclass(frozen=True)
class Scenario:
    """A closed-loop scenario built from :class:`ScenarioConfig`."""

    name: str
    start_m: np.ndarray
    start_heading_rad: float
    goal_m: np.ndarray
    goal_tolerance_m: float
    speed_mps: float
    initial_speed_mps: float
    sample_time_s: float
    n_steps: int
    plant_substeps: int
    obstacle_start_m: np.ndarray
    obstacle_velocity_mps: np.ndarray
    obstacle_radius_m: np.ndarray
    obstacle_appear_s: np.ndarray
    obstacle_anchor: str = "world"
    #: None: constant velocity from the ``obstacle_*`` arrays (the scripted obstacles)
    obstacle_motion: ObstacleMotion | None = None
    #: the planner and the MPC see an obstacle only within this centre distance (m); None: all
    sensor_range_m: float | None = None
    #: hand the visible obstacles to the planner and the MPC nearest first (else index order)
    nearest_first: bool = False
    #: end the run at the first step the vehicle's footprint overlaps a present obstacle
    #: (termination ``contact``; among walkers: no metric on a run that drove through one)
    end_at_contact: bool = False
    #: the road as polygons (global, m; each (P, 2)): what the lateral MPC keeps the ego on
    #: with ``controller.road_edge_weight``; empty: no road (the scripted scenarios)
    road_polygons_m: tuple[np.ndarray, ...] = ()

    @property
    def n_obstacles(self) -> int:
        return int(self.obstacle_radius_m.shape[0])

    @property
    def line_frame(self) -> LineFrame:
        d = self.goal_m - self.start_m
        return LineFrame(self.start_m.copy(), float(np.arctan2(d[1], d[0])))

    def obstacles_at(self, time_s: float) -> ObstacleSnapshot:
        """Obstacle positions at ``time_s``; before appearance an obstacle sits where it will appear.

        With an :attr:`obstacle_motion`, its states; visible where present (the sensor range
        is applied by the loop, which knows where the vehicle is)."""
        if self.obstacle_motion is not None:
            positions, velocities, present = self.obstacle_motion.states_at(time_s)
            return ObstacleSnapshot(positions, velocities, self.obstacle_radius_m.copy(),
                                    present)
        elapsed = np.maximum(time_s - self.obstacle_appear_s, 0.0)[:, None]
        positions = self.obstacle_start_m + elapsed * self.obstacle_velocity_mps
        # a small tolerance so that an obstacle appearing at t = 3.0 s is seen at step 30
        visible = time_s + 1e-9 >= self.obstacle_appear_s
        return ObstacleSnapshot(positions, self.obstacle_velocity_mps.copy(),
                                self.obstacle_radius_m.copy(), visible)


    def attraction_goal_m(self, position_m: np.ndarray) -> np.ndarray:
        """Where the planner's attraction pulls the vehicle at ``position_m``: the goal here
        (a scenario with a road may pull along it)."""
        return self.goal_m

    @property
    def follows_road(self) -> bool:
        """Whether :meth:`attraction_goal_m` moves with the vehicle (the loop asks it each
        step)."""
        return False

    @property
    def attraction_route(self) -> tuple[np.ndarray, float, float] | None:
        """The polyline (P, 2) the planner's attraction follows, how far ahead along it (m)
        it pulls at least and how long ahead at the ego's speed (s), for a planner that
        follows it along its rollout (:meth:`~pipeline.loop.planner.ApfPlanner.follow_route`);
        None: the goal."""
        return None

    @property
    def senses(self) -> bool:
        """Whether the loop must ask :meth:`sense` what is seen (a sensor range here; a
        scenario with occluders too)."""
        return self.sensor_range_m is not None

    def sense(self, snapshot: ObstacleSnapshot, position_m: np.ndarray,
              reach_m: float) -> ObstacleSnapshot:
        """``snapshot`` as the vehicle at ``position_m`` sees it: within
        :attr:`sensor_range_m` (centre distance). ``reach_m``: the vehicle's reach from
        ``position_m`` (a scenario that hides obstacles never hides one within it)."""
        if self.sensor_range_m is None:
            return snapshot
        return snapshot.sensed_from(position_m, self.sensor_range_m)

    def nominal_position_m(self, time_s: float) -> np.ndarray:
        """Where a vehicle at ``speed_mps`` along the start-goal line would be at ``time_s``."""
        d = self.goal_m - self.start_m
        return self.start_m + self.speed_mps * time_s * d / np.linalg.norm(d)

    def anchored(self, which: np.ndarray, vehicle_m: np.ndarray) -> Scenario:
        """The scenario with obstacles ``which`` (bool mask) moved by the vehicle's offset from
        its nominal place at their appearance (``obstacle_anchor="vehicle"``)."""
        starts = self.obstacle_start_m.copy()
        for j in np.flatnonzero(which):
            starts[j] += np.asarray(vehicle_m, float) \
                - self.nominal_position_m(float(self.obstacle_appear_s[j]))
        return replace(self, obstacle_start_m=starts)


#: The key that chooses a scenario's source (what its one-line refusals name).
SOURCE_KEY = "scenario.source._target_"


@dataclass(frozen=True)
class Extra:
    """An optional extra a scenario source needs: the modules it imports and the one line that
    says how to install it."""

    name: str
    modules: tuple[str, ...]
    install_line: str

    def missing(self) -> str | None:
        """None when every module imports; else :attr:`install_line`."""
        import importlib

        try:
            for module in self.modules:
                importlib.import_module(module)
        except ImportError:
            return self.install_line
        return None

    def require(self) -> None:
        """Raise :class:`~pipeline.errors.MissingExtraError` (the install line) when missing."""
        missing = self.missing()
        if missing is not None:
            raise MissingExtraError(f"config error: {missing}")


class ScenarioSource(Protocol):
    """Where scenarios come from: one class per source, named by ``scenario.source._target_``
    and built as ``cls(scenario_config, vehicle_radius_m)`` (the scenario's configuration, a
    family's base for a family; the vehicle's footprint radius, m, which a draw keeps its
    obstacles off).

    Attributes read with a default when a class leaves them out: ``needs_extra`` (None),
    ``parts_key`` (None: the tune's training and held-out families differ by seed only; a key
    such as ``scenario.pedestrians.scenes``: a list the tune splits into disjoint parts) and
    ``study`` (None: the plain run; else the dotted path of a function ``(cfg, out_dir) ->
    objective value(s)`` that runs one scenario of this source in its place and judges it its
    own way, as CommonRoad's drivability checker does).
    """

    #: The optional extra this source needs (None: none); checked before anything else.
    needs_extra: ClassVar[Extra | None]

    def build(self, cfg: ScenarioConfig) -> Scenario:
        """The scenario the loop runs, from a scenario configuration (one member's)."""
        ...

    def member(self, seed: int, index: int) -> ScenarioConfig:
        """Member ``index`` of the family drawn with ``seed``: a plain scenario configuration
        (``family = None``) that :meth:`build` turns into the scenario, the same on every
        machine and whatever the family's size. A source without families refuses."""
        ...


def source_class(target: str) -> type:
    """The class ``target`` (``module.Class``) names, with the methods a source has; a
    :class:`ConfigError` naming ``scenario.source._target_`` otherwise."""
    cls = resolve_target(SOURCE_KEY, target)
    missing = [name for name in ("build", "member") if not callable(getattr(cls, name, None))]
    if missing:
        raise ConfigError(SOURCE_KEY, target, "a scenario source: a class with build(cfg) and "
                          "member(seed, index) (pipeline.loop.scenario.ScenarioSource; it has "
                          f"no {', '.join(m + '()' for m in missing)})")
    return cls


def scenario_source(cfg: ScenarioConfig, vehicle_radius_m: float = 1.0) -> ScenarioSource:
    """The source of ``cfg`` (:meth:`ScenarioConfig.source_target_of`), built for it."""
    target = cfg.source_target
    source_class(target)  # its methods, before it is built
    return build_target(SOURCE_KEY, target, (cfg, float(vehicle_radius_m)),
                        "cls(scenario_config, vehicle_radius_m)")


def source_extra(scenario: Any) -> Extra | None:
    """The optional extra the source of ``scenario`` (a scenario mapping, typed or not yet:
    asked before the rest of the configuration is checked) needs, or None."""
    return getattr(source_class(ScenarioConfig.source_target_of(scenario)), "needs_extra", None)


def build_scenario(cfg: ScenarioConfig) -> Scenario:
    """Turn the scenario config into arrays, by its source (:class:`ScenarioSource`).

    Parameters
    ----------
    cfg : ScenarioConfig

    Returns
    -------
    Scenario
    """
    return scenario_source(cfg).build(cfg)


def scripted_scenario(cfg: ScenarioConfig) -> Scenario:
    """The scripted scenario of ``cfg``: its ``obstacles``, each invisible until its
    appearance time and then at constant velocity."""
    obs = cfg.obstacles
    return Scenario(
        name=cfg.name,
        start_m=np.asarray(cfg.start_xy_m, dtype=float),
        # wrapped once, in closed form, where it enters: [-pi, pi] (the same heading)
        start_heading_rad=math.remainder(float(cfg.start_heading_rad), 2.0 * math.pi),
        goal_m=np.asarray(cfg.goal_xy_m, dtype=float),
        goal_tolerance_m=float(cfg.goal_tolerance_m),
        speed_mps=float(cfg.speed_mps),
        initial_speed_mps=float(cfg.speed_mps if cfg.initial_speed_mps is None
                                else cfg.initial_speed_mps),
        sample_time_s=float(cfg.sample_time_s),
        n_steps=int(cfg.n_steps),
        plant_substeps=int(cfg.plant_substeps),
        obstacle_start_m=np.array([[o.x_m, o.y_m] for o in obs], dtype=float).reshape(-1, 2),
        obstacle_velocity_mps=np.array([[o.vx_mps, o.vy_mps] for o in obs],
                                       dtype=float).reshape(-1, 2),
        obstacle_radius_m=np.array([o.radius_m for o in obs], dtype=float),
        obstacle_appear_s=np.array([o.appear_time_s for o in obs], dtype=float),
        obstacle_anchor=str(getattr(cfg, "obstacle_anchor", "world")),
    )


def with_family_seed(base: ScenarioConfig, seed: int) -> ScenarioConfig:
    """``base`` whose family is drawn with ``seed`` (``base`` itself when it already is)."""
    if base.family is None:
        raise ValueError(f"scenario {base.name} has no family to draw members from")
    if base.family.seed == seed:
        return base
    return replace(base, family=replace(base.family, seed=int(seed)))


def refuse_blocks(cfg: ScenarioConfig, target: str, blocks: dict[str, str]) -> None:
    """A built-in source given a block that belongs to another source (it would be ignored):
    one line naming ``scenario.source._target_`` and the source the block needs.
    ``blocks`` maps a block's name to that source."""
    for block, wanted in blocks.items():
        if getattr(cfg, block) is not None:
            raise ConfigError(SOURCE_KEY, target, f"{wanted} for a scenario with a "
                              f"scenario.{block} block ({target} would ignore it)")


class ScriptedSource:
    """The paper's scenario and its seeded family (``conf/scenario/paper_sudden_obstacle.yaml``
    and ``family.yaml``): the configuration's obstacles, and members drawn by
    :func:`draw_family_member`."""

    needs_extra: ClassVar[Extra | None] = None

    def __init__(self, scenario: ScenarioConfig, vehicle_radius_m: float = 1.0) -> None:
        refuse_blocks(scenario, ScenarioSourceConfig.SCRIPTED,
                      {"pedestrians": ScenarioSourceConfig.PEDESTRIANS,
                       "commonroad": ScenarioSourceConfig.COMMONROAD})
        self.base, self.vehicle_radius_m = scenario, float(vehicle_radius_m)

    def build(self, cfg: ScenarioConfig) -> Scenario:
        return scripted_scenario(cfg)

    def member(self, seed: int, index: int) -> ScenarioConfig:
        return draw_family_member(with_family_seed(self.base, seed), index,
                                  self.vehicle_radius_m)


def _uniform(rng: np.random.Generator, bounds: Sequence[float]) -> float:
    return float(rng.uniform(bounds[0], bounds[1]))


def draw_family_member(base: ScenarioConfig, index: int,
                       vehicle_radius_m: float = 1.0) -> ScenarioConfig:
    """Scenario ``index`` of the family described by ``base.family``.

    The first obstacle is the "sudden" one of the paper: it appears at a random time, a random
    distance ahead of where the vehicle would be at that time and a random lateral offset, and it
    is static, crossing the path (moving toward and over the start-goal line) or oncoming. Up to
    two further obstacles (static or slowly moving) are scattered along the route; draws that
    would sit on the vehicle when they appear are redrawn. Every draw comes from
    ``numpy.random.default_rng([seed, index])``.

    Parameters
    ----------
    base : ScenarioConfig
        Start, goal, speed, timing and ``family`` ranges.
    index : int
        Member number (>= 0).
    vehicle_radius_m : float
        Footprint used to keep further obstacles off the vehicle when they appear.

    Returns
    -------
    ScenarioConfig
        A plain scenario (``family = None``) named ``<base name>_s<seed>_i<index>``.
    """
    fam = base.family
    if fam is None:
        raise ValueError(f"scenario {base.name} has no family to draw members from")
    rng = np.random.default_rng([fam.seed, index])
    start, goal = np.asarray(base.start_xy_m, float), np.asarray(base.goal_xy_m, float)
    e1 = (goal - start) / np.linalg.norm(goal - start)
    e2 = np.array([-e1[1], e1[0]])
    counts = np.arange(1, len(fam.obstacle_count_probabilities) + 1)
    n_obstacles = int(rng.choice(counts, p=np.asarray(fam.obstacle_count_probabilities)))

    def to_global(along: float, lateral: float) -> np.ndarray:
        return start + along * e1 + lateral * e2

    obstacles = [_sudden_obstacle(rng, base, fam, e1, e2, to_global)]
    for _ in range(n_obstacles - 1):
        obstacles.append(_further_obstacle(rng, base, fam, goal, vehicle_radius_m, to_global))
    return replace(base, name=f"{base.name}_s{fam.seed}_i{index:04d}", obstacles=obstacles,
                   family=None)


def _sudden_obstacle(rng: np.random.Generator, base: ScenarioConfig, fam: FamilyConfig,
                     e1: np.ndarray, e2: np.ndarray,
                     to_global: Callable[[float, float], np.ndarray]) -> ObstacleConfig:
    """The family member's first obstacle, the paper's "sudden" one (see
    :func:`draw_family_member`; ``e1``, ``e2``: along and across the start-goal line)."""
    appear = _uniform(rng, fam.appear_time_s)
    along = base.speed_mps * appear + _uniform(rng, fam.ahead_m)
    lateral = _uniform(rng, fam.lateral_m)
    radius = _uniform(rng, fam.radius_m)
    kind = rng.uniform()
    if kind < fam.static_probability:
        vel = np.zeros(2)
    elif kind < fam.static_probability + fam.oncoming_probability:
        vel = -_uniform(rng, fam.oncoming_speed_mps) * e1
    else:
        toward = -np.sign(lateral) if lateral != 0.0 else (1.0 if rng.uniform() < 0.5 else -1.0)
        vel = toward * _uniform(rng, fam.crossing_speed_mps) * e2
    pos = to_global(along, lateral)
    return ObstacleConfig(x_m=float(pos[0]), y_m=float(pos[1]), vx_mps=float(vel[0]),
                          vy_mps=float(vel[1]), radius_m=radius, appear_time_s=appear)


def _further_obstacle(rng: np.random.Generator, base: ScenarioConfig, fam: FamilyConfig,
                      goal: np.ndarray, vehicle_radius_m: float,
                      to_global: Callable[[float, float], np.ndarray]) -> ObstacleConfig:
    """One further obstacle along the route, redrawn (up to 50 times) while it would sit on
    the vehicle when it appears or on the goal."""
    for _attempt in range(50):
        appear_k = _uniform(rng, fam.extra_appear_time_s)
        along_k, lateral_k = _uniform(rng, fam.extra_x_m), _uniform(rng, fam.extra_y_m)
        radius_k = _uniform(rng, fam.radius_m)
        moving = rng.uniform() < 0.5
        heading = rng.uniform(-np.pi, np.pi)
        speed_k = rng.uniform(0.0, 0.5) if moving else 0.0
        vel_k = speed_k * np.array([np.cos(heading), np.sin(heading)])
        nominal = to_global(base.speed_mps * appear_k, 0.0)
        pos_k = to_global(along_k, lateral_k)
        clear = radius_k + vehicle_radius_m + 1.5
        if np.linalg.norm(pos_k - nominal) > clear and np.linalg.norm(pos_k - goal) > clear:
            break
    return ObstacleConfig(x_m=float(pos_k[0]), y_m=float(pos_k[1]), vx_mps=float(vel_k[0]),
                          vy_mps=float(vel_k[1]), radius_m=radius_k, appear_time_s=appear_k)


def family_members(base: ScenarioConfig, vehicle_radius_m: float = 1.0) -> list[ScenarioConfig]:
    """All ``base.family.size`` members, in index order (:meth:`ScenarioSource.member` of the
    family's seed)."""
    if base.family is None:
        raise ValueError("scenario has no family block")
    source = scenario_source(base, vehicle_radius_m)
    return [source.member(base.family.seed, i) for i in range(base.family.size)]


def route_point_ahead(route: KernelValues, x: float, y: float, distance: float,
                      end_x: float, end_y: float) -> tuple[float, float]:
    """The point ``distance`` (m) along the polyline ``route`` (rows ``[x, y]``, at least two)
    beyond the projection of ``(x, y)`` on it (the nearest point of the nearest segment, the
    first of equals); ``(end_x, end_y)`` past its end. Scalar arithmetic, so CPython and numba
    (:mod:`pipeline.loop.compiled`, inside the APF's rollout) run the same statement."""
    best, nearest, share, before, nearest_length = inf, 0, 0.0, 0.0, 0.0
    walked = 0.0
    for i in range(len(route) - 1):
        sx, sy = route[i][0], route[i][1]
        dx, dy = route[i + 1][0] - sx, route[i + 1][1] - sy
        length_sq = dx * dx + dy * dy
        u = ((x - sx) * dx + (y - sy) * dy) / max(length_sq, 1e-12)
        u = min(max(u, 0.0), 1.0)
        qx, qy = sx + u * dx - x, sy + u * dy - y
        gap = sqrt(qx * qx + qy * qy)
        length = sqrt(length_sq)
        if gap < best:
            best, nearest, share, before, nearest_length = gap, i, u, walked, length
        walked += length
    target = before + share * nearest_length + distance
    if target > walked:
        return end_x, end_y
    walked = before
    for i in range(nearest, len(route) - 1):
        sx, sy = route[i][0], route[i][1]
        dx, dy = route[i + 1][0] - sx, route[i + 1][1] - sy
        length = sqrt(dx * dx + dy * dy)
        if walked + length >= target and length > 0.0:
            u = (target - walked) / length
            return sx + u * dx, sy + u * dy
        walked += length
    last = len(route) - 1
    return route[last][0], route[last][1]
