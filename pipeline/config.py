"""Structured configuration: dataclass schemas, range checks, and the interpretation register.

Every number the pipeline uses lives in one of these dataclasses. Hydra composes YAML files in
``conf/`` onto them (each YAML names its schema in ``defaults``); ``OmegaConf.to_object`` then
builds the dataclasses, whose ``__post_init__`` checks ranges and raises :class:`ConfigError`
naming the key, the value and what is allowed.

Only the entry points call :func:`register_configs`; stages receive the typed dataclasses.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field
from typing import Any, Dict, List, Optional

from omegaconf import MISSING


MAX_HORIZON = 200


def _qp_memory_gib(horizon: float, obstacles: float) -> float:
    """Rough memory of compiling the lateral QP: CVXPY's canonicalization grows with N^2, about
    1.4 kB N^2 (12 GiB at N = 3000, measured order of magnitude)."""
    n = float(horizon)
    return 1440.0 * n * n * (1.0 + float(obstacles) / 30.0) / 2**30


class ConfigError(ValueError):
    """An invalid configuration value.

    Parameters
    ----------
    key : str
        Dotted config key, e.g. ``controller.horizon``.
    value : Any
        The offending value.
    allowed : str
        Human-readable description of the allowed values.
    """

    def __init__(self, key: str, value: Any, allowed: str) -> None:
        self.key = key
        self.value = value
        self.allowed = allowed
        super().__init__(f"config error: {key}={value!r} is invalid; allowed: {allowed}")


def _finite(key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(key, value, "a finite number")
    if not math.isfinite(float(value)):
        raise ConfigError(key, value, "a finite number (not NaN or inf)")
    return float(value)


def _at_least(key: str, value: Any, low: float, inclusive: bool = True) -> None:
    v = _finite(key, value)
    if (v < low) if inclusive else (v <= low):
        raise ConfigError(key, value, f"{'>=' if inclusive else '>'} {low}")


def _between(key: str, value: Any, low: float, high: float) -> None:
    v = _finite(key, value)
    if not low <= v <= high:
        raise ConfigError(key, value, f"a number in [{low}, {high}]")


def _choice(key: str, value: Any, options: tuple) -> None:
    if value not in options:
        raise ConfigError(key, value, "one of " + ", ".join(str(o) for o in options))


def _safe_name(key: str, value: Any) -> None:
    """A name that becomes a folder name: letters, digits and ``_ - . + = ,`` only."""
    import re

    if value is MISSING or value is None:
        return
    text = str(value)
    if not text or text in (".", "..") or not re.fullmatch(r"[A-Za-z0-9_.+=,-]{1,100}", text):
        raise ConfigError(key, value, "a name of 1-100 letters, digits or _ - . + = , "
                          "(it becomes a folder name; no '/' or '..')")


def _pair(key: str, value: Any) -> None:
    if len(value) != 2:
        raise ConfigError(key, list(value), "a list of two finite numbers [x_m, y_m]")
    for i, v in enumerate(value):
        _finite(f"{key}[{i}]", v)


@dataclass
class VehicleConfig:
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
            _between(f"vehicle.{key}", getattr(self, key), low, high)
        _between("vehicle.steering_max_rad", self.steering_max_rad, 1e-3, 1.2)
        _safe_name("vehicle.name", self.name)

    @property
    def wheelbase_m(self) -> float:
        return self.cg_to_front_m + self.cg_to_rear_m


@dataclass
class PlannerConfig:
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
    braking_decel_mps2: float = 2.0
    stop_margin_m: float = 1.0
    speed_floor_mps: float = 1.0

    def __post_init__(self) -> None:
        _safe_name("planner.name", self.name)
        _at_least("planner.braking_decel_mps2", self.braking_decel_mps2, 0.0, inclusive=False)
        _at_least("planner.stop_margin_m", self.stop_margin_m, 0.0)
        _at_least("planner.speed_floor_mps", self.speed_floor_mps, 0.0, inclusive=False)
        _at_least("planner.step_size", self.step_size, 0.0, inclusive=False)
        _at_least("planner.h_max", self.h_max, 0.0)
        _at_least("planner.beta", self.beta, 0.0)
        _at_least("planner.rho_p_m", self.rho_p_m, 0.0, inclusive=False)
        _at_least("planner.rho0_m", self.rho0_m, 0.0, inclusive=False)
        _choice("planner.repulsion_law", self.repulsion_law, ("polynomial", "exponential", "none"))
        _choice("planner.k_rep_source", self.k_rep_source, ("adaptive_h", "constant"))
        _at_least("planner.k_rep_constant", self.k_rep_constant, 0.0)
        _between("planner.alpha_e", self.alpha_e, 0.0, 50.0)
        _at_least("planner.step_min_m", self.step_min_m, 0.0)
        if self.step_max_m is not None:
            _at_least("planner.step_max_m", self.step_max_m, 0.0, inclusive=False)
            if self.step_max_m < self.step_min_m:
                raise ConfigError("planner.step_max_m", self.step_max_m,
                                  f">= planner.step_min_m ({self.step_min_m}) or null")
        _at_least("planner.rho_floor_m", self.rho_floor_m, 0.0, inclusive=False)
        _choice("planner.obstacle_prediction", self.obstacle_prediction,
                ("current", "constant_velocity"))
        _at_least("planner.closing_speed_gain_s_per_m", self.closing_speed_gain_s_per_m, 0.0)


@dataclass
class ModelConfig:
    """Settings of the MPC's lateral prediction model."""

    b2_heading_entry: float = -1.0
    speed_grid_mps: float = 0.1
    validity_heading_rad: float = 0.35

    def __post_init__(self) -> None:
        _choice("model.b2_heading_entry", self.b2_heading_entry, (-1.0, 1.0))
        _at_least("model.speed_grid_mps", self.speed_grid_mps, 0.0, inclusive=False)
        _between("model.validity_heading_rad", self.validity_heading_rad, 0.0, math.pi)


@dataclass
class ControllerConfig:
    """Lateral MPC settings (CVXPY + Clarabel)."""

    name: str = MISSING
    kind: str = "mpc"
    backend: str = "clarabel_direct"
    horizon: int = 10
    control_horizon: int = 3
    input_hold: str = "hold_last"
    q_lateral: float = 10.0
    q_heading: float = 5.0
    q_yaw_rate: float = 0.1
    q_steering: float = 0.5
    r_steering_rate: float = 1.0
    slack_weight_linear: float = 1.0e4
    slack_weight_quadratic: float = 1.0e3
    safety_margin_m: float = 0.2
    constraint_activation_m: float = 12.0
    halfplane_normal: str = "lateral_side"
    max_obstacles: int = 3
    heading_reference: str = "path_slope"
    heading_ref_max_rad: float = 0.5
    yaw_rate_ref_max_rad_s: float = 0.6
    path_beyond_end: str = "extend"
    solver_max_iter: int = 200
    lookahead_min_m: float = 2.0
    lookahead_time_s: float = 0.8
    output_weights: List[float] = field(default_factory=lambda: [1.0, 1.0])
    input_weights: List[float] = field(default_factory=lambda: [0.1, 0.1])
    input_rate_weights: List[float] = field(default_factory=lambda: [0.01, 0.01])
    accel_bounds_mps2: List[float] = field(default_factory=lambda: [-3.0, 3.0])
    ltv_iterations: int = 1
    reference_alignment: str = "literal"

    def __post_init__(self) -> None:
        _choice("controller.kind", self.kind, ("mpc", "pure_pursuit", "kinematic_mpc"))
        _choice("controller.backend", self.backend, ("cvxpy", "clarabel_direct"))
        for key in ("output_weights", "input_weights", "input_rate_weights"):
            _pair(f"controller.{key}", getattr(self, key))
            for i, w in enumerate(getattr(self, key)):
                _at_least(f"controller.{key}[{i}]", w, 0.0)
        _pair("controller.accel_bounds_mps2", self.accel_bounds_mps2)
        if not self.accel_bounds_mps2[0] < self.accel_bounds_mps2[1]:
            raise ConfigError("controller.accel_bounds_mps2", list(self.accel_bounds_mps2),
                              "[low, high] with low < high")
        if isinstance(self.ltv_iterations, bool) or not isinstance(self.ltv_iterations, int) \
                or not 1 <= self.ltv_iterations <= 50:
            raise ConfigError("controller.ltv_iterations", self.ltv_iterations,
                              "an integer in [1, 50]")
        _choice("controller.reference_alignment", self.reference_alignment,
                ("literal", "shifted"))
        _at_least("controller.lookahead_min_m", self.lookahead_min_m, 0.0, inclusive=False)
        _at_least("controller.lookahead_time_s", self.lookahead_time_s, 0.0)
        for key in ("horizon", "control_horizon", "max_obstacles", "solver_max_iter"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int):
                raise ConfigError(f"controller.{key}", value, "an integer")
        if not 1 <= self.horizon <= MAX_HORIZON:
            memory = (f" (the compiled QP grows with N: N = {self.horizon} would need about "
                      f"{_qp_memory_gib(self.horizon, self.max_obstacles):.3g} GiB)"
                      if self.horizon > MAX_HORIZON else "")
            raise ConfigError("controller.horizon", self.horizon,
                              f"an integer in [1, {MAX_HORIZON}]{memory}")
        if not 1 <= self.control_horizon <= self.horizon:
            raise ConfigError("controller.control_horizon", self.control_horizon,
                              f"an integer in [1, controller.horizon={self.horizon}]")
        if not 1 <= self.max_obstacles <= 50:
            raise ConfigError("controller.max_obstacles", self.max_obstacles,
                              "an integer in [1, 50]")
        if self.solver_max_iter > 100000:
            raise ConfigError("controller.solver_max_iter", self.solver_max_iter,
                              "an integer in [1, 100000]")
        _safe_name("controller.name", self.name)
        if self.solver_max_iter < 1:
            raise ConfigError("controller.solver_max_iter", self.solver_max_iter, "an integer >= 1")
        _choice("controller.input_hold", self.input_hold, ("hold_last", "zero_rate"))
        _choice("controller.halfplane_normal", self.halfplane_normal, ("lateral_side", "radial"))
        for key in ("q_lateral", "q_heading", "q_yaw_rate", "q_steering", "r_steering_rate",
                    "slack_weight_linear", "slack_weight_quadratic", "safety_margin_m",
                    "constraint_activation_m"):
            _at_least(f"controller.{key}", getattr(self, key), 0.0)
        _at_least("controller.r_steering_rate", self.r_steering_rate, 0.0, inclusive=False)
        _choice("controller.heading_reference", self.heading_reference,
                ("path_slope", "apf_force"))
        _between("controller.heading_ref_max_rad", self.heading_ref_max_rad, 0.0, math.pi / 2)
        _at_least("controller.yaw_rate_ref_max_rad_s", self.yaw_rate_ref_max_rad_s, 0.0,
                  inclusive=False)
        _choice("controller.path_beyond_end", self.path_beyond_end, ("extend", "hold"))


@dataclass
class ObstacleConfig:
    """One circular obstacle, invisible before ``appear_time_s``, then moving at constant velocity."""

    x_m: float = MISSING
    y_m: float = MISSING
    vx_mps: float = 0.0
    vy_mps: float = 0.0
    radius_m: float = 0.5
    appear_time_s: float = 0.0


@dataclass
class FamilyConfig:
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
            _pair(f"scenario.family.{key}", value)
            if value[0] > value[1]:
                raise ConfigError(f"scenario.family.{key}", list(value), "[low, high] with low <= high")
        for key in ("radius_m", "appear_time_s", "extra_appear_time_s", "crossing_speed_mps",
                    "oncoming_speed_mps"):
            if getattr(self, key)[0] < 0:
                raise ConfigError(f"scenario.family.{key}", list(getattr(self, key)),
                                  "a range of non-negative numbers")
        _between("scenario.family.static_probability", self.static_probability, 0.0, 1.0)
        _between("scenario.family.oncoming_probability", self.oncoming_probability, 0.0, 1.0)
        if self.static_probability + self.oncoming_probability > 1.0:
            raise ConfigError("scenario.family.oncoming_probability", self.oncoming_probability,
                              f"<= 1 - static_probability ({1.0 - self.static_probability})")
        probs = self.obstacle_count_probabilities
        if not 1 <= len(probs) <= 3 or any(not math.isfinite(p) or p < 0 for p in probs) \
                or not math.isclose(sum(probs), 1.0, abs_tol=1e-9):
            raise ConfigError("scenario.family.obstacle_count_probabilities", list(probs),
                              "1 to 3 non-negative numbers (for 1, 2, 3 obstacles) summing to 1")


@dataclass
class ScenarioConfig:
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

    def __post_init__(self) -> None:
        _pair("scenario.start_xy_m", self.start_xy_m)
        _pair("scenario.goal_xy_m", self.goal_xy_m)
        _finite("scenario.start_heading_rad", self.start_heading_rad)
        gap = math.dist(self.start_xy_m, self.goal_xy_m)
        if gap <= self.goal_tolerance_m:
            raise ConfigError("scenario.goal_xy_m", list(self.goal_xy_m),
                              f"a goal farther than goal_tolerance_m={self.goal_tolerance_m} "
                              f"from start_xy_m={list(self.start_xy_m)}")
        _between("scenario.goal_tolerance_m", self.goal_tolerance_m, 1e-3, 100.0)
        for i, v in enumerate(list(self.start_xy_m) + list(self.goal_xy_m)):
            key = f"scenario.{'start' if i < 2 else 'goal'}_xy_m[{i % 2}]"
            _between(key, v, -1e5, 1e5)
        if gap > 10_000.0:
            raise ConfigError("scenario.goal_xy_m", list(self.goal_xy_m),
                              "a goal within 10 km of the start")
        _between("scenario.speed_mps", self.speed_mps, 0.1, 40.0)
        _between("scenario.sample_time_s", self.sample_time_s, 1e-3, 1.0)
        _safe_name("scenario.name", self.name)
        if self.initial_speed_mps is not None:
            _between("scenario.initial_speed_mps", self.initial_speed_mps, 0.0, 40.0)
        for key in ("n_steps", "plant_substeps"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"scenario.{key}", value, "an integer >= 1")
        if not 2 <= self.n_steps <= 100_000:
            raise ConfigError("scenario.n_steps", self.n_steps,
                              "an integer in [2, 100000] (the simulated time must exceed "
                              "sample_time_s)")
        if self.plant_substeps > 1000:
            raise ConfigError("scenario.plant_substeps", self.plant_substeps,
                              "an integer in [1, 1000]")
        if not self.obstacles and self.family is None and not self.allow_no_obstacles:
            raise ConfigError("scenario.obstacles", [], "a non-empty obstacle list (or "
                              "scenario.allow_no_obstacles=true for an obstacle-free run)")
        seen = set()
        for i, obs in enumerate(self.obstacles):
            key = f"scenario.obstacles[{i}]"
            for attr in ("x_m", "y_m", "vx_mps", "vy_mps", "radius_m", "appear_time_s"):
                _finite(f"{key}.{attr}", getattr(obs, attr))
            _between(f"{key}.radius_m", obs.radius_m, 1e-3, 100.0)
            _at_least(f"{key}.appear_time_s", obs.appear_time_s, 0.0)
            for attr in ("x_m", "y_m"):
                _between(f"{key}.{attr}", getattr(obs, attr), -1e5, 1e5)
            for attr in ("vx_mps", "vy_mps"):
                _between(f"{key}.{attr}", getattr(obs, attr), -1000.0, 1000.0)
            signature = (obs.x_m, obs.y_m, obs.vx_mps, obs.vy_mps, obs.radius_m, obs.appear_time_s)
            if signature in seen:
                raise ConfigError(f"{key}", signature, "obstacles that are not exact duplicates")
            seen.add(signature)


@dataclass
class MetricsConfig:
    """Thresholds and readings of the Table 1 metrics (definitions: :mod:`pipeline.metrics`).

    The ``*_definition``-like string switches select which reading a claim's primary metric
    uses; every reading is computed and logged under its own key as well (register entries).
    """

    reaction_steering_band_rad: float = 0.01
    reaction_lateral_band_m: float = 0.05
    reaction_obstacle: str = "threatening"
    reaction_interpolation: str = "linear"
    threat_margin_m: float = 0.5
    threat_horizon_s: float = 3.0
    threat_clearance_m: float = 2.0
    lateral_accel: str = "vy_dot_plus_vx_r"
    smoothness_window: str = "avoidance"
    repulsion_need: str = "threat"
    repulsion_onset_force: float = 1.0
    recovery_lateral_band_m: float = 0.25
    recovery_heading_band_rad: float = 0.05
    recovery_heading_stop_m: float = 3.0
    oscillation: str = "net_reversals_after_pass"
    lateral_sign_band_m: float = 0.05
    yaw_rate_sign_band_rad_s: float = 0.02
    collision_check: str = "continuous"
    attribution_steering_samples: int = 9
    attribution_extra_s: float = 2.0
    goal_tolerance_m: Optional[float] = None

    def __post_init__(self) -> None:
        for key in ("reaction_steering_band_rad", "reaction_lateral_band_m", "threat_clearance_m",
                    "threat_horizon_s", "repulsion_onset_force",
                    "recovery_lateral_band_m", "recovery_heading_band_rad",
                    "recovery_heading_stop_m", "attribution_extra_s",
                    "lateral_sign_band_m", "yaw_rate_sign_band_rad_s"):
            _at_least(f"metrics.{key}", getattr(self, key), 0.0, inclusive=False)
        if self.goal_tolerance_m is not None:
            _at_least("metrics.goal_tolerance_m", self.goal_tolerance_m, 0.0, inclusive=False)
        _at_least("metrics.threat_margin_m", self.threat_margin_m, 0.0)
        _choice("metrics.reaction_obstacle", self.reaction_obstacle,
                ("threatening", "first_visible"))
        _choice("metrics.reaction_interpolation", self.reaction_interpolation,
                ("linear", "sample"))
        _choice("metrics.lateral_accel", self.lateral_accel, ("vy_dot_plus_vx_r", "vx_r"))
        _choice("metrics.smoothness_window", self.smoothness_window, ("avoidance", "whole_run"))
        _choice("metrics.repulsion_need", self.repulsion_need, ("threat", "clearance_band"))
        _choice("metrics.oscillation", self.oscillation,
                ("net_reversals_after_pass", "sign_changes_whole_run"))
        _choice("metrics.collision_check", self.collision_check, ("continuous", "sampled"))
        value = self.attribution_steering_samples
        if isinstance(value, bool) or not isinstance(value, int) or not 2 <= value <= 101:
            raise ConfigError("metrics.attribution_steering_samples", value,
                              "an integer in [2, 101]")


def _default_margins() -> dict:
    return {"C0": 0.02, "C1": 0.05, "C2": 0.1, "C3": 0.05, "C4": 0.1, "C5": 0.5}


def _default_margin_reasons() -> dict:
    return {
        "C0": "two percentage points of collision rate: four scenarios in 200, below what one "
              "reading of a threshold moves",
        "C1": "half a sample time (Ts = 0.1 s): the resolution the paper's 10 Hz loop can act on",
        "C2": "0.1 m/s^3 of RMS lateral jerk, about 5 % of the values measured here and well "
              "below what a passenger notices",
        "C3": "5 percentage points of the repulsive impulse",
        "C4": "one sample time (0.1 s) of settling time",
        "C5": "half a reversal of the lateral error: any systematic extra reversal exceeds it",
    }


@dataclass
class ClaimsConfig:
    """How paired differences become one of four outcomes.

    ``margins`` is each claim's smallest effect of interest (units of its primary metric; C0: a
    collision-rate difference), declared with its reason in ``margin_reasons``.
    """

    alpha: float = 0.05
    n_resamples: int = 999
    seed: int = 0
    estimator: str = "hodges_lehmann"
    test: str = "wilcoxon"
    pairs: str = "neither_collided"
    min_pairs: int = 10
    tie_tolerance: float = 1e-9
    margins: Dict[str, float] = field(default_factory=_default_margins)
    margin_reasons: Dict[str, str] = field(default_factory=_default_margin_reasons)
    comparable_clearance_m: float = 2.0
    cap_binding_share: float = 0.5

    def __post_init__(self) -> None:
        _between("claims.alpha", self.alpha, 1e-6, 0.5)
        for key in ("n_resamples", "seed", "min_pairs"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ConfigError(f"claims.{key}", value, "an integer >= 0")
        if self.n_resamples < 99:
            raise ConfigError("claims.n_resamples", self.n_resamples, "an integer >= 99")
        _choice("claims.estimator", self.estimator, ("hodges_lehmann", "median"))
        _choice("claims.test", self.test, ("wilcoxon", "sign"))
        _choice("claims.pairs", self.pairs, ("neither_collided", "all"))
        _at_least("claims.tie_tolerance", self.tie_tolerance, 0.0)
        for claim in ("C0", "C1", "C2", "C3", "C4", "C5"):
            if claim not in self.margins:
                raise ConfigError(f"claims.margins.{claim}", None, "a margin >= 0 per claim")
            _at_least(f"claims.margins.{claim}", self.margins[claim], 0.0)
            if not str(self.margin_reasons.get(claim, "")).strip():
                raise ConfigError(f"claims.margin_reasons.{claim}", None,
                                  "a sentence saying why the margin is what it is")
        _at_least("claims.comparable_clearance_m", self.comparable_clearance_m, 0.0)
        _between("claims.cap_binding_share", self.cap_binding_share, 0.0, 1.0)


@dataclass
class RunConfig:
    """Bookkeeping of one run."""

    seed: int = 0
    method: str = ""
    variant: str = "default"

    def __post_init__(self) -> None:
        if self.method:
            _safe_name("run.method", self.method)
        _safe_name("run.variant", self.variant)


@dataclass
class ExperimentConfig:
    """The composed configuration of one closed-loop run."""

    vehicle: VehicleConfig = MISSING
    planner: PlannerConfig = MISSING
    controller: ControllerConfig = MISSING
    scenario: ScenarioConfig = MISSING
    model: ModelConfig = field(default_factory=ModelConfig)
    metrics: MetricsConfig = field(default_factory=MetricsConfig)
    claims: ClaimsConfig = field(default_factory=ClaimsConfig)
    run: RunConfig = field(default_factory=RunConfig)

    def __post_init__(self) -> None:
        # cross-group checks need the whole config
        for i, obs in enumerate(self.scenario.obstacles):
            gap = math.dist(self.scenario.start_xy_m, (obs.x_m, obs.y_m))
            if obs.appear_time_s == 0.0 and gap < obs.radius_m + self.vehicle.footprint_radius_m:
                raise ConfigError(f"scenario.obstacles[{i}]", [obs.x_m, obs.y_m],
                                  "an obstacle that does not overlap the vehicle at the start "
                                  f"(centre distance >= {obs.radius_m + self.vehicle.footprint_radius_m} m)")
        goal_tol = self.metrics.goal_tolerance_m
        if goal_tol is None:
            self.metrics.goal_tolerance_m = self.scenario.goal_tolerance_m
        elif not math.isclose(goal_tol, self.scenario.goal_tolerance_m):
            raise ConfigError("metrics.goal_tolerance_m", goal_tol,
                              f"equal to scenario.goal_tolerance_m "
                              f"({self.scenario.goal_tolerance_m}) or null (follows it): the run "
                              "stops at one, the metrics judge with the other")
        if len(self.scenario.obstacles) > self.controller.max_obstacles:
            raise ConfigError("controller.max_obstacles", self.controller.max_obstacles,
                              f">= the number of obstacles ({len(self.scenario.obstacles)})")
        if self.planner.speed_floor_mps < self.vehicle.min_model_speed_mps:
            raise ConfigError("planner.speed_floor_mps", self.planner.speed_floor_mps,
                              f">= vehicle.min_model_speed_mps ({self.vehicle.min_model_speed_mps})")

    @property
    def method_name(self) -> str:
        """Label of the compared method (``run.method``, else the planner's name)."""
        return self.run.method or self.planner.name

    def to_dict(self) -> dict:
        return asdict(self)

    def config_hash(self) -> str:
        """Stable SHA-256 (first 16 hex digits) of what a run depends on: the resolved
        configuration without ``claims`` (how runs are compared re-scores, never re-simulates)."""
        data = self.to_dict()
        data.pop("claims", None)
        text = json.dumps(data, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


@dataclass(frozen=True)
class RegisterEntry:
    """One reading of an ambiguous passage of the paper."""

    topic: str
    paper_says: str
    default: str
    alternatives: str
    config_key: str


INTERPRETATION_REGISTER: tuple[RegisterEntry, ...] = (
    RegisterEntry(
        "Sign of B2", "B2 printed as [0 0 0 1 0]^T (minus signs lost in extraction)",
        "B2 = [0, 0, -1, 0, 0]^T: d(psi - psi_d)/dt = r - r_d (no effect on these runs: the "
        "reference line is straight, so r_d = 0)",
        "+1 (literal placement of a positive entry in the heading row)",
        "model.b2_heading_entry"),
    RegisterEntry(
        "Adaptive gain k_rep of the exponential law",
        "k_rep e^{alpha(1 - d/d0)} d/|d|^2, k_rep not given",
        "k_rep = H_i (the adaptive coefficient, so C3's distance gating carries over)",
        "a constant k_rep (planner.k_rep_constant)", "planner.k_rep_source"),
    RegisterEntry(
        "Two different 'alpha'", "alpha is both the APF step size and the exponent's slope",
        "two parameters: planner.step_size (step) and planner.alpha_e (exponent)",
        "-", "planner.step_size, planner.alpha_e"),
    RegisterEntry(
        "Step cap of the unnormalized rollout",
        "improved step is alpha*F without normalization",
        "each rollout step is capped at planner.step_max_m = 0.5 m (improved preset); without it "
        "the first step is alpha*|g - p|, i.e. metres, and explodes near an obstacle",
        "null: no cap (literal)", "planner.step_max_m"),
    RegisterEntry(
        "Minimum movement threshold",
        "'If F_total is too small, the system may be forced to push'",
        "a step shorter than planner.step_min_m is lengthened to step_min_m along F "
        "(along the goal direction when F = 0)",
        "0: off", "planner.step_min_m"),
    RegisterEntry(
        "Value of beta in H_i (improved)", "'use exp(beta (s - s0)^2) to adjust sensitivity', no value",
        "beta = 0.25 (wider longitudinal support than the baseline's beta = 1)",
        "any beta >= 0", "planner.beta"),
    RegisterEntry(
        "Distance in the repulsion laws", "rho = |p - p_obs|",
        "centre-to-centre distance, floored at planner.rho_floor_m so an obstacle at p gives a "
        "finite force (direction: away from the goal line's left normal when p = o)",
        "-", "planner.rho_floor_m"),
    RegisterEntry(
        "Obstacle positions inside the APF rollout",
        "the APF uses the obstacle list O, no time index inside the rollout",
        "current (measured) positions, held over the rollout; the MPC constraints still predict "
        "obstacle motion at constant velocity",
        "constant_velocity prediction (velocity-aware variant)", "planner.obstacle_prediction"),
    RegisterEntry(
        "Velocity/acceleration sensitivity coefficient",
        "introduction promises repulsion scaled by relative velocity; never defined",
        "off in baseline and improved; the velocity_aware preset scales repulsion by "
        "1 + gain * closing speed", "gain > 0", "planner.closing_speed_gain_s_per_m"),
    RegisterEntry(
        "APF path to lateral MPC reference",
        "Section 3.1: y_ref from the rollout; psi_apf = atan2(F_y, F_x), omega_ref = sat(...)",
        "lateral reference = rollout interpolated at the MPC's predicted stations; heading "
        "reference = path slope, saturated at controller.heading_ref_max_rad",
        "apf_force: heading ramps toward psi_apf at the saturated rate omega_max",
        "controller.heading_reference"),
    RegisterEntry(
        "Reference beyond the end of the rollout",
        "the baseline rollout covers only Np * 0.1 m = 1 m, the MPC looks vx * Np * Ts ahead",
        "extend the last rollout segment linearly (slope saturated)",
        "hold: keep the last lateral position", "controller.path_beyond_end"),
    RegisterEntry(
        "Inputs after the control horizon",
        "Nc = 3 (Appendix A, MATLAB: manipulated variable held after Nc)",
        "hold_last: steering rate held at its Nc-th value", "zero_rate: steering angle held",
        "controller.input_hold"),
    RegisterEntry(
        "Collision-avoidance constraints 'from APF'",
        "'Collision avoidance constraints from APF' (no formula)",
        "one soft half-plane per obstacle and horizon step, side chosen by the APF reference: "
        "sigma (y_k - o_y) >= sqrt(R^2 - (x_k - o_x)^2), sigma = sign(y_ref,k - o_y), "
        "R = r_o + r_v + margin (exact for the disk at the MPC's fixed station x_k)",
        "radial: n . (p_k - o_k) >= R, n from the predicted obstacle toward the APF reference "
        "point (tangent plane; mostly longitudinal, so a lateral MPC can meet it only with slack)",
        "controller.halfplane_normal"),
    RegisterEntry(
        "Time alignment of y_ref in nlmpcmove (kinematic track)",
        "y_ref = [p_1; ...; p_Np] with p_1 the current position, passed to nlmpcmove",
        "literal: row i is the reference of predicted step i, as nlmpcmove reads it (so step 1 "
        "tracks the current position)", "shifted: row i + 1 for step i",
        "controller.reference_alignment"),
    RegisterEntry(
        "Discretization of the kinematic prediction model",
        "Appendix A advances x(k+1) = x(k) + f(x, u) Ts; nlmpc's own discretization is not given",
        "forward Euler for the MPC's prediction (as Appendix A's loop); the plant integrates the "
        "same ODE exactly with RK4 substeps", "-", "scenario.plant_substeps"),
    RegisterEntry(
        "C1: whose appearance starts the reaction clock",
        "Table 1: 'how quickly the system reacts to a suddenly appearing obstacle'",
        "the first obstacle that threatens the vehicle's straight continuation when it appears; "
        "the band crossing interpolated between samples", "first_visible (any obstacle, even a "
        "harmless one); sample (first sample outside the band)",
        "metrics.reaction_obstacle, metrics.reaction_interpolation"),
    RegisterEntry(
        "What threatens", "'sudden obstacle', 'collision risk' (no definition)",
        "an obstacle whose constant-velocity motion comes within both radii + 0.5 m of the "
        "straight continuation of the vehicle's motion within 3 s",
        "other margins and horizons", "metrics.threat_margin_m, metrics.threat_horizon_s"),
    RegisterEntry(
        "C2: lateral acceleration and window", "Table 1: 'smooth curvature and gradual turns'",
        "a_y = vy_dot + vx r; jerk over the avoidance window (threat to recovery)",
        "vx_r (drops vy_dot); whole_run", "metrics.lateral_accel, metrics.smoothness_window"),
    RegisterEntry(
        "C3: when repulsion is needed",
        "Table 2: 'strong repulsion only when needed'; baseline: 'low sensitivity for far "
        "distances'",
        "needed while an obstacle threatens the straight continuation; the score is the share "
        "of repulsive impulse applied while none does",
        "clearance_band: repulsion beyond threat_clearance_m of clearance is unneeded",
        "metrics.repulsion_need"),
    RegisterEntry(
        "C5: what counts as oscillation", "Table 1: 'no sharp drops or oscillations'",
        "reversals of the lateral error after the obstacle is passed, net of the manoeuvre",
        "sign_changes_whole_run (lateral error + yaw rate over the run, the out-and-back "
        "included)", "metrics.oscillation"),
    RegisterEntry(
        "Safety check between samples", "(not in the paper)",
        "continuous: closest approach of linearly interpolated vehicle and obstacles between "
        "log rows; collisions attributed by a sampled reachability check",
        "sampled: clearance at the log rows only",
        "metrics.collision_check, metrics.attribution_steering_samples"),
    RegisterEntry(
        "From paired differences to an outcome", "Tables 1-2 are qualitative",
        "Hodges-Lehmann estimate, Wilcoxon signed-rank test, C1-C5 on pairs where neither "
        "collided, margins per claim (Methods section)",
        "median / sign test / all pairs / other margins",
        "claims.estimator, claims.test, claims.pairs, claims.margins"),
    RegisterEntry(
        "Comparable encounters (kinematic track)",
        "Appendix A's baseline reference crawls at 1 m/s",
        "a claim is compared on the kinematic track only when both methods come within 2 m of "
        "the obstacle", "any other distance", "claims.comparable_clearance_m"),
    RegisterEntry(
        "Run length", "100 steps of 0.1 s (Appendix A)",
        "130 steps: at 3 m/s a 100-step run ends at the goal line before the vehicle can settle; "
        "the run stops early once the goal line is reached",
        "100 (literal)", "scenario.n_steps"),
)


def register_configs() -> None:
    """Register the schemas in Hydra's ConfigStore (called by entry points and tests)."""
    from hydra.core.config_store import ConfigStore

    store = ConfigStore.instance()
    store.store(name="experiment_schema", node=ExperimentConfig)
    store.store(group="vehicle", name="vehicle_schema", node=VehicleConfig)
    store.store(group="planner", name="planner_schema", node=PlannerConfig)
    store.store(group="controller", name="controller_schema", node=ControllerConfig)
    store.store(group="scenario", name="scenario_schema", node=ScenarioConfig)


def to_experiment_config(cfg: Any) -> ExperimentConfig:
    """Build the typed config from a composed Hydra/OmegaConf config, running every range check.

    Parameters
    ----------
    cfg : omegaconf.DictConfig
        Composed config (``hydra`` node, if present, is ignored).

    Returns
    -------
    ExperimentConfig
    """
    from omegaconf import OmegaConf

    # the hydra node is Hydra's own (some of its values exist only inside a running job)
    if "hydra" in cfg:
        cfg = OmegaConf.masked_copy(cfg, [k for k in cfg.keys() if k != "hydra"])
    data = OmegaConf.to_container(cfg, resolve=True)
    data.pop("hydra", None)
    data.pop("experiment", None)
    schema = OmegaConf.structured(ExperimentConfig)
    merged = OmegaConf.merge(schema, data)
    return OmegaConf.to_object(merged)
