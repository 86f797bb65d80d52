"""Counts over a table of runs (one row per scenario), computed in one place: collisions (and
whether they were avoidable: the published label where the table carries it, see
:mod:`pipeline.analysis.unavoidable`), non-recoveries, scenarios without a threat, goal not reached,
validity exceedances, fallbacks, how often the APF's step cap binds."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import pandas as pd


def _flags(table: pd.DataFrame, column: str, default: bool = False) -> pd.Series:
    """A boolean column (``True``/``False`` written as text by CSV included); ``default``
    where the column is absent."""
    if column not in table:
        return pd.Series([default] * len(table), index=table.index, dtype=bool)

    def read(v: object) -> bool:
        if isinstance(v, str):
            return v.strip().lower() == "true"
        return default if v is None or v != v else bool(v)  # NaN: unknown, the default

    return table[column].map(read).astype(bool)


def optional_flags(table: pd.DataFrame, column: str) -> pd.Series:
    """True / False / None (not applicable) per row."""
    if column not in table:
        return pd.Series([None] * len(table), index=table.index, dtype=object)

    def read(v: object) -> bool | None:
        if isinstance(v, (bool, np.bool_)):
            return bool(v)
        text = str(v).lower()
        return {"true": True, "false": False}.get(text)
    return table[column].map(read)


def collided(table: pd.DataFrame) -> pd.Series:
    """Per row: did the run collide."""
    return _flags(table, "collision")


def not_recovered(table: pd.DataFrame) -> pd.Series:
    """Per row: did the run not recover within its length."""
    return ~_flags(table, "recovered", default=True)


@dataclass(frozen=True)
class Tally:
    """Counts of one method over a table of scenarios.

    ``collisions_unavoidable`` is the published label's count: where the table was labelled
    across methods (:func:`pipeline.analysis.unavoidable.label_across_methods`) a collision
    another method avoided on the same scenario is avoidable; ``collisions_unavoidable_run``
    counts the runs' own labels (equal where the table was not labelled across methods).
    """

    scenarios: int
    collisions: int
    collisions_avoidable: int
    collisions_unavoidable: int
    collisions_unavoidable_run: int
    not_recovered: int
    no_threat: int
    goal_not_reached: int
    heading_validity_exceeded: int
    fallback_steps: int
    step_cap_binding_share: float
    min_clearance_median_m: float

    @classmethod
    def of(cls, table: pd.DataFrame) -> Tally:
        hit = collided(table)
        # the published label (the table's collision_avoidable once labelled across methods)
        avoidable = optional_flags(table, "collision_avoidable")
        unavoidable = int((hit & (avoidable == False)).sum())
        # the runs' own labels where they were kept beside it
        run = optional_flags(table, "collision_unavoidable_run") \
            if "collision_unavoidable_run" in table else None
        return cls(
            scenarios=int(len(table)), collisions=int(hit.sum()),
            collisions_avoidable=int((hit & (avoidable == True)).sum()),
            collisions_unavoidable=unavoidable,
            collisions_unavoidable_run=unavoidable if run is None
            else int((hit & (run == True)).sum()),
            not_recovered=int(not_recovered(table).sum()),
            no_threat=int((~_flags(table, "threatened", default=True)).sum()),
            goal_not_reached=int((~_flags(table, "goal_reached", default=True)).sum()),
            heading_validity_exceeded=int(_flags(table, "heading_validity_exceeded").sum()),
            fallback_steps=int(pd.to_numeric(table["fallback_count"], errors="coerce")
                               .fillna(0).sum()) if "fallback_count" in table else 0,
            step_cap_binding_share=float(pd.to_numeric(table["step_cap_binding_share"],
                                                       errors="coerce").mean())
            if "step_cap_binding_share" in table else float("nan"),
            min_clearance_median_m=float(pd.to_numeric(table["min_clearance_m"],
                                                       errors="coerce").median())
            if "min_clearance_m" in table else float("nan"))

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
