"""The computation: one short function per Table 1 criterion (``*_block``), and
:func:`compute_metrics` / :func:`compute_metrics_readings` over them; ``*_READS`` name the
settings each criterion reads. Definitions: :mod:`pipeline.analysis.metrics`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial
from typing import Any

import numpy as np

from pipeline.analysis.metrics.geometry import (
    ObstacleTrack,
    clearance_series,
    collision_is_avoidable,
    continuous_clearance,
    ego_disc_view,
    min_time_to_collision,
    obstacle_tracks,
    straight_line_time_to_contact,
)
from pipeline.analysis.metrics.results import (
    Crowd,
    Fallbacks,
    LateralJerk,
    ModelValidity,
    Progress,
    Reaction,
    Recovery,
    Repulsion,
    RunMetrics,
    Safety,
    Smoothness,
    SolverIterations,
    Stability,
    StepCap,
    Threat,
)
from pipeline.analysis.metrics.signals import (
    Signals,
    TrajectoryContext,
    band_exit_time,
    max_abs,
    reversal_count,
    rms,
    settling_time,
    sign_changes,
    time_derivative,
    trajectory_signals,
    window_mask,
)
from pipeline.analysis.settings import MetricsConfig
from pipeline.loop.trajectory import TrajectoryLike


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


def threat_horizon(sig: Signals, thresholds: MetricsConfig) -> float | np.ndarray:
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
    none did) by both radii, for good; with ``pass_reading = "last_threat"`` (among walkers, who
    may walk ahead of the vehicle for the whole run) from the first row after which no obstacle
    threatens any more (the first appearance when none ever did)."""
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
    if thresholds.pass_reading == "last_threat":
        passed_time = _last_threat_passed(t, threat_now, appear, colliding)
    elif ever:
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


def _last_threat_passed(t: np.ndarray, threat_now: np.ndarray, appear: list[float],
                        colliding: int | None) -> float:
    """``pass_reading = "last_threat"``: the time of the first row after the last one on which
    any obstacle threatened (NaN when one threatens on the last row); the first obstacle's
    appearance when none ever threatened (NaN when none appeared). The obstacle a run collided
    with (``colliding``) threatens until the run's end: never passed (NaN)."""
    if colliding is not None:
        return float("nan")
    rows = np.nonzero(threat_now.any(axis=1))[0] if threat_now.size else np.zeros(0, int)
    if rows.size == 0:
        first = min(appear, default=np.inf)
        return float(first) if np.isfinite(first) else float("nan")
    return float(t[rows[-1] + 1]) if rows[-1] + 1 < len(t) else float("nan")


def reaction_block(sig: Signals, geo: ThreatGeometry, thresholds: MetricsConfig) -> Reaction:
    """C1: when the steering angle first leaves its band after the obstacle's appearance."""
    interpolate = thresholds.reaction_interpolation == "linear"
    has_delta = bool(np.any(np.isfinite(sig.delta)))

    def delay(j: int | None) -> float:
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


def lateral_acceleration(sig: Signals, thresholds: MetricsConfig) -> np.ndarray:
    """C2's lateral acceleration (m/s^2): ``vy_dot + vx r``, or ``v r`` (``lateral_accel =
    vx_r``, and without a lateral-velocity column)."""
    if thresholds.lateral_accel == "vx_r" or sig.vy is None:
        return sig.speed * sig.yaw_rate
    return time_derivative(sig.vy, sig.t) + sig.vx * sig.yaw_rate


def avoidance_window(sig: Signals, threat: Threat, geo: ThreatGeometry, recovery: Recovery
                     ) -> tuple[float, float]:
    """C2's avoidance window (s): from the appearance of the threat (of the first visible
    obstacle when none threatened) to recovery, or the run's end; ``(nan, nan)`` when no
    obstacle appeared."""
    start = threat.threat_appear_time_s if geo.threatening is not None \
        else threat.obstacle_appear_time_s
    if not np.isfinite(start):
        return float("nan"), float("nan")
    end = geo.passed_time_s + recovery.recovery_time_s if recovery.recovered else sig.t[-1]
    return float(start), float(end)


def smoothness_block(sig: Signals, threat: Threat, geo: ThreatGeometry, recovery: Recovery,
                     thresholds: MetricsConfig) -> Smoothness:
    """C2: a_y = vy_dot + vx r (or v r), its jerk, over the avoidance window and the run."""
    t = sig.t
    lat_acc_old = sig.speed * sig.yaw_rate
    lat_acc = lateral_acceleration(sig, thresholds)
    jerk = time_derivative(lat_acc, t)
    start, end = avoidance_window(sig, threat, geo, recovery)
    window = window_mask(t, start, end)
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
        curvature_rate_rms_1_per_ms=rms(time_derivative(curvature, t)),
        smoothness_window_start_s=start, smoothness_window_end_s=end)


def lateral_jerk_signal(trajectory: TrajectoryLike, context: TrajectoryContext,
                        thresholds: MetricsConfig) -> LateralJerk:
    """One run's lateral jerk at its log times (C2's signal, ``thresholds.lateral_accel``'s
    reading), for a window that is not the run's own (one common to both runs of a pair)."""
    sig = trajectory_signals(trajectory, context)
    return LateralJerk(sig.t.copy(), time_derivative(lateral_acceleration(sig, thresholds),
                                                     sig.t))


def repulsion_block(tr: TrajectoryLike, sig: Signals, geo: ThreatGeometry, clearance: np.ndarray,
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

    def share(mask: np.ndarray | np.bool_) -> float:  # no repulsion: none unnecessary
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


def safety_block(tr: TrajectoryLike, sig: Signals, tracks: list[ObstacleTrack],
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
                   min_time_to_collision(tr, context.vehicle_radius_m, tracks)),
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


def validity_block(tr: TrajectoryLike, context: TrajectoryContext) -> ModelValidity | None:
    """:class:`ModelValidity` from the columns the loop logged (None without any of them)."""
    if "model_error_1s_m" not in tr and "tyre_slip_norm" not in tr:
        return None

    def column(name: str) -> np.ndarray:
        return tr[name].to_numpy(float) if name in tr else np.full(len(tr), np.nan)

    heading = column("model_heading_error_rad")
    tyre = column("tyre_slip_norm")
    stepped = tr["solver_status"].astype(str).to_numpy() != "end" if "solver_status" in tr \
        else np.ones(len(tr), bool)
    beyond = tr["path_beyond_limit"].to_numpy() if "path_beyond_limit" in tr else None
    model_05, model_1 = _quantiles(column("model_error_05s_m")), _quantiles(column(
        "model_error_1s_m"))
    plan_1 = _quantiles(column("plan_error_1s_m"))
    return ModelValidity(
        model_heading_error_max_rad=max_abs(heading),
        share_steps_beyond_bound=_share(heading > context.validity_heading_rad,
                                        np.isfinite(heading)),
        share_steps_tyre_nonlinear=_share(tyre > context.tyre_linear_limit, np.isfinite(tyre)),
        share_steps_path_beyond_limit=_share(beyond.astype(bool), stepped)
        if beyond is not None else float("nan"),
        prediction_error_05s_p50_m=model_05[0], prediction_error_05s_p95_m=model_05[1],
        prediction_error_1s_p50_m=model_1[0], prediction_error_1s_p95_m=model_1[1],
        plan_error_1s_p50_m=plan_1[0], plan_error_1s_p95_m=plan_1[1])


def solver_blocks(tr: TrajectoryLike) -> tuple[SolverIterations | None, Fallbacks | None]:
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
SAFETY_READS = ("collision_check", "attribution_steering_samples", "attribution_switch_samples",
                "attribution_extra_s")
THREAT_READS = SAFETY_READS + ("threat_margin_m", "threat_horizon_s", "pass_reading")
RECOVERY_READS = THREAT_READS + ("recovery_reading", "recovery_lateral_band_m",
                                 "recovery_heading_band_rad", "recovery_heading_stop_m")
REACTION_READS = THREAT_READS + ("reaction_obstacle", "reaction_interpolation",
                                 "reaction_steering_band_rad", "reaction_lateral_band_m")
SMOOTHNESS_READS = RECOVERY_READS + ("lateral_accel", "smoothness_window")
STABILITY_READS = THREAT_READS + ("oscillation", "lateral_sign_band_m",
                                  "yaw_rate_sign_band_rad_s")
def crowd_block(sig: Signals, tracks: list[ObstacleTrack], clearance: np.ndarray,
                safety: Safety, progress: Progress, context: TrajectoryContext
                ) -> Crowd | None:
    """The crowd-navigation metrics (:class:`~pipeline.analysis.metrics.results.Crowd`) of a
    run among walkers (``context.personal_space_m`` set), else None.

    A step intrudes where the surface gap to the nearest visible walker is below
    ``personal_space_m``; the contact's relative speed is ``|v_platform - v_walker|`` on the
    first logged step whose gap to some walker is negative (forward differences of the logged
    positions: the walker's as logged, the platform's ``X_m, Y_m``); the contact came at the
    walkers' appearance when none of those walkers was visible one logged step before (or
    the contact is on the first step). Within a walker's reach the sensor range never hides
    it, so not visible there means not yet in the recording."""
    if context.personal_space_m is None:
        return None
    t = sig.t
    inside = np.nan_to_num(clearance, nan=np.inf) < context.personal_space_m
    dt = np.diff(t, append=t[-1]) if t.size else t
    entries = int(np.count_nonzero(inside[1:] & ~inside[:-1]) + (1 if inside[:1].any() else 0))
    straight = float(np.linalg.norm(np.subtract(context.goal_m, context.start_m)))
    relative = float("nan")
    at_appearance = False
    if safety.collision and t.size > 0:  # a contact on the first logged step: a log of one row
        velocity = np.vstack([np.diff(sig.xy, axis=0) / np.diff(t)[:, None],
                              np.full((1, 2), np.nan)])
        for k in range(t.size):
            hits = [j for j, track in enumerate(tracks) if track.visible[k] and np.linalg.norm(
                sig.xy[k] - track.position[k]) - track.radius[k] - context.vehicle_radius_m < 0]
            if hits:
                mine = velocity[k] if np.all(np.isfinite(velocity[k])) else velocity[k - 1]
                relative = float(min(np.linalg.norm(mine - tracks[j].velocity[k])
                                     for j in hits))
                at_appearance = k == 0 or not any(tracks[j].visible[k - 1] for j in hits)
                break
    in_range = np.sum([track.visible for track in tracks], axis=0) if tracks \
        else np.zeros(t.size)
    beyond = float(np.mean(in_range > context.obstacle_slots)) \
        if context.obstacle_slots is not None and t.size else 0.0
    return Crowd(
        timeout=bool(not progress.goal_reached and not safety.collision),
        path_ratio=progress.path_length_m / straight if progress.goal_reached and straight > 0
        else float("nan"),
        personal_space_intrusion_share=float(inside.mean()) if inside.size else float("nan"),
        personal_space_intrusion_s=float(np.sum(dt[inside])),
        personal_space_entries=entries,
        contact_relative_speed_mps=relative, walkers_beyond_slots_share=beyond,
        contact_at_appearance=bool(at_appearance),
        straight_line_meets=None if context.crossing is None else context.crossing[0],
        standing_touched=None if context.crossing is None else context.crossing[1])


REPULSION_READS = THREAT_READS + ("repulsion_need", "near_field_m", "repulsion_onset_force",
                                  "threat_clearance_m")
PROGRESS_READS = ("goal_tolerance_m",)


def compute_metrics(trajectory: TrajectoryLike, context: TrajectoryContext,
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


def compute_metrics_readings(trajectory: TrajectoryLike, context: TrajectoryContext,
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
    # an ego of several discs: every distance from the disc nearest to each obstacle
    trajectory = ego_disc_view(trajectory, context.vehicle_offsets_m)
    sig = trajectory_signals(trajectory, context)
    tracks = obstacle_tracks(trajectory)
    clearance = clearance_series(trajectory, context.vehicle_radius_m, tracks)
    step_cap = StepCap(float(np.nanmean(trajectory["apf_step_cap_share"].to_numpy(float)))) \
        if "apf_step_cap_share" in trajectory else None
    iterations, fallbacks = solver_blocks(trajectory)
    validity = validity_block(trajectory, context)
    memo: dict[tuple[Any, ...], object] = {}

    def once(criterion: str, reads: tuple[str, ...], thresholds: MetricsConfig,
             build: Callable[[], Any]) -> Any:
        key = (criterion,) + tuple(getattr(thresholds, name) for name in reads)
        if key not in memo:
            memo[key] = build()
        return memo[key]

    results = []
    for thresholds in readings:
        # each build bound to this reading's values (partial), built only when not memoized
        safety, colliding = once("safety", SAFETY_READS, thresholds, partial(
            safety_block, trajectory, sig, tracks, clearance, context, thresholds))
        threat, geo = once("threat", THREAT_READS, thresholds, partial(
            threat_block, sig, tracks, context, thresholds, colliding))
        recovery = once("recovery", RECOVERY_READS, thresholds,
                        partial(recovery_block, sig, geo, thresholds))
        results.append(RunMetrics(
            threat=threat,
            reaction=once("reaction", REACTION_READS, thresholds,
                          partial(reaction_block, sig, geo, thresholds)),
            smoothness=once("smoothness", SMOOTHNESS_READS, thresholds,
                            partial(smoothness_block, sig, threat, geo, recovery, thresholds)),
            recovery=recovery,
            stability=once("stability", STABILITY_READS, thresholds,
                           partial(stability_block, sig, threat, geo, thresholds)),
            safety=safety,
            progress=once("progress", PROGRESS_READS, thresholds,
                          partial(progress_block, sig, context, thresholds)),
            repulsion=once("repulsion", REPULSION_READS, thresholds,
                           partial(repulsion_block, trajectory, sig, geo, clearance, thresholds)),
            step_cap=step_cap, iterations=iterations, fallbacks=fallbacks,
            validity=validity))
        if context.personal_space_m is not None:
            last = results[-1]
            results[-1] = replace(last, crowd=crowd_block(sig, tracks, clearance, last.safety,
                                                          last.progress, context))
    return results
