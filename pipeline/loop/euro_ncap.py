"""The Euro NCAP crossings (``scenario=euro_ncap``): the scripted tests of Euro NCAP's AEB/LSS
VRU protocol that the paper's sudden obstacle stands for, as a seeded family.

Each member is one test: a case, the ego's test speed and an impact position, drawn from
``numpy.random.default_rng([seed, index])`` over the protocol's grid (``scenario.source.params``,
every value named, :class:`EuroNcapSettings`). The cases (our reading of the protocol, to be
checked against it; the register lists every value):

* ``CPNC-50``: a child runs out from between two cars parked on the near side (hidden until it
  clears them), impact at 50 % of the ego's width;
* ``CPFA-50``: an adult walks across from the far side (over the oncoming lane), 50 %;
* ``CPNA-25`` / ``CPNA-75``: an adult walks in from the near side, 25 % / 75 %;
* ``CBNAO-50``: a cyclist crosses from the near side from behind a parked car, 50 %.

The geometry is the protocol's idea of a test: the road runs along +x, the ego starts at the
origin on its lane's centre at the test speed, and the road user is placed so that, were the
ego to hold its lane and its speed, its front would meet the road user's centre at the impact
position: ``fraction`` of the ego's width measured from the side the road user comes from.
The road user stands still at its start and walks (rides) at its constant speed from its
start time (a reading: the protocol's short acceleration is left out), timed so that the ego
has driven ``lead_time_s`` before it starts. Parked cars are static rectangles (covered by
discs as every rectangle is, :mod:`pipeline.loop.cover`) that also hide what is behind them
(the line-of-sight test of CommonRoad's occlusion,
:func:`~pipeline.loop.commonroad_scenario.sight_view`).

The protocol's outcome of a test is whether the road user is hit and, if so, the ego's speed
at the impact (:func:`protocol_outcome`), judged on the true shapes (the car's rectangle, the
road user's disc or the bicycle's rectangle, the parked cars' rectangles); the MPC and the
run's own collision check see their disc covers. Nothing here asks which method drove.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any, ClassVar

import numpy as np

from pipeline.errors import ConfigError
from pipeline.loop.commonroad_scenario import sight_view
from pipeline.loop.cover import cover_centres
from pipeline.loop.scenario import (
    Extra,
    ObstacleSnapshot,
    Scenario,
    refuse_blocks,
    with_family_seed,
)
from pipeline.loop.settings import ObstacleConfig, ScenarioConfig, ScenarioSourceConfig
from pipeline.validation import flag

#: The source's class as ``scenario.source._target_`` names it.
TARGET = "pipeline.loop.euro_ncap.EuroNcapSource"
KEY = "scenario.source.params"
KMH = 1.0 / 3.6


@dataclass(frozen=True)
class Case:
    """One of the protocol's test cases: who crosses, from which side, at what speed, the
    impact positions it is tested at and what hides it."""

    name: str
    road_user: str            # child, adult or cyclist
    side: str                 # near (the kerb side, right: y < 0) or far
    impact_fractions: tuple[float, ...]
    obstruction: str          # none, two_parked_cars or parked_car


#: The cases (our reading of Euro NCAP's AEB/LSS VRU protocol; the names are the protocol's).
CASES: dict[str, Case] = {
    "CPNC-50": Case("CPNC-50", "child", "near", (0.5,), "two_parked_cars"),
    "CPFA-50": Case("CPFA-50", "adult", "far", (0.5,), "none"),
    "CPNA-25": Case("CPNA-25", "adult", "near", (0.25,), "none"),
    "CPNA-75": Case("CPNA-75", "adult", "near", (0.75,), "none"),
    "CBNAO-50": Case("CBNAO-50", "cyclist", "near", (0.5,), "parked_car"),
}


@dataclass(frozen=True)
class EuroNcapSettings:
    """``scenario.source.params`` of ``scenario=euro_ncap``: every value of the tests, named
    (defaults: our reading of the protocol; ``conf/scenario/euro_ncap.yaml`` says where each
    comes from). Lengths in m, speeds in km/h as the protocol gives them."""

    cases: tuple[str, ...] = tuple(CASES)
    ego_speeds_kmh: tuple[float, ...] = (10.0, 15.0, 20.0, 25.0, 30.0, 35.0, 40.0, 45.0,
                                         50.0, 55.0, 60.0)
    speed_tolerance_kmh: float = 1.0
    ego_length_m: float = 4.5
    ego_width_m: float = 1.8
    cover_discs: int = 3
    child_speed_kmh: float = 5.0
    adult_near_speed_kmh: float = 5.0
    adult_far_speed_kmh: float = 8.0
    cyclist_speed_kmh: float = 15.0
    child_radius_m: float = 0.25
    adult_radius_m: float = 0.3
    cyclist_length_m: float = 1.9
    cyclist_width_m: float = 0.6
    near_start_m: float = 4.0
    far_start_m: float = 6.0
    parked_car_length_m: float = 4.5
    parked_car_width_m: float = 1.8
    parked_lateral_gap_m: float = 1.0
    parked_cars_gap_m: float = 1.0
    cyclist_obstruction_clearance_m: float = 1.0
    lead_time_s: float = 1.0
    run_on_m: float = 20.0
    lane_width_m: float = 3.5
    oncoming_lane: bool = True
    sensor_range_m: float = 60.0
    occlusion: bool = True
    end_at_contact: bool = False
    step_margin: float = 1.5

    #: Allowed ranges of the numeric keys (inclusive).
    RANGES: ClassVar[dict[str, tuple[float, float]]] = {
        "speed_tolerance_kmh": (0.0, 5.0), "ego_length_m": (1.0, 20.0),
        "ego_width_m": (0.5, 3.0), "cover_discs": (1, 10),
        "child_speed_kmh": (0.5, 30.0), "adult_near_speed_kmh": (0.5, 30.0),
        "adult_far_speed_kmh": (0.5, 30.0), "cyclist_speed_kmh": (0.5, 60.0),
        "child_radius_m": (0.05, 1.0), "adult_radius_m": (0.05, 1.0),
        "cyclist_length_m": (0.5, 3.0), "cyclist_width_m": (0.2, 1.5),
        "near_start_m": (1.0, 30.0), "far_start_m": (1.0, 30.0),
        "parked_car_length_m": (1.0, 20.0), "parked_car_width_m": (0.5, 3.0),
        "parked_lateral_gap_m": (0.0, 10.0), "parked_cars_gap_m": (0.3, 10.0),
        "cyclist_obstruction_clearance_m": (0.0, 10.0), "lead_time_s": (0.0, 10.0),
        "run_on_m": (5.0, 200.0), "lane_width_m": (2.0, 6.0), "sensor_range_m": (1.0, 500.0),
        "step_margin": (1.0, 5.0)}
    FLAGS: ClassVar[tuple[str, ...]] = ("oncoming_lane", "occlusion", "end_at_contact")

    @classmethod
    def of(cls, params: dict[str, Any]) -> EuroNcapSettings:
        """The settings of ``params`` (the draw's own keys, ``case`` and the rest, are
        ignored here); a wrong key or value raises :class:`ConfigError` naming
        ``scenario.source.params.<key>`` and what is allowed."""
        names = {f.name for f in fields(cls)}
        drawn = {"case", "ego_speed_kmh", "nominal_speed_kmh", "impact_fraction"}
        unknown = sorted(set(params) - names - drawn)
        if unknown:
            raise ConfigError(f"{KEY}.{unknown[0]}", params[unknown[0]],
                              "one of the Euro NCAP keys: " + ", ".join(sorted(names)))
        values: dict[str, Any] = {}
        for name, value in params.items():
            if name in drawn:
                continue
            values[name] = _checked(name, value)
        settings = cls(**values)
        # a road user starts outside the ego's path, and beyond the parked cars' far side
        least = settings.ego_width_m / 2.0 + settings.parked_lateral_gap_m \
            + settings.parked_car_width_m
        for key in ("near_start_m", "far_start_m"):
            if getattr(settings, key) <= least:
                raise ConfigError(f"{KEY}.{key}", getattr(settings, key),
                                  f"a number in ({least:g}, 30] (m): beyond ego_width_m / 2 + "
                                  "parked_lateral_gap_m + parked_car_width_m, where a road user "
                                  "starts")
        return settings

    def speed_mps(self, road_user: str, side: str) -> float:
        """The road user's crossing speed (m/s)."""
        kmh = {"child": self.child_speed_kmh, "cyclist": self.cyclist_speed_kmh}.get(
            road_user, self.adult_near_speed_kmh if side == "near" else self.adult_far_speed_kmh)
        return kmh * KMH

    @property
    def road_edges_m(self) -> tuple[float, float]:
        """The road's right and left edges (lateral, m): the ego's lane centred on y = 0 and,
        with ``oncoming_lane``, the oncoming lane to its left."""
        half = self.lane_width_m / 2.0
        return -half, half + (self.lane_width_m if self.oncoming_lane else 0.0)

    def to_params(self) -> dict[str, Any]:
        """The settings as ``scenario.source.params`` (plain YAML values)."""
        out: dict[str, Any] = {}
        for name in (f.name for f in fields(self)):
            value = getattr(self, name)
            out[name] = list(value) if isinstance(value, tuple) else value
        return out


def _checked(name: str, value: Any) -> Any:
    """One key of :class:`EuroNcapSettings` checked (its one-line refusal otherwise)."""
    key = f"{KEY}.{name}"
    if name == "cases":
        cases = tuple(value) if isinstance(value, (list, tuple)) else None
        if not cases or any(c not in CASES for c in cases) or len(set(cases)) != len(cases):
            raise ConfigError(key, value, "a non-empty list of distinct cases from "
                              + ", ".join(CASES))
        return cases
    if name == "ego_speeds_kmh":
        speeds = tuple(value) if isinstance(value, (list, tuple)) else None
        if not speeds or any(isinstance(v, bool) or not isinstance(v, (int, float))
                             or not math.isfinite(v) or not 5.0 <= v <= 130.0 for v in speeds):
            raise ConfigError(key, value, "a non-empty list of speeds in [5, 130] km/h")
        return tuple(float(v) for v in speeds)
    if name in EuroNcapSettings.FLAGS:
        flag(key, value)
        return value
    low, high = EuroNcapSettings.RANGES[name]
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or not low <= value <= high:
        raise ConfigError(key, value, f"a number in [{low:g}, {high:g}]")
    if name == "cover_discs":
        if int(value) != value:
            raise ConfigError(key, value, f"an integer in [{low:g}, {high:g}]")
        return int(value)
    return float(value)


@dataclass(frozen=True)
class Encounter:
    """One test's geometry (global frame: the road along +x, the ego's lane centre y = 0).

    Attributes
    ----------
    case : Case
    ego_speed_mps, impact_fraction : float
    crossing_x_m : float
        The line the road user crosses on (its centre's x).
    impact_y_m : float
        Where on that line the road user's centre is when the ego's front reaches it
        (the impact position).
    start_m, velocity_mps : ndarray, shape (2,)
        The road user's centre at its start and its velocity once it moves.
    move_time_s : float
        When it starts to move.
    impact_time_s : float
        When the ego's front, at the test speed in its lane, reaches the crossing line.
    user_discs : ndarray, shape (k, 2)
        The road user's cover: its discs' offsets from its centre.
    user_radius_m : float
        Their radius.
    parked_m : ndarray, shape (p, 4, 2)
        The parked cars' rectangles (corners counter-clockwise).
    goal_x_m : float
    n_steps : int
    """

    case: Case
    ego_speed_mps: float
    impact_fraction: float
    crossing_x_m: float
    impact_y_m: float
    start_m: np.ndarray
    velocity_mps: np.ndarray
    move_time_s: float
    impact_time_s: float
    user_discs: np.ndarray
    user_radius_m: float
    parked_m: np.ndarray
    goal_x_m: float
    n_steps: int


def encounter(settings: EuroNcapSettings, case: Case, ego_speed_kmh: float,
              impact_fraction: float, sample_time_s: float) -> Encounter:
    """The geometry of one test (see the module docstring and :class:`Encounter`)."""
    s = settings
    v_ego = ego_speed_kmh * KMH
    sign = -1.0 if case.side == "near" else 1.0        # the side the road user comes from
    half_width = s.ego_width_m / 2.0
    impact_y = sign * (half_width - impact_fraction * s.ego_width_m)
    start_y = sign * (s.near_start_m if case.side == "near" else s.far_start_m)
    v_user = s.speed_mps(case.road_user, case.side)
    if case.road_user == "cyclist":
        # a bicycle crossing: its long side along its motion (across the road)
        centres, radius = cover_centres(s.cyclist_width_m, s.cyclist_length_m, s.cover_discs)
    else:
        centres = np.zeros((1, 2))
        radius = s.child_radius_m if case.road_user == "child" else s.adult_radius_m
    walk_s = abs(start_y - impact_y) / v_user
    front_m = s.ego_length_m / 2.0                      # the ego's front from its centre
    impact_time = s.lead_time_s + walk_s
    crossing_x = front_m + v_ego * impact_time
    parked = _parked_cars(s, case, crossing_x, half_width)
    goal_x = crossing_x + s.run_on_m
    n_steps = int(math.ceil(s.step_margin * goal_x / v_ego / sample_time_s)) + 10
    return Encounter(case, v_ego, impact_fraction, crossing_x, impact_y,
                     np.array([crossing_x, start_y]), np.array([0.0, -sign * v_user]),
                     s.lead_time_s, impact_time, centres, float(radius), parked, goal_x,
                     n_steps)


def _rectangle(x_low: float, x_high: float, y_low: float, y_high: float) -> np.ndarray:
    """An axis-aligned rectangle's corners, counter-clockwise."""
    return np.array([[x_low, y_low], [x_high, y_low], [x_high, y_high], [x_low, y_high]])


def _parked_cars(s: EuroNcapSettings, case: Case, crossing_x: float, half_width: float
                 ) -> np.ndarray:
    """The parked cars of ``case`` on the near side: their inner edge
    ``parked_lateral_gap_m`` outside the ego's side; two with a gap of ``parked_cars_gap_m``
    centred on the crossing line (the child comes out between them), or one whose front end is
    ``cyclist_obstruction_clearance_m`` before the bicycle's near edge (the cyclist comes out
    in front of it)."""
    inner = -(half_width + s.parked_lateral_gap_m)
    outer = inner - s.parked_car_width_m
    length = s.parked_car_length_m
    if case.obstruction == "two_parked_cars":
        gap = s.parked_cars_gap_m / 2.0
        return np.stack([_rectangle(crossing_x - gap - length, crossing_x - gap, outer, inner),
                         _rectangle(crossing_x + gap, crossing_x + gap + length, outer, inner)])
    if case.obstruction == "parked_car":
        front = crossing_x - s.cyclist_width_m / 2.0 - s.cyclist_obstruction_clearance_m
        return _rectangle(front - length, front, outer, inner)[None]
    return np.zeros((0, 4, 2))


@dataclass(frozen=True)
class EuroNcapScenario(Scenario):
    """A test: the road user's discs first (:attr:`user_discs` of them), then the parked cars'.
    Every obstacle is present from the start; the road user stands at its start until
    ``obstacle_appear_s`` (its start time) and then moves at constant velocity; the parked cars
    hide what is behind them from the ego within the sensor range
    (:func:`~pipeline.loop.commonroad_scenario.sight_view`)."""

    user_discs: int = 1
    occluders_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 2)))
    occluder_of: np.ndarray = field(default_factory=lambda: np.zeros(0, int))

    def obstacles_at(self, time_s: float) -> ObstacleSnapshot:
        moving = time_s + 1e-9 >= self.obstacle_appear_s
        elapsed = np.maximum(time_s - self.obstacle_appear_s, 0.0)[:, None]
        positions = self.obstacle_start_m + elapsed * self.obstacle_velocity_mps
        velocities = np.where(moving[:, None], self.obstacle_velocity_mps, 0.0)
        return ObstacleSnapshot(positions, velocities, self.obstacle_radius_m.copy(),
                                np.ones(self.n_obstacles, bool))

    @property
    def senses(self) -> bool:
        return True

    def sense(self, snapshot: ObstacleSnapshot, position_m: np.ndarray,
              reach_m: float) -> ObstacleSnapshot:
        """What the ego at ``position_m`` sees: within the sensor range and not behind a parked
        car; anything within its reach is always seen (no contact escapes the check)."""
        return sight_view(snapshot, position_m, reach_m,
                          Scenario.sense(self, snapshot, position_m, reach_m).visible,
                          self.occluders_m, self.occluder_of)


class EuroNcapSource:
    """The Euro NCAP family's source (``conf/scenario/euro_ncap.yaml``): members drawn by
    :meth:`member`, each built by :meth:`build` (see the module docstring)."""

    needs_extra: ClassVar[Extra | None] = None

    def __init__(self, scenario: ScenarioConfig, vehicle_radius_m: float = 1.0) -> None:
        refuse_blocks(scenario, TARGET, {"pedestrians": ScenarioSourceConfig.PEDESTRIANS,
                                         "commonroad": ScenarioSourceConfig.COMMONROAD})
        self.base = scenario
        self.settings = EuroNcapSettings.of(dict(scenario.source.params))

    def combinations(self) -> list[tuple[Case, float, float]]:
        """The protocol's grid: every case at each of its impact fractions and each test
        speed (km/h), in the configuration's order."""
        s = self.settings
        return [(CASES[name], fraction, speed) for name in s.cases
                for fraction in CASES[name].impact_fractions for speed in s.ego_speeds_kmh]

    def draw(self, seed: int, index: int) -> tuple[Case, float, float, float]:
        """Member ``index`` of seed ``seed``: its case, nominal test speed (km/h), impact
        fraction and the test speed it drives (the nominal one within
        ``speed_tolerance_kmh``). The grid (:meth:`combinations`) is walked in an order
        drawn from ``default_rng([seed])``, so the first members cover it once, the next
        once more; each member's speed within the tolerance is drawn from
        ``default_rng([seed, index])`` (neither depends on the family's size)."""
        grid = self.combinations()
        order = np.random.default_rng([int(seed)]).permutation(len(grid))
        case, fraction, nominal = grid[int(order[int(index) % len(grid)])]
        tolerance = self.settings.speed_tolerance_kmh
        jitter = float(np.random.default_rng([int(seed), int(index)]).uniform(-tolerance,
                                                                                tolerance))
        return case, nominal, fraction, min(max(nominal + jitter, 5.0), 130.0)

    def member(self, seed: int, index: int) -> ScenarioConfig:
        """Member ``index``: a plain scenario named ``<base>_s<seed>_i<index>_<case>_<nominal
        speed>`` whose params hold the draw (``case``, ``nominal_speed_kmh``,
        ``ego_speed_kmh``, ``impact_fraction``)."""
        base = with_family_seed(self.base, seed)
        case, nominal_kmh, fraction, speed_kmh = self.draw(seed, index)
        params = {**self.settings.to_params(), "case": case.name, "ego_speed_kmh": speed_kmh,
                  "nominal_speed_kmh": nominal_kmh, "impact_fraction": fraction}
        geometry = encounter(self.settings, case, speed_kmh, fraction,
                             float(base.sample_time_s))
        return replace(base, name=f"{base.name}_s{seed}_i{index:04d}_{case.name}_"
                                  f"{nominal_kmh:g}kmh",
                       start_xy_m=[0.0, 0.0], start_heading_rad=0.0,
                       goal_xy_m=[float(geometry.goal_x_m), 0.0],
                       speed_mps=float(geometry.ego_speed_mps), initial_speed_mps=None,
                       n_steps=int(geometry.n_steps),
                       obstacles=_obstacles(geometry, self.settings.cover_discs),
                       family=None, source=replace(base.source, params=params))

    def build(self, cfg: ScenarioConfig) -> Scenario:
        """The test of a member's configuration (its params hold the draw)."""
        params = dict(cfg.source.params)
        if "case" not in params:
            raise ConfigError("scenario.family", None, "a Euro NCAP family's member (draw "
                              "one with scenario.family; scenario=euro_ncap is a family)")
        case = CASES.get(params["case"])
        if case is None:
            raise ConfigError(f"{KEY}.case", params["case"], "one of " + ", ".join(CASES))
        geometry = encounter(self.settings, case, float(params["ego_speed_kmh"]),
                             float(params["impact_fraction"]), float(cfg.sample_time_s))
        from pipeline.loop.scenario import scripted_scenario

        scripted = scripted_scenario(cfg)
        n_user = geometry.user_discs.shape[0]
        parked = geometry.parked_m
        discs_per_car = (scripted.n_obstacles - n_user) // max(parked.shape[0], 1)
        own = np.concatenate([np.full(n_user, -1),
                              np.repeat(np.arange(parked.shape[0]), discs_per_car)]).astype(int)
        s = self.settings
        plain = {f.name: getattr(scripted, f.name) for f in fields(Scenario)}
        right, left = s.road_edges_m
        road = np.array([[-50.0, right], [geometry.goal_x_m + 50.0, right],
                         [geometry.goal_x_m + 50.0, left], [-50.0, left]])
        plain.update(sensor_range_m=s.sensor_range_m, nearest_first=True,
                     end_at_contact=s.end_at_contact, road_polygons_m=(road,))
        return EuroNcapScenario(**plain, user_discs=n_user,
                                occluders_m=parked if s.occlusion else np.zeros((0, 4, 2)),
                                occluder_of=own if s.occlusion else np.zeros(0, int))


def _obstacles(geometry: Encounter, cover_discs: int) -> list[ObstacleConfig]:
    """The member's obstacles: the road user's discs (moving from its start time), then each
    parked car's cover of ``cover_discs`` discs (static)."""
    out = [ObstacleConfig(x_m=float(geometry.start_m[0] + dx),
                          y_m=float(geometry.start_m[1] + dy),
                          vx_mps=float(geometry.velocity_mps[0]),
                          vy_mps=float(geometry.velocity_mps[1]),
                          radius_m=float(geometry.user_radius_m),
                          appear_time_s=float(geometry.move_time_s))
           for dx, dy in geometry.user_discs.tolist()]
    for corners in geometry.parked_m:
        low, high = corners.min(axis=0), corners.max(axis=0)
        centres, radius = cover_centres(float(high[0] - low[0]), float(high[1] - low[1]),
                                        cover_discs)
        middle = (low + high) / 2.0
        out += [ObstacleConfig(x_m=float(middle[0] + cx), y_m=float(middle[1] + cy),
                               radius_m=float(radius), appear_time_s=0.0)
                for cx, cy in centres.tolist()]
    return out


def ego_vehicle(vehicle: Any, settings: EuroNcapSettings) -> Any:
    """The vehicle with the ego's rectangle (``ego_length_m`` x ``ego_width_m``) covered by
    ``cover_discs`` discs, as a CommonRoad run shapes its ego."""
    from pipeline.loop.cover import rectangle_cover

    offsets, radius = rectangle_cover(settings.ego_length_m, settings.ego_width_m,
                                      settings.cover_discs)
    return replace(vehicle, footprint_radius_m=round(float(radius), 9),
                   footprint_discs=settings.cover_discs,
                   footprint_span_m=round(float(offsets[-1] - offsets[0]), 9))


@dataclass(frozen=True)
class ProtocolOutcome:
    """The protocol's outcome of one run, on the true shapes: whether the road user was hit,
    when and at what ego speed (km/h; NaN when avoided), whether a parked car was touched, the
    steps the ego's rectangle spent off the road, and the least gap to the road user (m; 0
    once they overlap)."""

    hit: bool
    impact_time_s: float
    impact_speed_kmh: float
    other_contact: bool
    steps_off_road: int
    least_gap_m: float


def rectangle_corners(centre_x: np.ndarray, centre_y: np.ndarray, heading: np.ndarray,
                      length_m: float, width_m: float) -> np.ndarray:
    """Corners (T, 4, 2), counter-clockwise, of a ``length_m`` x ``width_m`` rectangle centred
    at each ``(centre_x, centre_y)`` with its long side along ``heading``."""
    c, s = np.cos(heading), np.sin(heading)
    local = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]) \
        * np.array([length_m / 2.0, width_m / 2.0])
    x = centre_x[:, None] + c[:, None] * local[None, :, 0] - s[:, None] * local[None, :, 1]
    y = centre_y[:, None] + s[:, None] * local[None, :, 0] + c[:, None] * local[None, :, 1]
    return np.stack([x, y], axis=-1)


def _point_segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances (T, P, E) from points (T, P, 2) to segments ``a -> b`` (T, E, 2)."""
    ab = (b - a)[:, None, :, :]                                     # (T, 1, E, 2)
    ap = points[:, :, None, :] - a[:, None, :, :]                    # (T, P, E, 2)
    t = np.clip(np.sum(ap * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-18),
                0.0, 1.0)
    return np.linalg.norm(ap - t[..., None] * ab, axis=-1)


def polygon_gap(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Per step the gap (m) between two convex polygons (T, 4, 2) each (counter-clockwise):
    0 where they overlap (no separating axis among their edges' normals), else the least
    vertex-to-edge distance."""
    overlap = np.ones(first.shape[0], bool)
    for poly in (first, second):
        edges = np.roll(poly, -1, axis=1) - poly                       # (T, 4, 2)
        normals = np.stack([edges[..., 1], -edges[..., 0]], axis=-1)   # outward for CCW
        for e in range(4):
            n = normals[:, e, :]                                        # (T, 2)
            p1 = np.einsum("tkd,td->tk", first, n)
            p2 = np.einsum("tkd,td->tk", second, n)
            separated = (p1.max(axis=1) < p2.min(axis=1)) | (p2.max(axis=1) < p1.min(axis=1))
            overlap &= ~separated
    gap = np.minimum(
        _point_segment_distance(first, second, np.roll(second, -1, axis=1)).min(axis=(1, 2)),
        _point_segment_distance(second, first, np.roll(first, -1, axis=1)).min(axis=(1, 2)))
    return np.where(overlap, 0.0, gap)


def disc_gap(rectangle: np.ndarray, heading: np.ndarray, length_m: float, width_m: float,
             centre: np.ndarray, radius_m: float) -> np.ndarray:
    """Per step the gap (m) between rectangles (T, 4, 2; ``length_m`` x ``width_m`` along
    ``heading``) and discs at ``centre`` (T, 2): the distance from the disc's centre to the
    rectangle, less the radius (negative inside)."""
    middle = rectangle.mean(axis=1)
    d = centre - middle
    c, s = np.cos(heading), np.sin(heading)
    along, across = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    qx = np.maximum(np.abs(along) - length_m / 2.0, 0.0)
    qy = np.maximum(np.abs(across) - width_m / 2.0, 0.0)
    inside = (np.abs(along) <= length_m / 2.0) & (np.abs(across) <= width_m / 2.0)
    return np.where(inside, -radius_m, np.hypot(qx, qy) - radius_m)


def protocol_outcome(trajectory: Any, geometry: Encounter, settings: EuroNcapSettings
                     ) -> ProtocolOutcome:
    """The outcome of a run's ``trajectory`` (its logged columns) on the true shapes: the
    ego's ``ego_length_m`` x ``ego_width_m`` rectangle about its logged position against the
    road user (a disc, or the bicycle's ``cyclist_length_m`` x ``cyclist_width_m`` rectangle
    across the road, at the centre of its logged discs) and the parked cars' rectangles
    (``geometry.parked_m``); the first step they overlap, the ego's speed there (its
    ``hypot(vx, vy)``), and, up to that step (the test ends there), whether a parked car was
    touched and the steps its rectangle reaches beyond the road's edges
    (:attr:`EuroNcapSettings.road_edges_m`)."""
    t = trajectory
    x, y, psi = (t[c].to_numpy(float) for c in ("X_m", "Y_m", "psi_rad"))
    length, width = settings.ego_length_m, settings.ego_width_m
    ego = rectangle_corners(x, y, psi, length, width)
    n_user = geometry.user_discs.shape[0]
    centre = np.mean([t[[f"obs{j}_x_m", f"obs{j}_y_m"]].to_numpy(float) for j in range(n_user)],
                     axis=0)                                                 # (T, 2)
    if geometry.case.road_user == "cyclist":
        bike = rectangle_corners(centre[:, 0], centre[:, 1], np.full(len(t), np.pi / 2.0),
                                 settings.cyclist_length_m, settings.cyclist_width_m)
        user = polygon_gap(ego, bike)
    else:
        user = np.maximum(disc_gap(ego, psi, length, width, centre, geometry.user_radius_m),
                          0.0)
    hit_steps = np.flatnonzero(user <= 0.0)
    # the test ends at the impact (the run goes on: what it does after is not the test's)
    end = int(hit_steps[0]) + 1 if hit_steps.size else len(t)
    other = False
    for corners in geometry.parked_m:
        parked = np.broadcast_to(corners, ego.shape)[:end]
        other = other or bool((polygon_gap(ego[:end], parked) <= 0.0).any())
    half_l, half_w = length / 2.0, width / 2.0
    reach = half_l * np.abs(np.sin(psi[:end])) + half_w * np.abs(np.cos(psi[:end]))
    right, left = settings.road_edges_m
    off = int(np.count_nonzero((y[:end] - reach < right) | (y[:end] + reach > left)))
    least = float(np.min(user)) if user.size else float("nan")
    if hit_steps.size:
        k = int(hit_steps[0])
        speed = float(np.hypot(t["vx_mps"].to_numpy(float)[k],
                               np.nan_to_num(t["vy_mps"].to_numpy(float)[k])))
        return ProtocolOutcome(True, float(t["time_s"].to_numpy(float)[k]), speed / KMH, other,
                               off, least)
    return ProtocolOutcome(False, float("nan"), float("nan"), other, off, least)
