"""Metrics stage: Table 1 of the paper as numbers, pure functions of a logged trajectory.

Every function takes arrays (or the trajectory table) and thresholds from
:class:`pipeline.config.MetricsConfig`; none of them runs a simulation. Definitions (also shown
in the report):

* **Reaction delay** (C1, s): first time at or after the obstacle appears at which the steering
  angle differs from its value at appearance by more than ``reaction_steering_band_rad``, minus the
  appearance time. A second variant uses the lateral deviation (band ``reaction_lateral_band_m``).
  NaN plus ``reacted = False`` when the band is never left.
* **Smoothness** (C2): RMS and max of the steering rate (rad/s, the applied input); lateral
  acceleration ``a_y = v^2 kappa = v r``; RMS and max lateral jerk ``d a_y / dt`` (m/s^3, central
  differences); RMS curvature rate ``d kappa / dt`` with ``kappa = r / v`` (1/(m s)).
* **Repulsion modulation** (C3): repulsive impulse ``sum |F_rep| Ts``; share of it applied while
  the obstacle's clearance exceeds ``threat_clearance_m`` (0 when no repulsion was applied at
  all); peak ``|F_rep|``; clearance at which repulsion first switched on.
* **Goal-direction recovery** (C4, s): from the moment every obstacle is passed (the vehicle's
  longitudinal position exceeds each obstacle's by both radii, for good), the settling time of
  the lateral error to the original start-goal line, computed with python-control's
  ``step_info`` on the mirrored signal ``e0 - e(t)`` (a step from 0 to ``e0``) with an absolute
  band: ``SettlingTimeThreshold = recovery_lateral_band_m / |e0|``; NaN plus
  ``recovered = False`` if the error is outside the band at the end of the run. Secondary: the
  same settling time of the heading error to the bearing of the goal
  (``recovery_heading_band_rad``), judged until ``recovery_heading_stop_m`` before the goal
  line, where that bearing turns fast.
* **Path stability** (C5): overshoot past the start-goal line on the side opposite the detour
  after the obstacle is passed (m); sign changes of the lateral error (outside
  ``lateral_sign_band_m``) and of the yaw rate (outside ``yaw_rate_sign_band_rad_s``), and their
  sum ``oscillation_count``; largest
  per-step heading change (rad).
* **Safety**: minimum clearance (centre distance minus both radii, m), collision flag (clearance
  < 0), minimum time to collision (clearance / closing speed while closing, s).
* **Progress**: time to reach the goal line (NaN if not reached), path length (m).
* **Solver**: median and p95 of Clarabel's iteration count, fallback count, largest heading
  error against the model's validity bound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import control
import numpy as np
import pandas as pd

from pipeline.config import MetricsConfig


@dataclass(frozen=True)
class TrajectoryContext:
    """What the metrics need besides the table: geometry of the run (SI units)."""

    start_m: tuple[float, float]
    goal_m: tuple[float, float]
    vehicle_radius_m: float
    validity_heading_rad: float = math.inf


def _nan_to_none(value):
    if isinstance(value, (float, np.floating)) and not np.isfinite(value):
        return None
    if isinstance(value, np.generic):
        return value.item()
    return value


def rms(values: np.ndarray) -> float:
    """Root mean square of the finite entries (NaN for none)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(np.sqrt(np.mean(v**2))) if v.size else float("nan")


def max_abs(values: np.ndarray) -> float:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(np.max(np.abs(v))) if v.size else float("nan")


def sign_changes(values: np.ndarray, band: float) -> int:
    """Number of sign changes of ``values`` counting only samples with ``|v| > band``."""
    v = np.asarray(values, dtype=float)
    signs = np.sign(v[np.abs(v) > band])
    return int(np.count_nonzero(signs[1:] != signs[:-1])) if signs.size > 1 else 0


def time_derivative(values: np.ndarray, time_s: np.ndarray) -> np.ndarray:
    """Central-difference derivative (one-sided at the ends)."""
    v = np.asarray(values, dtype=float)
    if v.size < 2:
        return np.full(v.shape, np.nan)
    return np.gradient(v, np.asarray(time_s, dtype=float))


def first_exit_time(time_s: np.ndarray, values: np.ndarray, start_time_s: float,
                    band: float) -> float:
    """Time from ``start_time_s`` until ``|values - values(start)|`` first exceeds ``band``."""
    t = np.asarray(time_s, dtype=float)
    v = np.asarray(values, dtype=float)
    after = np.nonzero(t >= start_time_s - 1e-9)[0]
    if after.size == 0:
        return float("nan")
    ref = v[after[0]]
    exits = after[np.abs(v[after] - ref) > band]
    return float(t[exits[0]] - start_time_s) if exits.size else float("nan")


def settling_time(time_s: np.ndarray, error: np.ndarray, band: float) -> float:
    """Time after ``time_s[0]`` from which ``|error|`` stays within ``band`` (NaN if it ends
    outside).

    Uses ``control.step_info`` on the mirrored signal ``e0 - e(t)``, a step from 0 to ``e0`` whose
    settling band ``SettlingTimeThreshold * |e0|`` is set to ``band``.
    """
    t = np.asarray(time_s, dtype=float) - float(time_s[0])
    e = np.asarray(error, dtype=float)
    if e.size == 0 or not np.all(np.isfinite(e)):
        return float("nan")
    if abs(e[-1]) > band:
        return float("nan")
    e0 = float(e[0])
    if abs(e0) <= band and np.all(np.abs(e) <= band):
        return 0.0
    if abs(e0) <= 1e-12:
        # step_info needs a non-zero step; the error starts at zero, so measure from the
        # last exit directly (same convention: first sample after the last exit)
        outside = np.nonzero(np.abs(e) > band)[0]
        return float(t[outside[-1] + 1])
    mirrored = e0 - e
    if np.all(np.sign(e0) * mirrored < 0.9 * abs(e0)):
        # step_info's rise-time search would find no 90 % point; settle by direct rule
        outside = np.nonzero(np.abs(e) > band)[0]
        return float(t[outside[-1] + 1])
    info = control.step_info(mirrored, t, final_output=e0, SettlingTimeThreshold=band / abs(e0))
    return float(info["SettlingTime"])


def obstacle_count(trajectory: pd.DataFrame) -> int:
    j = 0
    while f"obs{j}_x_m" in trajectory.columns:
        j += 1
    return j


def clearance_series(trajectory: pd.DataFrame, vehicle_radius_m: float) -> np.ndarray:
    """Per-step clearance to the nearest visible obstacle (NaN while none is visible)."""
    xy = trajectory[["X_m", "Y_m"]].to_numpy(float)
    result = np.full(len(trajectory), np.inf)
    for j in range(obstacle_count(trajectory)):
        centre = trajectory[[f"obs{j}_x_m", f"obs{j}_y_m"]].to_numpy(float)
        gap = (np.linalg.norm(xy - centre, axis=1) - trajectory[f"obs{j}_radius_m"].to_numpy(float)
               - vehicle_radius_m)
        visible = trajectory[f"obs{j}_visible"].to_numpy(bool)
        result = np.where(visible, np.minimum(result, gap), result)
    return np.where(np.isfinite(result), result, np.nan)


def min_time_to_collision(trajectory: pd.DataFrame, vehicle_radius_m: float) -> float:
    """Smallest ``clearance / closing speed`` over steps and visible obstacles while closing."""
    t = trajectory["time_s"].to_numpy(float)
    xy = trajectory[["X_m", "Y_m"]].to_numpy(float)
    best = np.inf
    for j in range(obstacle_count(trajectory)):
        centre = trajectory[[f"obs{j}_x_m", f"obs{j}_y_m"]].to_numpy(float)
        dist = np.linalg.norm(xy - centre, axis=1)
        closing = -time_derivative(dist, t)
        gap = np.maximum(dist - trajectory[f"obs{j}_radius_m"].to_numpy(float) - vehicle_radius_m,
                         0.0)
        visible = trajectory[f"obs{j}_visible"].to_numpy(bool)
        ok = visible & (closing > 1e-6)
        if np.any(ok):
            best = min(best, float(np.min(gap[ok] / closing[ok])))
    return float(best) if np.isfinite(best) else float("nan")


def compute_metrics(trajectory: pd.DataFrame, context: TrajectoryContext,
                    thresholds: MetricsConfig) -> dict:
    """All Table 1 metrics of one logged run.

    Parameters
    ----------
    trajectory : pandas.DataFrame
        The simulation log (or a scored external trajectory with the same columns).
    context : TrajectoryContext
    thresholds : MetricsConfig

    Returns
    -------
    dict
        Flat mapping of metric name to value; NaN is returned as ``None`` so JSON stays valid.
    """
    tr = trajectory
    t = tr["time_s"].to_numpy(float)
    dt = float(np.median(np.diff(t))) if t.size > 1 else float("nan")
    start, goal = np.asarray(context.start_m, float), np.asarray(context.goal_m, float)
    line = (goal - start) / np.linalg.norm(goal - start)
    normal = np.array([-line[1], line[0]])
    xy = tr[["X_m", "Y_m"]].to_numpy(float)
    along = (xy - start) @ line
    lateral = (xy - start) @ normal
    # optional columns are derived from the path when a scored trajectory lacks them
    if "psi_rad" in tr:
        psi = tr["psi_rad"].to_numpy(float)
    else:
        psi = np.unwrap(np.arctan2(time_derivative(xy[:, 1], t), time_derivative(xy[:, 0], t)))
    if "vx_mps" in tr:
        speed = np.hypot(tr["vx_mps"].to_numpy(float), tr["vy_mps"].to_numpy(float)) \
            if "vy_mps" in tr else tr["vx_mps"].to_numpy(float)
    else:
        speed = np.hypot(time_derivative(xy[:, 0], t), time_derivative(xy[:, 1], t))
    yaw_rate = tr["r_rad_s"].to_numpy(float) if "r_rad_s" in tr \
        else time_derivative(np.unwrap(psi), t)
    delta = tr["delta_rad"].to_numpy(float) if "delta_rad" in tr else np.full(len(tr), np.nan)
    steer_rate = tr["steering_rate_rad_s"].to_numpy(float) if "steering_rate_rad_s" in tr \
        else time_derivative(delta, t)
    heading_error = np.arctan2(np.sin(psi - np.arctan2(line[1], line[0])),
                               np.cos(psi - np.arctan2(line[1], line[0])))
    to_goal = goal - xy
    bearing = np.arctan2(to_goal[:, 1], to_goal[:, 0])
    bearing_error = np.arctan2(np.sin(psi - bearing), np.cos(psi - bearing))

    out: dict = {"n_steps_logged": int(len(tr)), "duration_s": float(t[-1] - t[0]) if t.size else 0.0}

    # --- which obstacle matters: the first to appear (ties: the closest at its appearance)
    n_obs = obstacle_count(tr)
    appear_time = float("nan")
    passed_time = float("nan")
    if n_obs:
        appear = []
        for j in range(n_obs):
            vis = tr[f"obs{j}_visible"].to_numpy(bool)
            appear.append(t[np.argmax(vis)] if vis.any() else np.inf)
        j0 = int(np.argmin(appear))
        if np.isfinite(appear[j0]):
            appear_time = float(appear[j0])
            # obstacle "passed": vehicle ahead of every obstacle's centre by both radii, for good
            behind = np.ones(len(tr), dtype=bool)
            for j in range(n_obs):
                ox = (tr[[f"obs{j}_x_m", f"obs{j}_y_m"]].to_numpy(float) - start) @ line
                reach = tr[f"obs{j}_radius_m"].to_numpy(float) + context.vehicle_radius_m
                vis = tr[f"obs{j}_visible"].to_numpy(bool)
                behind &= (~vis & (t < appear[j])) | (along - ox > reach)
            not_behind = np.nonzero(~behind & (t >= appear_time))[0]
            if not_behind.size and not_behind[-1] + 1 < len(tr):
                passed_time = float(t[not_behind[-1] + 1])
            elif not_behind.size == 0:
                passed_time = appear_time
    out["obstacle_appear_time_s"] = appear_time
    out["obstacle_passed_time_s"] = passed_time

    # --- C1 reaction
    if np.isfinite(appear_time):
        delay = first_exit_time(t, delta, appear_time, thresholds.reaction_steering_band_rad) \
            if np.any(np.isfinite(delta)) else float("nan")
        out["reaction_delay_s"] = delay
        out["reacted"] = bool(np.isfinite(delay))
        out["reaction_delay_lateral_s"] = first_exit_time(t, lateral, appear_time,
                                                          thresholds.reaction_lateral_band_m)
    else:
        out.update(reaction_delay_s=float("nan"), reacted=False,
                   reaction_delay_lateral_s=float("nan"))

    # --- C2 smoothness
    lat_acc = speed * yaw_rate
    jerk = time_derivative(lat_acc, t)
    curvature = yaw_rate / np.maximum(speed, 1e-3)
    out["steering_rate_rms_rad_s"] = rms(steer_rate)
    out["steering_rate_max_rad_s"] = max_abs(steer_rate)
    out["lateral_accel_max_mps2"] = max_abs(lat_acc)
    out["lateral_jerk_rms_mps3"] = rms(jerk)
    out["lateral_jerk_max_mps3"] = max_abs(jerk)
    out["curvature_rate_rms_1_per_ms"] = rms(time_derivative(curvature, t))

    # --- C3 repulsion modulation
    clearance = clearance_series(tr, context.vehicle_radius_m)
    if "apf_rep_norm" in tr:
        rep = np.nan_to_num(tr["apf_rep_norm"].to_numpy(float))
        impulse = float(np.sum(rep) * dt)
        far = np.nan_to_num(clearance, nan=np.inf) > thresholds.threat_clearance_m
        out["repulsive_impulse"] = impulse
        # no repulsion at all means no unnecessary repulsion either: share 0, not missing
        out["repulsive_impulse_far_share"] = float(np.sum(rep[far]) * dt / impulse) \
            if impulse > 0 else 0.0
        out["repulsive_force_peak"] = float(np.max(rep)) if rep.size else float("nan")
        on = np.nonzero(rep > 1e-9)[0]
        out["repulsion_onset_clearance_m"] = float(clearance[on[0]]) if on.size else float("nan")
    # --- C4 recovery
    if np.isfinite(passed_time):
        after = t >= passed_time - 1e-9
        lat_settle = settling_time(t[after], lateral[after], thresholds.recovery_lateral_band_m)
        # the bearing to the goal turns fast right before the goal: judge heading until
        # recovery_heading_stop_m before the goal line
        goal_along = float((goal - start) @ line)
        heading_window = after & (along <= goal_along - thresholds.recovery_heading_stop_m)
        head_settle = settling_time(t[heading_window], bearing_error[heading_window],
                                    thresholds.recovery_heading_band_rad) \
            if np.count_nonzero(heading_window) > 1 else float("nan")
        out["recovery_lateral_s"] = lat_settle
        out["recovery_heading_s"] = head_settle
        out["recovery_time_s"] = lat_settle
        out["recovered"] = bool(np.isfinite(lat_settle))
        # --- C5 overshoot past the line, on the side opposite the detour
        before = (t >= appear_time - 1e-9) & ~after
        detour_side = np.sign(lateral[before][np.argmax(np.abs(lateral[before]))]) \
            if np.any(before) else 0.0
        out["overshoot_m"] = float(max(0.0, np.max(-detour_side * lateral[after]))) \
            if detour_side != 0 else 0.0
    else:
        out.update(recovery_lateral_s=float("nan"), recovery_heading_s=float("nan"),
                   recovery_time_s=float("nan"), recovered=False, overshoot_m=float("nan"))
    out["lateral_sign_changes"] = sign_changes(lateral, thresholds.lateral_sign_band_m)
    out["yaw_rate_sign_changes"] = sign_changes(yaw_rate, thresholds.yaw_rate_sign_band_rad_s)
    out["oscillation_count"] = out["lateral_sign_changes"] + out["yaw_rate_sign_changes"]
    dpsi = np.abs(np.diff(np.unwrap(psi)))
    out["heading_step_max_rad"] = float(np.max(dpsi)) if dpsi.size else float("nan")
    out["max_lateral_deviation_m"] = max_abs(lateral)

    # --- safety and progress
    out["min_clearance_m"] = float(np.nanmin(clearance)) if np.any(np.isfinite(clearance)) \
        else float("nan")
    out["collision"] = bool(np.nanmin(clearance) < 0.0) if np.any(np.isfinite(clearance)) \
        else False
    out["min_time_to_collision_s"] = min_time_to_collision(tr, context.vehicle_radius_m)
    reached = np.nonzero(along >= (goal - start) @ line - thresholds.goal_tolerance_m)[0]
    out["goal_reached"] = bool(reached.size)
    out["time_to_goal_s"] = float(t[reached[0]] - t[0]) if reached.size else float("nan")
    out["path_length_m"] = float(np.sum(np.linalg.norm(np.diff(xy, axis=0), axis=1)))
    out["max_abs_heading_error_rad"] = max_abs(heading_error)
    out["heading_validity_exceeded"] = bool(out["max_abs_heading_error_rad"]
                                            > context.validity_heading_rad)

    # --- solver (deterministic parts only; wall-clock times live in timing.json)
    if "solver_iterations" in tr:
        it = tr["solver_iterations"].to_numpy(float)
        it = it[np.isfinite(it) & (it >= 0)]
        out["solver_iterations_median"] = float(np.median(it)) if it.size else float("nan")
        out["solver_iterations_p95"] = float(np.percentile(it, 95)) if it.size else float("nan")
    if "fallback" in tr:
        fb = tr["fallback"].astype(str)
        out["fallback_count"] = int(fb.isin(["shifted_plan", "safe_input"]).sum())
        out["fallback_safe_input_count"] = int((fb == "safe_input").sum())
    return {k: _nan_to_none(v) for k, v in out.items()}
