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
  the avoidance window (appearance of the threat to recovery, or run end; its start and end are
  recorded) and over the whole run. Steering rate and curvature rate as secondaries. Read on a
  window common to both runs of a pair (``claims.c2_window = common``), both runs' RMS jerk is
  taken over the union of their two avoidance windows (:mod:`pipeline.analysis.claims.windows`).
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
  ``collision_avoidable`` by a reachability check from the state at the obstacle's appearance,
  on the kinematic bicycle within the track's actuators: steering targets across
  ``[-delta_max, delta_max]`` (reached at the steering-rate limit on the lateral track, at once
  on the Appendix-A track, where the steering angle is the input), each with full braking, no
  acceleration and (on the Appendix-A track, whose controller commands it) full acceleration,
  held throughout or switched to another such pair at one of ``attribution_switch_samples``
  sample times (swerve and straighten out); avoidable when any of them keeps a non-negative
  clearance to every obstacle until ``attribution_extra_s`` after the contact. That is the
  run's own label. The report publishes a collision as *unavoidable* only when, besides, no
  method that ran the same scenario (same track, family seed and member) avoided it
  (:mod:`pipeline.analysis.unavoidable`): "unavoidable" means no manoeuvre tried by the oracle
  and no method in the ledger avoided it. Minimum time to collision.
* **Progress**: time to reach the goal line (NaN if not reached), path length (m).
* **Solver**: median and p95 of Clarabel's iteration count, fallback count, largest heading
  error against the model's validity bound, share of rollout steps where the step cap bound.
* **Model validity** (:class:`ModelValidity`): does the MPC's model hold where it is used? The
  loop logs, per step, the largest heading error of the plant against that step's frame over
  the next second, the tyres' normalized slip, whether the reference path was clipped at the
  curvature limit, and the model's and the plan's position error 0.5 s and 1 s ahead
  (:func:`pipeline.loop.controller.prediction_check.prediction_check`); the run's shares and quantiles.
  The run leaves the model's validity (``heading_validity_exceeded``) when that heading error
  exceeds ``model.validity_heading_rad`` (the heading to the line for a scored trajectory).
"""

# The definitions above are the report's Methods (``pipeline.analysis.metrics.__doc__``); the
# code is in modules of one concern: signals, geometry, results, criteria.
from pipeline.analysis.metrics.criteria import (
                                                PROGRESS_READS,
                                                REACTION_READS,
                                                RECOVERY_READS,
                                                REPULSION_READS,
                                                SAFETY_READS,
                                                SMOOTHNESS_READS,
                                                STABILITY_READS,
                                                THREAT_READS,
                                                ThreatGeometry,
                                                avoidance_window,
                                                compute_metrics,
                                                compute_metrics_readings,
                                                lateral_acceleration,
                                                lateral_jerk_signal,
                                                progress_block,
                                                reaction_block,
                                                recovery_block,
                                                repulsion_block,
                                                safety_block,
                                                smoothness_block,
                                                solver_blocks,
                                                stability_block,
                                                threat_block,
                                                threat_horizon,
                                                validity_block,
)
from pipeline.analysis.metrics.geometry import (
                                                ObstacleTrack,
                                                clearance_series,
                                                collision_is_avoidable,
                                                continuous_clearance,
                                                min_time_to_collision,
                                                obstacle_count,
                                                obstacle_tracks,
                                                straight_line_time_to_contact,
)
from pipeline.analysis.metrics.results import (
                                                METRIC_KEYS,
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
                                                float_columns,
                                                max_abs,
                                                reversal_count,
                                                rms,
                                                settling_time,
                                                sign_changes,
                                                time_derivative,
                                                trajectory_signals,
                                                window_mask,
)

__all__ = ["TrajectoryContext", "rms", "max_abs", "sign_changes", "time_derivative",
           "settling_time", "float_columns", "band_exit_time", "reversal_count", "Signals",
           "trajectory_signals", "obstacle_count", "clearance_series", "min_time_to_collision",
           "straight_line_time_to_contact", "ObstacleTrack", "obstacle_tracks",
           "continuous_clearance", "collision_is_avoidable", "Threat", "Reaction", "Smoothness",
           "Repulsion", "StepCap", "Recovery", "Stability", "Safety", "Progress", "ModelValidity",
           "SolverIterations", "Fallbacks", "RunMetrics", "METRIC_KEYS", "ThreatGeometry",
           "threat_horizon", "threat_block", "reaction_block", "recovery_block",
           "smoothness_block", "repulsion_block", "stability_block", "safety_block",
           "progress_block", "validity_block", "solver_blocks", "SAFETY_READS", "THREAT_READS",
           "RECOVERY_READS", "REACTION_READS", "SMOOTHNESS_READS", "STABILITY_READS",
           "REPULSION_READS", "PROGRESS_READS", "compute_metrics", "compute_metrics_readings",
           "LateralJerk", "avoidance_window", "lateral_acceleration", "lateral_jerk_signal",
           "window_mask"]
