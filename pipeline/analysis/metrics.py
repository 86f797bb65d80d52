"""Metrics stage: Table 1 of the paper as numbers, pure functions of a logged trajectory.

Every function takes arrays (or the trajectory table) and thresholds from
:class:`pipeline.config.MetricsConfig`; none of them runs a simulation. A *threat* is an obstacle
whose constant-velocity motion comes within both radii plus ``threat_margin_m`` of the straight
continuation of the vehicle's current motion before the run ends (``threat_horizon_s = None``;
the older reading looks a fixed number of seconds ahead), closed form, see
:func:`straight_line_time_to_contact`; an obstacle the vehicle collides with threatened by
definition. Definitions (also in the report's Methods section):

* **Reaction delay** (C1, s): from the appearance of the first obstacle that threatens the
  vehicle when it appears (``reaction_obstacle = threatening``; the older reading takes the first
  visible obstacle, harmless or not) until the applied steering angle first leaves a band of
  ``reaction_steering_band_rad`` around its value then, the crossing interpolated between samples
  (exact: the steering angle is piecewise linear under a held steering rate). NaN, with
  ``threatened = False``, when no obstacle threatens.
* **Smoothness** (C2): lateral acceleration ``a_y = vy_dot + vx r`` (``lateral_accel``; the older
  reading drops ``vy_dot``), lateral jerk ``d a_y / dt`` by central differences; RMS and max over
  the avoidance window (appearance of the threat to recovery, or run end) and over the whole run.
  Steering rate and curvature rate as secondaries.
* **Repulsion modulation** (C3, Table 2's two halves). C3a: the repulsive impulse
  ``sum |F_rep| Ts`` applied while no obstacle threatens and none is within ``near_field_m``
  (unneeded repulsion; force holding the vehicle off a near obstacle is needed), absolute and as
  a share of all repulsion (0 when none was applied); ``repulsion_need = threat`` counts only
  threats as need, ``clearance_band`` only clearance within ``threat_clearance_m``. C3b: time to
  contact at the onset of significant repulsion (``|F_rep| > repulsion_onset_force``) while an
  obstacle threatens (higher = earlier).
* **Goal-direction recovery** (C4, s): from the moment every obstacle that ever threatened is
  passed (the vehicle ahead of it by both radii for good; every obstacle when none threatened),
  the settling time of the lateral error (python-control ``step_info`` convention, absolute band
  ``recovery_lateral_band_m``); NaN with ``recovered = False`` when it does not settle.
* **Path stability** (C5): after the obstacle is passed, reversals of the lateral error's
  direction beyond a hysteresis of ``lateral_sign_band_m``, net of the manoeuvre itself (an apex
  of the detour after the pass is not counted): one out-and-back scores 0, an overshoot and
  return 1. The older reading counts sign changes of lateral error and yaw rate over the run.
  Overshoot past the line and the largest per-step heading change as secondaries.
* **Safety**: minimum clearance and collision from a continuous check (vehicle and obstacles
  interpolated linearly between log rows, closest approach in closed form), so a fast obstacle
  cannot pass through the vehicle between two rows; each collision is classified
  ``collision_avoidable`` by a reachability check from the state at the obstacle's appearance:
  steering targets across ``[-delta_max, delta_max]`` reached at the steering-rate limit, each
  with and without full braking, on the kinematic bicycle; avoidable when any of them keeps a
  non-negative clearance to every obstacle. Minimum time to collision.
* **Progress**: time to reach the goal line (NaN if not reached), path length (m).
* **Solver**: median and p95 of Clarabel's iteration count, fallback count, largest heading
  error against the model's validity bound, share of rollout steps where the step cap bound.
* **Model validity** (:class:`ModelValidity`): does the MPC's model hold where it is used? The
  loop logs, per step, the largest heading error of the plant against that step's frame over
  the next second, the tyres' normalized slip, whether the reference path was clipped at the
  curvature limit, and the model's and the plan's position error 0.5 s and 1 s ahead
  (:func:`pipeline.loop.controller.path.prediction_check`); the run's shares and quantiles.
  The run leaves the model's validity (``heading_validity_exceeded``) when that heading error
  exceeds ``model.validity_heading_rad`` (the heading to the line for a scored trajectory).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
import pandas as pd

from pipeline.analysis.settings import MetricsConfig
from pipeline.loop.trajectory import obstacle_indices


@dataclass(frozen=True)
class TrajectoryContext:
    """What the metrics need besides the table: geometry and limits of the run (SI units).

    The limits feed the collision attribution (defaults: the compact car of ``conf/vehicle``).
    """

    start_m: tuple[float, float]
    goal_m: tuple[float, float]
    vehicle_radius_m: float
    validity_heading_rad: float = math.inf
    tyre_linear_limit: float = math.inf
    wheelbase_m: float = 2.5
    steering_max_rad: float = 0.4
    steering_rate_max_rad_s: float = 1.0
    braking_mps2: float = 3.0


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
    # imported here: python-control costs a second to import, and readers of run folders (the
    # report, verify, aggregate) never settle a signal themselves
    import control

    info = control.step_info(mirrored, t, final_output=e0, SettlingTimeThreshold=band / abs(e0))
    return float(info["SettlingTime"])


def obstacle_count(trajectory: pd.DataFrame) -> int:
    """How many obstacles the table carries (their indices may have gaps)."""
    return len(obstacle_indices(trajectory.columns))


def float_columns(frame: pd.DataFrame, *names: str) -> np.ndarray:
    """Columns ``names`` of ``frame`` side by side as floats, shape (rows, len(names)); the
    same values as ``frame[list(names)].to_numpy(float)`` without pandas' multi-column
    selection (an index lookup and a copy of a block, ten times the cost)."""
    return np.column_stack([frame[name].to_numpy(float) for name in names])


def clearance_series(trajectory: pd.DataFrame, vehicle_radius_m: float) -> np.ndarray:
    """Per-step clearance to the nearest visible obstacle (NaN while none is visible)."""
    xy = float_columns(trajectory, "X_m", "Y_m")
    result = np.full(len(trajectory), np.inf)
    for j in obstacle_indices(trajectory.columns):
        centre = float_columns(trajectory, f"obs{j}_x_m", f"obs{j}_y_m")
        gap = (np.linalg.norm(xy - centre, axis=1) - trajectory[f"obs{j}_radius_m"].to_numpy(float)
               - vehicle_radius_m)
        visible = trajectory[f"obs{j}_visible"].to_numpy(bool)
        result = np.where(visible, np.minimum(result, gap), result)
    return np.where(np.isfinite(result), result, np.nan)


def min_time_to_collision(trajectory: pd.DataFrame, vehicle_radius_m: float) -> float:
    """Smallest ``clearance / closing speed`` over steps and visible obstacles while closing."""
    t = trajectory["time_s"].to_numpy(float)
    xy = float_columns(trajectory, "X_m", "Y_m")
    best = np.inf
    for j in obstacle_indices(trajectory.columns):
        centre = float_columns(trajectory, f"obs{j}_x_m", f"obs{j}_y_m")
        dist = np.linalg.norm(xy - centre, axis=1)
        closing = -time_derivative(dist, t)
        gap = np.maximum(dist - trajectory[f"obs{j}_radius_m"].to_numpy(float) - vehicle_radius_m,
                         0.0)
        visible = trajectory[f"obs{j}_visible"].to_numpy(bool)
        ok = visible & (closing > 1e-6)
        if np.any(ok):
            best = min(best, float(np.min(gap[ok] / closing[ok])))
    return float(best) if np.isfinite(best) else float("nan")


def band_exit_time(time_s: np.ndarray, values: np.ndarray, start_time_s: float, band: float,
                   interpolate: bool = True) -> float:
    """Time from ``start_time_s`` until ``|values - values(start)|`` first exceeds ``band``.

    With ``interpolate`` the crossing is placed by linear interpolation between the last sample
    inside the band and the first outside (exact for a piecewise-linear signal); otherwise at the
    first sample outside. NaN if the band is never left.
    """
    t = np.asarray(time_s, dtype=float)
    v = np.asarray(values, dtype=float)
    after = np.nonzero(t >= start_time_s - 1e-9)[0]
    if after.size == 0:
        return float("nan")
    deviation = np.abs(v[after] - v[after[0]])
    exits = np.nonzero(deviation > band)[0]
    if exits.size == 0:
        return float("nan")
    i = exits[0]
    if not interpolate or i == 0:
        return float(t[after[i]] - start_time_s)
    d0, d1 = deviation[i - 1], deviation[i]
    t0, t1 = t[after[i - 1]], t[after[i]]
    return float(t0 + (band - d0) / (d1 - d0) * (t1 - t0) - start_time_s)


def straight_line_time_to_contact(p: np.ndarray, v: np.ndarray, o: np.ndarray, ov: np.ndarray,
                                  reach_m: np.ndarray, horizon_s) -> np.ndarray:
    """First time in ``[0, horizon_s]`` at which ``|(o + ov t) - (p + v t)| <= reach`` (inf if
    none): the vehicle continuing straight at its current velocity, the obstacle at constant
    velocity. Closed form (a quadratic in t); arrays broadcast over rows (``horizon_s`` too: a
    per-row horizon such as the time left in the run).
    """
    r0 = np.asarray(o, float) - np.asarray(p, float)
    dv = np.asarray(ov, float) - np.asarray(v, float)
    a = np.sum(dv * dv, axis=-1)
    b = 2.0 * np.sum(r0 * dv, axis=-1)
    c = np.sum(r0 * r0, axis=-1) - np.asarray(reach_m, float) ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        disc = b * b - 4.0 * a * c
        first = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a)
    hit = (disc >= 0.0) & (a > 1e-12) & (first >= 0.0) & (first <= horizon_s)
    return np.where(c <= 0.0, 0.0, np.where(hit, first, np.inf))


def reversal_count(values: np.ndarray, band: float) -> tuple[int, int]:
    """Direction reversals of a signal with a hysteresis of ``band``, and the first direction.

    The direction is set by the first move of more than ``band`` from the start; a reversal is
    counted each time the signal retreats from its running extreme by more than ``band``.

    Returns
    -------
    count : int
    first_direction : int
        +1, -1, or 0 when the signal never moved by more than ``band``.
    """
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size < 2:
        return 0, 0
    start = extreme = float(v[0])
    direction = first = count = 0
    for x in v[1:].tolist():
        if direction == 0:
            if x - start > band or start - x > band:
                direction = first = 1 if x > start else -1
                extreme = x
        elif direction == 1:
            if x > extreme:
                extreme = x
            elif extreme - x > band:
                count, direction, extreme = count + 1, -1, x
        else:
            if x < extreme:
                extreme = x
            elif x - extreme > band:
                count, direction, extreme = count + 1, 1, x
    return count, first


@dataclass(frozen=True)
class ObstacleTrack:
    """One obstacle as logged: positions (n, 2), forward-difference velocities (n, 2), radii
    (n,), visibility (n,) and the first visible row (-1 if never visible)."""

    position: np.ndarray
    velocity: np.ndarray
    radius: np.ndarray
    visible: np.ndarray
    appear: int


def obstacle_tracks(trajectory: pd.DataFrame) -> list[ObstacleTrack]:
    """Every obstacle of the table as an :class:`ObstacleTrack`."""
    t = trajectory["time_s"].to_numpy(float)
    tracks = []
    for j in obstacle_indices(trajectory.columns):
        pos = float_columns(trajectory, f"obs{j}_x_m", f"obs{j}_y_m")
        vel = np.zeros_like(pos)
        if len(t) > 1:
            vel[:-1] = np.diff(pos, axis=0) / np.diff(t)[:, None]
            vel[-1] = vel[-2]
        visible = trajectory[f"obs{j}_visible"].to_numpy(bool)
        tracks.append(ObstacleTrack(pos, vel, trajectory[f"obs{j}_radius_m"].to_numpy(float),
                                    visible, int(np.argmax(visible)) if visible.any() else -1))
    return tracks


def continuous_clearance(time_s: np.ndarray, xy: np.ndarray, tracks: list[ObstacleTrack],
                         vehicle_radius_m: float) -> tuple[float, int, float]:
    """Smallest clearance with vehicle and obstacles moving linearly between log rows.

    Over each interval where the obstacle is visible at both ends the closest approach of the
    relative position is found in closed form; single visible rows count as well.

    Returns
    -------
    min_clearance_m : float
        NaN when no obstacle is ever visible.
    contact_obstacle : int
        Index of the obstacle of the first contact (clearance < 0), -1 if none.
    contact_time_s : float
        Time of that first contact (the interval's closest approach), NaN if none.
    """
    best, contact_j, contact_t = np.inf, -1, np.inf
    for j, track in enumerate(tracks):
        rel = xy - track.position
        vis = track.visible
        reach = track.radius + vehicle_radius_m
        gaps = np.where(vis, np.linalg.norm(rel, axis=1) - reach, np.inf)
        times = np.asarray(time_s, float).copy()
        if len(rel) > 1:
            p0, d = rel[:-1], np.diff(rel, axis=0)
            dd = np.sum(d * d, axis=1)
            with np.errstate(invalid="ignore", divide="ignore"):
                s = np.clip(np.where(dd > 0, -np.sum(p0 * d, axis=1) / dd, 0.0), 0.0, 1.0)
            closest = np.linalg.norm(p0 + s[:, None] * d, axis=1) - reach[1:]
            both = vis[:-1] & vis[1:]
            interval_gaps = np.where(both, closest, np.inf)
            interval_times = time_s[:-1] + s * np.diff(time_s)
            gaps = np.concatenate([gaps, interval_gaps])
            times = np.concatenate([times, interval_times])
        if np.isfinite(gaps).any():
            best = min(best, float(np.min(gaps)))
            touching = np.nonzero(gaps < 0.0)[0]
            if touching.size:
                first = float(np.min(times[touching]))
                if first < contact_t:
                    contact_j, contact_t = j, first
    return (float(best) if np.isfinite(best) else float("nan"), contact_j,
            float(contact_t) if np.isfinite(contact_t) else float("nan"))


def collision_is_avoidable(time_s: np.ndarray, pose: np.ndarray, tracks: list[ObstacleTrack],
                           contact_obstacle: int, contact_time_s: float,
                           context: TrajectoryContext, thresholds: MetricsConfig) -> bool:
    """Whether any admissible manoeuvre from the state at the colliding obstacle's appearance
    keeps a non-negative clearance to every obstacle (a sampled reachability check).

    Manoeuvres: steering targets ``linspace(-delta_max, delta_max, attribution_steering_samples)``
    reached at the steering-rate limit and held, each at constant speed and under full braking
    (``context.braking_mps2``, down to standstill), integrated on the kinematic bicycle
    (``context.wheelbase_m``) in steps of 0.02 s from the appearance until the contact time plus
    ``attribution_extra_s``. Obstacles follow their logged tracks (extrapolated at their last
    velocity), each from its own appearance on.

    Parameters
    ----------
    time_s : ndarray, shape (n,)
    pose : ndarray, shape (n, 5)
        ``X, Y, psi, speed, delta`` per log row (delta NaN when unknown: taken as 0).
    """
    t = np.asarray(time_s, float)
    track = tracks[contact_obstacle]
    a = track.appear
    if a < 0:
        return True
    x0, y0, psi0, v0, delta0 = (float(v) for v in pose[a])
    delta0 = delta0 if np.isfinite(delta0) else 0.0
    if not all(np.isfinite([x0, y0, psi0, v0])):
        return False
    dt = 0.02
    end = contact_time_s + thresholds.attribution_extra_s
    steps = max(int(np.ceil((end - t[a]) / dt)), 1)
    targets = np.linspace(-context.steering_max_rad, context.steering_max_rad,
                          thresholds.attribution_steering_samples)
    brake = np.array([0.0, context.braking_mps2])
    target, decel = (g.ravel() for g in np.meshgrid(targets, brake))
    X, Y = np.full(target.size, x0), np.full(target.size, y0)
    psi, v, delta = np.full(target.size, psi0), np.full(target.size, v0), \
        np.full(target.size, delta0)
    ok = np.ones(target.size, dtype=bool)
    rate = context.steering_rate_max_rad_s * dt
    for k in range(1, steps + 1):
        delta = delta + np.clip(target - delta, -rate, rate)
        X = X + dt * v * np.cos(psi)
        Y = Y + dt * v * np.sin(psi)
        psi = psi + dt * v * np.tan(delta) / context.wheelbase_m
        v = np.maximum(v - decel * dt, 0.0)
        now = t[a] + k * dt
        for other in tracks:
            if other.appear < 0 or now < t[other.appear] - 1e-9:
                continue
            i = min(int(np.searchsorted(t, now, side="right")) - 1, len(t) - 1)
            centre = other.position[i] + other.velocity[i] * (now - t[i])
            reach = other.radius[i] + context.vehicle_radius_m
            ok &= np.hypot(X - centre[0], Y - centre[1]) >= reach
        if not ok.any():
            return False
    return bool(ok.any())


# --- result objects: one block per Table 1 criterion ------------------------------------------

class _Block:
    """A frozen block of metrics; its fields are the ``metrics.json`` keys it owns."""

    def to_json(self) -> dict:
        """The block's keys and values, NaN as ``None`` and numpy scalars as Python ones."""
        return {f.name: _nan_to_none(getattr(self, f.name)) for f in fields(self)}

    @classmethod
    def from_json(cls, data: dict):
        """The block read back from ``metrics.json`` (``None`` for its keys when absent)."""
        return cls(**{f.name: _none_to_nan(data.get(f.name)) for f in fields(cls)})

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))


@dataclass(frozen=True)
class Threat(_Block):
    """Which obstacle threatened and when (s); when every threat was passed (s)."""

    threatened: bool
    obstacle_appear_time_s: float
    threat_appear_time_s: float
    obstacle_passed_time_s: float


@dataclass(frozen=True)
class Reaction(_Block):
    """C1: reaction delays (s) from the threat's (or the first visible obstacle's) appearance."""

    reaction_delay_threat_s: float
    reaction_delay_first_visible_s: float
    reaction_delay_s: float
    reacted: bool
    reaction_delay_lateral_s: float


@dataclass(frozen=True)
class Smoothness(_Block):
    """C2: steering rate (rad/s), lateral acceleration (m/s^2), jerk (m/s^3), curvature rate."""

    steering_rate_rms_rad_s: float
    steering_rate_max_rad_s: float
    steering_rate_rms_window_rad_s: float
    lateral_accel_max_mps2: float
    lateral_jerk_rms_run_mps3: float
    lateral_jerk_max_mps3: float
    lateral_jerk_rms_window_mps3: float
    lateral_jerk_max_window_mps3: float
    lateral_jerk_rms_vx_r_mps3: float
    lateral_jerk_rms_mps3: float
    curvature_rate_rms_1_per_ms: float


@dataclass(frozen=True)
class Repulsion(_Block):
    """C3a: repulsive impulse at the vehicle (force x s) and its unneeded share; C3b: onset."""

    repulsive_impulse: float
    repulsion_unneeded_impulse: float
    repulsion_unneeded_share: float
    repulsion_unneeded_share_threat: float
    repulsive_impulse_far_share: float
    repulsive_force_peak: float
    repulsion_onset_clearance_m: float
    repulsion_onset_ttc_s: float


@dataclass(frozen=True)
class StepCap(_Block):
    """Share of rollout steps on which the APF's step cap bound."""

    step_cap_binding_share: float


@dataclass(frozen=True)
class Recovery(_Block):
    """C4: settling times (s) after every threat is passed."""

    recovery_lateral_s: float
    recovery_heading_s: float
    recovery_time_s: float
    recovered: bool


@dataclass(frozen=True)
class Stability(_Block):
    """C5: reversals and sign changes (counts), overshoot (m), largest heading step (rad)."""

    lateral_sign_changes: int
    yaw_rate_sign_changes: int
    oscillation_whole_run_count: int
    oscillation_after_pass_count: float
    yaw_rate_sign_changes_after_pass: float
    overshoot_m: float
    oscillation_count: float
    heading_step_max_rad: float
    max_lateral_deviation_m: float


@dataclass(frozen=True)
class Safety(_Block):
    """Clearance (m, sampled and continuous), collision and its attribution, time to collision."""

    min_clearance_sampled_m: float
    min_clearance_continuous_m: float
    min_clearance_m: float
    collision: bool
    collision_avoidable: bool | None
    min_time_to_collision_s: float


@dataclass(frozen=True)
class Progress(_Block):
    """Log length, goal reached and when (s), path length (m), heading against validity."""

    n_steps_logged: int
    duration_s: float
    goal_reached: bool
    time_to_goal_s: float
    path_length_m: float
    max_abs_heading_error_rad: float
    heading_validity_exceeded: bool


@dataclass(frozen=True)
class ModelValidity(_Block):
    """Does the MPC's model hold where it is used? Shares of the run's steps (0-1) whose
    prediction left the small-angle bound over the next second, with a tyre beyond its linear
    range, whose reference path was clipped at the curvature limit; the model's prediction
    error (replayed with the applied inputs) and the plan's, 0.5 s and 1 s ahead (m,
    median and 95th percentile over the run's steps). NaN where the run logged no such
    column (a scored trajectory, pure pursuit)."""

    model_heading_error_max_rad: float
    share_steps_beyond_bound: float
    share_steps_tyre_nonlinear: float
    share_steps_path_clipped: float
    prediction_error_05s_p50_m: float
    prediction_error_05s_p95_m: float
    prediction_error_1s_p50_m: float
    prediction_error_1s_p95_m: float
    plan_error_1s_p50_m: float
    plan_error_1s_p95_m: float


@dataclass(frozen=True)
class SolverIterations(_Block):
    """Median and 95th percentile of the QP solver's iteration count."""

    solver_iterations_median: float
    solver_iterations_p95: float


@dataclass(frozen=True)
class Fallbacks(_Block):
    """Steps on which the controller fell back (shifted plan or safe input)."""

    fallback_count: int
    fallback_safe_input_count: int


@dataclass(frozen=True)
class RunMetrics:
    """Every Table 1 metric of one run, one block per criterion (python-control style).

    Blocks that need a column the trajectory lacks (APF forces, solver columns) are ``None``
    and their keys are absent from :meth:`to_json`.
    """

    threat: Threat
    reaction: Reaction
    smoothness: Smoothness
    recovery: Recovery
    stability: Stability
    safety: Safety
    progress: Progress
    repulsion: Repulsion | None = None
    step_cap: StepCap | None = None
    iterations: SolverIterations | None = None
    fallbacks: Fallbacks | None = None
    validity: ModelValidity | None = None

    def blocks(self) -> tuple[_Block, ...]:
        """The blocks present, in Table 1 order."""
        return tuple(b for b in (self.threat, self.reaction, self.smoothness, self.repulsion,
                                 self.step_cap, self.recovery, self.stability, self.safety,
                                 self.progress, self.iterations, self.fallbacks,
                                 self.validity)
                     if b is not None)

    def to_json(self) -> dict:
        """Flat mapping of metric name to value (``metrics.json``); NaN as ``None``."""
        out: dict = {}
        for block in self.blocks():
            out.update(block.to_json())
        return out

    def value(self, name: str) -> float:
        """One metric by its name as a float (booleans as 0/1; NaN when missing or absent)."""
        for block in self.blocks():
            if name in block.keys():
                v = getattr(block, name)
                return float(v) if v is not None else math.nan
        return math.nan

    @classmethod
    def from_json(cls, data: dict) -> "RunMetrics":
        """Read back what :meth:`to_json` wrote (keys of other records are ignored)."""
        def optional(block):
            return block.from_json(data) if any(k in data for k in block.keys()) else None

        return cls(Threat.from_json(data), Reaction.from_json(data),
                   Smoothness.from_json(data), Recovery.from_json(data),
                   Stability.from_json(data), Safety.from_json(data), Progress.from_json(data),
                   optional(Repulsion), optional(StepCap), optional(SolverIterations),
                   optional(Fallbacks), optional(ModelValidity))


#: Every key :meth:`RunMetrics.to_json` can write.
METRIC_KEYS: tuple[str, ...] = tuple(k for block in (
    Threat, Reaction, Smoothness, Repulsion, StepCap, Recovery, Stability, Safety, Progress,
    SolverIterations, Fallbacks, ModelValidity) for k in block.keys())


def _none_to_nan(value):
    return math.nan if value is None else value


# --- the computation: one short function per criterion -----------------------------------------

@dataclass(frozen=True)
class Signals:
    """The trajectory's signals in the goal-line frame; optional columns derived from the path
    when a scored trajectory lacks them (``vy`` is None then)."""

    t: np.ndarray
    dt: float
    start: np.ndarray
    goal: np.ndarray
    line: np.ndarray
    xy: np.ndarray
    along: np.ndarray
    lateral: np.ndarray
    psi: np.ndarray
    velocity: np.ndarray
    speed: np.ndarray
    vx: np.ndarray
    vy: np.ndarray | None
    yaw_rate: np.ndarray
    delta: np.ndarray
    steer_rate: np.ndarray
    heading_error: np.ndarray
    bearing_error: np.ndarray
    model_heading_error: np.ndarray | None = None


def trajectory_signals(tr: pd.DataFrame, context: TrajectoryContext) -> Signals:
    """The signals every criterion reads, from the table's columns (or the path)."""
    t = tr["time_s"].to_numpy(float)
    dt = float(np.median(np.diff(t))) if t.size > 1 else float("nan")
    start, goal = np.asarray(context.start_m, float), np.asarray(context.goal_m, float)
    line = (goal - start) / np.linalg.norm(goal - start)
    normal = np.array([-line[1], line[0]])
    xy = float_columns(tr, "X_m", "Y_m")
    if "psi_rad" in tr:
        psi = tr["psi_rad"].to_numpy(float)
    else:
        psi = np.unwrap(np.arctan2(time_derivative(xy[:, 1], t), time_derivative(xy[:, 0], t)))
    if "vx_mps" in tr:
        vx = tr["vx_mps"].to_numpy(float)
        vy = tr["vy_mps"].to_numpy(float) if "vy_mps" in tr else np.zeros(len(tr))
        speed = np.hypot(vx, vy)
        velocity = np.column_stack([vx * np.cos(psi) - vy * np.sin(psi),
                                    vx * np.sin(psi) + vy * np.cos(psi)])
    else:
        velocity = np.column_stack([time_derivative(xy[:, 0], t), time_derivative(xy[:, 1], t)])
        speed = np.hypot(velocity[:, 0], velocity[:, 1])
        vx, vy = speed, None
    yaw_rate = tr["r_rad_s"].to_numpy(float) if "r_rad_s" in tr \
        else time_derivative(np.unwrap(psi), t)
    delta = tr["delta_rad"].to_numpy(float) if "delta_rad" in tr else np.full(len(tr), np.nan)
    steer_rate = tr["steering_rate_rad_s"].to_numpy(float) if "steering_rate_rad_s" in tr \
        else time_derivative(delta, t)
    line_heading = np.arctan2(line[1], line[0])
    heading_error = np.arctan2(np.sin(psi - line_heading), np.cos(psi - line_heading))
    to_goal = goal - xy
    bearing = np.arctan2(to_goal[:, 1], to_goal[:, 0])
    bearing_error = np.arctan2(np.sin(psi - bearing), np.cos(psi - bearing))
    model_heading = tr["model_heading_error_rad"].to_numpy(float) \
        if "model_heading_error_rad" in tr else None
    return Signals(t, dt, start, goal, line, xy, (xy - start) @ line, (xy - start) @ normal, psi,
                   velocity, speed, vx, vy, yaw_rate, delta, steer_rate, heading_error,
                   bearing_error, model_heading)


@dataclass(frozen=True)
class ThreatGeometry:
    """What the threat analysis found, for the other criteria: per-row time to contact with
    each obstacle (inf: no threat), appearance times, and the obstacles that matter."""

    ttc: np.ndarray
    threat_now: np.ndarray
    appear: list[float]
    first_visible: int | None
    threatening: int | None
    passed_time_s: float


def threat_horizon(sig: Signals, thresholds: MetricsConfig):
    """How far ahead the straight continuation is checked: until the run ends (per row), or a
    fixed ``threat_horizon_s`` (the older reading)."""
    if thresholds.threat_horizon_s is None:
        return np.maximum(sig.t[-1] - sig.t, 0.0) if sig.t.size else 0.0
    return thresholds.threat_horizon_s


def threat_block(sig: Signals, tracks: list[ObstacleTrack], context: TrajectoryContext,
                 thresholds: MetricsConfig, colliding: int | None = None
                 ) -> tuple[Threat, ThreatGeometry]:
    """Threats: the straight continuation of the current motion against each visible obstacle
    (:func:`threat_horizon`); an obstacle the vehicle collides with (``colliding``) threatened
    by definition, so a collision never comes with "nothing threatened". The obstacle is passed
    when the vehicle is ahead of every obstacle that ever threatened (every visible one when
    none did) by both radii, for good."""
    t, n = sig.t, len(sig.t)
    horizon = threat_horizon(sig, thresholds)
    ttc = np.full((n, len(tracks)), np.inf)
    for j, track in enumerate(tracks):
        reach = track.radius + context.vehicle_radius_m + thresholds.threat_margin_m
        ttc[:, j] = np.where(track.visible, straight_line_time_to_contact(
            sig.xy, sig.velocity, track.position, track.velocity, reach, horizon), np.inf)
    threat_now = np.isfinite(ttc)
    appear = [t[track.appear] if track.appear >= 0 else np.inf for track in tracks]
    at_appearance = [bool(track.appear >= 0 and threat_now[track.appear, j])
                     for j, track in enumerate(tracks)]
    order = sorted(range(len(tracks)), key=lambda j: (appear[j], j))
    first_visible = next((j for j in order if np.isfinite(appear[j])), None)
    threatening = next((j for j in order if at_appearance[j]), None)
    if threatening is None and colliding is not None and np.isfinite(appear[colliding]):
        threatening = colliding
    ever = [j for j in range(len(tracks)) if threat_now[:, j].any() or j == threatening] or \
        [j for j in range(len(tracks)) if np.isfinite(appear[j])]
    passed_time = float("nan")
    if ever:
        behind = np.ones(n, dtype=bool)
        for j in ever:
            ox = (tracks[j].position - sig.start) @ sig.line
            reach = tracks[j].radius + context.vehicle_radius_m
            behind &= (~tracks[j].visible & (t < appear[j])) | (sig.along - ox > reach)
        first_appear = min(appear[j] for j in ever)
        not_behind = np.nonzero(~behind & (t >= first_appear))[0]
        if not_behind.size and not_behind[-1] + 1 < n:
            passed_time = float(t[not_behind[-1] + 1])
        elif not_behind.size == 0:
            passed_time = first_appear
    block = Threat(threatened=threatening is not None,
                   obstacle_appear_time_s=appear[first_visible] if first_visible is not None
                   else float("nan"),
                   threat_appear_time_s=appear[threatening] if threatening is not None
                   else float("nan"),
                   obstacle_passed_time_s=passed_time)
    return block, ThreatGeometry(ttc, threat_now, appear, first_visible, threatening,
                                 passed_time)


def reaction_block(sig: Signals, geo: ThreatGeometry, thresholds: MetricsConfig) -> Reaction:
    """C1: when the steering angle first leaves its band after the obstacle's appearance."""
    interpolate = thresholds.reaction_interpolation == "linear"
    has_delta = bool(np.any(np.isfinite(sig.delta)))

    def delay(j):
        if j is None or not has_delta:
            return float("nan")
        return band_exit_time(sig.t, sig.delta, geo.appear[j],
                              thresholds.reaction_steering_band_rad, interpolate)

    threat, first = delay(geo.threatening), delay(geo.first_visible)
    chosen = geo.threatening if thresholds.reaction_obstacle == "threatening" \
        else geo.first_visible
    value = threat if chosen is geo.threatening else first
    lateral = band_exit_time(sig.t, sig.lateral, geo.appear[chosen],
                             thresholds.reaction_lateral_band_m, interpolate) \
        if chosen is not None else float("nan")
    return Reaction(threat, first, value, bool(np.isfinite(value)), lateral)


def _after_pass(sig: Signals, geo: ThreatGeometry) -> np.ndarray:
    """Rows from the moment every threat is passed on (none when it never is)."""
    if not np.isfinite(geo.passed_time_s):
        return np.zeros(len(sig.t), dtype=bool)
    return sig.t >= geo.passed_time_s - 1e-9


def recovery_block(sig: Signals, geo: ThreatGeometry, thresholds: MetricsConfig) -> Recovery:
    """C4: settling of the lateral error (and of the heading to the goal) after the pass."""
    if not np.isfinite(geo.passed_time_s):
        return Recovery(float("nan"), float("nan"), float("nan"), False)
    after = _after_pass(sig, geo)
    lateral = settling_time(sig.t[after], sig.lateral[after], thresholds.recovery_lateral_band_m)
    # the bearing to the goal turns fast right before the goal: judge heading until
    # recovery_heading_stop_m before the goal line
    goal_along = float((sig.goal - sig.start) @ sig.line)
    window = after & (sig.along <= goal_along - thresholds.recovery_heading_stop_m)
    heading = settling_time(sig.t[window], sig.bearing_error[window],
                            thresholds.recovery_heading_band_rad) \
        if np.count_nonzero(window) > 1 else float("nan")
    chosen = heading if thresholds.recovery_reading == "heading" else lateral
    return Recovery(lateral, heading, chosen, bool(np.isfinite(chosen)))


def smoothness_block(sig: Signals, threat: Threat, geo: ThreatGeometry, recovery: Recovery,
                     thresholds: MetricsConfig) -> Smoothness:
    """C2: a_y = vy_dot + vx r (or v r), its jerk, over the avoidance window and the run."""
    t = sig.t
    lat_acc_old = sig.speed * sig.yaw_rate
    lat_acc = time_derivative(sig.vy, t) + sig.vx * sig.yaw_rate if sig.vy is not None \
        else lat_acc_old
    if thresholds.lateral_accel == "vx_r":
        lat_acc = lat_acc_old
    jerk = time_derivative(lat_acc, t)
    start = threat.threat_appear_time_s if geo.threatening is not None \
        else threat.obstacle_appear_time_s
    end = geo.passed_time_s + recovery.recovery_time_s if recovery.recovered else t[-1]
    window = (t >= start - 1e-9) & (t <= end + 1e-9) if np.isfinite(start) \
        else np.zeros(len(t), dtype=bool)
    curvature = sig.yaw_rate / np.maximum(sig.speed, 1e-3)
    jerk_window, jerk_run = rms(jerk[window]), rms(jerk)
    return Smoothness(
        steering_rate_rms_rad_s=rms(sig.steer_rate), steering_rate_max_rad_s=max_abs(sig.steer_rate),
        steering_rate_rms_window_rad_s=rms(sig.steer_rate[window]),
        lateral_accel_max_mps2=max_abs(lat_acc), lateral_jerk_rms_run_mps3=jerk_run,
        lateral_jerk_max_mps3=max_abs(jerk), lateral_jerk_rms_window_mps3=jerk_window,
        lateral_jerk_max_window_mps3=max_abs(jerk[window]),
        lateral_jerk_rms_vx_r_mps3=rms(time_derivative(lat_acc_old, t)),
        lateral_jerk_rms_mps3=jerk_window if thresholds.smoothness_window == "avoidance"
        else jerk_run,
        curvature_rate_rms_1_per_ms=rms(time_derivative(curvature, t)))


def repulsion_block(tr: pd.DataFrame, sig: Signals, geo: ThreatGeometry, clearance: np.ndarray,
                    thresholds: MetricsConfig) -> Repulsion | None:
    """C3a: repulsive impulse applied while nothing threatens or is near (``repulsion_need``);
    C3b: time to contact at the onset of significant repulsion. None without APF force
    columns."""
    if "apf_rep_norm" not in tr:
        return None
    rep = np.nan_to_num(tr["apf_rep_norm"].to_numpy(float))
    impulse = float(np.sum(rep) * sig.dt)
    needed_threat = geo.threat_now.any(axis=1)
    near = np.nan_to_num(clearance, nan=np.inf) <= thresholds.near_field_m
    needed_band = np.nan_to_num(clearance, nan=np.inf) <= thresholds.threat_clearance_m
    needed = {"threat_or_near": needed_threat | near, "threat": needed_threat,
              "clearance_band": needed_band}[thresholds.repulsion_need]
    unneeded = float(np.sum(rep[~needed]) * sig.dt)

    def share(mask):  # no repulsion at all means no unnecessary repulsion either: 0
        return float(np.sum(rep[mask]) * sig.dt / impulse) if impulse > 0 else 0.0

    on = np.nonzero(rep > 1e-9)[0]
    onset = np.nonzero(needed_threat & (rep > thresholds.repulsion_onset_force))[0]
    return Repulsion(
        repulsive_impulse=impulse, repulsion_unneeded_impulse=unneeded,
        repulsion_unneeded_share=unneeded / impulse if impulse > 0 else 0.0,
        repulsion_unneeded_share_threat=share(~needed_threat),
        repulsive_impulse_far_share=share(~needed_band),
        repulsive_force_peak=float(np.max(rep)) if rep.size else float("nan"),
        repulsion_onset_clearance_m=float(clearance[on[0]]) if on.size else float("nan"),
        repulsion_onset_ttc_s=float(np.min(geo.ttc[onset[0]])) if onset.size
        else float("nan"))


def stability_block(sig: Signals, threat: Threat, geo: ThreatGeometry,
                    thresholds: MetricsConfig) -> Stability:
    """C5: reversals after the pass net of the manoeuvre; sign changes over the run."""
    sign_lat = sign_changes(sig.lateral, thresholds.lateral_sign_band_m)
    sign_yaw = sign_changes(sig.yaw_rate, thresholds.yaw_rate_sign_band_rad_s)
    after_pass, yaw_after, overshoot = float("nan"), float("nan"), float("nan")
    if np.isfinite(geo.passed_time_s):
        after = _after_pass(sig, geo)
        lateral = sig.lateral[after]
        count, first = reversal_count(lateral, thresholds.lateral_sign_band_m)
        away = first != 0 and np.sign(lateral[0]) == first
        after_pass = max(count - (1 if away else 0), 0)
        yaw_after = sign_changes(sig.yaw_rate[after], thresholds.yaw_rate_sign_band_rad_s)
        before = (sig.t >= threat.obstacle_appear_time_s - 1e-9) & ~after
        side = np.sign(sig.lateral[before][np.argmax(np.abs(sig.lateral[before]))]) \
            if np.any(before) else 0.0
        overshoot = float(max(0.0, np.max(-side * lateral))) if side != 0 else 0.0
    dpsi = np.abs(np.diff(np.unwrap(sig.psi)))
    return Stability(
        lateral_sign_changes=sign_lat, yaw_rate_sign_changes=sign_yaw,
        oscillation_whole_run_count=sign_lat + sign_yaw,
        oscillation_after_pass_count=after_pass, yaw_rate_sign_changes_after_pass=yaw_after,
        overshoot_m=overshoot,
        oscillation_count=after_pass if thresholds.oscillation == "net_reversals_after_pass"
        else sign_lat + sign_yaw,
        heading_step_max_rad=float(np.max(dpsi)) if dpsi.size else float("nan"),
        max_lateral_deviation_m=max_abs(sig.lateral))


def safety_block(tr: pd.DataFrame, sig: Signals, tracks: list[ObstacleTrack],
                 clearance: np.ndarray, context: TrajectoryContext,
                 thresholds: MetricsConfig) -> tuple[Safety, int | None]:
    """Clearance from the continuous check (sampled as the older reading), collision and
    whether it was avoidable, minimum time to collision; and the obstacle collided with (None
    without a collision)."""
    sampled = float(np.nanmin(clearance)) if np.any(np.isfinite(clearance)) else float("nan")
    continuous, contact_j, contact_t = continuous_clearance(sig.t, sig.xy, tracks,
                                                           context.vehicle_radius_m)
    use_continuous = thresholds.collision_check == "continuous"
    chosen = continuous if use_continuous else sampled
    collision = bool(np.isfinite(chosen) and chosen < 0.0)
    if collision and not use_continuous:
        contact_j = int(np.argmin([np.nanmin(np.where(track.visible, np.linalg.norm(
            sig.xy - track.position, axis=1) - track.radius, np.inf)) for track in tracks]))
        contact_t = float(sig.t[np.nanargmin(clearance)])
    pose = np.column_stack([sig.xy, sig.psi, sig.speed, sig.delta])
    avoidable = collision_is_avoidable(sig.t, pose, tracks, contact_j, contact_t, context,
                                       thresholds) if collision and contact_j >= 0 else None
    return (Safety(sampled, continuous, chosen, collision, avoidable,
                   min_time_to_collision(tr, context.vehicle_radius_m)),
            contact_j if collision and contact_j >= 0 else None)


def progress_block(sig: Signals, context: TrajectoryContext,
                   thresholds: MetricsConfig) -> Progress:
    """Goal line reached (within the goal tolerance) and when; path length; heading error
    against the model's validity bound."""
    t = sig.t
    tolerance = thresholds.goal_tolerance_m if thresholds.goal_tolerance_m is not None else 0.5
    reached = np.nonzero(sig.along >= (sig.goal - sig.start) @ sig.line - tolerance)[0]
    heading = max_abs(sig.heading_error)
    # against the bound: the heading error the MPC's model is about (its own frame's, over
    # each prediction's second) where the run logged it, else the heading to the line
    judged = max_abs(sig.model_heading_error) if sig.model_heading_error is not None \
        else heading
    return Progress(
        n_steps_logged=int(len(t)), duration_s=float(t[-1] - t[0]) if t.size else 0.0,
        goal_reached=bool(reached.size),
        time_to_goal_s=float(t[reached[0]] - t[0]) if reached.size else float("nan"),
        path_length_m=float(np.sum(np.linalg.norm(np.diff(sig.xy, axis=0), axis=1))),
        max_abs_heading_error_rad=heading,
        heading_validity_exceeded=bool(judged > context.validity_heading_rad))


def _share(flags: np.ndarray, known: np.ndarray) -> float:
    """Share of ``flags`` among the rows where ``known`` (NaN when none is)."""
    return float(np.count_nonzero(flags & known) / np.count_nonzero(known)) \
        if np.count_nonzero(known) else float("nan")


def _quantiles(values: np.ndarray) -> tuple[float, float]:
    """Median and 95th percentile of the finite entries (NaN for none)."""
    v = values[np.isfinite(values)]
    if not v.size:
        return float("nan"), float("nan")
    p50, p95 = np.percentile(v, [50, 95])
    return float(p50), float(p95)


def validity_block(tr: pd.DataFrame, context: TrajectoryContext) -> ModelValidity | None:
    """:class:`ModelValidity` from the columns the loop logged (None without any of them)."""
    if "model_error_1s_m" not in tr and "tyre_slip_norm" not in tr:
        return None

    def column(name: str) -> np.ndarray:
        return tr[name].to_numpy(float) if name in tr else np.full(len(tr), np.nan)

    heading = column("model_heading_error_rad")
    tyre = column("tyre_slip_norm")
    stepped = tr["solver_status"].astype(str).to_numpy() != "end" if "solver_status" in tr \
        else np.ones(len(tr), bool)
    clipped = tr["path_clipped"].to_numpy() if "path_clipped" in tr else None
    model_05, model_1 = _quantiles(column("model_error_05s_m")), _quantiles(column(
        "model_error_1s_m"))
    plan_1 = _quantiles(column("plan_error_1s_m"))
    return ModelValidity(
        model_heading_error_max_rad=max_abs(heading),
        share_steps_beyond_bound=_share(heading > context.validity_heading_rad,
                                        np.isfinite(heading)),
        share_steps_tyre_nonlinear=_share(tyre > context.tyre_linear_limit, np.isfinite(tyre)),
        share_steps_path_clipped=_share(clipped.astype(bool), stepped)
        if clipped is not None else float("nan"),
        prediction_error_05s_p50_m=model_05[0], prediction_error_05s_p95_m=model_05[1],
        prediction_error_1s_p50_m=model_1[0], prediction_error_1s_p95_m=model_1[1],
        plan_error_1s_p50_m=plan_1[0], plan_error_1s_p95_m=plan_1[1])


def solver_blocks(tr: pd.DataFrame) -> tuple[SolverIterations | None, Fallbacks | None]:
    """Solver iterations and fallbacks (deterministic parts only; wall-clock times live in
    ``timing.json``); None without the columns."""
    iterations = fallbacks = None
    if "solver_iterations" in tr:
        it = tr["solver_iterations"].to_numpy(float)
        it = it[np.isfinite(it) & (it >= 0)]
        iterations = SolverIterations(
            float(np.median(it)) if it.size else float("nan"),
            float(np.percentile(it, 95)) if it.size else float("nan"))
    if "fallback" in tr:
        fb = tr["fallback"].astype(str)
        fallbacks = Fallbacks(int(fb.isin(["shifted_plan", "safe_input"]).sum()),
                              int((fb == "safe_input").sum()))
    return iterations, fallbacks


#: The :class:`MetricsConfig` fields each reading-dependent criterion reads, itself or through
#: the criteria it is computed from (threat from safety's collision; recovery, reaction,
#: stability and repulsion from the threat geometry; smoothness from recovery too): what
#: :func:`compute_metrics_readings` shares a criterion's result between readings on.
SAFETY_READS = ("collision_check", "attribution_steering_samples", "attribution_extra_s")
THREAT_READS = SAFETY_READS + ("threat_margin_m", "threat_horizon_s")
RECOVERY_READS = THREAT_READS + ("recovery_reading", "recovery_lateral_band_m",
                                 "recovery_heading_band_rad", "recovery_heading_stop_m")
REACTION_READS = THREAT_READS + ("reaction_obstacle", "reaction_interpolation",
                                 "reaction_steering_band_rad", "reaction_lateral_band_m")
SMOOTHNESS_READS = RECOVERY_READS + ("lateral_accel", "smoothness_window")
STABILITY_READS = THREAT_READS + ("oscillation", "lateral_sign_band_m",
                                  "yaw_rate_sign_band_rad_s")
REPULSION_READS = THREAT_READS + ("repulsion_need", "near_field_m", "repulsion_onset_force",
                                  "threat_clearance_m")
PROGRESS_READS = ("goal_tolerance_m",)


def compute_metrics(trajectory: pd.DataFrame, context: TrajectoryContext,
                    thresholds: MetricsConfig) -> RunMetrics:
    """All Table 1 metrics of one logged run.

    Parameters
    ----------
    trajectory : pandas.DataFrame
        The simulation log (or a scored external trajectory with the same columns).
    context : TrajectoryContext
    thresholds : MetricsConfig

    Returns
    -------
    RunMetrics
        One block per criterion; ``to_json()`` gives the flat ``metrics.json`` mapping.
    """
    return compute_metrics_readings(trajectory, context, [thresholds])[0]


def compute_metrics_readings(trajectory: pd.DataFrame, context: TrajectoryContext,
                             readings: list[MetricsConfig]) -> list[RunMetrics]:
    """:func:`compute_metrics` of one logged run under each metric reading in ``readings``,
    the same numbers, in one pass: the signals, obstacle tracks, clearances, step cap and
    solver counts are computed once, and each criterion once per distinct value of the fields
    it reads (``*_READS``), e.g. the safety check once per ``collision_check`` when readings
    differ only in thresholds elsewhere (the multiverse's re-scoring).

    Returns
    -------
    list of RunMetrics
        In the order of ``readings``.
    """
    sig = trajectory_signals(trajectory, context)
    tracks = obstacle_tracks(trajectory)
    clearance = clearance_series(trajectory, context.vehicle_radius_m)
    step_cap = StepCap(float(np.nanmean(trajectory["apf_step_cap_share"].to_numpy(float)))) \
        if "apf_step_cap_share" in trajectory else None
    iterations, fallbacks = solver_blocks(trajectory)
    validity = validity_block(trajectory, context)
    memo: dict[tuple, object] = {}

    def once(criterion: str, reads: tuple[str, ...], thresholds: MetricsConfig, build):
        key = (criterion,) + tuple(getattr(thresholds, name) for name in reads)
        if key not in memo:
            memo[key] = build()
        return memo[key]

    results = []
    for thresholds in readings:
        # each build is called at once, inside this iteration (the lambdas' names are current)
        safety, colliding = once("safety", SAFETY_READS, thresholds, lambda: safety_block(
            trajectory, sig, tracks, clearance, context, thresholds))
        threat, geo = once("threat", THREAT_READS, thresholds, lambda: threat_block(
            sig, tracks, context, thresholds, colliding))
        recovery = once("recovery", RECOVERY_READS, thresholds,
                        lambda: recovery_block(sig, geo, thresholds))
        results.append(RunMetrics(
            threat=threat,
            reaction=once("reaction", REACTION_READS, thresholds,
                          lambda: reaction_block(sig, geo, thresholds)),
            smoothness=once("smoothness", SMOOTHNESS_READS, thresholds,
                            lambda: smoothness_block(sig, threat, geo, recovery, thresholds)),
            recovery=recovery,
            stability=once("stability", STABILITY_READS, thresholds,
                           lambda: stability_block(sig, threat, geo, thresholds)),
            safety=safety,
            progress=once("progress", PROGRESS_READS, thresholds,
                          lambda: progress_block(sig, context, thresholds)),
            repulsion=once("repulsion", REPULSION_READS, thresholds,
                           lambda: repulsion_block(trajectory, sig, geo, clearance, thresholds)),
            step_cap=step_cap, iterations=iterations, fallbacks=fallbacks,
            validity=validity))
    return results
