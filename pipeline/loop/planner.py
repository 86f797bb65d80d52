"""Planner stage: the APF rollout (baseline and improved as presets of one switch space) and the
velocity planner ``V_r = f_v(obstacles)``.

Equations (paper Section 2)::

    F_att(p) = g - p
    H_i      = H_max / (1 + exp(beta (s - s_o)^2))      if rho_i <= rho_p else 0
    polynomial  F_rep,i = H_i (1/rho - 1/rho0) (p - o)/rho^3            for rho < rho0
    exponential F_rep,i = k_rep exp(alpha_e (1 - rho/rho0)) (p - o)/rho^2 for rho < rho0
    p_{t+1}  = p_t + step_size * F/|F|   (normalized)   or   p_t + step_size * F

then the minimum-movement threshold (``step_min_m``) and the registered step cap
(``step_max_m``). All positions in metres, global frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import exp, inf, sqrt
from typing import NamedTuple

import numpy as np

from pipeline.loop.arrays import KernelValues
from pipeline.loop.kernels import Kernels
from pipeline.loop.scenario import ObstacleSnapshot, route_point_ahead
from pipeline.loop.settings import PlannerConfig

_TINY = 1e-12
#: no route to follow (:func:`apf_rollout_arrays`' ``route``)
NO_ROUTE = np.zeros((0, 2))


@dataclass(frozen=True)
class ApfRollout:
    """The APF's short reference path over the horizon.

    Attributes
    ----------
    path_m : ndarray, shape (Np, 2)
        ``p_1 .. p_Np``; ``p_1`` is the vehicle's position.
    attraction : ndarray, shape (Np - 1, 2)
        ``F_att`` at ``p_1 .. p_{Np-1}``.
    repulsion : ndarray, shape (Np - 1, 2)
        ``F_rep`` (sum over obstacles) at the same points.
    step_cap_active : ndarray of bool, shape (Np - 1,)
        Whether the step cap shortened each step.
    step_min_active : ndarray of bool, shape (Np - 1,)
        Whether the minimum-movement threshold lengthened each step.
    """

    path_m: np.ndarray
    attraction: np.ndarray
    repulsion: np.ndarray
    step_cap_active: np.ndarray
    step_min_active: np.ndarray


def adaptive_coefficient(position_m: np.ndarray, obstacle_positions_m: np.ndarray,
                         h_max: float, beta: float, rho_p_m: float) -> np.ndarray:
    """Adaptive repulsive coefficient ``H_i`` for each obstacle.

    ``H_i = H_max / (1 + exp(beta (s - s_o)^2))`` when ``rho_i <= rho_p``, else 0, with
    ``s`` the longitudinal (x) coordinate.

    Returns
    -------
    ndarray, shape (n,)
    """
    obstacles = np.asarray(obstacle_positions_m, dtype=float).reshape(-1, 2)
    rho = np.linalg.norm(position_m[None, :] - obstacles, axis=1)
    ds = position_m[0] - obstacles[:, 0]
    # exp overflows for large beta*ds^2; 1/(1+inf) = 0 is the right limit
    with np.errstate(over="ignore"):
        h = h_max / (1.0 + np.exp(beta * ds**2))
    return np.where(rho <= rho_p_m, h, 0.0)


def repulsive_force(position_m: np.ndarray, goal_m: np.ndarray,
                    obstacle_positions_m: np.ndarray, params: PlannerConfig,
                    closing_speed_mps: np.ndarray | None = None) -> np.ndarray:
    """Sum of the repulsive forces of all obstacles at ``position_m``.

    Parameters
    ----------
    position_m, goal_m : ndarray, shape (2,)
    obstacle_positions_m : ndarray, shape (n, 2)
    params : PlannerConfig
        ``repulsion_law`` (``none`` turns repulsion off: the no-APF peer), ``rho0_m``, ``alpha_e``, ``k_rep_source`` and the H_i constants.
    closing_speed_mps : ndarray, shape (n,), optional
        Rate at which each obstacle's distance shrinks; with
        ``closing_speed_gain_s_per_m > 0`` repulsion is scaled by ``1 + gain * max(0, closing)``.

    Returns
    -------
    ndarray, shape (2,)
    """
    obstacles = np.asarray(obstacle_positions_m, dtype=float).reshape(-1, 2)
    if obstacles.shape[0] == 0 or params.repulsion_law == "none":
        return np.zeros(2)
    diff = position_m[None, :] - obstacles
    rho = np.linalg.norm(diff, axis=1)
    # direction away from the obstacle; at rho = 0 use the left normal of the goal direction
    to_goal = goal_m - position_m
    normal = np.array([-to_goal[1], to_goal[0]])
    normal = normal / np.linalg.norm(normal) if np.linalg.norm(normal) > _TINY else np.array([0.0, 1.0])
    direction = np.where(rho[:, None] > _TINY, diff / np.maximum(rho, _TINY)[:, None], normal[None, :])
    rho_eff = np.maximum(rho, params.rho_floor_m)
    h = adaptive_coefficient(position_m, obstacles, params.h_max, params.beta, params.rho_p_m)
    if params.repulsion_law == "polynomial":
        magnitude = h * (1.0 / rho_eff - 1.0 / params.rho0_m) / rho_eff**2
    else:
        k_rep = h if params.k_rep_source == "adaptive_h" else params.k_rep_constant
        magnitude = k_rep * np.exp(params.alpha_e * (1.0 - rho_eff / params.rho0_m)) / rho_eff
    magnitude = np.where(rho < params.rho0_m, magnitude, 0.0)
    if closing_speed_mps is not None and params.closing_speed_gain_s_per_m > 0.0:
        magnitude = magnitude * (1.0 + params.closing_speed_gain_s_per_m
                                 * np.maximum(np.asarray(closing_speed_mps, dtype=float), 0.0))
    return (magnitude[:, None] * direction).sum(axis=0)


def apf_step(position_m: np.ndarray, goal_m: np.ndarray, obstacle_positions_m: np.ndarray,
             params: PlannerConfig, closing_speed_mps: np.ndarray | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool, bool]:
    """One APF update ``p -> p + step``.

    Returns
    -------
    next_position_m, attraction, repulsion : ndarray, shape (2,)
    cap_active, min_active : bool
        Whether the step cap or the minimum-movement threshold changed the step.
    """
    attraction = goal_m - position_m
    repulsion = repulsive_force(position_m, goal_m, obstacle_positions_m, params, closing_speed_mps)
    total = attraction + repulsion
    norm = float(np.linalg.norm(total))
    if params.normalize_step:
        step = params.step_size * total / norm if norm > _TINY else np.zeros(2)
    else:
        step = params.step_size * total
    length = float(np.linalg.norm(step))
    min_active = cap_active = False
    if params.step_min_m > 0.0 and length < params.step_min_m:
        if norm > _TINY:
            direction = total / norm
        else:
            goal_dist = np.linalg.norm(attraction)
            direction = attraction / goal_dist if goal_dist > _TINY else np.zeros(2)
        step = params.step_min_m * direction
        min_active = True
    elif params.step_max_m is not None and length > params.step_max_m:
        step = step * (params.step_max_m / length)
        cap_active = True
    return position_m + step, attraction, repulsion, cap_active, min_active


def apf_rollout(position_m: np.ndarray, goal_m: np.ndarray, obstacles: ObstacleSnapshot,
                params: PlannerConfig, horizon: int, sample_time_s: float,
                vehicle_velocity_mps: np.ndarray | None = None) -> ApfRollout:
    """Roll the APF out over the horizon: ``p_1`` = vehicle position, ``p_2 .. p_Np`` by
    :func:`apf_step`.

    The rollout runs on plain floats (a handful of obstacles, ``Np - 1`` sequential steps:
    numpy's per-call overhead would dominate); :func:`apf_step` is the vectorized statement of
    the same update and the tests hold the two together.

    Parameters
    ----------
    position_m, goal_m : ndarray, shape (2,)
    obstacles : ObstacleSnapshot
        Visible obstacles only.
    params : PlannerConfig
    horizon : int
        ``Np``, number of points of the path.
    sample_time_s : float
        Time per rollout step, used only for ``obstacle_prediction = constant_velocity``.
    vehicle_velocity_mps : ndarray, shape (2,), optional
        For the closing-speed scaling of the velocity-aware variant.
    """
    return _rollout(None, apf_kernel_settings(params), position_m, goal_m, obstacles, horizon,
                    sample_time_s, vehicle_velocity_mps)


def _rollout(kernels: Kernels | None, settings: ApfSettings, position_m: np.ndarray,
             goal_m: np.ndarray, obstacles: ObstacleSnapshot, horizon: int,
             sample_time_s: float, vehicle_velocity_mps: np.ndarray | None,
             route_m: np.ndarray = NO_ROUTE, route_lookahead_m: float = 0.0) -> ApfRollout:
    """:func:`apf_rollout_arrays` run by ``kernels`` (None: by CPython, as the function
    stands); ``settings`` is :func:`apf_kernel_settings`; ``route_m`` (P, 2; empty: none) the
    polyline the attraction follows ``route_lookahead_m`` ahead."""
    vvx, vvy = (float(vehicle_velocity_mps[0]), float(vehicle_velocity_mps[1])) \
        if vehicle_velocity_mps is not None else (0.0, 0.0)
    if vehicle_velocity_mps is None and settings.closing_speed_on:
        settings = settings._replace(closing_speed_on=False)  # no velocity, no scaling
    start = (float(position_m[0]), float(position_m[1]), float(goal_m[0]), float(goal_m[1]))
    kernel = kernels.apf_rollout if kernels is not None else apf_rollout_arrays
    if kernels is None or not kernels.compiled:
        return ApfRollout(*kernel(
            *start, obstacles.positions_m.tolist(), obstacles.velocities_mps.tolist(),
            settings, int(horizon), float(sample_time_s), vvx, vvy, route_m.tolist(),
            float(route_lookahead_m)))
    return ApfRollout(*kernel(
        *start, np.ascontiguousarray(obstacles.positions_m, dtype=float).reshape(-1, 2),
        np.ascontiguousarray(obstacles.velocities_mps, dtype=float).reshape(-1, 2), settings,
        int(horizon), float(sample_time_s), vvx, vvy,
        np.ascontiguousarray(route_m, dtype=float).reshape(-1, 2), float(route_lookahead_m)))


def _exp_or_inf(x: float) -> float:
    """``exp(x)``, ``inf`` where it overflows (CPython raises; compiled, ``exp`` gives inf)."""
    try:
        return exp(x)
    except OverflowError:
        return inf


def apf_rollout_arrays(px: float, py: float, gx: float, gy: float, centres: KernelValues,  # noqa: C901
                       velocities: KernelValues, settings: ApfSettings, horizon: int,
                       sample_time_s: float, vvx: float, vvy: float, route: KernelValues,
                       route_lookahead: float
                       ) -> tuple[KernelValues, KernelValues, KernelValues, KernelValues,
                                  KernelValues]:
    """The rollout of :func:`apf_rollout` on plain numbers: ``path (max(Np, 1), 2), attraction
    (Np - 1, 2), repulsion (Np - 1, 2), step cap active, step minimum used (Np - 1,)``.

    ``centres`` and ``velocities`` are the obstacles' rows ``[x, y]`` (lists in CPython, arrays
    compiled); ``settings`` is :func:`apf_kernel_settings`. ``route`` (rows ``[x, y]``, at
    least two; fewer: none) is a polyline the attraction follows: at every rollout point it
    pulls towards the point ``route_lookahead`` (m) along the route beyond that point's
    projection on it (:func:`route_point_ahead`; past the route's end the goal ``gx, gy``), so
    the rollout follows the road through a bend instead of heading for one fixed point. This one statement runs in CPython
    (a single run) and compiled by numba (:mod:`pipeline.loop.compiled`, the family runner's
    workers): the same operations on the same C library's functions, so the same bits (the
    tests hold them equal).
    """
    h_max, beta, rho_p, rho0 = settings.h_max, settings.beta, settings.rho_p_m, settings.rho0_m
    alpha_e, k_const = settings.alpha_e, settings.k_rep_constant
    floor, gain = settings.rho_floor_m, settings.closing_speed_gain_s_per_m
    step_size, step_min, step_max = settings.step_size, settings.step_min_m, settings.step_max_m
    repulsion_on, polynomial = settings.repulsion_on, settings.polynomial
    constant_k, predict = settings.constant_k_rep, settings.predict_obstacles
    normalize, closing_on = settings.normalize_step, settings.closing_speed_on
    n = horizon
    steps = max(n - 1, 0)
    path = np.empty((max(n, 1), 2))
    attraction = np.empty((steps, 2))
    repulsion = np.empty((steps, 2))
    cap = np.zeros(steps, dtype=np.bool_)
    low = np.zeros(steps, dtype=np.bool_)
    path[0, 0], path[0, 1] = px, py
    n_obstacles = len(centres)
    along_route = len(route) >= 2
    for t in range(steps):
        if along_route:
            cx, cy = route_point_ahead(route, px, py, route_lookahead, gx, gy)
            ax, ay = cx - px, cy - py
        else:
            ax, ay = gx - px, gy - py
        rx = ry = 0.0
        if n_obstacles > 0 and repulsion_on:
            # direction away from an obstacle sitting exactly at p: left normal of the goal
            nlen = sqrt(ay * ay + ax * ax)
            if nlen > _TINY:
                nx, ny = -ay / nlen, ax / nlen
            else:
                nx, ny = 0.0, 1.0
            for j in range(n_obstacles):
                ox, oy = centres[j][0], centres[j][1]
                ovx, ovy = velocities[j][0], velocities[j][1]
                if predict:
                    ox, oy = ox + t * sample_time_s * ovx, oy + t * sample_time_s * ovy
                dx, dy = px - ox, py - oy
                rho = sqrt(dx * dx + dy * dy)
                if rho >= rho0:
                    continue
                if rho > _TINY:
                    ux, uy = dx / max(rho, _TINY), dy / max(rho, _TINY)
                else:
                    ux, uy = nx, ny
                rho_eff = max(rho, floor)
                h = 0.0
                if rho <= rho_p:
                    # 1 / (1 + inf) = 0 is the right limit where exp overflows
                    h = h_max / (1.0 + _exp_or_inf(beta * (dx * dx)))
                if polynomial:
                    # rho_eff * rho_eff, not rho_eff**2: CPython's ** is the C library's pow, off
                    # by a bit from the product for some arguments, where numba multiplies
                    magnitude = h * (1.0 / rho_eff - 1.0 / rho0) / (rho_eff * rho_eff)
                else:
                    k_rep = k_const if constant_k else h
                    magnitude = k_rep * exp(alpha_e * (1.0 - rho_eff / rho0)) / rho_eff
                if closing_on:
                    lx, ly = -dx, -dy
                    dist = max(rho, _TINY)
                    closing = ((vvx - ovx) * lx + (vvy - ovy) * ly) / dist
                    magnitude = magnitude * (1.0 + gain * max(closing, 0.0))
                rx += magnitude * ux
                ry += magnitude * uy
        fx, fy = ax + rx, ay + ry
        norm = sqrt(fx * fx + fy * fy)
        if normalize:
            if norm > _TINY:
                sx, sy = step_size * fx / norm, step_size * fy / norm
            else:
                sx, sy = 0.0, 0.0
        else:
            sx, sy = step_size * fx, step_size * fy
        length = sqrt(sx * sx + sy * sy)
        if step_min > 0.0 and length < step_min:
            if norm > _TINY:
                dirx, diry = fx / norm, fy / norm
            else:
                goal_dist = sqrt(ax * ax + ay * ay)
                if goal_dist > _TINY:
                    dirx, diry = ax / goal_dist, ay / goal_dist
                else:
                    dirx, diry = 0.0, 0.0
            sx, sy = step_min * dirx, step_min * diry
            low[t] = True
        elif length > step_max:  # no cap: step_max is inf
            scale = step_max / length
            sx, sy = sx * scale, sy * scale
            cap[t] = True
        px, py = px + sx, py + sy
        path[t + 1, 0], path[t + 1, 1] = px, py
        attraction[t, 0], attraction[t, 1] = ax, ay
        repulsion[t, 0], repulsion[t, 1] = rx, ry
    return path, attraction, repulsion, cap, low


def plan_speed(position_m: np.ndarray, heading_rad: float, obstacles: ObstacleSnapshot,
               nominal_speed_mps: float, vehicle_radius_m: float,
               params: PlannerConfig, path_m: np.ndarray | None = None,
               speed_mps: float | None = None) -> float:
    """Velocity planning ``V_r = f_v(obstacles)`` (Section 3.1: "considers the relative
    position and motion of obstacles"; "safety constraints (e.g., minimum stopping
    distance)"), by ``params.velocity_rule``:

    * ``predicted_clearance`` (default, needs ``path_m``): :func:`clearance_speed`, the fastest
      speed whose constant-velocity prediction along the APF's path keeps its clearance;
    * ``stopping_distance`` (the earlier reading): an obstacle counts when it lies ahead of the
      vehicle inside a corridor as wide as both radii plus ``stop_margin_m``; with ``gap`` the
      free distance to it, the speed is capped at ``sqrt(2 a_brake max(gap - stop_margin,
      0))`` (the speed from which the vehicle can stop in the gap), never below
      ``speed_floor_mps`` and never above the nominal speed. It ignores where the obstacle
      goes and where the vehicle steers: it slowed the vehicle in front of obstacles crossing
      the way it swerved, and collisions rose (27 / 22 to 66 / 98 of 200 in the fixed frame).

    Returns
    -------
    float
        Planned speed (m/s).
    """
    if not params.velocity_planning or obstacles.positions_m.shape[0] == 0:
        return float(nominal_speed_mps)
    if params.velocity_rule == "predicted_clearance" and path_m is not None:
        return clearance_speed(path_m, obstacles, nominal_speed_mps,
                               nominal_speed_mps if speed_mps is None else speed_mps,
                               vehicle_radius_m, params)
    forward = np.array([np.cos(heading_rad), np.sin(heading_rad)])
    left = np.array([-forward[1], forward[0]])
    rel = obstacles.positions_m - position_m[None, :]
    ahead = rel @ forward
    lateral = np.abs(rel @ left)
    corridor = obstacles.radii_m + vehicle_radius_m + params.stop_margin_m
    relevant = (ahead > 0.0) & (lateral < corridor)
    if not np.any(relevant):
        return float(nominal_speed_mps)
    gap = float(np.min(ahead[relevant] - obstacles.radii_m[relevant])) - vehicle_radius_m
    allowed = np.sqrt(2.0 * params.braking_decel_mps2 * max(gap - params.stop_margin_m, 0.0))
    return float(np.clip(allowed, params.speed_floor_mps, nominal_speed_mps))


def path_at_arc_length(path_m: np.ndarray, stations_m: np.ndarray) -> np.ndarray:
    """Points of the polyline ``path_m`` (n, 2) at arc lengths ``stations_m`` from its first
    point, continued along its last segment beyond its end; shape (len(stations_m), 2). A path
    that does not move gives its first point."""
    steps = np.diff(path_m, axis=0)
    lengths = np.hypot(steps[:, 0], steps[:, 1])
    keep = lengths > 1e-9
    if not keep.any():
        return np.repeat(path_m[:1], len(stations_m), axis=0)
    points = np.vstack([path_m[:1], path_m[1:][keep]])
    arc = np.concatenate([[0.0], np.cumsum(lengths[keep])])
    out = np.column_stack([np.interp(stations_m, arc, points[:, 0]),
                           np.interp(stations_m, arc, points[:, 1])])
    beyond = stations_m > arc[-1]
    if beyond.any():
        direction = (points[-1] - points[-2]) / (arc[-1] - arc[-2])
        out[beyond] = points[-1] + (stations_m[beyond] - arc[-1])[:, None] * direction
    return out


def clearance_speed(path_m: np.ndarray, obstacles: ObstacleSnapshot, nominal_speed_mps: float,
                    speed_mps: float, vehicle_radius_m: float, params: PlannerConfig) -> float:
    """The fastest of ``speed_candidates`` speeds in ``[speed_floor_mps, nominal]`` whose
    prediction keeps the clearance: the vehicle along ``path_m`` (the APF rollout, continued
    along its last segment), its speed moving from ``speed_mps`` towards the candidate at
    most ``braking_decel_mps2``, every obstacle at constant velocity, over
    ``speed_check_horizon_s`` in steps of 0.1 s; "keeps" = a clearance of at least
    ``stop_margin_m`` beyond both radii. When no candidate keeps it, the one with the largest
    predicted clearance (the faster one on a tie): slowing down is chosen only where it is
    predicted to be safer."""
    candidates = np.linspace(params.speed_floor_mps, nominal_speed_mps, params.speed_candidates)
    dt = 0.1
    steps = max(int(np.ceil(params.speed_check_horizon_s / dt)), 1)
    times = dt * np.arange(1, steps + 1)
    change = params.braking_decel_mps2 * dt
    speed = np.full(candidates.size, float(speed_mps))
    along = np.zeros(candidates.size)
    distances = np.empty((steps, candidates.size))
    for j in range(steps):
        new = speed + np.clip(candidates - speed, -change, change)
        along = along + 0.5 * (speed + new) * dt
        speed = new
        distances[j] = along
    points = path_at_arc_length(np.asarray(path_m, float), distances.ravel()).reshape(
        steps, candidates.size, 2)
    centres = obstacles.positions_m[None, :, :] + times[:, None, None] \
        * obstacles.velocities_mps[None, :, :]                      # (steps, n, 2)
    gaps = np.linalg.norm(points[:, :, None, :] - centres[:, None, :, :], axis=-1) \
        - obstacles.radii_m[None, None, :] - vehicle_radius_m        # (steps, cand, n)
    clearance = gaps.min(axis=(0, 2))
    keeps = np.nonzero(clearance >= params.stop_margin_m)[0]
    if keeps.size:
        return float(candidates[keeps[-1]])
    best = np.flatnonzero(clearance == clearance.max())
    return float(candidates[best[-1]])


class ApfPlanner:
    """The planner protocol and its built-in: the paper's APF (baseline or improved by its
    settings) rolled out over the horizon, and velocity planning.

    A planner of your own subclasses this (or follows the same two methods) and is named by
    ``planner._target_`` (``module.Class``); it is built as ``cls(settings, horizon,
    sample_time_s)`` and may read its own settings from ``settings.params``.
    """

    def __init__(self, settings: PlannerConfig, horizon: int, sample_time_s: float,
                 kernels: Kernels | None = None) -> None:
        self.settings, self.horizon, self.sample_time_s = settings, horizon, sample_time_s
        # apf_rollout's settings, once; its statement run by ``kernels`` (CPython's when
        # omitted, or compiled: the same bits)
        self._settings = apf_kernel_settings(settings)
        self._kernels = kernels
        self._route_m, self._route_lookahead_m, self._route_lookahead_s = NO_ROUTE, 0.0, 0.0

    def follow_route(self, route_m: np.ndarray, lookahead_m: float,
                     lookahead_s: float = 0.0) -> None:
        """Let the attraction follow ``route_m`` (P, 2; a road's centreline), pulling at every
        rollout point towards the point ahead along it (:func:`route_point_ahead`) by the
        farther of ``lookahead_m`` and ``lookahead_s`` at the vehicle's speed of the step;
        the goal handed to :meth:`rollout` is where it pulls past the route's end."""
        self._route_m = np.ascontiguousarray(route_m, dtype=float).reshape(-1, 2)
        self._route_lookahead_m = float(lookahead_m)
        self._route_lookahead_s = float(lookahead_s)

    def route_lookahead_m(self, vehicle_velocity_mps: np.ndarray | None) -> float:
        """The look-ahead along the route (m) at the vehicle's velocity: the farther of the
        distance and the time at its speed (:meth:`follow_route`)."""
        if not self._route_lookahead_s or vehicle_velocity_mps is None:
            return self._route_lookahead_m
        speed = float(np.hypot(vehicle_velocity_mps[0], vehicle_velocity_mps[1]))
        return max(self._route_lookahead_m, self._route_lookahead_s * speed)

    def rollout(self, position_m: np.ndarray, goal_m: np.ndarray, obstacles: ObstacleSnapshot,
                vehicle_velocity_mps: np.ndarray | None = None) -> ApfRollout:
        """The reference path (``horizon`` points from the vehicle's position) and the forces
        behind it (:func:`apf_rollout`; along the route :meth:`follow_route` set)."""
        return _rollout(self._kernels, self._settings, position_m, goal_m, obstacles,
                        self.horizon, self.sample_time_s, vehicle_velocity_mps,
                        self._route_m, self.route_lookahead_m(vehicle_velocity_mps))

    def speed(self, position_m: np.ndarray, heading_rad: float, obstacles: ObstacleSnapshot,
              nominal_speed_mps: float, vehicle_radius_m: float,
              path_m: np.ndarray | None = None, speed_mps: float | None = None) -> float:
        """The planned speed ``V_r`` (:func:`plan_speed`; ``path_m``: the rollout the vehicle
        follows, ``speed_mps``: its speed now)."""
        return plan_speed(position_m, heading_rad, obstacles, nominal_speed_mps,
                          vehicle_radius_m, self.settings, path_m, speed_mps)


class ApfSettings(NamedTuple):
    """The APF settings as :func:`apf_rollout_arrays` takes them (numba compiles a named tuple
    as it is): the numbers of :class:`~pipeline.loop.settings.PlannerConfig`, its switches as
    booleans, no step cap as ``inf``."""

    h_max: float
    beta: float
    rho_p_m: float
    rho0_m: float
    alpha_e: float
    k_rep_constant: float
    rho_floor_m: float
    closing_speed_gain_s_per_m: float
    step_size: float
    step_min_m: float
    step_max_m: float
    repulsion_on: bool
    polynomial: bool
    constant_k_rep: bool
    predict_obstacles: bool
    normalize_step: bool
    closing_speed_on: bool


def apf_kernel_settings(params: PlannerConfig) -> ApfSettings:
    """``params`` as :func:`apf_rollout_arrays` takes them (:class:`ApfSettings`)."""
    return ApfSettings(
        float(params.h_max), float(params.beta), float(params.rho_p_m), float(params.rho0_m),
        float(params.alpha_e), float(params.k_rep_constant), float(params.rho_floor_m),
        float(params.closing_speed_gain_s_per_m), float(params.step_size),
        float(params.step_min_m), inf if params.step_max_m is None else float(params.step_max_m),
        params.repulsion_law != "none", params.repulsion_law == "polynomial",
        params.k_rep_source != "adaptive_h", params.obstacle_prediction == "constant_velocity",
        bool(params.normalize_step), params.closing_speed_gain_s_per_m > 0.0)


def make_planner(settings: PlannerConfig, horizon: int, sample_time_s: float,
                 kernels: Kernels | None = None) -> ApfPlanner:
    """The planner ``settings._target_`` names (a user's class), else :class:`ApfPlanner`
    (its rollout by ``kernels``: CPython's when omitted; compiled, the same bits)."""
    from pipeline.validation import build_target

    if settings._target_:
        return build_target("planner._target_", settings._target_,
                            (settings, horizon, sample_time_s),
                            "Planner(settings, horizon, sample_time_s)")
    return ApfPlanner(settings, horizon, sample_time_s, kernels)
