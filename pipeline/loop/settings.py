"""Settings of the closed loop (scenario, vehicle, model, planner, controller), beside the stages
that use them.

Every number the loop uses lives in one of these dataclasses. Hydra composes YAML files in
``conf/`` onto them (each YAML names its schema in ``defaults``); ``OmegaConf.to_object`` then
builds the dataclasses, whose ``__post_init__`` checks ranges and raises
:class:`pipeline.errors.ConfigError` naming the key, the value and what is allowed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Dict, List, Optional, Protocol

from omegaconf import MISSING

from pipeline.errors import ConfigError
from pipeline.loop.controller_settings import ControllerConfig as ControllerConfig
from pipeline.validation import (
    FrozenAfterValidation,
    at_least,
    between,
    choice,
    finite,
    flag,
    integer_in,
    pair,
    safe_name,
    target_path,
    without_earlier_readings,
)

#: |scenario.start_heading_rad| at most one turn (rad); the scenario wraps it to [-pi, pi]
START_HEADING_LIMIT_RAD = 2.0 * math.pi
#: A run's steps at most (scenario.n_steps, scenario.commonroad.n_steps, a CommonRoad goal)
MAX_RUN_STEPS = 100_000


@dataclass
class VehicleConfig(FrozenAfterValidation):
    """Vehicle parameters for the lateral model and the nonlinear plant (SI units)."""

    name: str = MISSING
    source: str = MISSING
    mass_kg: float = 1500.0
    yaw_inertia_kg_m2: float = 2500.0
    cg_to_front_m: float = 1.2
    cg_to_rear_m: float = 1.3
    cornering_stiffness_front_n_per_rad: float = 60000.0
    cornering_stiffness_rear_n_per_rad: float = 60000.0
    tire_friction: float = 0.9
    footprint_radius_m: float = 1.0
    steering_max_rad: float = 0.4
    steering_rate_max_rad_s: float = 1.0
    min_model_speed_mps: float = 1.0
    speed_time_constant_s: float = 0.5
    accel_max_mps2: float = 3.0
    # the ego as several discs of footprint_radius_m along its heading (a car's rectangle
    # covered, pipeline.loop.cover): how many, and the distance between the first and the last
    # centre, centred on the logged position; 1 and 0: one disc (the paper's reading)
    footprint_discs: int = 1
    footprint_span_m: float = 0.0
    # below this speed the plant and the lateral MPC's model are the kinematic single-track
    # (no tyre slip, no 1/v_x terms), so the lateral track may brake to a stop
    # (planner.speed_floor_mps down to 0); None: the dynamic model at every speed, floored at
    # min_model_speed_mps (earlier releases)
    kinematic_below_mps: Optional[float] = None
    # the plant's braking limit (m/s^2, a deceleration) where it is not accel_max_mps2: a
    # passenger car brakes at 8-9 m/s^2 and accelerates at about 3 (Appendix A bounds a in
    # [-3, 3]); None: accel_max_mps2 both ways (the paper's, earlier releases)
    brake_max_mps2: Optional[float] = None

    #: Physical range of each parameter (a road vehicle, from a cart to a truck).
    BOUNDS = {"mass_kg": (10.0, 1e5), "yaw_inertia_kg_m2": (1.0, 1e7),
              "cg_to_front_m": (0.05, 20.0), "cg_to_rear_m": (0.05, 20.0),
              "cornering_stiffness_front_n_per_rad": (10.0, 1e7),
              "cornering_stiffness_rear_n_per_rad": (10.0, 1e7), "tire_friction": (0.01, 3.0),
              "footprint_radius_m": (0.0, 20.0), "steering_rate_max_rad_s": (1e-3, 20.0),
              "min_model_speed_mps": (0.05, 20.0), "speed_time_constant_s": (1e-3, 100.0),
              "accel_max_mps2": (1e-3, 50.0)}

    def __post_init__(self) -> None:
        for key, (low, high) in self.BOUNDS.items():
            between(f"vehicle.{key}", getattr(self, key), low, high)
        between("vehicle.steering_max_rad", self.steering_max_rad, 1e-3, 1.2)
        integer_in("vehicle.footprint_discs", self.footprint_discs, 1, 8)
        between("vehicle.footprint_span_m", self.footprint_span_m, 0.0, 50.0)
        if self.kinematic_below_mps is not None:
            between("vehicle.kinematic_below_mps", self.kinematic_below_mps,
                    self.min_model_speed_mps, 20.0)
        if self.brake_max_mps2 is not None:
            between("vehicle.brake_max_mps2", self.brake_max_mps2, 1e-3, 50.0)
        if self.footprint_discs == 1 and self.footprint_span_m != 0.0:
            raise ConfigError("vehicle.footprint_span_m", self.footprint_span_m,
                              "0 with vehicle.footprint_discs=1 (one disc spans nothing)")
        safe_name("vehicle.name", self.name)

    #: The keys added after the config hash was first pinned, with the reading from before
    #: them (left out of the hash while they hold it: :meth:`hash_view`)
    BEFORE_KEYS: ClassVar[dict[str, Any]] = {"footprint_discs": 1, "footprint_span_m": 0.0,
                                             "kinematic_below_mps": None,
                                             "brake_max_mps2": None}

    @staticmethod
    def hash_view(data: dict[str, Any]) -> dict[str, Any]:
        """``asdict`` of a vehicle as the config hash reads it: a key of :data:`BEFORE_KEYS`
        holding the reading from before it is left out (one disc hashes as before the keys)."""
        return without_earlier_readings(data, VehicleConfig.BEFORE_KEYS)

    @property
    def footprint_offsets_m(self) -> Any:
        """The ego's disc centres along its heading (m, ndarray; ``[0.0]`` for one disc)."""
        from pipeline.loop.cover import footprint_offsets_m

        return footprint_offsets_m(self.footprint_discs, self.footprint_span_m)

    @property
    def wheelbase_m(self) -> float:
        return self.cg_to_front_m + self.cg_to_rear_m

    @property
    def braking_limit_mps2(self) -> float:
        """The plant's braking limit: ``brake_max_mps2``, else ``accel_max_mps2``."""
        return float(self.accel_max_mps2 if self.brake_max_mps2 is None else self.brake_max_mps2)


@dataclass
class PlannerConfig(FrozenAfterValidation):
    """APF rollout settings. ``baseline`` and ``improved`` are two presets of these switches."""

    name: str = MISSING
    step_size: float = 0.1
    normalize_step: bool = True
    h_max: float = 50.0
    beta: float = 1.0
    rho_p_m: float = 6.0
    rho0_m: float = 4.0
    repulsion_law: str = "polynomial"
    k_rep_source: str = "adaptive_h"
    k_rep_constant: float = 25.0
    alpha_e: float = 2.0
    step_min_m: float = 0.0
    step_max_m: Optional[float] = None
    rho_floor_m: float = 0.05
    obstacle_prediction: str = "current"
    closing_speed_gain_s_per_m: float = 0.0
    # velocity planning V_r = f_v(obstacles): off for the paper scenario
    velocity_planning: bool = False
    velocity_rule: str = "predicted_clearance"
    braking_decel_mps2: float = 2.0
    stop_margin_m: float = 1.0
    speed_floor_mps: float = 1.0
    speed_candidates: int = 7
    speed_check_horizon_s: float = 3.0
    # a planner of your own (Hydra's convention): module.Class, built with (these settings,
    # horizon, sample time); None: the paper's APF (pipeline.loop.planner.ApfPlanner).
    # ``params`` carries its own settings. Both enter the run hash only when set.
    _target_: Optional[str] = None
    params: Dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        safe_name("planner.name", self.name)
        target_path("planner._target_", self._target_)
        at_least("planner.braking_decel_mps2", self.braking_decel_mps2, 0.0, inclusive=False)
        at_least("planner.stop_margin_m", self.stop_margin_m, 0.0)
        # 0 stops the platform (the kinematic track only: see ExperimentConfig's check)
        at_least("planner.speed_floor_mps", self.speed_floor_mps, 0.0)
        choice("planner.velocity_rule", self.velocity_rule,
               ("predicted_clearance", "stopping_distance"))
        if isinstance(self.speed_candidates, bool) or not isinstance(self.speed_candidates, int) \
                or not 2 <= self.speed_candidates <= 100:
            raise ConfigError("planner.speed_candidates", self.speed_candidates,
                              "an integer in [2, 100]")
        between("planner.speed_check_horizon_s", self.speed_check_horizon_s, 0.1, 60.0)
        at_least("planner.step_size", self.step_size, 0.0, inclusive=False)
        at_least("planner.h_max", self.h_max, 0.0)
        at_least("planner.beta", self.beta, 0.0)
        at_least("planner.rho_p_m", self.rho_p_m, 0.0, inclusive=False)
        at_least("planner.rho0_m", self.rho0_m, 0.0, inclusive=False)
        choice("planner.repulsion_law", self.repulsion_law, ("polynomial", "exponential", "none"))
        choice("planner.k_rep_source", self.k_rep_source, ("adaptive_h", "constant"))
        at_least("planner.k_rep_constant", self.k_rep_constant, 0.0)
        between("planner.alpha_e", self.alpha_e, 0.0, 50.0)
        at_least("planner.step_min_m", self.step_min_m, 0.0)
        if self.step_max_m is not None:
            at_least("planner.step_max_m", self.step_max_m, 0.0, inclusive=False)
            if self.step_max_m < self.step_min_m:
                raise ConfigError("planner.step_max_m", self.step_max_m,
                                  f">= planner.step_min_m ({self.step_min_m}) or null")
        at_least("planner.rho_floor_m", self.rho_floor_m, 0.0, inclusive=False)
        choice("planner.obstacle_prediction", self.obstacle_prediction,
                ("current", "constant_velocity"))
        at_least("planner.closing_speed_gain_s_per_m", self.closing_speed_gain_s_per_m, 0.0)


@dataclass
class ModelConfig(FrozenAfterValidation):
    """Settings of the MPC's lateral prediction model."""

    b2_heading_entry: float = -1.0
    speed_grid_mps: float = 0.1
    validity_heading_rad: float = 0.35
    tyre_linear_tolerance: float = 0.05

    def __post_init__(self) -> None:
        choice("model.b2_heading_entry", self.b2_heading_entry, (-1.0, 1.0))
        at_least("model.speed_grid_mps", self.speed_grid_mps, 0.0, inclusive=False)
        between("model.validity_heading_rad", self.validity_heading_rad, 0.0, math.pi)
        between("model.tyre_linear_tolerance", self.tyre_linear_tolerance, 1e-4, 0.9)


@dataclass
class ObstacleConfig(FrozenAfterValidation):
    """One circular obstacle, invisible before ``appear_time_s``, then moving at constant velocity."""

    x_m: float = MISSING
    y_m: float = MISSING
    vx_mps: float = 0.0
    vy_mps: float = 0.0
    radius_m: float = 0.5
    appear_time_s: float = 0.0


@dataclass
class FamilyConfig(FrozenAfterValidation):
    """Seeded random draws of obstacles around a base scenario.

    Member ``i`` of seed ``s`` is drawn from ``numpy.random.default_rng([s, i])`` alone, so it is
    the same on every machine and does not depend on the family size. Ranges are ``[low, high]``.
    """

    seed: int = 0
    size: int = 200
    n_jobs: int = 2
    appear_time_s: List[float] = field(default_factory=lambda: [2.0, 4.0])
    ahead_m: List[float] = field(default_factory=lambda: [4.0, 8.0])
    lateral_m: List[float] = field(default_factory=lambda: [-2.0, 2.0])
    radius_m: List[float] = field(default_factory=lambda: [0.3, 0.7])
    crossing_speed_mps: List[float] = field(default_factory=lambda: [0.2, 0.8])
    oncoming_speed_mps: List[float] = field(default_factory=lambda: [0.3, 1.0])
    static_probability: float = 0.25
    oncoming_probability: float = 0.25
    obstacle_count_probabilities: List[float] = field(default_factory=lambda: [0.5, 0.3, 0.2])
    extra_x_m: List[float] = field(default_factory=lambda: [8.0, 26.0])
    extra_y_m: List[float] = field(default_factory=lambda: [-3.0, 3.0])
    extra_appear_time_s: List[float] = field(default_factory=lambda: [0.0, 6.0])

    def __post_init__(self) -> None:
        for key in ("seed", "size", "n_jobs"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int):
                raise ConfigError(f"scenario.family.{key}", value, "an integer")
        if self.seed < 0:
            raise ConfigError("scenario.family.seed", self.seed, "an integer >= 0")
        if self.size < 1:
            raise ConfigError("scenario.family.size", self.size, "an integer >= 1")
        if self.n_jobs < 1:
            raise ConfigError("scenario.family.n_jobs", self.n_jobs, "an integer >= 1")
        for key in ("appear_time_s", "ahead_m", "lateral_m", "radius_m", "crossing_speed_mps",
                    "oncoming_speed_mps", "extra_x_m", "extra_y_m", "extra_appear_time_s"):
            value = getattr(self, key)
            pair(f"scenario.family.{key}", value)
            if value[0] > value[1]:
                raise ConfigError(f"scenario.family.{key}", list(value), "[low, high] with low <= high")
        for key in ("radius_m", "appear_time_s", "extra_appear_time_s", "crossing_speed_mps",
                    "oncoming_speed_mps"):
            if getattr(self, key)[0] < 0:
                raise ConfigError(f"scenario.family.{key}", list(getattr(self, key)),
                                  "a range of non-negative numbers")
        between("scenario.family.static_probability", self.static_probability, 0.0, 1.0)
        between("scenario.family.oncoming_probability", self.oncoming_probability, 0.0, 1.0)
        if self.static_probability + self.oncoming_probability > 1.0:
            raise ConfigError("scenario.family.oncoming_probability", self.oncoming_probability,
                              f"<= 1 - static_probability ({1.0 - self.static_probability})")
        probs = self.obstacle_count_probabilities
        if not 1 <= len(probs) <= 3 or any(not math.isfinite(p) or p < 0 for p in probs) \
                or not math.isclose(sum(probs), 1.0, abs_tol=1e-9):
            raise ConfigError("scenario.family.obstacle_count_probabilities", list(probs),
                              "1 to 3 non-negative numbers (for 1, 2, 3 obstacles) summing to 1")


@dataclass
class CommonRoadConfig(FrozenAfterValidation):
    """``scenario=commonroad``: a CommonRoad scenario XML read by commonroad-io (the optional
    extra ``pip install '.[commonroad]'``; docs/commonroad.md). Start, heading, speed, goal,
    sample time and run length come from its planning problem; the obstacles from the file."""

    path: str = MISSING
    # which planning problem of the file (None: the one with the lowest id)
    planning_problem_id: Optional[int] = None
    # the ego's true shape for the drivability checker and the exported trajectory's vehicle
    # (commonroad-vehicle-models' parameter sets): FORD_ESCORT, BMW_320i or VW_VANAGON
    vehicle_type: str = "BMW_320i"
    # the discs our planner, MPC and own check see for an obstacle's shape and for the ego:
    # cover (the shape's bounding rectangle covered by cover_discs equal discs along its long
    # side, each its own obstacle with its own half-plane; the ego's rectangle, vehicle_type's,
    # likewise: vehicle.footprint_* are set from it), circumscribed (one disc holding the shape;
    # the ego a vehicle.footprint_radius_m disc: earlier releases' reading) or half_width (a
    # disc of half its smaller side: under-covers)
    obstacle_disc: str = "cover"
    # discs per rectangle under obstacle_disc=cover (1: the circumscribed disc)
    cover_discs: int = 3
    # what the ego sees: obstacles within this centre distance (m; None: every present one)
    sensor_range_m: Optional[float] = None
    # a static obstacle (a parked car) hides what stands behind it: an obstacle is seen while
    # the line from the ego to its centre crosses no static obstacle's rectangle (anything
    # within the ego's reach is seen)
    occlusion: bool = False
    # the planner's attraction pulls towards the point this far (m) along the route's lanelet
    # centreline ahead of the ego (the route: the shortest lanelet path from the start's lanelet
    # to the goal's); None: straight towards the goal point (earlier releases)
    route_lookahead_m: Optional[float] = None
    # and at least this long (s) ahead at the ego's speed (a pure pursuit's look-ahead time:
    # the distance grows with the speed; the farther of the two); None: the distance alone.
    # Without route_lookahead_m there is no route, and this has nothing to scale
    route_lookahead_s: Optional[float] = None
    # the road is the file's lanelets, each widened by half this (m) to either side, so that
    # neighbours whose shared edges do not meet exactly are one road: USA_US101-23_1's
    # lanelets leave gaps of up to 3 cm between them, which the MPC's road rows read as the
    # road's edge (the ego held in one lane) and the off-road check as off the road (a car
    # over a lane marking); 0: the lanelets as they are (earlier releases)
    lanelet_gap_m: float = 0.0
    # an obstacle whose centre is this close to the planning problem's initial position at its
    # initial time step is the ego's own recording, and dropped
    ego_match_tolerance_m: float = 0.5
    # None: the initial state's speed (the scenario's own); a number overrides it
    speed_mps: Optional[float] = None
    # None: until the goal's last time step (or the file's last obstacle time step)
    n_steps: Optional[int] = None

    VEHICLE_TYPES = ("FORD_ESCORT", "BMW_320i", "VW_VANAGON")
    #: The keys added after the config hash was first pinned, with the reading from before
    #: them: everything present seen, straight to the goal (left out of the hash while held)
    BEFORE_KEYS: ClassVar[dict[str, Any]] = {"sensor_range_m": None, "occlusion": False,
                                             "route_lookahead_m": None,
                                             "route_lookahead_s": None,
                                             "lanelet_gap_m": 0.0}

    def __post_init__(self) -> None:
        if not isinstance(self.path, str) or not self.path:
            raise ConfigError("scenario.commonroad.path", self.path,
                              "the path of a CommonRoad scenario XML file")
        if self.planning_problem_id is not None and (
                isinstance(self.planning_problem_id, bool)
                or not isinstance(self.planning_problem_id, int)):
            raise ConfigError("scenario.commonroad.planning_problem_id",
                              self.planning_problem_id, "an integer id or null")
        choice("scenario.commonroad.vehicle_type", self.vehicle_type, self.VEHICLE_TYPES)
        choice("scenario.commonroad.obstacle_disc", self.obstacle_disc,
               ("cover", "circumscribed", "half_width"))
        integer_in("scenario.commonroad.cover_discs", self.cover_discs, 1, 8)
        if self.sensor_range_m is not None:
            between("scenario.commonroad.sensor_range_m", self.sensor_range_m, 1.0, 1000.0)
        if self.route_lookahead_m is not None:
            between("scenario.commonroad.route_lookahead_m", self.route_lookahead_m, 1.0, 500.0)
        if self.route_lookahead_s is not None:
            between("scenario.commonroad.route_lookahead_s", self.route_lookahead_s, 0.1, 10.0)
        flag("scenario.commonroad.occlusion", self.occlusion)
        between("scenario.commonroad.lanelet_gap_m", self.lanelet_gap_m, 0.0, 0.5)
        between("scenario.commonroad.ego_match_tolerance_m", self.ego_match_tolerance_m,
                0.0, 10.0)
        if self.speed_mps is not None:
            between("scenario.commonroad.speed_mps", self.speed_mps, 0.1, 40.0)
        if self.n_steps is not None and (isinstance(self.n_steps, bool)
                                         or not isinstance(self.n_steps, int)
                                         or not 2 <= self.n_steps <= MAX_RUN_STEPS):
            raise ConfigError("scenario.commonroad.n_steps", self.n_steps,
                              f"an integer in [2, {MAX_RUN_STEPS}] or null")


@dataclass
class PedestrianConfig(FrozenAfterValidation):
    """Recorded pedestrians (ETH/UCY tracks) as the scenario's dynamic obstacles
    (:mod:`pipeline.loop.pedestrians`; ``scenario=pedestrians``).

    A family draws, per member, a scene of ``scenes``, a window of its recording, the platform's
    speed and a crossing through the scene's busy part; the member keeps the drawn ``scene``
    and ``window_start_s``. Pedestrians are discs of ``radius_m`` on their recorded tracks
    (linear between samples); the planner and the MPC see one only within ``sensor_range_m``
    of the vehicle's centre and predict it at constant velocity. They do not react.
    """

    #: folder of the track files (``<scene>.txt.gz`` or ``<scene>.txt``); relative paths are
    #: read from the project's ``data/`` folder (``pipeline/data`` in an installed package)
    data_dir: str = "eth_ucy"
    scenes: List[str] = field(default_factory=lambda: ["biwi_hotel", "crowds_zara01",
                                                       "crowds_zara02", "students001"])
    #: recording time per frame number (s): frames are numbered 10 apart at 2.5 Hz
    seconds_per_frame: float = 0.04
    radius_m: float = 0.3
    sensor_range_m: float = 6.0
    #: pedestrians whose recorded track comes this close to the start-goal segment within the
    #: run's time are simulated (and count for collisions); the others never come near
    corridor_m: float = 8.0
    crossing_length_m: float = 10.0
    platform_speed_mps: List[float] = field(default_factory=lambda: [1.0, 2.0])
    #: start and goal lie inside the scene's recorded extent, shrunk by this margin
    scene_margin_m: float = 0.5
    #: free space around the start at t = 0 beyond both radii
    start_clearance_m: float = 1.0
    #: draws tried per member before the scene is declared too small for the crossing
    max_draws: int = 1000
    #: how a crossing is drawn: ``scene`` (its midpoint a place someone walked at any time of
    #: the recording, start and goal where someone walked: busy, never aimed) or ``aimed``
    #: (its midpoint where a walker will be when the platform arrives: a stress test that the
    #: straight line hits by construction)
    draw: str = "aimed"
    #: ``scene`` draws: start and goal each within this distance of a recorded position
    walkable_radius_m: float = 1.0
    #: the run ends at the first contact with a walker (the crowd-navigation convention: no
    #: metric on a trajectory that drove through a person)
    end_at_contact: bool = False
    #: ``replayed`` (on their recorded tracks) or ``reactive`` (each walker follows its
    #: recorded route under Helbing and Molnar's social force, avoiding the platform)
    walkers: str = "replayed"
    #: reactive walkers: relaxation time (s) towards the desired velocity
    social_tau_s: float = 0.5
    #: reactive walkers: the recorded position this far ahead (s) is the walker's target
    social_lookahead_s: float = 2.0
    #: reactive walkers: repulsion strength A (m/s^2) and range B (m) of the exponential
    #: social force A exp(-gap / B), from other walkers and from the platform
    social_strength_mps2: float = 2.1
    social_range_m: float = 0.3
    #: reactive walkers: speed at most this factor times the recorded speed ahead
    social_max_speed_factor: float = 1.3
    #: the metrics count an intrusion into a walker's personal space where the surface gap
    #: is below this (m; Francis et al. 2023 and CrowdNav's discomfort distance: 0.2-0.5 m)
    personal_space_m: float = 0.5
    #: each recorded track goes on this long (s) before its first and after its last sample,
    #: straight at its first (last) segment's velocity: a walker walks into and out of the
    #: recorded area instead of appearing (vanishing) at its edge; 0: the recording as it is
    track_extension_s: float = 0.0
    #: a member's drawn scene and the recording time at its t = 0 (null in the family's base)
    scene: Optional[str] = None
    window_start_s: Optional[float] = None

    #: Keys added after the hash was pinned, with the reading from before each (left out of
    #: the hash while they hold it; :meth:`ScenarioConfig.hash_view`).
    BEFORE_KEYS = {"draw": "aimed", "walkable_radius_m": 1.0, "end_at_contact": False,
                   "walkers": "replayed", "social_tau_s": 0.5, "social_lookahead_s": 2.0,
                   "social_strength_mps2": 2.1, "social_range_m": 0.3,
                   "social_max_speed_factor": 1.3, "personal_space_m": 0.5,
                   "track_extension_s": 0.0}

    def __post_init__(self) -> None:
        key = "scenario.pedestrians"
        if not isinstance(self.data_dir, str) or not self.data_dir:
            raise ConfigError(f"{key}.data_dir", self.data_dir, "a folder path")
        if not self.scenes or any(not isinstance(s, str) or not s or "/" in s
                                  for s in self.scenes):
            raise ConfigError(f"{key}.scenes", list(self.scenes or []),
                              "a non-empty list of scene names (track files without "
                              "extension, no '/')")
        for name in self.scenes:
            safe_name(f"{key}.scenes", name)
        between(f"{key}.seconds_per_frame", self.seconds_per_frame, 1e-4, 10.0)
        between(f"{key}.radius_m", self.radius_m, 0.01, 5.0)
        if isinstance(self.sensor_range_m, bool) or not isinstance(self.sensor_range_m,
                                                                   (int, float)) \
                or not 0.0 < self.sensor_range_m <= 100.0:
            raise ConfigError(f"{key}.sensor_range_m", self.sensor_range_m,
                              "a number in (0, 100] (m)")
        between(f"{key}.corridor_m", self.corridor_m, 0.0, 1000.0)
        between(f"{key}.crossing_length_m", self.crossing_length_m, 1.0, 1000.0)
        pair(f"{key}.platform_speed_mps", self.platform_speed_mps)
        low, high = self.platform_speed_mps
        if not 0.1 <= low <= high <= 40.0:
            raise ConfigError(f"{key}.platform_speed_mps", list(self.platform_speed_mps),
                              "[low, high] with 0.1 <= low <= high <= 40 (m/s)")
        between(f"{key}.scene_margin_m", self.scene_margin_m, 0.0, 100.0)
        between(f"{key}.start_clearance_m", self.start_clearance_m, 0.0, 100.0)
        if isinstance(self.max_draws, bool) or not isinstance(self.max_draws, int) \
                or not 1 <= self.max_draws <= 100_000:
            raise ConfigError(f"{key}.max_draws", self.max_draws, "an integer in [1, 100000]")
        if self.scene is not None:
            safe_name(f"{key}.scene", self.scene)
        if self.window_start_s is not None:
            finite(f"{key}.window_start_s", self.window_start_s)
        choice(f"{key}.draw", self.draw, ("scene", "aimed"))
        between(f"{key}.walkable_radius_m", self.walkable_radius_m, 0.05, 100.0)
        choice(f"{key}.end_at_contact", self.end_at_contact, (True, False))
        choice(f"{key}.walkers", self.walkers, ("replayed", "reactive"))
        between(f"{key}.social_tau_s", self.social_tau_s, 0.05, 10.0)
        between(f"{key}.social_lookahead_s", self.social_lookahead_s, 0.1, 30.0)
        between(f"{key}.social_strength_mps2", self.social_strength_mps2, 0.0, 100.0)
        between(f"{key}.social_range_m", self.social_range_m, 0.01, 10.0)
        between(f"{key}.social_max_speed_factor", self.social_max_speed_factor, 1.0, 5.0)
        between(f"{key}.personal_space_m", self.personal_space_m, 0.0, 10.0)
        between(f"{key}.track_extension_s", self.track_extension_s, 0.0, 10.0)


@dataclass
class ScenarioSourceConfig(FrozenAfterValidation):
    """Which scenario source builds the scenario and draws its family's members
    (:class:`pipeline.loop.scenario.ScenarioSource`), named by Hydra's ``_target_`` as a
    planner or a controller of one's own is.

    ``_target_`` is the source's class (``module.Class``); null: the built-in source that the
    scenario's shape implies (:meth:`ScenarioConfig.source_target_of`), which is how a
    configuration written before the key (a run folder's ``config.yaml``) reads. ``params``
    carries a source's own settings (a source from outside the package has no typed block of
    its own in this schema)."""

    _target_: Optional[str] = None
    params: Dict[str, Any] = field(default_factory=dict)

    #: The built-in sources: the paper's scenario and its scripted family, the recorded
    #: pedestrians (ETH/UCY), a CommonRoad file.
    SCRIPTED = "pipeline.loop.scenario.ScriptedSource"
    PEDESTRIANS = "pipeline.loop.pedestrians.PedestrianSource"
    COMMONROAD = "pipeline.loop.commonroad_scenario.CommonRoadSource"

    def __post_init__(self) -> None:
        target_path("scenario.source._target_", self._target_)
        if not isinstance(self.params, dict):
            raise ConfigError("scenario.source.params", self.params,
                              "a mapping of the source's own settings")


@dataclass
class ScenarioConfig(FrozenAfterValidation):
    """Start, goal, speed, run length and obstacles of one closed-loop run."""

    name: str = MISSING
    start_xy_m: List[float] = field(default_factory=lambda: [0.0, 0.0])
    start_heading_rad: float = 0.0
    goal_xy_m: List[float] = field(default_factory=lambda: [30.0, 0.0])
    goal_tolerance_m: float = 0.5
    speed_mps: float = 3.0
    sample_time_s: float = 0.1
    n_steps: int = 130
    plant_substeps: int = 10
    initial_speed_mps: Optional[float] = None
    obstacles: List[ObstacleConfig] = field(default_factory=list)
    allow_no_obstacles: bool = False
    family: Optional[FamilyConfig] = None
    # scenario=commonroad: start, goal, timing and obstacles from a CommonRoad XML
    commonroad: Optional[CommonRoadConfig] = None
    # "world": obstacles appear where the config puts them; "vehicle": x_m, y_m are read for a
    # vehicle at its nominal place (start + speed_mps * appear_time_s along the start-goal
    # line) and shifted with the vehicle's actual position when the obstacle appears (Figure 1:
    # "interrupted after the mobile platform moved in three seconds")
    obstacle_anchor: str = "world"
    # recorded pedestrians as the dynamic obstacles (scenario=pedestrians); null: none
    pedestrians: Optional[PedestrianConfig] = None
    # the scenario source (scenario.source._target_): what builds the scenario and draws its
    # family's members; null target: the built-in the blocks above imply
    source: ScenarioSourceConfig = field(default_factory=ScenarioSourceConfig)

    #: The range of ``speed_mps`` and ``initial_speed_mps`` (m/s); a planner of one's own
    #: plans its speed within it too (:mod:`pipeline.loop.plugins`).
    SPEED_BOUNDS_MPS = (0.1, 40.0)

    def __post_init__(self) -> None:
        # the checks in the order they always ran (the first failure is the one reported)
        self._check_geometry()
        self._check_timing()
        self._check_obstacles()

    @staticmethod
    def source_target_of(data: Any) -> str:
        """The ``module.Class`` of the source of a scenario mapping (a dict, an OmegaConf node
        or this schema): ``source._target_`` when set, else the built-in its shape implies (a
        ``commonroad`` block: CommonRoad; a ``pedestrians`` block: recorded pedestrians; else
        the scripted scenario and its family)."""
        get = data.get if hasattr(data, "get") else lambda key: getattr(data, key, None)
        source = get("source")
        target = None if source is None else (
            source.get("_target_") if hasattr(source, "get") else source._target_)
        if target:
            return str(target)
        if get("commonroad") is not None:
            return ScenarioSourceConfig.COMMONROAD
        if get("pedestrians") is not None:
            return ScenarioSourceConfig.PEDESTRIANS
        return ScenarioSourceConfig.SCRIPTED

    @property
    def source_target(self) -> str:
        """This scenario's source (:meth:`source_target_of`)."""
        return self.source_target_of(self)

    @staticmethod
    def hash_view(data: dict[str, Any]) -> dict[str, Any]:
        """``asdict`` of a scenario as the config hash reads it: each key added since the hash
        was first pinned is left out while it holds the reading from before the key, so that a
        configuration's hash does not move with the schema (a new key's other values do move
        it)."""
        data = dict(data)
        source = data.get("source", 0)
        if source is None or (isinstance(source, dict) and not source.get("params") and (
                source.get("_target_") in (None, ScenarioConfig.source_target_of(
                    {**data, "source": None})))):
            data.pop("source", None)  # the built-in the shape implies, as before the key
        if data.get("obstacle_anchor") == "world":
            data.pop("obstacle_anchor")  # the default reading, as before the key
        if data.get("commonroad", 0) is None:
            data.pop("commonroad")  # not a CommonRoad scenario, as before the key
        elif isinstance(data.get("commonroad"), dict) \
                and data["commonroad"].get("obstacle_disc") != "cover":
            # read only under the cover: an earlier reading hashes as before the key
            data["commonroad"] = {k: v for k, v in data["commonroad"].items()
                                  if k != "cover_discs"}
        if isinstance(data.get("commonroad"), dict):
            data["commonroad"] = without_earlier_readings(data["commonroad"],
                                                          CommonRoadConfig.BEFORE_KEYS)
        if data.get("pedestrians", 0) is None:
            data.pop("pedestrians")  # no recorded pedestrians, as before the key
        elif isinstance(data.get("pedestrians"), dict):
            data["pedestrians"] = without_earlier_readings(data["pedestrians"],
                                                           PedestrianConfig.BEFORE_KEYS)
        return data

    def check_with_vehicle(self, footprint_radius_m: float) -> None:
        """The checks that need the vehicle (:class:`~pipeline.config.ExperimentConfig` runs
        them): a recorded pedestrian is seen before it touches the vehicle."""
        ped = self.pedestrians
        if ped is not None and ped.sensor_range_m <= footprint_radius_m + ped.radius_m:
            raise ConfigError("scenario.pedestrians.sensor_range_m", ped.sensor_range_m,
                              f"a number in ({footprint_radius_m + ped.radius_m:g}"
                              ", 100] (m): beyond vehicle.footprint_radius_m + "
                              "scenario.pedestrians.radius_m, so that a pedestrian is seen "
                              "before it touches the vehicle")

    def _check_geometry(self) -> None:
        pair("scenario.start_xy_m", self.start_xy_m)
        pair("scenario.goal_xy_m", self.goal_xy_m)
        heading = finite("scenario.start_heading_rad", self.start_heading_rad)
        if abs(heading) > START_HEADING_LIMIT_RAD:
            # the scenario wraps it once where it enters; beyond a turn either way the number
            # is the same heading or degrees typed as radians (a 1e16 rad one once hung a run)
            raise ConfigError("scenario.start_heading_rad", self.start_heading_rad,
                              f"a number in [-{START_HEADING_LIMIT_RAD:.4f}, "
                              f"{START_HEADING_LIMIT_RAD:.4f}] (rad, one turn either way)")
        gap = math.dist(self.start_xy_m, self.goal_xy_m)
        if gap <= self.goal_tolerance_m:
            raise ConfigError("scenario.goal_xy_m", list(self.goal_xy_m),
                              f"a goal farther than goal_tolerance_m={self.goal_tolerance_m} "
                              f"from start_xy_m={list(self.start_xy_m)}")
        between("scenario.goal_tolerance_m", self.goal_tolerance_m, 1e-3, 100.0)
        for i, v in enumerate(list(self.start_xy_m) + list(self.goal_xy_m)):
            key = f"scenario.{'start' if i < 2 else 'goal'}_xy_m[{i % 2}]"
            between(key, v, -1e5, 1e5)
        if gap > 10_000.0:
            raise ConfigError("scenario.goal_xy_m", list(self.goal_xy_m),
                              "a goal within 10 km of the start")

    def _check_timing(self) -> None:
        between("scenario.speed_mps", self.speed_mps, *self.SPEED_BOUNDS_MPS)
        between("scenario.sample_time_s", self.sample_time_s, 1e-3, 1.0)
        safe_name("scenario.name", self.name)
        if self.initial_speed_mps is not None:
            between("scenario.initial_speed_mps", self.initial_speed_mps, 0.0,
                    self.SPEED_BOUNDS_MPS[1])
        if self.obstacle_anchor not in ("world", "vehicle"):
            raise ConfigError("scenario.obstacle_anchor", self.obstacle_anchor,
                              "one of 'world', 'vehicle'")
        for key in ("n_steps", "plant_substeps"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"scenario.{key}", value, "an integer >= 1")
        if not 2 <= self.n_steps <= MAX_RUN_STEPS:
            raise ConfigError("scenario.n_steps", self.n_steps,
                              f"an integer in [2, {MAX_RUN_STEPS}] (the simulated time must exceed "
                              "sample_time_s)")
        if self.plant_substeps > 1000:
            raise ConfigError("scenario.plant_substeps", self.plant_substeps,
                              "an integer in [1, 1000]")

    def _check_obstacles(self) -> None:
        if self.commonroad is not None and (self.family is not None or self.obstacles
                                            or self.pedestrians is not None):
            raise ConfigError("scenario.commonroad", "with family, obstacles or pedestrians",
                              "a CommonRoad scenario alone (its obstacles come from its file; "
                              "no scenario.family, scenario.obstacles or scenario.pedestrians)")
        # the scripted source runs the obstacle list; every other source brings its own
        if not self.obstacles and self.family is None and not self.allow_no_obstacles \
                and self.source_target == ScenarioSourceConfig.SCRIPTED:
            raise ConfigError("scenario.obstacles", [], "a non-empty obstacle list (or "
                              "scenario.allow_no_obstacles=true for an obstacle-free run)")
        seen = set()
        for i, obs in enumerate(self.obstacles):
            key = f"scenario.obstacles[{i}]"
            for attr in ("x_m", "y_m", "vx_mps", "vy_mps", "radius_m", "appear_time_s"):
                finite(f"{key}.{attr}", getattr(obs, attr))
            between(f"{key}.radius_m", obs.radius_m, 1e-3, 100.0)
            at_least(f"{key}.appear_time_s", obs.appear_time_s, 0.0)
            for attr in ("x_m", "y_m"):
                between(f"{key}.{attr}", getattr(obs, attr), -1e5, 1e5)
            for attr in ("vx_mps", "vy_mps"):
                between(f"{key}.{attr}", getattr(obs, attr), -1000.0, 1000.0)
            signature = (obs.x_m, obs.y_m, obs.vx_mps, obs.vy_mps, obs.radius_m, obs.appear_time_s)
            if signature in seen:
                raise ConfigError(f"{key}", signature, "obstacles that are not exact duplicates")
            seen.add(signature)


class LoopSettings(Protocol):
    """What the closed loop reads of a composed configuration (``ExperimentConfig`` has it)."""

    vehicle: VehicleConfig
    model: ModelConfig
    planner: PlannerConfig
    controller: Any  # one kind's schema (ControllerConfig: MpcSettings, ...)
    scenario: ScenarioConfig
