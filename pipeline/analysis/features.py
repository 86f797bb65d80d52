"""Does it look like the paper? The paper's words about its figures as measured features.

Table 2 and Sections 3-4 describe the figures in words: the baseline shows "slow and aggressive
curved avoidance", "sharp turns after avoidance", an "uncontrolled response" and "drops sharply
and reacts suddenly"; the improved method "fast and smooth avoidance", "returns smoothly to goal
direction" and "minimal oscillation". Each phrase becomes a feature of one run's
``metrics.json`` with a threshold in config (``features.*``, outside the run hash); a run shows a
feature or not. A track and reading *looks like the paper* to the degree that the baseline
shows the baseline's phrases and the improved method the improved method's
(:func:`paper_likeness`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pipeline.validation import FrozenAfterValidation, at_least


@dataclass
class FeatureConfig(FrozenAfterValidation):
    """Thresholds of the features (``features.*``); each names the metric it reads."""

    slow_reaction_s: float = 0.5                 # reaction_delay_s at or above
    aggressive_lateral_accel_mps2: float = 2.0   # lateral_accel_max_mps2 at or above
    sharp_return_overshoot_m: float = 0.2        # overshoot_m at or above
    uncontrolled_yaw_reversals: int = 6          # yaw_rate_sign_changes at or above
    sudden_jerk_mps3: float = 15.0               # lateral_jerk_max_mps3 at or above
    fast_reaction_s: float = 0.3                 # reaction_delay_s at or below
    smooth_jerk_rms_mps3: float = 2.0            # lateral_jerk_rms_mps3 at or below
    smooth_return_s: float = 3.0                 # recovery_time_s at or below, without overshoot
    minimal_oscillations: int = 1                # oscillation_count at or below

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            at_least(f"features.{name}", getattr(self, name), 0.0)


@dataclass(frozen=True)
class Feature:
    """One phrase of the paper as a test on a run's metrics."""

    key: str
    phrase: str
    describes: str          # "baseline" or "improved": whose figure the paper says shows it
    rule: str               # the test in words, for the report
    present: Callable[[dict[str, Any], FeatureConfig], bool | None]


def _value(metrics: dict[str, Any], key: str) -> float:
    value = metrics.get(key)
    if value is None or isinstance(value, str):
        return math.nan
    return float(value)


FeatureTest = Callable[[dict[str, Any], FeatureConfig], bool | None]


def _at_least(key: str, threshold: str) -> FeatureTest:
    def test(m: dict[str, Any], cfg: FeatureConfig) -> bool | None:
        v = _value(m, key)
        return None if math.isnan(v) else v >= getattr(cfg, threshold)
    return test


def _at_most(key: str, threshold: str, missing_means: bool | None = None) -> FeatureTest:
    def test(m: dict[str, Any], cfg: FeatureConfig) -> bool | None:
        v = _value(m, key)
        return missing_means if math.isnan(v) else v <= getattr(cfg, threshold)
    return test


def _smooth_return(m: dict[str, Any], cfg: FeatureConfig) -> bool | None:
    recovery, overshoot = _value(m, "recovery_time_s"), _value(m, "overshoot_m")
    if math.isnan(recovery):
        return False  # never settled back
    return recovery <= cfg.smooth_return_s and not overshoot >= cfg.sharp_return_overshoot_m


FEATURES: tuple[Feature, ...] = (
    Feature("slow_avoidance", "slow ... avoidance", "baseline",
            "reaction delay >= features.slow_reaction_s (or no reaction)",
            lambda m, c: True if math.isnan(_value(m, "reaction_delay_s"))
            else _value(m, "reaction_delay_s") >= c.slow_reaction_s),
    Feature("aggressive_curved", "aggressive curved avoidance", "baseline",
            "peak lateral acceleration >= features.aggressive_lateral_accel_mps2",
            _at_least("lateral_accel_max_mps2", "aggressive_lateral_accel_mps2")),
    Feature("sharp_turns_after", "sharp turns after avoidance", "baseline",
            "overshoot past the line after the pass >= features.sharp_return_overshoot_m",
            _at_least("overshoot_m", "sharp_return_overshoot_m")),
    Feature("uncontrolled", "uncontrolled response", "baseline",
            "yaw-rate reversals over the run >= features.uncontrolled_yaw_reversals",
            _at_least("yaw_rate_sign_changes", "uncontrolled_yaw_reversals")),
    Feature("drops_sharply", "drops sharply and reacts suddenly", "baseline",
            "peak lateral jerk >= features.sudden_jerk_mps3",
            _at_least("lateral_jerk_max_mps3", "sudden_jerk_mps3")),
    Feature("fast_avoidance", "fast ... avoidance", "improved",
            "reaction delay <= features.fast_reaction_s",
            _at_most("reaction_delay_s", "fast_reaction_s", missing_means=False)),
    Feature("smooth_avoidance", "smooth avoidance", "improved",
            "lateral jerk RMS <= features.smooth_jerk_rms_mps3",
            _at_most("lateral_jerk_rms_mps3", "smooth_jerk_rms_mps3")),
    Feature("smooth_return", "returns smoothly to goal direction", "improved",
            "recovered within features.smooth_return_s without an overshoot of "
            "features.sharp_return_overshoot_m", _smooth_return),
    Feature("minimal_oscillation", "minimal oscillation", "improved",
            "oscillations <= features.minimal_oscillations",
            _at_most("oscillation_count", "minimal_oscillations")),
)


def feature_row(metrics: dict[str, Any], cfg: FeatureConfig) -> dict[str, bool | None]:
    """Every feature of one run: present, absent, or None when its metric is missing."""
    return {f.key: f.present(metrics, cfg) for f in FEATURES}


def paper_likeness(baseline: dict[str, bool | None], improved: dict[str, bool | None]) -> int:
    """How many of the paper's descriptions a pair of runs matches: the baseline's phrases
    present in the baseline run, the improved method's in the improved run."""
    return sum(bool((baseline if f.describes == "baseline" else improved).get(f.key))
               for f in FEATURES)
