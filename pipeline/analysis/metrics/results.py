"""The metrics as result objects: one frozen block per Table 1 criterion, :class:`RunMetrics`
holding them (``to_json`` / ``from_json``: ``metrics.json``), and :data:`METRIC_KEYS`."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, TypeVar

import numpy as np

from pipeline.analysis.metrics.signals import rms, window_mask


def _nan_to_none(value: Any) -> Any:
    if isinstance(value, (float, np.floating)) and not np.isfinite(value):
        return None
    if isinstance(value, np.generic):
        return value.item()
    return value


B = TypeVar("B", bound="_Block")


class _Block:
    """A frozen block of metrics; its fields are the ``metrics.json`` keys it owns."""

    def to_json(self) -> dict[str, Any]:
        """The block's keys and values, NaN as ``None`` and numpy scalars as Python ones."""
        return {f.name: _nan_to_none(getattr(self, f.name))
                for f in fields(self)}  # type: ignore[arg-type]  # each subclass a dataclass

    @classmethod
    def from_json(cls: type[B], data: dict[str, Any]) -> B:
        """The block read back from ``metrics.json`` (``None`` for its keys when absent)."""
        return cls(**{f.name: _none_to_nan(data.get(f.name))
                      for f in fields(cls)})  # type: ignore[arg-type]

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))  # type: ignore[arg-type]


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
    """C2: steering rate (rad/s), lateral acceleration (m/s^2), jerk (m/s³), curvature rate."""

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
    #: the avoidance window the ``*_window`` values are taken over (s; NaN when none): what a
    #: window common to both runs of a pair is made of (:mod:`pipeline.analysis.claims.windows`)
    smoothness_window_start_s: float
    smoothness_window_end_s: float


@dataclass(frozen=True)
class LateralJerk:
    """One run's lateral jerk ``d a_y / dt`` (m/s³) at its log times (s): what C2's RMS is
    taken of, over any window (:meth:`rms_over`), e.g. one common to both runs of a pair."""

    time_s: np.ndarray
    jerk_mps3: np.ndarray

    def rms_over(self, start_s: float, end_s: float) -> float:
        """RMS of the samples with ``start_s <= t <= end_s`` (NaN when none), the samples
        :func:`pipeline.analysis.metrics.criteria.smoothness_block` takes its window over."""
        return rms(self.jerk_mps3[window_mask(self.time_s, start_s, end_s)])


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
    range, whose reference path asked for more curvature than the vehicle's limit (where the
    pursuit path clips it: where the clip bound); the model's prediction
    error (replayed with the applied inputs) and the plan's, 0.5 s and 1 s ahead (m,
    median and 95th percentile over the run's steps). NaN where the run logged no such
    column (a scored trajectory, pure pursuit)."""

    model_heading_error_max_rad: float
    share_steps_beyond_bound: float
    share_steps_tyre_nonlinear: float
    share_steps_path_beyond_limit: float
    prediction_error_05s_p50_m: float
    prediction_error_05s_p95_m: float
    prediction_error_1s_p50_m: float
    prediction_error_1s_p95_m: float
    plan_error_1s_p50_m: float
    plan_error_1s_p95_m: float


@dataclass(frozen=True)
class Crowd(_Block):
    """Among walkers, the crowd-navigation metrics (Francis et al. 2023; CrowdNav): whether
    the run timed out (neither the goal nor a contact before its last step), the path's length
    over the straight start-goal line, the share of logged steps (and their time, s) inside a
    walker's personal space (surface gap below ``personal_space_m``) and how often it was
    entered, the speed of the platform relative to the walker at the first contact (m/s;
    NaN without one), whether that contact came at the walker's appearance (every walker in
    contact then was not seen one step before: a recorded track that begins on or against
    the platform, which no planner could have seen coming), and the share of steps with more
    walkers in sensor range than the controller has obstacle slots; and the crossing's
    difficulty from the recording alone (whether the straight line at the drawn speed meets a
    walker, whether a platform standing still at the start is touched; None where the run's
    configuration has no drawn crossing)."""

    timeout: bool
    path_ratio: float
    personal_space_intrusion_share: float
    personal_space_intrusion_s: float
    personal_space_entries: int
    contact_relative_speed_mps: float
    walkers_beyond_slots_share: float
    contact_at_appearance: bool = False
    straight_line_meets: bool | None = None
    standing_touched: bool | None = None


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
    crowd: Crowd | None = None

    def blocks(self) -> tuple[_Block, ...]:
        """The blocks present, in Table 1 order (the crowd metrics last, among walkers)."""
        return tuple(b for b in (self.threat, self.reaction, self.smoothness, self.repulsion,
                                 self.step_cap, self.recovery, self.stability, self.safety,
                                 self.progress, self.iterations, self.fallbacks,
                                 self.validity, self.crowd)
                     if b is not None)

    def to_json(self) -> dict[str, Any]:
        """Flat mapping of metric name to value (``metrics.json``); NaN as ``None``."""
        out: dict[str, Any] = {}
        for block in self.blocks():
            out.update(block.to_json())
        return out

    def value(self, name: str) -> float:
        """One metric by its name as a float (booleans as 0/1; NaN when missing or absent)."""
        for block in self.blocks():
            if name in block.names():
                v = getattr(block, name)
                return float(v) if v is not None else math.nan
        return math.nan

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> RunMetrics:
        """Read back what :meth:`to_json` wrote (keys of other records are ignored)."""
        def optional(block: type[B]) -> B | None:
            return block.from_json(data) if any(k in data for k in block.names()) else None

        return cls(Threat.from_json(data), Reaction.from_json(data),
                   Smoothness.from_json(data), Recovery.from_json(data),
                   Stability.from_json(data), Safety.from_json(data), Progress.from_json(data),
                   optional(Repulsion), optional(StepCap), optional(SolverIterations),
                   optional(Fallbacks), optional(ModelValidity), optional(Crowd))


#: Every key :meth:`RunMetrics.to_json` can write.
METRIC_KEYS: tuple[str, ...] = tuple(k for block in (
    Threat, Reaction, Smoothness, Repulsion, StepCap, Recovery, Stability, Safety, Progress,
    SolverIterations, Fallbacks, ModelValidity, Crowd) for k in block.names())


def _none_to_nan(value: Any) -> Any:
    return math.nan if value is None else value
