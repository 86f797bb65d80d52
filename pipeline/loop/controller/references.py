"""From the APF path to what an MPC consumes: lateral and heading references at the predicted
stations, and the soft avoidance half-planes (one normal rule shared by both tracks)."""

from __future__ import annotations

from math import hypot, sqrt, tan
from typing import Any

import numpy as np

from pipeline.loop.arrays import KernelValues
from pipeline.loop.controller_settings import (
    KinematicMpcSettings,
    MpcSettings,
    PurePursuitSettings,
)
from pipeline.loop.kernels import Kernels
from pipeline.loop.settings import VehicleConfig

_NORMAL_EPS_M = 1e-6


def lateral_reference(path_line_m: np.ndarray, stations_m: np.ndarray,
                      controller: MpcSettings | PurePursuitSettings,
                      kernels: Kernels | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Lateral and heading references at the MPC's predicted stations.

    The APF path (line frame) is made monotone in x (points that do not advance are dropped),
    interpolated at ``stations_m``, and beyond its end either extended along its last segment
    (slope saturated at ``heading_ref_max_rad``) or held (``path_beyond_end``). The heading
    reference is the saturated slope of that curve.

    A dozen points and stations: the interpolation (:func:`reference_arrays`) runs on plain
    floats with ``np.interp``'s own arithmetic (the segment's slope times the offset from its
    left end, plus its left value; a station on a knot takes the knot's value), which is
    cheaper than numpy's per-call overhead and gives the same numbers (the tests hold it to
    ``np.interp``); ``kernels`` runs it (CPython's when omitted; compiled by numba, the same
    bits).

    Returns
    -------
    y_ref_m, psi_ref_rad : ndarray, shape (len(stations_m),)
    """
    max_slope = tan(controller.heading_ref_max_rad)
    extend = controller.path_beyond_end == "extend"
    if kernels is not None and kernels.compiled:
        y_ref, slopes = kernels.references(np.ascontiguousarray(path_line_m, dtype=float),
                                           np.ascontiguousarray(stations_m, dtype=float),
                                           max_slope, extend)
    else:
        kernel = kernels.references if kernels is not None else reference_arrays
        y_ref, slopes = kernel(path_line_m.tolist(), stations_m.tolist(), max_slope, extend)
    return y_ref, np.arctan(slopes)


def reference_arrays(path_line_m: KernelValues, stations_m: KernelValues, max_slope: float,
                     extend: bool) -> tuple[KernelValues, KernelValues]:
    """:func:`lateral_reference`'s interpolation on plain numbers: ``y_ref`` and the saturated
    slopes at the stations (arrays). ``path_line_m`` holds rows ``[x, y]`` and ``stations_m``
    numbers (lists in CPython, arrays compiled)."""
    n_points = len(path_line_m)
    # the path's points that advance in x (by more than 1e-9 m past the last one kept); read
    # from lists (CPython's arithmetic on numpy scalars is slower), written into arrays
    xs, ys = [path_line_m[0][0]], [path_line_m[0][1]]
    for i in range(1, n_points):
        x = path_line_m[i][0]
        if x > xs[-1] + 1e-9:
            xs.append(x)
            ys.append(path_line_m[i][1])
    count = len(xs)
    n = len(stations_m)
    y_ref, slopes = np.empty(n), np.zeros(n)
    if count < 2:
        # the rollout does not advance: hold its last lateral position (zero slope)
        y_ref[:] = path_line_m[n_points - 1][1]
        return y_ref, slopes
    low = -max_slope
    last = count - 1
    seg_slopes = [min(max((ys[i + 1] - ys[i]) / (xs[i + 1] - xs[i]), low), max_slope)
                  for i in range(last)]
    end_slope = seg_slopes[last - 1] if extend else 0.0
    last_x, last_y = xs[last], ys[last]
    j = -1  # the last knot at or left of the station (stations usually ascend)
    for k in range(n):
        station = stations_m[k]
        if station > last_x:
            y_ref[k] = last_y + end_slope * (station - last_x)
            slopes[k] = end_slope
            continue
        while j + 1 < count and xs[j + 1] <= station:
            j += 1
        while j >= 0 and xs[j] > station:
            j -= 1
        if j < 0:
            y = ys[0]
        elif j == last or xs[j] == station:
            y = ys[j]
        else:
            y = (ys[j + 1] - ys[j]) / (xs[j + 1] - xs[j]) * (station - xs[j]) + ys[j]
        y_ref[k] = y
        slopes[k] = seg_slopes[min(max(j, 0), last - 1)]
    return y_ref, slopes


def force_heading_reference(total_force_line: np.ndarray, heading_line_rad: float,
                            n_steps: int, sample_time_s: float,
                            controller: MpcSettings) -> np.ndarray:
    """Heading reference of Section 3.1: ramp toward ``psi_apf = atan2(F_y, F_x)`` at the
    saturated rate ``omega_ref = sat((psi_apf - theta)/Ts)``."""
    psi_apf = np.arctan2(total_force_line[1], total_force_line[0])
    error = np.arctan2(np.sin(psi_apf - heading_line_rad), np.cos(psi_apf - heading_line_rad))
    omega_ref = np.clip(error / sample_time_s, -controller.yaw_rate_ref_max_rad_s,
                        controller.yaw_rate_ref_max_rad_s)
    k = np.arange(1, n_steps + 1)
    ramp = np.clip(omega_ref * k * sample_time_s, -abs(error), abs(error))
    return np.clip(heading_line_rad + ramp, -controller.heading_ref_max_rad,
                   controller.heading_ref_max_rad)


def radial_normals(points_m: np.ndarray, centres_m: np.ndarray,
                   fallback: np.ndarray) -> np.ndarray:
    """Unit vectors from each predicted obstacle centre to a point, shape (N, 2).

    Where a point sits on the centre (closer than 1e-6 m) the row of ``fallback`` is used.
    """
    diff = points_m - centres_m
    dist = np.linalg.norm(diff, axis=1)
    return np.where(dist[:, None] > _NORMAL_EPS_M,
                    diff / np.maximum(dist, _NORMAL_EPS_M)[:, None], fallback)


def constrains(distance_m: float,
               controller: MpcSettings | KinematicMpcSettings) -> bool:
    """Whether an obstacle ``distance_m`` from the vehicle gets collision half-planes: the
    MPC's collision constraints are on (``controller.collision_constraints``) and it is within
    ``controller.constraint_activation_m``. The one place both tracks' half-planes
    (:func:`collision_halfplanes`, :func:`kinematic_halfplanes`), and so every backend, select
    their obstacles."""
    return controller.collision_constraints \
        and not distance_m > controller.constraint_activation_m  # (a NaN distance: constrained)


def collision_halfplanes(stations_m: np.ndarray, y_ref_m: np.ndarray, vehicle_line_m: np.ndarray,
                         predicted_obstacles_line_m: np.ndarray, radii_m: np.ndarray,
                         vehicle: VehicleConfig, controller: MpcSettings
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Soft half-plane data ``G y_k + s >= h`` of the lateral MPC, per horizon step and obstacle.

    With ``R = r_o + r_v + margin`` and the APF reference point ``q_k = (station_k, y_ref_k)``:

    * ``halfplane_normal = lateral_side`` (default): at station ``x_k`` the keep-out disk covers
      ``|y - o_y| < w_k = sqrt(R^2 - (x_k - o_x)^2)``; the APF chooses the side
      ``sigma = sign(y_ref_k - o_y)`` and the plane is ``sigma (y_k - o_y) >= w_k`` (exact for the
      disk at that station; empty where ``|x_k - o_x| >= R``).
    * ``halfplane_normal = radial``: ``n . (p_k - o_k) >= R`` with ``n`` the unit vector from the
      predicted obstacle to ``q_k`` (:func:`radial_normals`: the tangent plane of the disk facing
      the reference point).

    Obstacles farther than ``constraint_activation_m`` from the vehicle, every obstacle when
    ``collision_constraints`` is off (:func:`constrains`), and unused obstacle slots (fewer
    obstacles than ``max_obstacles``) get empty rows ``0 y + s >= 0`` that cannot bind, so one
    compiled problem serves any number of obstacles up to ``max_obstacles``.

    Parameters
    ----------
    predicted_obstacles_line_m : ndarray, shape (N, n, 2)
        Obstacle centres at the horizon's steps, line frame.

    Returns
    -------
    G, h : ndarray, shape (N, max_obstacles)
    """
    N, M = stations_m.shape[0], controller.max_obstacles
    G, h = np.zeros((N, M)), np.zeros((N, M))
    n_obs = predicted_obstacles_line_m.shape[1] if predicted_obstacles_line_m.ndim == 3 else 0
    vx, vy = vehicle_line_m.tolist()
    offsets = vehicle.footprint_offsets_m if vehicle.footprint_discs > 1 else None
    for j in range(min(n_obs, M)):
        cx, cy = predicted_obstacles_line_m[0, j].tolist()
        if not constrains(hypot(cx - vx, cy - vy), controller):
            continue
        reach = float(radii_m[j]) + vehicle.footprint_radius_m + controller.safety_margin_m
        fallback_side = 1.0 if vy > cy else (-1.0 if vy < cy else 1.0)
        rows = _lateral_side_rows if controller.halfplane_normal == "lateral_side" \
            else _radial_rows
        obstacle = predicted_obstacles_line_m[:, j, :]
        if offsets is not None:
            obstacle = nearest_ego_disc_shift(stations_m, obstacle, offsets)
        G[:, j], h[:, j] = rows(stations_m, y_ref_m, obstacle, reach, fallback_side)
    return G, h


def lateral_side_halfplane_arrays(stations_m: KernelValues, y_ref_m: KernelValues,
                                  vehicle_x: float, vehicle_y: float, obstacle_s: KernelValues,
                                  obstacle_d: KernelValues, n_obstacles: int,
                                  radii_m: KernelValues, n_slots: int, vehicle_reach_m: float,
                                  margin_m: float, activation_m: float, constrained: bool
                                  ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`collision_halfplanes` with ``halfplane_normal = lateral_side`` and an ego of one
    disc, on plain numbers (what the path frame runs each step, compiled by numba in
    :mod:`pipeline.loop.compiled`: the same operations in the same order, so the same bits).

    ``obstacle_s``, ``obstacle_d`` are the obstacles' path coordinates at the steps, step-major
    (``k n_obstacles + j``); ``vehicle_reach_m`` the ego disc's radius, ``margin_m`` the safety
    margin, ``activation_m`` ``controller.constraint_activation_m``, ``constrained``
    ``controller.collision_constraints``. Returns ``G, h`` of shape ``(len(stations),
    n_slots)``."""
    n = len(stations_m)
    G, h = np.zeros((n, n_slots)), np.zeros((n, n_slots))
    for j in range(min(n_obstacles, n_slots)):
        cx, cy = obstacle_s[j], obstacle_d[j]
        distance = hypot(cx - vehicle_x, cy - vehicle_y)
        # constrains(): on, and not farther than the activation distance (NaN: constrained)
        if not constrained or distance > activation_m:
            continue
        reach = radii_m[j] + vehicle_reach_m + margin_m
        fallback_side = 1.0 if vehicle_y > cy else (-1.0 if vehicle_y < cy else 1.0)
        reach_sq = reach * reach
        for k in range(n):
            ox, oy = obstacle_s[k * n_obstacles + j], obstacle_d[k * n_obstacles + j]
            dx = stations_m[k] - ox
            if not abs(dx) < reach:
                continue
            above = y_ref_m[k] - oy
            side = 1.0 if above > 0 else (-1.0 if above < 0 else
                                          (fallback_side if above == 0 else above))
            G[k, j] = side
            gap = reach_sq - dx * dx
            if gap < 0.0:  # max(gap, 0.0) as CPython takes it (a NaN or -0.0 stays)
                gap = 0.0
            h[k, j] = side * oy + sqrt(gap)
    return G, h


def nearest_ego_disc_shift(stations_m: np.ndarray, obstacle: np.ndarray,
                           offsets_m: np.ndarray) -> np.ndarray:
    """An obstacle's centres at the stations (N, 2) as the ego's reference point sees them when
    the ego is several discs along its heading (``vehicle.footprint_discs``, centres
    ``offsets_m`` ahead of the reference point): each station's obstacle moved back along the
    path by the offset of the ego disc nearest to it along the path, so that the half-plane
    about the reference point keeps that disc out (the disc at ``station + c`` clears the
    obstacle at ``o`` exactly when the reference point clears ``o - c``). The ego's heading is
    taken along the path (the frame's small-angle reading); the nearest disc along the path
    is the one whose keep-out is widest at that station."""
    ahead = obstacle[:, 0][:, None] - stations_m[:, None]            # (N, 1)
    nearest = np.argmin(np.abs(ahead - offsets_m[None, :]), axis=1)    # (N,)
    shifted = obstacle.copy()
    shifted[:, 0] = obstacle[:, 0] - offsets_m[nearest]
    return shifted


def _lateral_side_rows(stations_m: np.ndarray, y_ref_m: np.ndarray, obstacle: np.ndarray,
                       reach: float, fallback_side: float) -> tuple[list[Any], list[Any]]:
    """One obstacle's ``G, h`` columns of :func:`collision_halfplanes` with
    ``halfplane_normal = lateral_side`` (``obstacle``: its centres at the stations, (N, 2))."""
    # ten stations: plain floats (the same arithmetic as the vectorized statement)
    gains, bounds = [], []
    reach_sq = reach * reach
    for station, y_ref, (ox, oy) in zip(stations_m.tolist(), y_ref_m.tolist(),
                                        obstacle.tolist(), strict=True):
        dx = station - ox
        if not abs(dx) < reach:
            gains.append(0.0)
            bounds.append(0.0)
            continue
        above = y_ref - oy
        side = 1.0 if above > 0 else (-1.0 if above < 0 else
                                      (fallback_side if above == 0 else above))
        gains.append(side)
        bounds.append(side * oy + sqrt(max(reach_sq - dx * dx, 0.0)))
    return gains, bounds


def _radial_rows(stations_m: np.ndarray, y_ref_m: np.ndarray, obstacle: np.ndarray,
                 reach: float, fallback_side: float) -> tuple[np.ndarray, np.ndarray]:
    """One obstacle's ``G, h`` columns of :func:`collision_halfplanes` with
    ``halfplane_normal = radial``."""
    ref = np.stack([stations_m, y_ref_m], axis=1)
    normal = radial_normals(ref, obstacle, np.array([0.0, fallback_side])[None, :])
    bound = reach - normal[:, 0] * (stations_m - obstacle[:, 0]) + normal[:, 1] * obstacle[:, 1]
    return normal[:, 1], bound


def kinematic_halfplanes(predicted_states: np.ndarray, reference_m: np.ndarray,
                         predicted_obstacles_m: np.ndarray, radii_m: np.ndarray,
                         vehicle: VehicleConfig,
                         controller: KinematicMpcSettings
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Soft half-planes ``nx x_k + ny y_k + s >= h`` of the kinematic LTV-MPC (global frame).

    The normal points from the predicted obstacle to the APF reference point
    (:func:`radial_normals`), or to the linearization trajectory where the reference sits on the
    obstacle; ``h = n . o_k + R``. An ego of several discs (``vehicle.footprint_discs``) keeps
    out the disc nearest to the obstacle at each predicted pose (the obstacle taken as
    ``o_k - c h_k``, ``h_k`` the rollout's heading). Unused slots, far obstacles and every
    obstacle when ``collision_constraints`` is off (:func:`constrains`) get empty rows.

    Returns
    -------
    Gx, Gy, h : ndarray, shape (N, max_obstacles)
    """
    N, M = reference_m.shape[1], controller.max_obstacles
    Gx, Gy, h = np.zeros((N, M)), np.zeros((N, M)), np.zeros((N, M))
    n_obs = predicted_obstacles_m.shape[1] if predicted_obstacles_m.ndim == 3 else 0
    discs = vehicle.footprint_offsets_m if vehicle.footprint_discs > 1 else None
    if discs is None:
        # one disc: every obstacle's columns at once (among walkers up to 50 of them), the
        # same elementwise operations as the loop below, so the same numbers
        _one_disc_halfplanes(predicted_states, reference_m,
                             predicted_obstacles_m[:, :min(n_obs, M), :], radii_m, vehicle,
                             controller, (Gx, Gy, h))
        return Gx, Gy, h
    for j in range(min(n_obs, M)):
        obstacle = predicted_obstacles_m[:, j, :]
        if not constrains(float(np.linalg.norm(obstacle[0] - predicted_states[:2, 0])),
                          controller):
            continue
        if discs is not None:
            # an ego of several discs: the obstacle as the reference point sees the ego disc
            # nearest to it at each predicted pose (o - c h, the heading of the rollout)
            heading = np.stack([np.cos(predicted_states[2, 1:]),
                                np.sin(predicted_states[2, 1:])], axis=1)       # (N, 2)
            centres = predicted_states[:2, 1:].T[:, None, :] \
                + discs[None, :, None] * heading[:, None, :]                    # (N, n, 2)
            nearest = np.argmin(np.linalg.norm(centres - obstacle[:, None, :], axis=2), axis=1)
            obstacle = obstacle - discs[nearest][:, None] * heading
        backup = radial_normals(predicted_states[:2, 1:].T, obstacle,
                                np.array([0.0, 1.0])[None, :])
        normal = radial_normals(reference_m.T, obstacle, backup)
        reach = radii_m[j] + vehicle.footprint_radius_m + controller.safety_margin_m
        Gx[:, j], Gy[:, j] = normal[:, 0], normal[:, 1]
        h[:, j] = np.sum(normal * obstacle, axis=1) + reach
    return Gx, Gy, h


def _one_disc_halfplanes(predicted_states: np.ndarray, reference_m: np.ndarray,
                         obstacles_m: np.ndarray, radii_m: np.ndarray, vehicle: VehicleConfig,
                         controller: KinematicMpcSettings,
                         out: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
    """:func:`kinematic_halfplanes`' columns for an ego of one disc, every obstacle of
    ``obstacles_m`` (N, m, 2) at once, into ``out`` (``Gx, Gy, h``, their first ``m``
    columns): the activation test on each obstacle's first predicted centre
    (:func:`constrains`), the normals from the predicted centre to the reference point (to the
    rollout where the reference sits on the centre, else ``(0, 1)``) and ``h = n . o + R``."""
    m = obstacles_m.shape[1]
    if m == 0 or not controller.collision_constraints:
        return
    Gx, Gy, h = out
    start = obstacles_m[0] - predicted_states[:2, 0]
    distance = np.sqrt(np.einsum("ij,ij->i", start, start))
    # constrains(): within the activation distance (a NaN distance: constrained)
    active = np.flatnonzero(~(distance > controller.constraint_activation_m))
    if active.size == 0:
        return
    obstacles = obstacles_m[:, active, :]
    backup = _radial_normals_3d(predicted_states[:2, 1:].T[:, None, :], obstacles,
                                np.array([0.0, 1.0]))
    normal = _radial_normals_3d(reference_m.T[:, None, :], obstacles, backup)
    reach = radii_m[active] + vehicle.footprint_radius_m + controller.safety_margin_m
    Gx[:, active], Gy[:, active] = normal[:, :, 0], normal[:, :, 1]
    h[:, active] = np.sum(normal * obstacles, axis=2) + reach


def _radial_normals_3d(points_m: np.ndarray, centres_m: np.ndarray,
                       fallback: np.ndarray) -> np.ndarray:
    """:func:`radial_normals` for many obstacles: ``points_m`` (N, 1, 2) against
    ``centres_m`` (N, m, 2), shape (N, m, 2)."""
    diff = points_m - centres_m
    dist = np.linalg.norm(diff, axis=2)
    return np.where(dist[:, :, None] > _NORMAL_EPS_M,
                    diff / np.maximum(dist, _NORMAL_EPS_M)[:, :, None], fallback)
