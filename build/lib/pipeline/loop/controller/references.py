"""From the APF path to what an MPC consumes: lateral and heading references at the predicted
stations, and the soft avoidance half-planes (one normal rule shared by both tracks)."""

from __future__ import annotations

from math import tan

import numpy as np

from pipeline.loop.settings import ControllerConfig, VehicleConfig

_NORMAL_EPS_M = 1e-6


def lateral_reference(path_line_m: np.ndarray, stations_m: np.ndarray,
                      controller: ControllerConfig) -> tuple[np.ndarray, np.ndarray]:
    """Lateral and heading references at the MPC's predicted stations.

    The APF path (line frame) is made monotone in x (points that do not advance are dropped),
    interpolated at ``stations_m``, and beyond its end either extended along its last segment
    (slope saturated at ``heading_ref_max_rad``) or held (``path_beyond_end``). The heading
    reference is the saturated slope of that curve.

    Returns
    -------
    y_ref_m, psi_ref_rad : ndarray, shape (len(stations_m),)
    """
    points = path_line_m.tolist()
    xs, ys = [points[0][0]], [points[0][1]]
    for x, y in points[1:]:
        if x > xs[-1] + 1e-9:
            xs.append(x)
            ys.append(y)
    if len(xs) < 2:
        # the rollout does not advance: hold its last lateral position
        return np.full(stations_m.shape, points[-1][1]), np.zeros(stations_m.shape)
    xs_a, ys_a = np.array(xs), np.array(ys)
    max_slope = tan(controller.heading_ref_max_rad)
    # np.minimum/np.maximum, not np.clip: the same values at a third of the call overhead
    seg_slopes = np.minimum(np.maximum((ys_a[1:] - ys_a[:-1]) / (xs_a[1:] - xs_a[:-1]),
                                       -max_slope), max_slope)
    end_slope = seg_slopes[-1] if controller.path_beyond_end == "extend" else 0.0
    y_ref = np.interp(stations_m, xs_a, ys_a)
    beyond = stations_m > xs[-1]
    if beyond.any():
        y_ref[beyond] = ys[-1] + end_slope * (stations_m[beyond] - xs[-1])
    idx = np.searchsorted(xs_a, stations_m, side="right") - 1
    idx = np.minimum(np.maximum(idx, 0), seg_slopes.size - 1)
    slope = np.where(beyond, end_slope, seg_slopes[idx])
    return y_ref, np.arctan(slope)


def force_heading_reference(total_force_line: np.ndarray, heading_line_rad: float,
                            n_steps: int, sample_time_s: float,
                            controller: ControllerConfig) -> np.ndarray:
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


def collision_halfplanes(stations_m: np.ndarray, y_ref_m: np.ndarray, vehicle_line_m: np.ndarray,
                         predicted_obstacles_line_m: np.ndarray, radii_m: np.ndarray,
                         vehicle: VehicleConfig, controller: ControllerConfig
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

    Obstacles farther than ``constraint_activation_m`` from the vehicle, and unused obstacle
    slots (fewer obstacles than ``max_obstacles``), get empty rows ``0 y + s >= 0`` that cannot
    bind, so one compiled problem serves any number of obstacles up to ``max_obstacles``.

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
    for j in range(min(n_obs, M)):
        current = predicted_obstacles_line_m[0, j]
        if np.linalg.norm(current - vehicle_line_m) > controller.constraint_activation_m:
            continue
        obstacle = predicted_obstacles_line_m[:, j, :]
        reach = radii_m[j] + vehicle.footprint_radius_m + controller.safety_margin_m
        fallback_side = np.sign(vehicle_line_m[1] - current[1]) or 1.0
        if controller.halfplane_normal == "lateral_side":
            dx = stations_m - obstacle[:, 0]
            inside = np.abs(dx) < reach
            half_width = np.sqrt(np.maximum(reach**2 - dx**2, 0.0))
            side = np.sign(y_ref_m - obstacle[:, 1])
            side = np.where(side == 0.0, fallback_side, side)
            G[:, j] = np.where(inside, side, 0.0)
            h[:, j] = np.where(inside, side * obstacle[:, 1] + half_width, 0.0)
            continue
        ref = np.stack([stations_m, y_ref_m], axis=1)
        normal = radial_normals(ref, obstacle, np.array([0.0, fallback_side])[None, :])
        G[:, j] = normal[:, 1]
        h[:, j] = reach - normal[:, 0] * (stations_m - obstacle[:, 0]) + normal[:, 1] * obstacle[:, 1]
    return G, h


def kinematic_halfplanes(predicted_states: np.ndarray, reference_m: np.ndarray,
                         predicted_obstacles_m: np.ndarray, radii_m: np.ndarray,
                         vehicle: VehicleConfig, controller: ControllerConfig
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Soft half-planes ``nx x_k + ny y_k + s >= h`` of the kinematic LTV-MPC (global frame).

    The normal points from the predicted obstacle to the APF reference point
    (:func:`radial_normals`), or to the linearization trajectory where the reference sits on the
    obstacle; ``h = n . o_k + R``. Unused slots and far obstacles get empty rows.

    Returns
    -------
    Gx, Gy, h : ndarray, shape (N, max_obstacles)
    """
    N, M = reference_m.shape[1], controller.max_obstacles
    Gx, Gy, h = np.zeros((N, M)), np.zeros((N, M)), np.zeros((N, M))
    n_obs = predicted_obstacles_m.shape[1] if predicted_obstacles_m.ndim == 3 else 0
    for j in range(min(n_obs, M)):
        obstacle = predicted_obstacles_m[:, j, :]
        if np.linalg.norm(obstacle[0] - predicted_states[:2, 0]) > controller.constraint_activation_m:
            continue
        backup = radial_normals(predicted_states[:2, 1:].T, obstacle,
                                np.array([0.0, 1.0])[None, :])
        normal = radial_normals(reference_m.T, obstacle, backup)
        reach = radii_m[j] + vehicle.footprint_radius_m + controller.safety_margin_m
        Gx[:, j], Gy[:, j] = normal[:, 0], normal[:, 1]
        h[:, j] = np.sum(normal * obstacle, axis=1) + reach
    return Gx, Gy, h
