"""The whole closed-loop step of a group of members in three compiled calls: what the lockstep
engine (:mod:`pipeline.loop.engine`) runs for the members of the default statement
(:mod:`pipeline.loop.lateral_group`: scripted obstacles, the APF's own rollout, the path
frame's lateral MPC on a kept DAQP workspace, the single-track plant).

Each function is, for every member it is handed, the statements the per-member loop runs, in
the same order on the same numbers (so the same bits: the tests hold the two equal):

* :func:`observe_plan_rows`: the observation (the obstacles at the step's time, the pose and
  its log row, the termination; :meth:`pipeline.loop.engine.MemberLoop.observe`) and the
  planner's rollout and its log columns (:meth:`~pipeline.loop.engine.MemberLoop.plan`,
  :func:`pipeline.loop.planner.apf_rollout_arrays`);
* :func:`frame_rows`: the path frame's step geometry, the predicted obstacles, the frame's
  arithmetic (:func:`~pipeline.loop.controller.path_rows.path_frame_rows`) and the QP's
  state and log values (:meth:`~pipeline.loop.controller.frames.PathFrame.finish_inputs`);
* :func:`control_rows`: the references, the QPs condensed and solved on each member's kept
  DAQP workspace (:func:`~pipeline.loop.controller.daqp_rows.daqp_condensed_rows`), the plan
  accepted or the fallback taken (:class:`~pipeline.loop.controller.base.PlanFallback`), the
  plans' poses (:func:`~pipeline.loop.controller.path_rows.plan_poses_rows`), the step's
  record and log columns, and the plant's step (:func:`pipeline.loop.model.single_track_rk4`);
* :func:`check_rows`: at a member's end, each step's prediction checked against what the plant
  then did, from the records' arrays.

Between the calls the group's driver looks up, in Python, what depends on caches of Python
objects (the prediction step, a model and its condensed prediction by speed): the calls hand
it the integer keys (a speed's index on the model grid) it needs. Compiled by numba
(:mod:`pipeline.loop.compiled`); there is no CPython twin (a member that is not in a group
steps through :class:`~pipeline.loop.engine.MemberLoop`).
"""

from __future__ import annotations

from math import atan2, cos, pi, sin, sqrt

import numpy as np

from pipeline.loop.controller.daqp_rows import daqp_condensed_rows
from pipeline.loop.controller.direct_rows import direct_readout_rows, direct_theta_rows
from pipeline.loop.controller.path_rows import path_frame_rows, plan_poses_rows
from pipeline.loop.controller.prediction_check import check_record_arrays
from pipeline.loop.model import single_track_rk4
from pipeline.loop.planner import ApfSettings, apf_rollout_arrays

#: The log's float columns (:func:`observe_plan_rows` and :func:`control_rows` write them; the
#: driver names them). Text and flag columns hold codes (``STATUS_CODES``, ``FALLBACK_CODES``;
#: 0/1 for the flags), NaN where nothing was logged.
LOG_COLUMNS = ("time_s", "X_m", "Y_m", "psi_rad", "e_y_m", "e_psi_rad", "vx_mps", "vy_mps",
               "r_rad_s", "delta_rad", "tyre_slip_norm", "steering_rate_rad_s",
               "speed_ref_mps", "y_ref_m", "psi_ref_rad", "path_beyond_limit",
               "path_curvature_1_per_m", "r_d_rad_s", "apf_next_x_m", "apf_next_y_m",
               "apf_end_x_m", "apf_end_y_m", "apf_att_x", "apf_att_y", "apf_rep_x",
               "apf_rep_y", "apf_rep_norm", "apf_step_capped", "apf_step_min_used",
               "apf_step_cap_share", "solver_status", "solver_iterations", "fallback",
               "max_slack_m")
(C_TIME, C_X, C_Y, C_PSI, C_EY, C_EPSI, C_VX, C_VY, C_R, C_DELTA, C_SLIP, C_RATE, C_SPEED_REF,
 C_YREF, C_PSIREF, C_BEYOND, C_CURV, C_RD, C_NEXT_X, C_NEXT_Y, C_END_X, C_END_Y, C_ATT_X,
 C_ATT_Y, C_REP_X, C_REP_Y, C_REP_NORM, C_CAPPED, C_MIN_USED, C_CAP_SHARE, C_STATUS, C_ITER,
 C_FALLBACK, C_SLACK) = range(34)
N_LOG_COLUMNS = 34

#: ``solver_status`` by code (0: not logged)
STATUS_CODES = ("", "end", "optimal", "infeasible", "solver_error", "unbounded", "user_limit",
                "non_finite_data", "not_solved")
S_END, S_OPTIMAL, S_INFEASIBLE, S_ERROR, S_UNBOUNDED, S_LIMIT, S_NON_FINITE, S_NOT_SOLVED = \
    range(1, 9)
#: ``fallback`` by code
FALLBACK_CODES = ("", "end", "none", "shifted_plan", "safe_input")
F_END, F_NONE, F_SHIFTED, F_SAFE = range(1, 5)

#: termination by code (0: running)
TERMINATIONS = ("max_steps", "non_finite_state", "goal_line", "max_steps")
T_NON_FINITE, T_GOAL, T_MAX_STEPS = 1, 2, 3

#: :mod:`~pipeline.loop.controller.daqp_native`'s flags (plain numbers here, for numba)
NON_FINITE_FLAG, SETUP_FAILED_FLAG = -100, -101


def _tyre_slip(state: np.ndarray, constants: np.ndarray) -> float:
    """:func:`pipeline.loop.simulate.tyre_slip_norm` of the plant's ``constants``."""
    a, b, cf, cr, lim_f, lim_r = (constants[2], constants[3], constants[4], constants[5],
                                  constants[6], constants[7])
    vx, vy, r, delta = state[3], state[4], state[5], state[6]
    vx = vx if vx > 0.1 else 0.1
    front = abs(cf * (delta - atan2(vy + a * r, vx)) / lim_f)
    rear = abs(cr * atan2(vy - b * r, vx) / lim_r)
    return front if front > rear else rear


def _plant_columns(log: np.ndarray, state: np.ndarray, constants: np.ndarray) -> None:
    """The single-track plant's log columns (:meth:`SingleTrackPlant.log_columns`)."""
    log[C_VX], log[C_VY], log[C_R], log[C_DELTA] = state[3], state[4], state[5], state[6]
    log[C_SLIP] = _tyre_slip(state, constants)


#: The largest grid index kept as an integer key (well inside int64 and exact in a double)
_LARGEST_KEY = 1.0e15


def _grid_key(speed_mps: float, grid_mps: float) -> int:
    """``round(speed / grid)`` (half to even, as Python's ``round`` of a float), the integer
    key of a speed on the model grid (:func:`pipeline.loop.model.model_speed_mps`); -1 where
    it is no integer key (beyond :data:`_LARGEST_KEY`, or not a number): the driver then
    reads the speed itself."""
    quotient = speed_mps / grid_mps
    if not quotient < _LARGEST_KEY:
        return -1
    return int(np.rint(quotient))


def _as_int(value: float) -> int:
    """``int(value)`` of an integral float, refusing what Python's ``int`` refuses (compiled,
    a cast of NaN or infinity would give any integer silently)."""
    if np.isnan(value):
        raise ValueError("cannot convert float NaN to integer")
    if np.isinf(value):
        raise OverflowError("cannot convert float infinity to integer")
    return int(value)


def _settings_of(row: np.ndarray) -> ApfSettings:
    """:class:`~pipeline.loop.planner.ApfSettings` from its row of numbers (the driver's
    ``apf_settings``: the named tuple's fields in order, the switches as 0/1)."""
    return ApfSettings(row[0], row[1], row[2], row[3], row[4], row[5], row[6], row[7], row[8],
                       row[9], row[10], row[11] != 0.0, row[12] != 0.0, row[13] != 0.0,
                       row[14] != 0.0, row[15] != 0.0, row[16] != 0.0)


def observe_plan_rows(k: int, members: np.ndarray, states: np.ndarray,
                      sample_times: np.ndarray,
                      last_steps: np.ndarray, lines: np.ndarray, goal_line_x: np.ndarray,
                      goal_tolerance: np.ndarray, goals: np.ndarray,
                      obstacle_starts: np.ndarray, obstacle_velocities: np.ndarray,
                      obstacle_radii: np.ndarray, obstacle_appear: np.ndarray,
                      n_obstacles: np.ndarray, plant_constants: np.ndarray,
                      apf_settings: np.ndarray, horizon: int, nominal_speeds: np.ndarray,
                      speed_floors: np.ndarray, grids: np.ndarray, log: np.ndarray,
                      obstacle_log: np.ndarray, visible_log: np.ndarray,
                      terminations: np.ndarray, rollouts: np.ndarray, visible_positions: np.ndarray,
                      visible_velocities: np.ndarray, visible_radii: np.ndarray,
                      visible_counts: np.ndarray, speed_keys: np.ndarray) -> int:  # pragma: no cover (numba's)
    """Step ``k``'s observation and rollout of each member in ``members`` (indices of the
    group's rows); returns how many of them go on (those that end have their last row logged
    and their ``terminations`` code set).

    Per row ``i``: ``states (7,)``, ``lines (5,)``: the start-goal line's origin, the cosine
    and sine of its heading (``math``'s, as the pose row takes them) and the heading; the obstacles'
    arrays padded to the widest (``n_obstacles`` each); ``apf_settings (17,)``
    (:func:`_settings_of`). Writes row ``k`` of ``log (n, rows, N_LOG_COLUMNS)``,
    ``obstacle_log (n, rows, J, 3)`` (x, y, radius) and ``visible_log (n, rows, J)``; the
    rollouts ``(n, rows, horizon, 2)``; the visible obstacles in index order (positions, velocities,
    radii, counts); ``speed_keys (n, 2)``: the model-grid index of the speed the prediction
    step is read at (the slower of the measured and the planned) and of the measured speed
    (:func:`pipeline.loop.model.model_speed_mps`: ``round(max(v, floor) / grid)``)."""
    going = 0
    for i in members:
        state = states[i]
        row = log[i, k]
        ts = sample_times[i]
        time_s = k * ts
        # Scenario.obstacles_at (scripted: constant velocity from their appearance)
        n_obs = n_obstacles[i]
        count = 0
        for j in range(n_obs):
            elapsed = time_s - obstacle_appear[i, j]
            if elapsed <= 0.0:  # np.maximum(elapsed, 0): NaN stays NaN
                elapsed = 0.0
            ox = obstacle_starts[i, j, 0] + elapsed * obstacle_velocities[i, j, 0]
            oy = obstacle_starts[i, j, 1] + elapsed * obstacle_velocities[i, j, 1]
            seen = time_s + 1e-9 >= obstacle_appear[i, j]
            obstacle_log[i, k, j, 0], obstacle_log[i, k, j, 1] = ox, oy
            obstacle_log[i, k, j, 2] = obstacle_radii[i, j]
            visible_log[i, k, j] = seen
            if seen:
                visible_positions[i, count, 0], visible_positions[i, count, 1] = ox, oy
                visible_velocities[i, count, 0] = obstacle_velocities[i, j, 0]
                visible_velocities[i, count, 1] = obstacle_velocities[i, j, 1]
                visible_radii[i, count] = obstacle_radii[i, j]
                count += 1
        visible_counts[i] = count
        # _pose_row
        origin_x, origin_y, c_line, s_line, heading = (lines[i, 0], lines[i, 1], lines[i, 2],
                                                        lines[i, 3], lines[i, 4])
        X, Y, psi = state[0], state[1], state[2]
        dx, dy = X - origin_x, Y - origin_y
        along, lateral = c_line * dx + s_line * dy, -s_line * dx + c_line * dy
        e_psi = atan2(sin(psi - heading), cos(psi - heading))
        row[C_TIME], row[C_X], row[C_Y], row[C_PSI] = time_s, X, Y, psi
        row[C_EY], row[C_EPSI] = lateral, e_psi
        # _termination
        total = 0.0
        for entry in range(7):
            total += state[entry]
        ending = 0
        if not np.isfinite(total):
            ending = T_NON_FINITE
        elif along >= goal_line_x[i] - goal_tolerance[i]:
            ending = T_GOAL
        elif k == last_steps[i]:
            ending = T_MAX_STEPS
        if ending:
            terminations[i] = ending
            _plant_columns(row, state, plant_constants[i])
            row[C_FALLBACK], row[C_STATUS] = F_END, S_END
            continue
        going += 1
        # the rollout (ApfPlanner.rollout with the plant's velocity)
        c, s = cos(state[2]), sin(state[2])
        vvx, vvy = state[3] * c - state[4] * s, state[3] * s + state[4] * c
        path, attraction, repulsion, capped, low = apf_rollout_arrays(
            X, Y, goals[i, 0], goals[i, 1], visible_positions[i, :count],
            visible_velocities[i, :count], _settings_of(apf_settings[i]), horizon, ts, vvx,
            vvy, np.zeros((0, 2)), 0.0)
        rollouts[i, k] = path
        # _apf_columns
        n_path = path.shape[0]
        if n_path > 1:
            ax, ay, rx, ry = attraction[0, 0], attraction[0, 1], repulsion[0, 0], repulsion[0, 1]
            nx, ny = path[1, 0], path[1, 1]
        else:
            ax = ay = rx = ry = 0.0
            nx, ny = path[0, 0], path[0, 1]
        n_capped, n_low = 0, 0
        for t in range(capped.shape[0]):
            n_capped += 1 if capped[t] else 0
            n_low += 1 if low[t] else 0
        row[C_NEXT_X], row[C_NEXT_Y] = nx, ny
        row[C_END_X], row[C_END_Y] = path[n_path - 1, 0], path[n_path - 1, 1]
        row[C_ATT_X], row[C_ATT_Y], row[C_REP_X], row[C_REP_Y] = ax, ay, rx, ry
        row[C_REP_NORM] = sqrt(rx * rx + ry * ry)
        row[C_CAPPED] = 1.0 if n_capped > 0 else 0.0
        row[C_MIN_USED] = 1.0 if n_low > 0 else 0.0
        row[C_CAP_SHARE] = n_capped / capped.shape[0] if capped.shape[0] else 0.0
        # the speed rule without velocity planning: the nominal speed
        speed_ref = nominal_speeds[i]
        row[C_SPEED_REF] = speed_ref
        # PathFrame.step_geometry's model speeds, as grid indices
        floor, grid = speed_floors[i], grids[i]
        speed = state[3] if state[3] > floor else floor
        slow = speed if speed < speed_ref else speed_ref
        slow = slow if slow > floor else floor
        speed_keys[i, 0] = _grid_key(slow, grid)
        speed_keys[i, 1] = _grid_key(speed if speed > floor else floor, grid)
    return going


def frame_rows(members: np.ndarray, states: np.ndarray, nominal_speeds: np.ndarray,
               steps_s: np.ndarray, speed_floors: np.ndarray, accel_max: np.ndarray,
               horizon: int, rollouts: np.ndarray, k: int, line_cos_sin: np.ndarray,
               lines: np.ndarray, extend: np.ndarray, kappa_max: np.ndarray,
               vy_gains: np.ndarray, time_constants: np.ndarray, brake_max: np.ndarray,
               plans_xy: np.ndarray, plans_course: np.ndarray, plan_lengths: np.ndarray,
               visible_positions: np.ndarray, visible_velocities: np.ndarray,
               visible_radii: np.ndarray, visible_counts: np.ndarray, slots: int,
               vehicle_reach: np.ndarray, margins: np.ndarray, activation: np.ndarray,
               constrained: np.ndarray, grids: np.ndarray, log: np.ndarray
               ) -> tuple[np.ndarray, ...]:  # pragma: no cover (numba's)
    """The path frame of each member in ``members`` (the rows :func:`observe_plan_rows` kept
    going): :meth:`PathFrame.step_geometry <pipeline.loop.controller.frames.PathFrame.
    step_geometry>` with the prediction step ``steps_s`` the driver looked up, the visible
    obstacles predicted at constant velocity, :func:`~pipeline.loop.controller.path_rows.
    path_frame_rows`, and :meth:`~pipeline.loop.controller.frames.PathFrame.finish_inputs`'
    arithmetic: the measured state as errors from the path and row ``k``'s log values.

    Returns :func:`path_frame_rows`' arrays (one row per member of ``members``, in its order),
    then ``x0s (n, 5)``, the path arcs ``ds``, their ``n_intervals``, the model-grid index
    of each member's mean predicted speed (the model :meth:`finish_inputs` predicts with;
    :func:`_grid_key`) and that speed."""
    n = members.shape[0]
    N = horizon
    targets = np.empty((n, N, 2))
    cos_sin = np.empty((n, 2))
    extends = np.empty(n, dtype=np.bool_)
    kappa, ds, speeds, speed_refs = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    gains_vy, dts, n_intervals = np.empty(n), np.empty(n), np.empty(n, dtype=np.int64)
    positions, taus, accels, brakes = np.empty((n, 2)), np.empty(n), np.empty(n), np.empty(n)
    width = plans_xy.shape[1]
    plans, courses = np.zeros((n, width, 2)), np.zeros((n, width))
    lengths = np.zeros(n, dtype=np.int64)
    reach, margin, active, constraining = np.empty(n), np.empty(n), np.empty(n), \
        np.empty(n, dtype=np.bool_)
    starts = np.zeros(n + 1, dtype=np.int64)
    for r in range(n):
        starts[r + 1] = starts[r] + N * visible_counts[members[r]]
    obstacles = np.empty((starts[n], 2))
    radii = np.empty(starts[n] // N if N > 0 else 0)
    for r in range(n):
        i = members[r]
        state = states[i]
        floor = speed_floors[i]
        speed = state[3] if state[3] > floor else floor
        speed_ref = nominal_speeds[i]
        dt = steps_s[i]
        far = speed_ref if speed_ref > speed else speed
        far = far + accel_max[i] * dt
        ds[r], n_intervals[r] = speed * dt, _as_int(np.ceil(N * far / speed)) + 1
        targets[r] = rollouts[i, k]
        cos_sin[r, 0], cos_sin[r, 1] = line_cos_sin[i, 0], line_cos_sin[i, 1]
        extends[r], kappa[r] = extend[i], kappa_max[i]
        speeds[r], speed_refs[r], dts[r], gains_vy[r] = speed, speed_ref, dt, vy_gains[i]
        positions[r, 0], positions[r, 1] = state[0], state[1]
        taus[r], accels[r], brakes[r] = time_constants[i], accel_max[i], brake_max[i]
        length = plan_lengths[i]
        plans[r, :length], courses[r, :length] = plans_xy[i, :length], plans_course[i, :length]
        lengths[r] = length
        reach[r], margin[r] = vehicle_reach[i], margins[i]
        active[r], constraining[r] = activation[i], constrained[i]
        # ObstacleSnapshot.predicted_positions at dt, 2 dt, ..., N dt, step-major
        count = visible_counts[i]
        first = starts[r]
        for step in range(N):
            t = dt * (step + 1)
            for j in range(count):
                obstacles[first + step * count + j, 0] = \
                    visible_positions[i, j, 0] + t * visible_velocities[i, j, 0]
                obstacles[first + step * count + j, 1] = \
                    visible_positions[i, j, 1] + t * visible_velocities[i, j, 1]
        for j in range(count):
            radii[first // N + j] = visible_radii[i, j]
    (points, headings, curvature, beyond, frame, stations, r_d, vx, obstacle_s, obstacle_d, G,
     h) = path_frame_rows(targets, cos_sin, extends, kappa, ds, n_intervals, positions, speeds,
                          speed_refs, gains_vy, dts, N, taus, accels, brakes, plans, courses,
                          lengths, obstacles, starts, radii, slots, reach, margin, active,
                          constraining)
    x0s = np.empty((n, 5))
    mean_keys, means = np.empty(n, dtype=np.int64), np.empty(n)
    for r in range(n):
        i = members[r]
        state = states[i]
        # finish_inputs: the model of the mean predicted speed, the state as errors
        total = 0.0
        for c in range(N + 1):
            total += vx[r, c]
        mean = total / (N + 1)
        floor = speed_floors[i]
        means[r] = mean
        mean_keys[r] = _grid_key(mean if mean > floor else floor, grids[i])
        d0, heading0 = frame[r, 1], frame[r, 2]
        heading_error = (state[2] - heading0 + pi) % (2.0 * pi) - pi
        x0s[r, 0], x0s[r, 1], x0s[r, 2], x0s[r, 3], x0s[r, 4] = \
            d0, state[4], heading_error, state[5], state[6]
        row = log[i, k]
        # the log: the path's first point across the line, its heading against the line
        px, py = points[r, 1, 0] - lines[i, 0], points[r, 1, 1] - lines[i, 1]
        if lines[i, 4] == 0.0:
            row[C_YREF] = py
        else:
            row[C_YREF] = -line_cos_sin[i, 1] * px + line_cos_sin[i, 0] * py
        row[C_PSIREF] = headings[r, 1] - lines[i, 4]
        stop = _as_int(np.ceil(stations[r, N] / ds[r] - 1e-9))
        m = n_intervals[r]
        stop = stop if stop >= 0 else (m + stop if m + stop > 0 else 0)
        stop = stop if stop < m else m
        any_beyond = False
        for c in range(stop):
            any_beyond = any_beyond or beyond[r, c]
        row[C_BEYOND] = 1.0 if any_beyond else 0.0
        row[C_CURV], row[C_RD] = curvature[r, 0], r_d[r, 0]
    return (points, headings, curvature, beyond, frame, stations, r_d, vx, G, h, x0s, ds,
            n_intervals, mean_keys, means)


#: :func:`solve_rows`' exit flag of a member whose measured state is not finite (not solved,
#: as :meth:`~pipeline.loop.controller.lateral.LateralMpc.solve` leaves it)
NOT_SOLVED_FLAG = -200


def _finite_members(x0s: np.ndarray) -> np.ndarray:
    """The rows whose measured state is finite (the others are not solved, as
    :meth:`~pipeline.loop.controller.lateral.LateralMpc.solve` leaves them)."""
    n = x0s.shape[0]
    chosen = np.empty(n, dtype=np.int64)
    count = 0
    for r in range(n):
        total = 0.0
        for c in range(5):
            total += x0s[r, c]
        if np.isfinite(total):
            chosen[count] = r
            count += 1
    return chosen[:count]


def _qp_arrays(members: np.ndarray, packs: np.ndarray, n_u: int, horizon: int, slots: int,
               blockings: np.ndarray, x0s: np.ndarray, r_d: np.ndarray,
               model_gains: np.ndarray, G: np.ndarray, h: np.ndarray
               ) -> tuple[np.ndarray, ...]:
    """The rows solved (:func:`_finite_members`), then the condensing's arguments of them
    (``_condensing_arrays`` of :mod:`~pipeline.loop.controller.lateral_rows`): the
    steady-state references of each member's model (``model_gains (n, 5)`` times ``r_d``),
    the disturbance, the half-planes."""
    chosen = _finite_members(x0s)
    count = chosen.shape[0]
    N, M = horizon, slots
    packs_in = np.empty(count, dtype=np.int64)
    blocks, starts = np.empty((count, n_u, N)), np.empty((count, 5))
    disturbances, disturbed = np.empty((count, N)), np.empty(count, dtype=np.bool_)
    y_refs, psi_refs = np.zeros((count, N)), np.empty((count, N))
    r_refs, delta_refs = np.empty((count, N)), np.empty((count, N))
    present = np.ones(count, dtype=np.bool_)
    gains, bounds = np.empty((count, N, M)), np.empty((count, N, M))
    for q in range(count):
        r = chosen[q]
        packs_in[q] = packs[r]
        blocks[q], starts[q] = blockings[members[r]], x0s[r]
        any_disturbance = False
        for t in range(N):
            value = r_d[r, t]
            disturbances[q, t] = value
            any_disturbance = any_disturbance or value != 0.0
            psi_refs[q, t] = model_gains[r, 2] * value
            r_refs[q, t] = model_gains[r, 3] * value
            delta_refs[q, t] = model_gains[r, 4] * value
        disturbed[q] = any_disturbance
        gains[q], bounds[q] = G[r], h[r]
    return (chosen, packs_in, blocks, starts, disturbances, disturbed, y_refs, psi_refs,
            r_refs, present, delta_refs, gains, bounds)


def solve_rows(functions: np.ndarray, workspaces: np.ndarray, members: np.ndarray,
               packs: np.ndarray, offsets: np.ndarray, n_u: int, horizon: int, slots: int,
               blockings: np.ndarray, x0s: np.ndarray, r_d: np.ndarray, model_gains: np.ndarray,
               G: np.ndarray, h: np.ndarray, steering_max: np.ndarray, hessian_new: np.ndarray,
               iter_limits: np.ndarray) -> tuple[np.ndarray, ...]:  # pragma: no cover (numba's)
    """The QPs of ``members`` on their kept DAQP workspaces (row ``r`` of the per-step arrays
    is member ``members[r]`` of the group's): :func:`~pipeline.loop.controller.daqp_rows.
    daqp_condensed_rows` for those whose measured state is finite (the others
    :data:`NOT_SOLVED_FLAG`); each member's workspaces (one per statement's slots, shape
    (members, slots + 1, 5)) keep their flags (set up) in ``workspaces``; ``hessian_new``
    (rows, slots + 1): whether each statement's workspace must take the step's Hessian.
    Returns ``exitflags``, the log's status codes and iterations, whether each solution is one
    to accept (``optimal``), the plans, predicted states, slacks, whether each plan is finite
    and the slots of the statement solved (-1: none): one row per member of ``members``."""
    n, N, M = members.shape[0], horizon, slots
    (chosen, packs_in, blocks, starts, disturbances, disturbed, y_refs, psi_refs, r_refs,
     present, delta_refs, gains, bounds) = _qp_arrays(members, packs, n_u, N, M, blockings,
                                                      x0s, r_d, model_gains, G, h)
    count = chosen.shape[0]
    spaces = np.empty((count, M + 1, 5), dtype=np.int64)
    limits = np.empty(count, dtype=np.int64)
    dmax, fresh = np.empty(count), np.empty((count, M + 1), dtype=np.bool_)
    for q in range(count):
        r = chosen[q]
        i = members[r]
        spaces[q], limits[q] = workspaces[i], iter_limits[i]
        dmax[q], fresh[q] = steering_max[i], hessian_new[r]
    flags_in, iterations_in, _, plans_in, states_in, slacks_in, finite_in, used_in = \
        daqp_condensed_rows(functions, spaces, packs_in, offsets, n_u, N, M, blocks, starts,
                            disturbances, disturbed, y_refs, psi_refs, r_refs, present,
                            delta_refs, present, gains, bounds, dmax, fresh, limits)
    exitflags = np.full(n, NOT_SOLVED_FLAG, dtype=np.int64)
    codes = np.full(n, S_NOT_SOLVED, dtype=np.int64)
    iterations = np.full(n, -1, dtype=np.int64)
    ok = np.zeros(n, dtype=np.bool_)
    plans, states = np.zeros((n, N)), np.zeros((n, 5, N + 1))
    slacks, plan_finite = np.zeros(n), np.zeros(n, dtype=np.bool_)
    used = np.full(n, -1, dtype=np.int64)
    for q in range(count):
        r = chosen[q]
        workspaces[members[r], :, 4] = spaces[q, :, 4]
        used[r] = used_in[q]
        flag = flags_in[q]
        exitflags[r] = flag
        codes[r] = _status_code(flag)
        ok[r] = codes[r] == S_OPTIMAL
        if flag != NON_FINITE_FLAG and flag != SETUP_FAILED_FLAG:
            iterations[r] = iterations_in[q]
        plans[r], states[r] = plans_in[q], states_in[q]
        slacks[r], plan_finite[r] = slacks_in[q], finite_in[q]
    return exitflags, codes, iterations, ok, plans, states, slacks, plan_finite, used


def theta_rows(members: np.ndarray, packs: np.ndarray, offsets: np.ndarray,
               direct_packs: np.ndarray, direct_offsets: np.ndarray, n_u: int, horizon: int,
               slots: int, blockings: np.ndarray, x0s: np.ndarray, r_d: np.ndarray,
               model_gains: np.ndarray, G: np.ndarray, h: np.ndarray
               ) -> tuple[np.ndarray, ...]:  # pragma: no cover (numba's)
    """The ``clarabel_direct`` statements' parameter vectors of ``members`` whose measured
    state is finite (:func:`~pipeline.loop.controller.direct_rows.direct_theta_rows`), one
    row per member of ``members``: ``chosen`` (whether it is solved), ``thetas``, the slots
    each uses, the free responses and whether each vector is finite."""
    n, N, M = members.shape[0], horizon, slots
    (chosen, packs_in, blocks, starts, disturbances, disturbed, y_refs, psi_refs, r_refs,
     present, delta_refs, gains, bounds) = _qp_arrays(members, packs, n_u, N, M, blockings,
                                                      x0s, r_d, model_gains, G, h)
    count = chosen.shape[0]
    direct_in = np.empty(count, dtype=np.int64)
    for q in range(count):
        direct_in[q] = direct_packs[chosen[q]]
    thetas_in, used_in, frees_in, finite_in = direct_theta_rows(
        packs_in, offsets, direct_in, direct_offsets, n_u, N, M, starts, disturbances,
        disturbed, y_refs, psi_refs, r_refs, present, delta_refs, present, gains, bounds)
    solved = np.zeros(n, dtype=np.bool_)
    thetas = np.zeros((n, thetas_in.shape[1]))
    used = np.zeros(n, dtype=np.int64)
    frees = np.zeros((n, frees_in.shape[1]))
    finite = np.zeros(n, dtype=np.bool_)
    for q in range(count):
        r = chosen[q]
        solved[r] = True
        thetas[r], used[r], frees[r], finite[r] = thetas_in[q], used_in[q], frees_in[q], \
            finite_in[q]
    return solved, thetas, used, frees, finite


def readout_rows(members: np.ndarray, packs: np.ndarray, offsets: np.ndarray,
                 direct_packs: np.ndarray, direct_offsets: np.ndarray, n_u: int, horizon: int,
                 slots: int, Ws: np.ndarray, blockings: np.ndarray, x0s: np.ndarray,
                 frees: np.ndarray, G: np.ndarray, h: np.ndarray
                 ) -> tuple[np.ndarray, ...]:  # pragma: no cover (numba's)
    """:func:`~pipeline.loop.controller.direct_rows.direct_readout_rows` of ``members`` (their
    blockings by member): plans, predicted states, slacks, whether each plan is finite."""
    n = members.shape[0]
    blocks = np.empty((n, n_u, horizon))
    for r in range(n):
        blocks[r] = blockings[members[r]]
    _, plans, states, slacks, plan_finite = direct_readout_rows(
        packs, offsets, direct_packs, direct_offsets, n_u, horizon, slots, Ws, blocks, x0s,
        frees, G, h)
    return plans, states, slacks, plan_finite


def _status_code(flag: int) -> int:
    """The log's ``solver_status`` code of a :func:`solve_rows` exit flag
    (:attr:`DaqpCondensedQp.STATUS <pipeline.loop.controller.lateral_backends.
    DaqpCondensedQp.STATUS>`)."""
    if flag == NOT_SOLVED_FLAG:
        return S_NOT_SOLVED
    if flag == NON_FINITE_FLAG:
        return S_NON_FINITE
    if flag == 1 or flag == 2:
        return S_OPTIMAL
    if flag == -1:
        return S_INFEASIBLE
    if flag == -3:
        return S_UNBOUNDED
    if flag == -4:
        return S_LIMIT
    return S_ERROR


def apply_rows(k: int, members: np.ndarray, horizon: int, states: np.ndarray,  # noqa: C901
               x0s: np.ndarray, codes: np.ndarray, iterations: np.ndarray,
               solution_ok: np.ndarray, plans: np.ndarray, predicted: np.ndarray,
               slacks: np.ndarray, plan_finite: np.ndarray, solve_s: np.ndarray,
               last_plans: np.ndarray,
               plan_ages: np.ndarray, has_plan: np.ndarray, sample_times: np.ndarray,
               rate_max: np.ndarray, points: np.ndarray, headings: np.ndarray,
               curvature: np.ndarray, beyond: np.ndarray, ds: np.ndarray,
               n_intervals: np.ndarray, stations: np.ndarray, vx: np.ndarray,
               plans_xy: np.ndarray, plans_course: np.ndarray, plan_lengths: np.ndarray,
               r_d: np.ndarray, G: np.ndarray, h: np.ndarray, steps_s: np.ndarray,
               record_points: np.ndarray, record_headings: np.ndarray,
               record_curvature: np.ndarray, record_beyond: np.ndarray,
               record_sizes: np.ndarray, record_scalars: np.ndarray,
               record_stations: np.ndarray, record_x0: np.ndarray, record_r_d: np.ndarray,
               record_plan: np.ndarray, record_G: np.ndarray, record_h: np.ndarray,
               record_xy: np.ndarray, solve_times: np.ndarray, n_solves: np.ndarray,
               plant_constants: np.ndarray, substeps: np.ndarray, log: np.ndarray
               ) -> None:  # pragma: no cover (numba's)
    """Each member's step after its QP (``codes``: the log's status codes, ``solution_ok``:
    an optimal status with values, ``solve_s``: each solve's time): the plan accepted (a
    solution to accept and a finite plan) or the
    fallback taken (the last plan shifted while it lasts, else the steering eased to zero at
    its rate), the accepted plans' poses kept for the next step's stations, the step's
    prediction record (``record_*`` row ``k``; ``record_sizes``: the path's intervals,
    ``record_scalars``: its arc and the prediction step), its solve time, its log columns, and
    the plant stepped (the steering rate saturated; the speed towards the planned one, which
    the log already holds)."""
    n = members.shape[0]
    N = horizon
    accepted = np.zeros(n, dtype=np.bool_)
    for r in range(n):
        i = members[r]
        accepted[r] = solution_ok[r] and plan_finite[r]
    # PathFrame.after_step: the accepted plans' poses (plan_poses_rows on their rows)
    n_accepted = 0
    for r in range(n):
        n_accepted += 1 if accepted[r] else 0
    if n_accepted:
        which = np.empty(n_accepted, dtype=np.int64)
        q = 0
        for r in range(n):
            if accepted[r]:
                which[q] = r
                q += 1
        widest = 0
        for q in range(n_accepted):
            widest = n_intervals[which[q]] if n_intervals[which[q]] > widest else widest
        m = N + 1
        pts, hds = np.zeros((n_accepted, widest + 1, 2)), np.zeros((n_accepted, widest + 1))
        cvs, arcs = np.zeros((n_accepted, widest)), np.empty(n_accepted)
        counts = np.empty(n_accepted, dtype=np.int64)
        st, lat, err = np.empty((n_accepted, m)), np.empty((n_accepted, m)), \
            np.empty((n_accepted, m))
        vys, vxs = np.empty((n_accepted, m)), np.empty((n_accepted, m))
        for q in range(n_accepted):
            r = which[q]
            kk = n_intervals[r]
            pts[q, :kk + 1], hds[q, :kk + 1] = points[r, :kk + 1], headings[r, :kk + 1]
            cvs[q, :kk], arcs[q], counts[q] = curvature[r, :kk], ds[r], kk
            st[q], lat[q], err[q] = stations[r], predicted[r, 0], predicted[r, 2]
            vys[q], vxs[q] = predicted[r, 1], vx[r]
        xy, course = plan_poses_rows(pts, hds, cvs, arcs, counts, st, lat, err, vys, vxs)
        for q in range(n_accepted):
            i = members[which[q]]
            plans_xy[i], plans_course[i], plan_lengths[i] = xy[q], course[q], m
    for r in range(n):
        i = members[r]
        row = log[i, k]
        status, iteration = codes[r], iterations[r]
        if accepted[r]:
            command = plans[r, 0]
            last_plans[i] = plans[r]
            plan_ages[i], has_plan[i] = 0, True
            fallback = F_NONE
            slack = slacks[r] if not slacks[r] < 0.0 else 0.0
        else:
            plan_lengths[i] = 0
            slack = np.nan
            if has_plan[i] and plan_ages[i] + 1 < N:
                plan_ages[i] += 1
                command = last_plans[i, plan_ages[i]]
                fallback = F_SHIFTED
            else:
                delta = x0s[r, 4] if np.isfinite(x0s[r, 4]) else 0.0
                command = -delta / sample_times[i]
                command = command if command > -rate_max[i] else -rate_max[i]
                command = command if command < rate_max[i] else rate_max[i]
                fallback = F_SAFE
        solve_times[i, n_solves[i]] = solve_s[r]
        n_solves[i] += 1
        # the step's record (LateralMpc.keep_record)
        kk = n_intervals[r]
        record_points[i, k, :kk + 1] = points[r, :kk + 1]
        record_headings[i, k, :kk + 1] = headings[r, :kk + 1]
        record_curvature[i, k, :kk] = curvature[r, :kk]
        record_beyond[i, k, :kk] = beyond[r, :kk]
        record_sizes[i, k] = kk
        record_scalars[i, k, 0], record_scalars[i, k, 1] = ds[r], steps_s[i]
        record_scalars[i, k, 2] = 1.0 if accepted[r] else 0.0
        record_stations[i, k] = stations[r]
        record_x0[i, k] = x0s[r]
        record_r_d[i, k] = r_d[r]
        if accepted[r]:
            record_plan[i, k] = predicted[r, 0]
            record_xy[i, k] = plans_xy[i]
        record_G[i, k], record_h[i, k] = G[r], h[r]
        # _add_step_columns: the plant's (before its step), the input, the solver's
        state = states[i]
        _plant_columns(row, state, plant_constants[i])
        row[C_RATE] = command
        row[C_STATUS], row[C_ITER], row[C_FALLBACK], row[C_SLACK] = \
            status, iteration, fallback, slack
        # the plant's step (the engine's _advance_plants)
        limit = rate_max[i]
        rate = command if command > -limit else -limit
        rate = rate if rate < limit else limit
        states[i] = single_track_rk4(state, plant_constants[i], rate, row[C_SPEED_REF],
                                     sample_times[i], substeps[i])


def check_rows(points: np.ndarray, headings: np.ndarray, curvature: np.ndarray,
               sizes: np.ndarray, scalars: np.ndarray, stations: np.ndarray, x0s: np.ndarray,
               Ad: np.ndarray, Bd: np.ndarray, Ed: np.ndarray, plans: np.ndarray,
               n_records: int, xy: np.ndarray, psi: np.ndarray, delta: np.ndarray,
               half: int, one: int, ts: float) -> np.ndarray:  # pragma: no cover (numba's)
    """:func:`~pipeline.loop.controller.prediction_check.prediction_check` of one member's
    first ``n_records`` records, from the group's record arrays (row ``k``: the path of
    ``sizes[k]`` intervals, ``scalars[k]``: its arc, the prediction step, whether the plan was
    accepted; the model's ``Ad``, ``Bd``, ``Ed`` columns at the log's sample time ``ts``) and
    the log's ``xy``, ``psi``, ``delta``: the check's columns, one row per log row (NaN where
    none)."""
    rows = xy.shape[0]
    out = np.full((rows, 5), np.nan)
    no_plan = np.zeros(0)
    for k in range(min(n_records, rows)):
        last = k + one if k + one < rows - 1 else rows - 1
        K = sizes[k]
        plan = plans[k] if scalars[k, 2] != 0.0 else no_plan
        a, b, c, d, e = check_record_arrays(
            points[k, :K + 1], headings[k, :K + 1], curvature[k, :K], scalars[k, 0], K,
            stations[k], scalars[k, 1], x0s[k], Ad[k], Bd[k], Ed[k], plan, xy, psi, delta, k,
            last, half, one, ts)
        out[k, 0], out[k, 1], out[k, 2], out[k, 3], out[k, 4] = a, b, c, d, e
    return out
