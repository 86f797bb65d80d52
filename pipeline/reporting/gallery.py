"""A gallery of family members chosen by rule, drawn like the Figure 2/3 analogues.

The rule (:func:`gallery_members`): for the treatment and its first control, the member where
each collided worst (the deepest penetration, i.e. the lowest minimum clearance among its
collisions); for C1, C2 and C4 the member with the largest paired difference on the claim's
primary metric (among the pairs where neither collided); and a typical member (the treatment's
minimum clearance nearest its median over the members where neither collided). A member picked
twice is drawn once, with both reasons.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

#: the claims whose largest differences the gallery shows (the visible ones on a path)
GALLERY_CLAIMS = ("C1", "C2", "C4")


def _flags(table: pd.DataFrame, column: str) -> pd.Series:
    values = table[column] if column in table else pd.Series(False, index=table.index)
    return values.map(lambda v: str(v).strip().lower() in ("true", "1", "1.0"))


def gallery_members(tables: dict[str, pd.DataFrame], treatment: str, control: str,
                    primary_metrics: dict[str, str]) -> list[dict]:
    """Members to draw, in order, each ``{"member": int, "why": [str, ...]}``.

    Parameters
    ----------
    tables : dict of method -> family_metrics table (with ``member``)
    treatment, control : str
    primary_metrics : dict of claim id -> primary metric column
    """
    if treatment not in tables or control not in tables:
        return []
    a = tables[treatment].set_index("member")
    b = tables[control].set_index("member")
    common = a.index.intersection(b.index)
    a, b = a.loc[common], b.loc[common]
    picks: dict[int, list[str]] = {}

    def add(member, why: str) -> None:
        picks.setdefault(int(member), []).append(why)

    for method, table in ((treatment, a), (control, b)):
        collided = _flags(table, "collision")
        if collided.any() and "min_clearance_m" in table:
            clearance = pd.to_numeric(table.loc[collided, "min_clearance_m"], errors="coerce")
            if clearance.notna().any():
                add(clearance.idxmin(), f"{method}'s worst collision "
                                        f"({clearance.min():.2f} m clearance)")
    neither = ~(_flags(a, "collision") | _flags(b, "collision"))
    for claim in GALLERY_CLAIMS:
        metric = primary_metrics.get(claim)
        if metric is None or metric not in a or metric not in b:
            continue
        diff = (pd.to_numeric(a[metric], errors="coerce")
                - pd.to_numeric(b[metric], errors="coerce"))[neither]
        diff = diff[np.isfinite(diff)]
        if len(diff):
            member = diff.abs().idxmax()
            add(member, f"largest {claim} difference ({metric}: {diff[member]:+.3g})")
    if "min_clearance_m" in a and neither.any():
        clearance = pd.to_numeric(a.loc[neither, "min_clearance_m"], errors="coerce").dropna()
        if len(clearance):
            member = (clearance - clearance.median()).abs().idxmin()
            add(member, f"typical ({treatment}'s clearance {clearance[member]:.2f} m, median "
                        f"{clearance.median():.2f} m)")
    return [{"member": m, "why": why} for m, why in picks.items()]
