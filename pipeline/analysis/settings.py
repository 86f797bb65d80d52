"""Settings of the analysis half: metric thresholds and readings (``metrics.*``) and the rules that
turn paired differences into verdicts (``claims.*``, outside the run hash)."""

from __future__ import annotations

import dataclasses
import functools
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
    pass_reading: str = "ahead_of_threats"
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
        choice("metrics.pass_reading", self.pass_reading, ("ahead_of_threats", "last_threat"))
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


#: What a claim's id may be: it names rows, table columns and a config file.
CLAIM_ID_PATTERN = r"[A-Za-z][A-Za-z0-9_]{0,19}"


@dataclass
class ClaimEntry(FrozenAfterValidation):
    """One claim of the catalogue (``conf/claim/<id>.yaml``, ``claims.catalogue.<id>``): what
    the paper says, the metric that stands for it and which way is better, its margin (the
    smallest effect of interest, in the metric's units) and why the margin is what it is, and
    how the report describes it."""

    text: str = ""
    #: the primary metric: a key of each run's metrics.json (a column of family_metrics.csv)
    metric: str = ""
    #: which way of the metric is the claimed improvement: "lower" or "higher"
    better: str = "lower"
    #: other metrics shown beside it (never judged)
    secondary: List[str] = field(default_factory=list)
    #: "paired" (a paired difference of the metric) or "rate" (a rate of events, C0)
    kind: str = "paired"
    margin: Optional[float] = None
    margin_reason: str = ""
    #: the claim judges the APF's repulsive force: not judged against a method without one
    reads_apf_force: bool = False
    criterion: str = ""
    paper_description: str = ""
    paper_indicator: str = ""
    paper_improved: str = ""
    paper_original: str = ""
    definition: str = ""

    def check(self, claim_id: str) -> None:
        """Range checks, each error naming ``claims.catalogue.<claim_id>.<key>``."""
        import re

        key = f"claims.catalogue.{claim_id}"
        if not re.fullmatch(CLAIM_ID_PATTERN, str(claim_id)):
            raise ConfigError(key, claim_id, "a claim id of 1-20 letters, digits or _, "
                              "starting with a letter")
        if not str(self.metric or "").strip():
            raise ConfigError(f"{key}.metric", self.metric, "a metric name (a metrics.json key)")
        choice(f"{key}.better", self.better, ("lower", "higher"))
        choice(f"{key}.kind", self.kind, ("paired", "rate"))
        if self.margin is None:
            raise ConfigError(f"{key}.margin", None, "a margin >= 0 (the metric's units)")
        at_least(f"{key}.margin", self.margin, 0.0)
        if not str(self.margin_reason or "").strip():
            raise ConfigError(f"{key}.margin_reason", self.margin_reason,
                              "a sentence saying why the margin is what it is")


@functools.lru_cache(maxsize=1)
def _builtin_catalogue_data() -> tuple[tuple[str, dict[str, Any]], ...]:
    """The package's claims as plain data, in the order of ``conf/config.yaml``'s defaults
    entry ``claim: [...]``, each from ``conf/claim/<id>.yaml`` (read once)."""
    import yaml

    from pipeline.conf_dir import CONF_DIR, CONFIG_NAME

    top = yaml.safe_load((CONF_DIR / f"{CONFIG_NAME}.yaml").read_text())
    ids: list[str] = []
    for item in top.get("defaults", []):
        if isinstance(item, dict) and "claim" in item:
            ids = list(item["claim"])
    return tuple((claim_id, yaml.safe_load((CONF_DIR / "claim" / f"{claim_id}.yaml")
                                           .read_text())) for claim_id in ids)


@functools.lru_cache(maxsize=1)
def _builtin_entries() -> tuple[tuple[str, ClaimEntry], ...]:
    entries = []
    for claim_id, data in _builtin_catalogue_data():
        entry = ClaimEntry(**{**data, "secondary": list(data.get("secondary", []))})
        entry.check(claim_id)
        entry.freeze()
        entries.append((claim_id, entry))
    return tuple(entries)


def builtin_catalogue() -> dict[str, ClaimEntry]:
    """The package's claim catalogue (``conf/claim/``, in ``conf/config.yaml``'s order, each
    entry read-only): what a configuration with an empty ``claims.catalogue`` (one built
    without Hydra, or read from a run folder written before the catalogue) judges."""
    return dict(_builtin_entries())


def upgrade_claims_data(claims: dict[str, Any]) -> dict[str, Any]:
    """A stored ``claims`` block written before the catalogue (``margins`` and
    ``margin_reasons`` tables, no ``catalogue``) as it reads now: the package's catalogue with
    the stored margins and reasons. Any other block is returned unchanged."""
    if "catalogue" in claims or not ({"margins", "margin_reasons"} & set(claims)):
        return claims
    claims = dict(claims)
    margins = dict(claims.pop("margins", None) or {})
    reasons = dict(claims.pop("margin_reasons", None) or {})
    catalogue = {}
    for claim_id, entry in builtin_catalogue().items():
        data = dataclasses.asdict(entry)
        data["margin"] = margins.pop(claim_id, data["margin"])
        data["margin_reason"] = reasons.pop(claim_id, data["margin_reason"])
        catalogue[claim_id] = data
    unknown = sorted(set(margins) | set(reasons))
    if unknown:
        raise ConfigError(f"claims.margins.{unknown[0]}", margins.get(unknown[0]),
                          "a margin of one of " + ", ".join(catalogue))
    claims["catalogue"] = catalogue
    return claims


@dataclass
class ClaimsConfig(FrozenAfterValidation):
    """How paired differences become one of four outcomes.

    ``catalogue`` holds every claim judged (:class:`ClaimEntry`, one ``conf/claim/<id>.yaml``
    each), with its margin, the smallest effect of interest (units of its primary metric; C0: a
    collision-rate difference), and the margin's reason (:attr:`margins`,
    :attr:`margin_reasons`); empty, the package's (:func:`builtin_catalogue`; :attr:`entries`
    reads either).
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
    catalogue: Dict[str, ClaimEntry] = field(default_factory=dict)
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
        choice("claims.pairs", self.pairs, ("neither_collided", "all", "unsettled_last"))
        choice("claims.c2_window", self.c2_window, ("own", "common"))
        choice("claims.common_window", self.common_window, ("union", "intersection"))
        at_least("claims.tie_tolerance", self.tie_tolerance, 0.0)
        between("claims.floor_tie_share", self.floor_tie_share, 0.0, 1.0)
        for claim_id, entry in self.catalogue.items():
            if not isinstance(entry, ClaimEntry):
                raise ConfigError(f"claims.catalogue.{claim_id}", entry,
                                  "a claim entry (conf/claim/<id>.yaml's keys)")
            entry.check(claim_id)
        at_least("claims.comparable_clearance_m", self.comparable_clearance_m, 0.0)
        between("claims.cap_binding_share", self.cap_binding_share, 0.0, 1.0)

    @property
    def entries(self) -> dict[str, ClaimEntry]:
        """Every claim judged, by id, in the catalogue's order: ``catalogue``, or the
        package's when it is empty (the schema's default: a composed configuration holds the
        claims its defaults list chose, ``claim: [...]``, and only those)."""
        return self.catalogue or builtin_catalogue()

    @property
    def claim_ids(self) -> tuple[str, ...]:
        """Every claim judged, in the catalogue's order."""
        return tuple(self.entries)

    @property
    def margins(self) -> dict[str, float]:
        """Each claim's margin (its catalogue entry's), by claim id."""
        return {k: float(e.margin) for k, e in self.entries.items() if e.margin is not None}

    @property
    def margin_reasons(self) -> dict[str, str]:
        """Why each claim's margin is what it is, by claim id."""
        return {k: e.margin_reason for k, e in self.entries.items()}

    def with_margins(self, margins: dict[str, float]) -> ClaimsConfig:
        """These settings with the margins of ``margins`` (by claim id) replaced."""
        return dataclasses.replace(self, catalogue={
            k: dataclasses.replace(e, margin=margins.get(k, e.margin))
            for k, e in self.entries.items()})

    def freeze(self) -> ClaimsConfig:
        """Read-only, the catalogue's entries too."""
        for entry in self.catalogue.values():
            entry.freeze()
        super().freeze()
        return self
