"""A run's :class:`~pipeline.analysis.metrics.signals.TrajectoryContext` from its
configuration: what the metrics need besides the logged table (one place for every stage that
re-scores stored trajectories: the studies, the report, the API)."""

from __future__ import annotations

import functools
import math
from typing import Any

from pipeline.analysis.metrics.signals import TrajectoryContext


def trajectory_context(cfg: Any) -> TrajectoryContext:
    """Geometry and vehicle limits the metrics need, from the run's configuration (a
    :class:`pipeline.config.ExperimentConfig`; typed loosely because the configuration module,
    which holds every stage's settings, comes after this stage)."""
    v = cfg.vehicle
    start, goal = cfg.scenario.start_xy_m, cfg.scenario.goal_xy_m
    # the limits the collision attribution may use are the track's actuators: on the lateral
    # track a steering rate (limited) with the speed the planner's (braking at the vehicle's
    # limit); on the Appendix-A track (its plugins included) a steering angle and an
    # acceleration, both held over a sample, within the controller's bounds
    kinematic = cfg.controller.kind == "kinematic_mpc"
    low, high = cfg.controller.accel_bounds_mps2 if kinematic \
        else (-v.braking_limit_mps2, 0.0)
    return TrajectoryContext((start[0], start[1]), (goal[0], goal[1]),
                             v.footprint_radius_m, cfg.model.validity_heading_rad,
                             tyre_linear_limit=_tyre_limit(cfg.model.tyre_linear_tolerance),
                             wheelbase_m=v.wheelbase_m, steering_max_rad=v.steering_max_rad,
                             steering_rate_max_rad_s=math.inf if kinematic
                             else v.steering_rate_max_rad_s,
                             braking_mps2=max(-float(low), 0.0), accel_mps2=max(float(high), 0.0),
                             personal_space_m=_personal_space(cfg.scenario),
                             obstacle_slots=getattr(cfg.controller, "max_obstacles", None),
                             vehicle_offsets_m=tuple(float(c) for c in v.footprint_offsets_m),
                             crossing=_crossing(cfg.scenario, v.footprint_radius_m))


def _personal_space(scenario: Any) -> float | None:
    """The personal-space gap (m) of a scenario among walkers, else None."""
    walkers = getattr(scenario, "pedestrians", None)
    return float(walkers.personal_space_m) if walkers is not None else None


def _crossing(scenario: Any, vehicle_radius_m: float) -> tuple[bool, bool] | None:
    """A drawn crossing among recorded walkers: whether its straight line meets a walker and
    whether standing still at its start is touched (the recording alone); else None."""
    walkers = getattr(scenario, "pedestrians", None)
    if walkers is None or walkers.scene is None or walkers.window_start_s is None:
        return None
    from pipeline.loop.pedestrians import crossing_difficulty

    judged = crossing_difficulty(scenario, vehicle_radius_m)
    return judged.straight_line_meets, judged.standing_touched


@functools.lru_cache(maxsize=16)
def _tyre_limit(tolerance: float) -> float:
    """:func:`~pipeline.loop.model.tyre_linear_limit`, solved once per tolerance."""
    from pipeline.loop.model import tyre_linear_limit

    return tyre_linear_limit(tolerance)
