"""What a run returns to a tuner: statistics of metrics over a family's members.

``tune.objectives`` lists them (metric, statistic, direction); ``python -m pipeline.run``
returns their values (a float for one objective, a tuple for several), so that a sweeper of
Hydra's can rank runs by any metric of the ledger, and ``make tune`` computes the same values
with :func:`objective_values`.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import List

import numpy as np
import pandas as pd

from pipeline.analysis.metrics.results import METRIC_KEYS
from pipeline.errors import ConfigError
from pipeline.validation import FrozenAfterValidation, choice

#: Statistics over a family's members: mean, median, or a quantile ``q<percent>`` (q90).
STATISTIC_PATTERN = re.compile(r"^(mean|median|q(100|[1-9]?[0-9]))$")


@dataclass
class Objective(FrozenAfterValidation):
    """One objective: ``statistic`` of ``metric`` over the members, to ``direction``.

    Members without a value (e.g. no reaction to time) are left out of the statistic; when no
    member has one, the objective is the worst value (``inf`` for minimize, ``-inf`` for
    maximize), so a tuner never prefers a setting that shows nothing.
    """

    metric: str = "reaction_delay_s"
    statistic: str = "mean"
    direction: str = "minimize"

    # checked by the list that holds it (TuneConfig, TuneSpace), which knows its index

    def check(self, key: str) -> None:
        """Range checks with the full key path (``tune.objectives[1]``)."""
        if self.metric not in METRIC_KEYS:
            raise ConfigError(f"{key}.metric", self.metric,
                              "a metric of metrics.json (e.g. reaction_delay_s, "
                              "lateral_jerk_rms_mps3, recovery_time_s, collision)")
        if not isinstance(self.statistic, str) or not STATISTIC_PATTERN.match(self.statistic):
            raise ConfigError(f"{key}.statistic", self.statistic,
                              "mean, median or a quantile q0-q100 (e.g. q90)")
        choice(f"{key}.direction", self.direction, ("minimize", "maximize"))

    @property
    def label(self) -> str:
        return f"{self.statistic} {self.metric}"


@dataclass
class TuneConfig(FrozenAfterValidation):
    """``tune.*``: what ``pipeline.run`` returns (outside the run's config hash)."""

    objectives: List[Objective] = field(default_factory=lambda: [Objective()])

    def __post_init__(self) -> None:
        if not self.objectives:
            raise ConfigError("tune.objectives", [], "a list of at least one objective")
        for i, objective in enumerate(self.objectives):
            objective.check(f"tune.objectives[{i}]")


def objective_value(values: np.ndarray, objective: Objective) -> float:
    """``objective.statistic`` of the finite ``values`` (the worst value when none is)."""
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return math.inf if objective.direction == "minimize" else -math.inf
    if objective.statistic == "mean":
        return float(np.mean(values))
    if objective.statistic == "median":
        return float(np.median(values))
    return float(np.quantile(values, int(objective.statistic[1:]) / 100.0))


def objective_values(table: pd.DataFrame, objectives: list[Objective]) -> tuple[float, ...]:
    """The objectives over a family table (``family_metrics.csv``; one row for one run)."""
    out = []
    for objective in objectives:
        column = table[objective.metric] if objective.metric in table else pd.Series(dtype=float)
        out.append(objective_value(pd.to_numeric(column, errors="coerce").to_numpy(float),
                                   objective))
    return tuple(out)


#: Metrics that a run can fail to show before it ends, with the column of their clock's start
#: and the flag that says the event happened: censored at the run's end, such a member counts
#: with ``duration_s - start`` (a lower bound of its true value) instead of being dropped.
CENSORED_AT_RUN_END = {"reaction_delay_s": ("threat_appear_time_s", "reacted"),
                       "recovery_time_s": ("obstacle_passed_time_s", "recovered")}


def tuning_table(table: pd.DataFrame, censoring: str = "run_end") -> pd.DataFrame:
    """A family table as the tuning objectives read it, the way the ledger treats its members:
    collided members left out (the ledger judges C1-C5 on pairs where neither collided and
    counts collisions in C0; the tuning counts them in its safety constraint), and with
    ``censoring="run_end"`` a member that never reacted or never recovered counted at the run's
    end (:data:`CENSORED_AT_RUN_END`) rather than dropped (``"drop"``: left out)."""
    out = table.copy()
    if "collision" in out:
        out = out[~out["collision"].astype(bool)]
    if censoring != "run_end" or "duration_s" not in out:
        return out
    duration = pd.to_numeric(out["duration_s"], errors="coerce")
    for metric, (start, flag) in CENSORED_AT_RUN_END.items():
        if metric not in out or start not in out:
            continue
        value = pd.to_numeric(out[metric], errors="coerce")
        begun = pd.to_numeric(out[start], errors="coerce")
        missed = value.isna() & begun.notna()
        if flag in out:
            missed &= ~out[flag].astype(bool)
        out[metric] = value.where(~missed, duration - begun)
    return out
