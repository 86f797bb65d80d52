"""The path frame of many members in one call: what the lockstep engine
(:mod:`pipeline.loop.engine`) runs each step for the lateral MPCs it steps together
(:mod:`pipeline.loop.controller.lateral_rows`).

:func:`path_frame_rows` is, for each member, the path frame's three statements in the order
one member runs them (:func:`~pipeline.loop.controller.path.rollout_path_arrays`,
:func:`~pipeline.loop.controller.path.frame_step_arrays`,
:func:`~pipeline.loop.controller.references.lateral_side_halfplane_arrays`);
:func:`plan_poses_rows` is :func:`~pipeline.loop.controller.path.plan_poses_arrays` for each.
Compiled by numba (:mod:`pipeline.loop.compiled`), one call replaces three (or one) per member:
the same statements on the same numbers, so the same bits, without a call's overhead per
member (about 4 us each from Python here). Members' arrays of different lengths (their paths'
intervals, their obstacles, their last plans) come padded, with their lengths.
"""

from __future__ import annotations

import numpy as np

from pipeline.loop.controller.path import frame_step_arrays, plan_poses_arrays, rollout_path_arrays
from pipeline.loop.controller.references import lateral_side_halfplane_arrays


def path_frame_rows(targets: np.ndarray, line_cos_sin: np.ndarray, extend: np.ndarray,
                    kappa_max: np.ndarray, ds: np.ndarray, n_intervals: np.ndarray,
                    positions: np.ndarray, speeds: np.ndarray, speed_refs: np.ndarray,
                    vy_gains: np.ndarray, steps_s: np.ndarray, n_steps: int,
                    time_constants: np.ndarray, accel_max: np.ndarray, brake_max: np.ndarray,
                    plans_xy: np.ndarray,
                    plans_course: np.ndarray, plan_lengths: np.ndarray, obstacles: np.ndarray,
                    obstacle_starts: np.ndarray, radii: np.ndarray, n_slots: int,
                    vehicle_reach: np.ndarray, margins: np.ndarray, activation: np.ndarray,
                    constrained: np.ndarray) -> tuple[np.ndarray, ...]:
    """Each member's reference path (the APF rollout itself), its path-frame step and its
    collision half-planes.

    Parameters
    ----------
    targets : ndarray, shape (n, Np, 2)
        The members' APF rollouts.
    line_cos_sin : ndarray, shape (n, 2)
        Each start-goal line's unit direction.
    extend : ndarray of bool, shape (n,)
    kappa_max, ds, speeds, speed_refs, vy_gains, steps_s, time_constants, accel_max, brake_max
        Each ``(n,)``.
    n_intervals : ndarray of int, shape (n,)
        Each path's intervals (the padded outputs hold ``max(n_intervals)``).
    positions : ndarray, shape (n, 2)
    n_steps : int
        The MPC's horizon (the same for every member of the call).
    plans_xy, plans_course : ndarray, shape (n, m, 2) and (n, m)
        The last plans' poses, the first ``plan_lengths[i]`` of member ``i`` (0: none).
    obstacles : ndarray, shape (total, 2)
        The members' predicted obstacle centres (``n_steps`` rows per obstacle, step-major),
        member ``i``'s from ``obstacle_starts[i]`` to ``obstacle_starts[i + 1]``.
    obstacle_starts : ndarray of int, shape (n + 1,)
    radii : ndarray, shape (total / n_steps,)
        The obstacles' radii, member ``i``'s from ``obstacle_starts[i] / n_steps``.
    n_slots : int
    vehicle_reach, margins, activation : ndarray, shape (n,)
    constrained : ndarray of bool, shape (n,)

    Returns
    -------
    points (n, K + 1, 2), headings (n, K + 1), curvature (n, K), beyond (n, K),
    frame (n, 3): ``s0, d0, heading0``; stations (n, n_steps + 1), r_d (n, n_steps),
    vx (n, n_steps + 1), obstacle_s, obstacle_d (total,), G, h (n, n_steps, n_slots)
    """
    n = targets.shape[0]
    widest = 0
    for i in range(n):
        widest = n_intervals[i] if n_intervals[i] > widest else widest
    points = np.zeros((n, widest + 1, 2))
    headings = np.zeros((n, widest + 1))
    curvature = np.zeros((n, widest))
    beyond = np.zeros((n, widest), dtype=np.bool_)
    frame = np.zeros((n, 3))
    stations = np.zeros((n, n_steps + 1))
    r_d = np.zeros((n, n_steps))
    vx = np.zeros((n, n_steps + 1))
    total = obstacles.shape[0]
    obstacle_s, obstacle_d = np.zeros(total), np.zeros(total)
    G, h = np.zeros((n, n_steps, n_slots)), np.zeros((n, n_steps, n_slots))
    zeros = np.zeros(n_steps)
    for i in range(n):
        m = n_intervals[i]
        p, hd, cv, bd = rollout_path_arrays(targets[i], line_cos_sin[i, 0], line_cos_sin[i, 1],
                                            extend[i], kappa_max[i], ds[i], m)
        points[i, :m + 1], headings[i, :m + 1] = p, hd
        curvature[i, :m], beyond[i, :m] = cv, bd
        first, last = obstacle_starts[i], obstacle_starts[i + 1]
        length = plan_lengths[i]
        s0, d0, heading0, st, rd, v, s_o, d_o = frame_step_arrays(
            p, hd, cv, ds[i], m, positions[i, 0], positions[i, 1], speeds[i], speed_refs[i],
            vy_gains[i], steps_s[i], n_steps, time_constants[i], accel_max[i], brake_max[i],
            kappa_max[i],
            plans_xy[i, :length], plans_course[i, :length], obstacles[first:last])
        frame[i, 0], frame[i, 1], frame[i, 2] = s0, d0, heading0
        stations[i], r_d[i], vx[i] = st, rd, v
        obstacle_s[first:last], obstacle_d[first:last] = s_o, d_o
        n_obstacles = (last - first) // n_steps if n_steps > 0 else 0
        gains, bounds = lateral_side_halfplane_arrays(
            st[1:], zeros, s0, d0, s_o, d_o, n_obstacles,
            radii[first // n_steps:first // n_steps + n_obstacles] if n_steps > 0
            else radii[:0], n_slots, vehicle_reach[i], margins[i], activation[i],
            constrained[i])
        G[i], h[i] = gains, bounds
    return (points, headings, curvature, beyond, frame, stations, r_d, vx, obstacle_s,
            obstacle_d, G, h)


def plan_poses_rows(points: np.ndarray, headings: np.ndarray, curvature: np.ndarray,
                    ds: np.ndarray, n_intervals: np.ndarray, stations: np.ndarray,
                    lateral: np.ndarray, heading_error: np.ndarray, vy: np.ndarray,
                    vx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~pipeline.loop.controller.path.plan_poses_arrays` for each member (row ``i`` of
    every argument; ``points``, ``headings``, ``curvature`` padded as
    :func:`path_frame_rows` returns them): ``xy (n, m, 2), course (n, m)``."""
    n, m = stations.shape[0], stations.shape[1]
    xy, course = np.zeros((n, m, 2)), np.zeros((n, m))
    for i in range(n):
        k = n_intervals[i]
        xy[i], course[i] = plan_poses_arrays(points[i, :k + 1], headings[i, :k + 1],
                                             curvature[i, :k], ds[i], k, stations[i],
                                             lateral[i], heading_error[i], vy[i], vx[i])
    return xy, course
