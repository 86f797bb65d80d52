"""The paper's claims as data: each :class:`Claim` with its primary and secondary metrics
(:data:`ALL_CLAIMS`: C0 safety first, then :data:`CLAIMS` C1-C5), the four outcomes
(:class:`Outcome`) and the rules' text (:data:`OUTCOME_RULE`, :data:`SINGLE_RULE`)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum


@dataclass(frozen=True)
class Claim:
    """One claim of the paper and the metric that stands for it."""

    claim_id: str
    text: str
    primary_metric: str
    lower_is_better: bool
    secondary_metrics: tuple[str, ...]
    criterion: str = ""
    paper_description: str = ""
    paper_indicator: str = ""
    paper_improved: str = ""
    paper_original: str = ""
    definition: str = ""
    #: "paired" (a paired difference of a metric) or "rate" (a rate of events, e.g. C0)
    kind: str = "paired"
    #: the smallest effect of interest (units of the primary metric; C0: a rate difference),
    #: the default of ``claims.margins.<id>``, and why it is what it is
    margin: float = 0.0
    margin_reason: str = ""

    @property
    def is_rate(self) -> bool:
        return self.kind == "rate"


CLAIMS: tuple[Claim, ...] = (
    Claim("C1", "faster obstacle-avoidance response after a sudden obstacle appears",
          "reaction_delay_s", True, ("reaction_delay_lateral_s",
                                     "reaction_delay_first_visible_s"),
          criterion="Obstacle Avoidance Response",
          paper_description="How quickly and effectively the system reacts to a suddenly "
                            "appearing obstacle.",
          paper_indicator="Fast and smooth detour around the obstacle.",
          paper_improved="Fast and smooth avoidance",
          paper_original="Slow and aggressive curved avoidance",
          definition="Time (s) from the appearance of the first obstacle that threatens the "
                     "vehicle's straight continuation (within both radii + threat_margin_m, "
                     "threat_horizon_s ahead) until the steering angle first leaves a band of "
                     "reaction_steering_band_rad around its value then, the crossing "
                     "interpolated between samples; missing when nothing threatens.",
          margin=0.05,
          margin_reason=("half a sample time (Ts = 0.1 s): the resolution the paper's 10"
                         " Hz loop can act on")),
    Claim("C2", "smoother steering path (no sharp turns or jerks after avoidance)",
          "lateral_jerk_rms_mps3", True,
          ("lateral_jerk_rms_run_mps3", "lateral_jerk_max_window_mps3",
           "steering_rate_rms_window_rad_s", "curvature_rate_rms_1_per_ms"),
          criterion="Smoothness of Steering Path",
          paper_description="How natural or jerky the steering path is.",
          paper_indicator="Smooth curvature and gradual turns.",
          paper_improved="Smooth and stable path after avoidance",
          paper_original="Sharp turns after avoidance (jerky)",
          definition="RMS of the lateral jerk d(a_y)/dt (m/s^3) with a_y = vy_dot + vx r, by "
                     "central differences, over the avoidance window (appearance of the threat "
                     "to recovery, or run end).",
          margin=0.1,
          margin_reason=("0.1 m/s^3 of RMS lateral jerk, about 5 % of the values measure"
                         "d here and well below what a passenger notices")),
    Claim("C3a", "no repulsion while nothing is near (low sensitivity far away)",
          "repulsion_unneeded_share", True,
          ("repulsion_unneeded_share_threat", "repulsive_impulse_far_share",
           "repulsion_unneeded_impulse", "repulsive_force_peak"),
          criterion="Repulsive Force Modulation (first half: only when needed)",
          paper_description="How well the repulsive force from the APF is applied.",
          paper_indicator="Adaptive, distance-based repulsion that avoids unnecessary forces.",
          paper_improved="H_k is activated smoothly based on distance; strong repulsion only "
                         "when needed",
          paper_original="exp((s - s0)^2) causes low sensitivity for far distances",
          definition="Share (0-1) of the repulsive impulse sum |F_rep| Ts at the vehicle that "
                     "is applied while no obstacle threatens the straight continuation of the "
                     "current motion and none is within near_field_m (0 when no repulsion was "
                     "applied): force spent holding the vehicle off a near obstacle is needed.",
          margin=0.05,
          margin_reason=("5 percentage points of the repulsive impulse"
                         "")),
    Claim("C3b", "early repulsion when a threat appears",
          "repulsion_onset_ttc_s", False,
          ("repulsion_onset_clearance_m", "repulsive_force_peak"),
          criterion="Repulsive Force Modulation (second half: strong when needed)",
          paper_description="How well the repulsive force from the APF is applied.",
          paper_indicator="Adaptive, distance-based repulsion that avoids unnecessary forces.",
          paper_improved="strong repulsion only when needed",
          paper_original="low sensitivity for far distances",
          definition="Time to contact (s) of the straight continuation at the first step on "
                     "which the repulsion exceeds repulsion_onset_force while an obstacle "
                     "threatens (higher = earlier); missing when the repulsion never becomes "
                     "significant during a threat.",
          margin=0.1,
          margin_reason=("one sample time (0.1 s) of time to contact at the onset of rep"
                         "ulsion")),
    Claim("C4", "faster, smoother goal-direction recovery after avoidance",
          "recovery_time_s", True, ("recovery_lateral_s", "recovery_heading_s",
                                    "overshoot_m"),
          criterion="Goal Direction Recovery",
          paper_description="Whether the system can return to the goal path after avoidance.",
          paper_indicator="Smooth convergence back to the original trajectory.",
          paper_improved="Returns smoothly to goal direction after avoiding obstacles",
          paper_original="Recovery is slow and inconsistent",
          definition="Settling time (s, python-control step_info convention, absolute band "
                     "recovery_lateral_band_m) of the lateral error to the start-goal line "
                     "after every threatening obstacle is passed; missing if it never "
                     "settles.",
          margin=0.1,
          margin_reason=("one sample time (0.1 s) of settling time"
                         "")),
    Claim("C5", "more stable path (no sharp drops, minimal oscillation)",
          "oscillation_count", True, ("oscillation_whole_run_count", "heading_step_max_rad",
                                      "overshoot_m", "max_lateral_deviation_m"),
          criterion="Path Stability",
          paper_description="The overall stability of the path (oscillations, abrupt dips, "
                            "etc.).",
          paper_indicator="Stable trajectory with no sharp drops or oscillations.",
          paper_improved="Globally stable with minimal oscillation",
          paper_original="Unstable - drops sharply and reacts suddenly",
          definition="After the obstacle is passed, reversals of the lateral error's "
                     "direction (hysteresis lateral_sign_band_m), net of the manoeuvre: an apex "
                     "of the detour after the pass is not counted, so one out-and-back scores "
                     "0 and an overshoot with its return 1.",
          margin=0.5,
          margin_reason=("half a reversal of the lateral error: any systematic extra rev"
                         "ersal exceeds it")),
)

SAFETY = Claim(
    "C0", "no less safe (collision rate)", "collision", True,
    ("collision_avoidable", "min_clearance_m"),
    criterion="Safety (not a row of Table 1; judged first)",
    paper_description="Implied throughout: avoidance must avoid.",
    paper_indicator="No collision.",
    definition="Collision from a continuous check (vehicle and obstacles interpolated between "
               "log rows, closest approach in closed form); each collision labelled unavoidable "
               "only when a sampled reachability check from the state at the obstacle's "
               "appearance finds no escape and no method that ran the same scenario avoided "
               "it, avoidable otherwise.",
    kind="rate", margin=0.02,
    margin_reason=("two percentage points of collision rate: four scenarios in 2"
                   "00, below what one reading of a threshold moves"))

#: Every claim in the order the report shows them: safety first.
ALL_CLAIMS: tuple[Claim, ...] = (SAFETY,) + CLAIMS
#: Every claim's id, in that order (the ledger's rows per comparison).
CLAIM_IDS: tuple[str, ...] = tuple(c.claim_id for c in ALL_CLAIMS)
#: The claim whose primary metric a metric is (for messages).
CLAIM_OF_METRIC: dict[str, str] = {c.primary_metric: c.claim_id for c in ALL_CLAIMS}

#: The claims that read the APF's repulsive force (C3a: none while nothing is near, C3b: early
#: when a threat appears): not judged against the methods the paper names, none of which has
#: one (their force columns are zero: C3a would "contradict" improved for any repulsion at all).
FORCE_CLAIMS = ("C3a", "C3b")


class Outcome(StrEnum):
    """The four outcomes of a claim over a family (:data:`OUTCOME_RULE`)."""

    SUPPORTED = "supported"
    CONTRADICTED = "contradicted"
    EQUIVALENT = "equivalent"
    INCONCLUSIVE = "inconclusive"
    #: the estimate and the probability of improvement point opposite ways
    MIXED = "mixed"


OUTCOMES = tuple(o.value for o in Outcome)

OUTCOME_RULE = (
    "per claim, d = improved - comparison on each scenario (d < 0 is the claimed improvement); "
    "C1-C5 on pairs where neither method collided (all pairs as a sensitivity), pairs with a "
    "missing value counted apart. Estimate: Hodges-Lehmann of d (claims.estimator) with a paired "
    "bootstrap interval (scipy.stats.bootstrap, BCa where defined, claims.n_resamples, seeded); "
    "C0 (a rate): the difference of collision rates with Newcombe's hybrid score interval for "
    "paired proportions (Wilson limits from scipy.stats, honest at zero events). Every interval "
    "is at the level 1 - alpha / 7 (claims.interval_adjustment: Bonferroni over the seven "
    "claims against one comparison), and the interval is the test: 'equivalent' when it lies "
    "inside (-margin, +margin); otherwise 'supported' when it lies strictly below zero, the "
    "estimate is below zero and the probability of improvement PI = P(d < 0) + P(d = 0)/2 is "
    "not below 1/2, 'contradicted' the same way round, 'mixed' when the interval excludes "
    "zero but PI points the other way (both numbers in the note), and 'inconclusive' exactly "
    "when the interval contains zero and reaches past the margin (also with fewer than "
    "claims.min_pairs pairs). An estimate of exactly 0 or an interval ending at 0 (lattice "
    "metrics) never gives a direction. For C0 the interval alone gives the direction. The "
    "paired test (Wilcoxon signed-rank with Pratt's zeros, or the sign test; C0 McNemar's exact "
    "test) is shown Holm-adjusted beside it; where it disagrees with the interval the note says "
    "so. An interval clear of zero inside the margin is a real but small effect: the note says "
    "so; a claim on which claims.floor_tie_share of the pairs tie at the metric's floor notes "
    "that neither method shows the behaviour")

SINGLE_RULE = (
    "paper scenario: 'better' if improved beats the comparison on the primary metric by at "
    "least the claim's margin, 'worse' if it trails by at least the margin, 'within margin' "
    "otherwise, 'missing' when either value is missing")
