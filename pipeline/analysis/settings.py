"""Settings of the analysis half: metric thresholds and readings (``metrics.*``) and the rules that
turn paired differences into verdicts (``claims.*``, outside the run hash)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional

from pipeline.errors import ConfigError
from pipeline.validation import FrozenAfterValidation, at_least, between, choice


@dataclass
class MetricsConfig(FrozenAfterValidation):
    """Thresholds and readings of the Table 1 metrics (definitions: :mod:`pipeline.analysis.metrics`).

    The ``*_definition``-like string switches select which reading a claim's primary metric
    uses; every reading is computed and logged under its own key as well (register entries).
    """

    reaction_steering_band_rad: float = 0.01
    reaction_lateral_band_m: float = 0.05
    reaction_obstacle: str = "threatening"
    reaction_interpolation: str = "linear"
    threat_margin_m: float = 0.5
    threat_horizon_s: Optional[float] = None
    threat_clearance_m: float = 2.0
    near_field_m: float = 2.0
    lateral_accel: str = "vy_dot_plus_vx_r"
    smoothness_window: str = "avoidance"
    repulsion_need: str = "threat_or_near"
    repulsion_onset_force: float = 1.0
    recovery_lateral_band_m: float = 0.25
    recovery_heading_band_rad: float = 0.05
    recovery_heading_stop_m: float = 3.0
    recovery_reading: str = "lateral"
    oscillation: str = "net_reversals_after_pass"
    lateral_sign_band_m: float = 0.05
    yaw_rate_sign_band_rad_s: float = 0.02
    collision_check: str = "continuous"
    attribution_steering_samples: int = 9
    attribution_switch_samples: int = 4
    attribution_extra_s: float = 2.0
    goal_tolerance_m: Optional[float] = None

    def __post_init__(self) -> None:
        for key in ("reaction_steering_band_rad", "reaction_lateral_band_m", "threat_clearance_m",
                    "near_field_m", "repulsion_onset_force",
                    "recovery_lateral_band_m", "recovery_heading_band_rad",
                    "recovery_heading_stop_m", "attribution_extra_s",
                    "lateral_sign_band_m", "yaw_rate_sign_band_rad_s"):
            at_least(f"metrics.{key}", getattr(self, key), 0.0, inclusive=False)
        if self.threat_horizon_s is not None:
            at_least("metrics.threat_horizon_s", self.threat_horizon_s, 0.0, inclusive=False)
        if self.goal_tolerance_m is not None:
            at_least("metrics.goal_tolerance_m", self.goal_tolerance_m, 0.0, inclusive=False)
        at_least("metrics.threat_margin_m", self.threat_margin_m, 0.0)
        choice("metrics.reaction_obstacle", self.reaction_obstacle,
                ("threatening", "first_visible"))
        choice("metrics.reaction_interpolation", self.reaction_interpolation,
                ("linear", "sample"))
        choice("metrics.lateral_accel", self.lateral_accel, ("vy_dot_plus_vx_r", "vx_r"))
        choice("metrics.smoothness_window", self.smoothness_window, ("avoidance", "whole_run"))
        choice("metrics.repulsion_need", self.repulsion_need,
               ("threat_or_near", "threat", "clearance_band"))
        choice("metrics.recovery_reading", self.recovery_reading, ("lateral", "heading"))
        choice("metrics.oscillation", self.oscillation,
                ("net_reversals_after_pass", "sign_changes_whole_run"))
        choice("metrics.collision_check", self.collision_check, ("continuous", "sampled"))
        value = self.attribution_steering_samples
        if isinstance(value, bool) or not isinstance(value, int) or not 2 <= value <= 101:
            raise ConfigError("metrics.attribution_steering_samples", value,
                              "an integer in [2, 101]")
        value = self.attribution_switch_samples
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 10:
            raise ConfigError("metrics.attribution_switch_samples", value,
                              "an integer in [0, 10]")


def _claim_ids() -> tuple[str, ...]:
    """Every claim's id (the catalogue's: ``pipeline.analysis.claims.catalogue``, read when
    a config is made: the claims package imports this module)."""
    from pipeline.analysis.claims.catalogue import CLAIM_IDS

    return CLAIM_IDS


def _default_margins() -> dict[str, Any]:
    """Each claim's margin as the catalogue states it (one place: its Claim entry)."""
    from pipeline.analysis.claims.catalogue import ALL_CLAIMS

    return {c.claim_id: c.margin for c in ALL_CLAIMS}


def _default_margin_reasons() -> dict[str, Any]:
    """Why each claim's margin is what it is, as the catalogue states it."""
    from pipeline.analysis.claims.catalogue import ALL_CLAIMS

    return {c.claim_id: c.margin_reason for c in ALL_CLAIMS}


@dataclass
class ClaimsConfig(FrozenAfterValidation):
    """How paired differences become one of four outcomes.

    ``margins`` is each claim's smallest effect of interest (units of its primary metric; C0: a
    collision-rate difference), declared with its reason in ``margin_reasons``.
    """

    alpha: float = 0.05
    # the level of every ledger interval: 1 - alpha / (claims per comparison) (bonferroni), or
    # 1 - alpha (none); the interval is the test (a direction exactly when it excludes 0)
    interval_adjustment: str = "bonferroni"
    n_resamples: int = 9999
    # a bootstrap interval with a threshold of the outcome rule (0, +-margin) within an end's
    # Monte-Carlo band (mc_band_z binomial standard errors of the end's rank) is drawn again
    # with n_resamples_refine; still within it, the outcome reads the interval widened by the
    # bands (the conservative reading: no other seed is likely to overturn it)
    n_resamples_refine: int = 49999
    mc_band_z: float = 3.0
    seed: int = 0
    estimator: str = "hodges_lehmann"
    test: str = "wilcoxon"
    pairs: str = "neither_collided"
    min_pairs: int = 10
    tie_tolerance: float = 1e-9
    margins: Dict[str, float] = field(default_factory=_default_margins)
    margin_reasons: Dict[str, str] = field(default_factory=_default_margin_reasons)
    comparable_clearance_m: float = 2.0
    cap_binding_share: float = 0.5
    floor_tie_share: float = 0.9
    # what is compared with what: the treatment (the method whose claims are judged) and its
    # controls, by method name (run.method); any method, your own included
    treatment: str = "improved"
    controls: List[str] = field(default_factory=lambda: ["baseline", "baseline_matched"])
    # C2's window: each run's own avoidance window ("own"), or one common to both runs of a
    # pair ("common"), made of their two windows by ``common_window``: "union" (from the
    # earlier start to the later end, both runs over the same span) or "intersection"
    c2_window: str = "own"
    common_window: str = "union"
    # a comparison whose C1-C5 rest on fewer than this share of its scenarios (the pairs where
    # neither method collided) says so in the headline, with its worst-rank outcome beside it
    min_pair_share: float = 0.5
    # the nonlinear MPC's ledger (make nmpc-family) is the judge of record when the linear
    # MPC's model leaves its small-angle bound on more than this share of a judged method's
    # steps (model.validity_heading_rad)
    nmpc_judge_share: float = 0.02

    def __post_init__(self) -> None:
        from pipeline.validation import safe_name

        safe_name("claims.treatment", self.treatment)
        if not self.controls:
            raise ConfigError("claims.controls", [], "a list of at least one method name")
        for i, name in enumerate(self.controls):
            safe_name(f"claims.controls[{i}]", name)
        if self.treatment in self.controls:
            raise ConfigError("claims.controls", list(self.controls),
                              f"methods other than the treatment ({self.treatment})")
        between("claims.alpha", self.alpha, 1e-6, 0.5)
        for key in ("n_resamples", "seed", "min_pairs"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ConfigError(f"claims.{key}", value, "an integer >= 0")
        if self.n_resamples < 99:
            raise ConfigError("claims.n_resamples", self.n_resamples, "an integer >= 99")
        value = self.n_resamples_refine
        if isinstance(value, bool) or not isinstance(value, int) or value < 99:
            raise ConfigError("claims.n_resamples_refine", value, "an integer >= 99")
        between("claims.mc_band_z", self.mc_band_z, 0.0, 10.0)
        between("claims.min_pair_share", self.min_pair_share, 0.0, 1.0)
        between("claims.nmpc_judge_share", self.nmpc_judge_share, 0.0, 1.0)
        choice("claims.interval_adjustment", self.interval_adjustment, ("bonferroni", "none"))
        choice("claims.estimator", self.estimator, ("hodges_lehmann", "median"))
        choice("claims.test", self.test, ("wilcoxon", "sign"))
        choice("claims.pairs", self.pairs, ("neither_collided", "all"))
        choice("claims.c2_window", self.c2_window, ("own", "common"))
        choice("claims.common_window", self.common_window, ("union", "intersection"))
        at_least("claims.tie_tolerance", self.tie_tolerance, 0.0)
        claim_ids = _claim_ids()
        unknown = sorted(set(self.margins) - set(claim_ids))
        if unknown:
            raise ConfigError(f"claims.margins.{unknown[0]}", self.margins[unknown[0]],
                              "a margin for one of " + ", ".join(claim_ids))
        between("claims.floor_tie_share", self.floor_tie_share, 0.0, 1.0)
        for claim in claim_ids:
            if claim not in self.margins:
                raise ConfigError(f"claims.margins.{claim}", None, "a margin >= 0 per claim")
            at_least(f"claims.margins.{claim}", self.margins[claim], 0.0)
            if not str(self.margin_reasons.get(claim, "")).strip():
                raise ConfigError(f"claims.margin_reasons.{claim}", None,
                                  "a sentence saying why the margin is what it is")
        at_least("claims.comparable_clearance_m", self.comparable_clearance_m, 0.0)
        between("claims.cap_binding_share", self.cap_binding_share, 0.0, 1.0)
