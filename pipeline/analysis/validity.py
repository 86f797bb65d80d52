"""Does the MPC's model hold where the verdicts are made? One row per track, frame and method
over a scenario family, and the verdicts again on the scenarios where both methods' models held.

Each run's trajectory carries, per step, how that step's prediction held against the plant
(:func:`pipeline.loop.controller.prediction_check.prediction_check`); its ``metrics.json`` the run's
shares (:class:`pipeline.analysis.metrics.ModelValidity`). A row pools them over the family:
shares as the mean over runs of each run's share, errors as quantiles over every step of every
run. ``reports/latest/tables/model_validity.csv`` is the rows' :meth:`ValidityTable.to_frame`.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
import pandas as pd

from pipeline.analysis.claims.ledger import Ledger, family_ledger
from pipeline.analysis.claims.memo import IntervalMemo
from pipeline.analysis.settings import ClaimsConfig


@dataclass(frozen=True)
class ValidityRow:
    """One track, frame and method over a family (shares 0-1, errors in metres)."""

    track: str
    frame: str
    method: str
    runs: int
    runs_beyond_bound: int
    share_steps_beyond_bound: float
    share_steps_tyre_nonlinear: float
    share_steps_path_beyond_limit: float
    prediction_error_1s_p50_m: float
    prediction_error_1s_p95_m: float
    plan_error_1s_p50_m: float
    plan_error_1s_p95_m: float


#: Columns of ``model_validity.csv``, in order.
VALIDITY_COLUMNS = tuple(f.name for f in fields(ValidityRow))


def _mean(values: list[float]) -> float:
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return float(v.mean()) if v.size else float("nan")


def _pooled(values: list[np.ndarray], q: float) -> float:
    v = np.concatenate(values) if values else np.zeros(0)
    v = v[np.isfinite(v)]
    return float(np.percentile(v, q)) if v.size else float("nan")


#: The trajectory columns :func:`validity_row` reads.
VALIDITY_READS = ("model_error_1s_m", "plan_error_1s_m")


def validity_row(track: str, frame: str, method: str,
                 members: Iterable[tuple[pd.DataFrame, dict[str, Any]]]) -> ValidityRow:
    """The row of one family from its members' ``(trajectory, metrics.json mapping)``."""
    runs = beyond = 0
    shares: dict[str, list[float]] = {"share_steps_beyond_bound": [],
                                      "share_steps_tyre_nonlinear": [],
                                      "share_steps_path_beyond_limit": []}
    model, plan = [], []
    for trajectory, metrics in members:
        runs += 1
        beyond += bool(metrics.get("heading_validity_exceeded")) \
            and np.isfinite(metrics.get("model_heading_error_max_rad") or np.nan)
        for key in shares:
            value = metrics.get(key)
            shares[key].append(np.nan if value is None else float(value))
        if "model_error_1s_m" in trajectory:
            model.append(trajectory["model_error_1s_m"].to_numpy(float))
            plan.append(trajectory["plan_error_1s_m"].to_numpy(float))
    any_bound = any(np.isfinite(v) for v in shares["share_steps_beyond_bound"])
    return ValidityRow(
        track=track, frame=frame, method=method, runs=runs,
        runs_beyond_bound=int(beyond) if any_bound else -1,
        share_steps_beyond_bound=_mean(shares["share_steps_beyond_bound"]),
        share_steps_tyre_nonlinear=_mean(shares["share_steps_tyre_nonlinear"]),
        share_steps_path_beyond_limit=_mean(shares["share_steps_path_beyond_limit"]),
        prediction_error_1s_p50_m=_pooled(model, 50), prediction_error_1s_p95_m=_pooled(model, 95),
        plan_error_1s_p50_m=_pooled(plan, 50), plan_error_1s_p95_m=_pooled(plan, 95))


@dataclass(frozen=True)
class ValidityTable:
    """The rows of every family the report found."""

    rows: tuple[ValidityRow, ...]

    def to_frame(self) -> pd.DataFrame:
        """``model_validity.csv``: one row per track, frame and method (``runs_beyond_bound``
        empty where the model has no small-angle bound, the kinematic track's)."""
        frame = pd.DataFrame([asdict(r) for r in self.rows], columns=list(VALIDITY_COLUMNS))
        frame["runs_beyond_bound"] = frame["runs_beyond_bound"].astype("Int64").where(
            frame["runs_beyond_bound"] >= 0)
        return frame

    def row(self, track: str, frame: str, method: str) -> ValidityRow | None:
        return next((r for r in self.rows if (r.track, r.frame, r.method)
                     == (track, frame, method)), None)


def valid_in_both(treatment: pd.DataFrame, control: pd.DataFrame) -> set[Any]:
    """Scenarios (``scenario`` values) where neither method's run left its model's validity."""
    def valid(table: pd.DataFrame) -> set[Any]:
        flags = table["heading_validity_exceeded"] if "heading_validity_exceeded" in table \
            else pd.Series(False, index=table.index)
        exceeded = flags.map(lambda v: str(v).strip().lower() in ("true", "1", "1.0"))
        return set(table.loc[~exceeded, "scenario"])

    return valid(treatment) & valid(control)


def valid_scenario_ledgers(tables: dict[str, pd.DataFrame], claims: ClaimsConfig,
                           treatment: str, comparisons: tuple[str, ...],
                           memo: IntervalMemo | None = None) -> dict[str, tuple[Ledger, int]]:
    """Per comparison: the claims ledger on the scenarios where both methods' models held
    (:func:`valid_in_both`), and how many scenarios that is (intervals recalled from
    ``memo`` where it holds them)."""
    out = {}
    for comparison in comparisons:
        if treatment not in tables or comparison not in tables:
            continue
        keep = valid_in_both(tables[treatment], tables[comparison])
        subset = {m: tables[m][tables[m]["scenario"].isin(keep)]
                  for m in (treatment, comparison)}
        ledger = family_ledger(subset, claims, None, treatment, (comparison,),
                               sensitivity=False, memo=memo) if keep else Ledger((), treatment)
        out[comparison] = (ledger, len(keep))
    return out
