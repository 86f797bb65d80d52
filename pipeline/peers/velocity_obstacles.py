"""Velocity obstacles as a planner feeding the same MPC (Fiorini and Shiller, "Motion planning in
dynamic environments using velocity obstacles", IJRR 17(7), 1998).

A planner plug-in (``planner._target_``): each step it picks one velocity for the vehicle and
hands the MPC the straight path along it; the MPC (lateral on the paper's track, the kinematic
LTV-MPC on the Appendix-A track) tracks that path exactly as it tracks the APF's, and keeps its
own soft collision half-planes, which are linearized about this reference as in every other
method (:mod:`pipeline.loop.controller.references`).

Readings (the paper leaves these to the application; each is a ``planner.params`` key):

* **Velocity obstacle.** Obstacle ``j`` (centre ``o_j``, velocity ``v_j``, radius ``R_j``) is
  enlarged to the disc of radius ``R = R_j + vehicle_radius_m + margin_m`` (the configuration
  space of a disc-shaped vehicle). A candidate velocity ``v`` lies in ``VO_j`` when the ray of
  the relative velocity ``w = v - v_j`` from the vehicle's position ``p`` enters that disc
  within ``time_horizon_s``: the first root ``t_1`` of ``|o_j - p - t w| = R`` exists and
  ``0 <= t_1 <= tau`` (the VO truncated at a time horizon ``tau``, as Fiorini and Shiller
  truncate it; a tangent ray counts as inside). Obstacles do not react: the plain (not the
  reciprocal) velocity obstacle, with each obstacle's velocity as the scenario gives it
  (constant; visible obstacles only).
* **Already inside an enlarged disc** (``|o_j - p| <= R``: the margin has been entered): the
  velocities that close the distance (``w . (o_j - p) > 0``) are inside ``VO_j`` with time to
  collision 0, the others are outside it.
* **Candidates.** One speed, the planned one (``speed_mps``; by default ``planner.step_size /
  sample_time_s``, the speed at which the straight-to-goal reference runs: 0.3 m / 0.1 s = 3
  m/s, the scenario's nominal speed; the plant's speed loop is left to the MPC's speed
  reference as in every lateral-track method), and ``heading_count`` headings spread evenly
  over ``goal direction +- fan_half_angle_rad``.
* **Reachable velocities** (Fiorini and Shiller's RV, the velocities the vehicle's dynamics
  reach within a short interval; their avoidance velocities are RAV = RV minus the VOs): a car
  at constant speed reaches the headings within ``reachable_turn_rad`` of its velocity's
  heading (0.5 rad: about one second of full steering at 3 m/s, ``3 tan(0.4) / 2.5 = 0.51``
  rad/s). They are preferred, not required: the MPC, not this planner, holds the car to its
  limits, and a reference it cannot follow at once is still better than one into a VO. A
  vehicle slower than 0.1 m/s (or no velocity given) reaches every candidate;
  ``reachable_turn_rad: null`` makes every candidate reachable (the plain fan). Measured on
  family members 0-39 of the lateral track: 3 collisions with the plain fan (the vehicle,
  still turned away after passing one obstacle, is sent to the far side of the next, a turn it
  cannot make in time), none with it.
* **Choice.** Lexicographic: admissible (outside every ``VO_j``) first, then reachable, then
  the one closest to the goal direction; remaining ties (the two headings ``+-`` the same
  offset) to the one closer to the vehicle's velocity heading, then the left one. When none is
  admissible: reachable first, then the largest time to collision (minimum over obstacles of
  ``t_1``, not truncated at ``tau``; ``inf`` for a ray that misses), then again the goal
  direction.
* **Path.** ``horizon`` points ``p + k Ts v*`` (``k = 0 .. Np - 1``): straight along the chosen
  velocity from the vehicle's position, spaced as the MPC's predicted stations. The forces of
  :class:`~pipeline.loop.planner.ApfRollout` are zero (there is no potential field).
* **Vehicle radius.** The planner is not handed the vehicle, so ``vehicle_radius_m`` is a param:
  its default 1.0 m is ``vehicle.footprint_radius_m`` of ``conf/vehicle/compact_car.yaml``,
  the footprint the collision metrics and the MPC's half-planes use.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from math import atan2, hypot, isfinite, pi
from typing import Any

import numpy as np

from pipeline.errors import ConfigError
from pipeline.loop.planner import ApfPlanner, ApfRollout
from pipeline.loop.scenario import ObstacleSnapshot
from pipeline.loop.settings import PlannerConfig

_TINY = 1e-12
#: below this speed (m/s) the vehicle's velocity says nothing of its heading
_MOVING_MPS = 0.1


@dataclass(frozen=True)
class VoSettings:
    """The velocity-obstacle planner's settings (``planner.params``).

    Attributes
    ----------
    speed_mps : float or None
        Speed of every candidate velocity; None: ``planner.step_size / sample_time_s``.
    heading_count : int
        Number of candidate headings (odd: the goal direction itself is one of them).
    fan_half_angle_rad : float
        Candidates span the goal direction ``+-`` this angle.
    time_horizon_s : float
        ``tau``: a collision later than this does not put a velocity in a VO.
    vehicle_radius_m : float
        The vehicle's collision radius (``vehicle.footprint_radius_m``).
    margin_m : float
        Clearance added to every combined radius.
    reachable_turn_rad : float or None
        Headings within this angle of the vehicle's velocity are its reachable ones, preferred
        (None: every candidate counts as reachable).
    """

    speed_mps: float | None = None
    heading_count: int = 41
    fan_half_angle_rad: float = 1.0
    time_horizon_s: float = 3.0
    vehicle_radius_m: float = 1.0
    margin_m: float = 0.3
    reachable_turn_rad: float | None = 0.5

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> VoSettings:
        """Settings from ``planner.params``; a :class:`~pipeline.errors.ConfigError` (a
        ``ValueError``, one line) naming ``planner.params.<key>`` and its allowed range for an
        unknown key or a value out of range."""
        known = {f.name for f in fields(cls)}
        for key in params:
            if key not in known:
                raise ConfigError(f"planner.params.{key}", params[key],
                                  "a key of the velocity-obstacle planner: "
                                  + ", ".join(sorted(known)))
        values = {**{f.name: f.default for f in fields(cls)}, **dict(params)}
        speed = values["speed_mps"]
        if speed is not None:
            _number("planner.params.speed_mps", speed, 0.1, 40.0, low_open=False)
        count = values["heading_count"]
        if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= 1001:
            raise ConfigError("planner.params.heading_count", count, "an integer in [1, 1001]")
        _number("planner.params.fan_half_angle_rad", values["fan_half_angle_rad"], 0.0, pi)
        _number("planner.params.time_horizon_s", values["time_horizon_s"], 0.0, 600.0,
                low_open=True)
        _number("planner.params.vehicle_radius_m", values["vehicle_radius_m"], 0.0, 20.0)
        _number("planner.params.margin_m", values["margin_m"], 0.0, 20.0)
        reach = values["reachable_turn_rad"]
        if reach is not None:
            _number("planner.params.reachable_turn_rad", reach, 0.0, pi, low_open=True)
        return cls(None if speed is None else float(speed), int(count),
                   float(values["fan_half_angle_rad"]), float(values["time_horizon_s"]),
                   float(values["vehicle_radius_m"]), float(values["margin_m"]),
                   None if reach is None else float(reach))


def _number(key: str, value: Any, low: float, high: float, low_open: bool = False) -> None:
    """A finite real number in ``[low, high]`` (``(low, high]`` when ``low_open``), else a
    :class:`~pipeline.errors.ConfigError` naming ``key``."""
    allowed = f"a number in {'(' if low_open else '['}{low}, {high}]"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(key, value, allowed)
    v = float(value)
    if not isfinite(v) or v > high or v < low or (low_open and v == low):
        raise ConfigError(key, value, allowed)


def heading_offsets_rad(count: int, half_angle_rad: float) -> np.ndarray:
    """Offsets of the candidate headings from the goal direction, evenly spread over
    ``[-half_angle, +half_angle]``, exactly symmetric (``offsets[i] == -offsets[-1 - i]``).

    Parameters
    ----------
    count : int
        Number of headings (one: the goal direction alone).
    half_angle_rad : float

    Returns
    -------
    ndarray, shape (count,)
    """
    if count == 1:
        return np.zeros(1)
    steps = 2.0 * np.arange(count) - (count - 1)       # integers, symmetric about 0
    return half_angle_rad * steps / (count - 1)


def time_to_collision_s(relative_positions_m: np.ndarray, relative_velocities_mps: np.ndarray,
                        combined_radii_m: np.ndarray) -> np.ndarray:
    """First time at which each relative-velocity ray enters each enlarged disc.

    With ``d = o_j - p`` and ``w = v - v_j``, the first root of ``|d - t w| = R_j`` for
    ``t >= 0``; ``0`` where the vehicle is already inside the disc and ``w`` closes the
    distance; ``inf`` where the ray misses (or leaves) the disc.

    Parameters
    ----------
    relative_positions_m : ndarray, shape (n, 2)
        ``o_j - p``: each obstacle's centre relative to the vehicle.
    relative_velocities_mps : ndarray, shape (k, n, 2)
        ``v_i - v_j`` for candidate ``i`` and obstacle ``j``.
    combined_radii_m : ndarray, shape (n,)

    Returns
    -------
    ndarray, shape (k, n)
    """
    d = np.asarray(relative_positions_m, float)[None, :, :]
    w = np.asarray(relative_velocities_mps, float)
    radius = np.asarray(combined_radii_m, float)[None, :]
    a = np.sum(w * w, axis=-1)
    b = np.sum(w * d, axis=-1)
    c = np.sum(d * d, axis=-1) - radius * radius
    disc = b * b - a * c
    with np.errstate(invalid="ignore", divide="ignore"):
        first = (b - np.sqrt(np.maximum(disc, 0.0))) / a
    hits = (a > _TINY) & (b > 0.0) & (disc >= 0.0)
    out = np.where(hits, first, np.inf)
    inside = c <= 0.0
    return np.where(inside, np.where(b > 0.0, 0.0, np.inf), out)


def choose_velocity(position_m: np.ndarray, goal_m: np.ndarray, obstacles: ObstacleSnapshot,
                    settings: VoSettings, speed_mps: float,
                    vehicle_velocity_mps: np.ndarray | None = None
                    ) -> tuple[np.ndarray, bool, np.ndarray, np.ndarray]:
    """The velocity the planner picks (see the module's readings).

    Parameters
    ----------
    position_m, goal_m : ndarray, shape (2,)
    obstacles : ObstacleSnapshot
        Visible obstacles.
    settings : VoSettings
    speed_mps : float
        Speed of every candidate.
    vehicle_velocity_mps : ndarray, shape (2,), optional
        Breaks ties between headings equally far from the goal direction.

    Returns
    -------
    velocity_mps : ndarray, shape (2,)
        The chosen velocity.
    admissible : bool
        Whether it lies outside every velocity obstacle (False: the largest-time fallback).
    candidates_mps : ndarray, shape (k, 2)
        Every candidate velocity.
    inside : ndarray of bool, shape (k,)
        Whether each candidate lies in some ``VO_j``.
    """
    to_goal = np.asarray(goal_m, float) - np.asarray(position_m, float)
    if hypot(float(to_goal[0]), float(to_goal[1])) > _TINY:
        goal_heading = atan2(float(to_goal[1]), float(to_goal[0]))
    elif vehicle_velocity_mps is not None and float(np.hypot(*vehicle_velocity_mps)) > _TINY:
        goal_heading = atan2(float(vehicle_velocity_mps[1]), float(vehicle_velocity_mps[0]))
    else:
        goal_heading = 0.0
    offsets = heading_offsets_rad(settings.heading_count, settings.fan_half_angle_rad)
    headings = goal_heading + offsets
    candidates = speed_mps * np.column_stack([np.cos(headings), np.sin(headings)])
    n = obstacles.positions_m.shape[0]
    if n:
        relative = obstacles.positions_m - np.asarray(position_m, float)[None, :]
        radii = obstacles.radii_m + settings.vehicle_radius_m + settings.margin_m
        ttc = time_to_collision_s(relative, candidates[:, None, :]
                                  - obstacles.velocities_mps[None, :, :], radii)
        earliest = ttc.min(axis=1)
    else:
        earliest = np.full(offsets.size, np.inf)
    inside = earliest <= settings.time_horizon_s
    # how far each candidate turns from the vehicle's velocity (0 for a vehicle at rest)
    turn = np.zeros(offsets.size)
    if vehicle_velocity_mps is not None and float(np.hypot(*vehicle_velocity_mps)) > _MOVING_MPS:
        current = atan2(float(vehicle_velocity_mps[1]), float(vehicle_velocity_mps[0]))
        turn = np.abs(np.angle(np.exp(1j * (headings - current))))
    unreachable = turn > settings.reachable_turn_rad + 1e-12 \
        if settings.reachable_turn_rad is not None else np.zeros(offsets.size, bool)
    # np.lexsort: the last key is the primary one; -offsets puts the left heading first
    if not inside.all():
        order = np.lexsort((-offsets, turn, np.abs(offsets), unreachable, inside))
    else:
        order = np.lexsort((-offsets, turn, np.abs(offsets), -earliest, unreachable))
    best = int(order[0])
    return candidates[best], not bool(inside[best]), candidates, inside


class VelocityObstaclePlanner(ApfPlanner):
    """Velocity obstacles (Fiorini and Shiller 1998) as the planner of the closed loop: the
    reference path runs straight along the chosen velocity.

    Parameters
    ----------
    settings : PlannerConfig
        ``step_size`` (with ``sample_time_s``, the default speed) and ``params``
        (:class:`VoSettings`).
    horizon : int
        Points of the reference path.
    sample_time_s : float
    """

    def __init__(self, settings: PlannerConfig, horizon: int, sample_time_s: float) -> None:
        super().__init__(settings, horizon, sample_time_s)
        self.vo = VoSettings.from_params(settings.params)
        self.speed_mps = self.vo.speed_mps if self.vo.speed_mps is not None \
            else float(settings.step_size) / float(sample_time_s)

    def rollout(self, position_m: np.ndarray, goal_m: np.ndarray, obstacles: ObstacleSnapshot,
                vehicle_velocity_mps: np.ndarray | None = None) -> ApfRollout:
        """The reference path: ``horizon`` points from the vehicle's position along the chosen
        velocity (:func:`choose_velocity`), ``sample_time_s`` apart."""
        position = np.asarray(position_m, float)
        velocity, _, _, _ = choose_velocity(position, goal_m, obstacles, self.vo,
                                            self.speed_mps, vehicle_velocity_mps)
        n = max(int(self.horizon), 1)
        path = position[None, :] + (self.sample_time_s * np.arange(n))[:, None] * velocity[None, :]
        steps = n - 1
        zeros = np.zeros((steps, 2))
        return ApfRollout(path, zeros, zeros.copy(), np.zeros(steps, bool),
                          np.zeros(steps, bool))
