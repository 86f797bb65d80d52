"""The multiverse's analysis: each specification's ledger rows, and per claim and comparison
how robust the default outcome is and which choice moves it most."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pipeline.analysis.claims import OUTCOMES, family_ledger
from pipeline.store.runs import read_family
from pipeline.studies.multiverse.design import analysis_settings, matches, value_text
from pipeline.studies.multiverse.runs import family_table
from pipeline.studies.multiverse.space import Dimension, Space

ROBUSTNESS_RULE = (
    "per claim and comparison: 'robust' when at least robust_share of the specifications give "
    "the default specification's outcome, 'fragile' when fewer than fragile_share do, "
    "'sensitive' in between. A dimension's influence is the largest share, over its values, of "
    "the specifications with that value whose outcome differs from the default's; the most "
    "influential dimension is the one with the largest influence (ties: the larger spread of "
    "median estimates across its values), named with the values that flip most of their "
    "specifications (or the one value that flips the most)")


def analyse_specification(row: dict, folders: dict[str, Path], space: Space,
                          out_dir: Path) -> list[dict]:
    """Ledger rows (C0-C5 against each control) of one specification; ``folders`` holds the
    controls' families, then the treatment's (:func:`run_simulations`' order)."""
    treatment = list(folders)[-1]
    base = read_family(folders[treatment], members=False).settings
    metrics, claims = analysis_settings(row, space, base)
    tables = {m: family_table(folders[m], metrics, out_dir) for m in folders}
    ledger = family_ledger(tables, claims, improved=treatment,
                           comparisons=tuple(m for m in folders if m != treatment),
                           sensitivity=False)
    return [{"spec_id": row["spec_id"], "claim": r.claim_id, "comparison": r.comparison,
             "metric": r.claim.primary_metric, "estimate": r.result.estimate,
             "ci_low": r.result.ci_low, "ci_high": r.result.ci_high, "p_holm": r.p_holm,
             "prob_improvement": r.result.prob_improvement, "n_pairs": r.result.n_pairs,
             "margin": r.margin, "outcome": str(r.outcome)} for r in ledger]


def robustness(results: pd.DataFrame, design: pd.DataFrame, space: Space
               ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per claim and comparison: outcome shares, label, most influential dimension; and per
    dimension and value: the share of flipped outcomes and the median estimate.

    Returns
    -------
    robustness : DataFrame
    dimensions : DataFrame
    """
    merged = results.merge(design, on="spec_id")
    default_id = design.loc[design["kind"] == "default", "spec_id"].iloc[0]
    rows: list[dict[str, Any]] = []
    dim_rows: list[dict[str, Any]] = []
    for (claim, comparison), part in merged.groupby(["claim", "comparison"], sort=False):
        base = part[part["spec_id"] == default_id]
        default_outcome = base["outcome"].iloc[0] if len(base) else "n/a"
        flipped = part["outcome"] != default_outcome
        shares = {f"share_{o}": float(np.mean(part["outcome"] == o)) for o in OUTCOMES}
        agree = 1.0 - float(np.mean(flipped))
        label = "robust" if agree >= space.robust_share else (
            "fragile" if agree < space.fragile_share else "sensitive")
        best, best_key, holds = _most_influential(part, space, default_outcome, claim,
                                                  comparison, dim_rows)
        rows.append({"claim": claim, "comparison": comparison,
                     "default_outcome": default_outcome, "agree_share": agree, "label": label,
                     **shares, "n_specifications": int(len(part)),
                     "most_influential": best[0] if best else "",
                     "influence": best_key[0], "flipping_values": ", ".join(best[1]) if best
                     else "", "estimate_spread": best[2] if best else float("nan"),
                     # the choices under which most specifications support the claim
                     "holds_with": "; ".join(f"{name} ({100 * share:.0f} %)" for share, name
                                             in sorted(holds, reverse=True)[:6])})
    return pd.DataFrame(rows), pd.DataFrame(dim_rows)


def _most_influential(part: pd.DataFrame, space: Space, default_outcome: str, claim: str,
                      comparison: str, dim_rows: list[dict]) -> tuple:
    """Of one claim and comparison's specifications ``part``: the most influential dimension
    ``(key, flipping values, estimate spread)`` (None without one), its ``(influence,
    spread)``, and the ``(supported share, choice)`` pairs under which most specifications
    support the claim; each dimension value's row is appended to ``dim_rows``."""
    best: tuple[str, list[str], float] | None = None
    best_key = (-1.0, -1.0)
    holds: list[tuple[float, str]] = []
    for dim in space.dimensions:
        per_value = _value_effects(part, dim, default_outcome, claim, comparison, holds,
                                   dim_rows)
        if not per_value:
            continue
        influence = max(v[1] for v in per_value)
        estimates = [v[2] for v in per_value if np.isfinite(v[2])]
        spread = (max(estimates) - min(estimates)) if estimates else 0.0
        if (influence, spread) > best_key:
            flips = [str(v[0]) for v in per_value if v[1] >= 0.5 and v[0] != dim.default]
            if not flips and influence > 0:
                # no value flips most of its specifications: name the one that flips most
                flips = [str(max(per_value, key=lambda v: v[1])[0])]
            best, best_key = (dim.key, flips, spread), (influence, spread)
    return best, best_key, holds


def _value_effects(part: pd.DataFrame, dim: Dimension, default_outcome: str, claim: str,
                   comparison: str, holds: list, dim_rows: list[dict]) -> list[tuple]:
    """Per value of ``dim`` present in ``part``: ``(value, flipped share, median estimate)``;
    the value's row appended to ``dim_rows``, and to ``holds`` when most of its
    specifications support the claim."""
    per_value = []
    for value in dim.values:
        subset = part[matches(part[dim.key], value)]
        if not len(subset):
            continue
        flip_share = float(np.mean(subset["outcome"] != default_outcome))
        estimate = float(np.nanmedian(subset["estimate"])) if \
            subset["estimate"].notna().any() else float("nan")
        outcomes = subset["outcome"].value_counts()
        supported = float(np.mean(subset["outcome"] == "supported"))
        if supported >= 0.5:
            holds.append((supported, f"{dim.key}={value_text(value)}"))
        per_value.append((value, flip_share, estimate))
        dim_rows.append({"claim": claim, "comparison": comparison, "dimension": dim.key,
                         "value": value_text(value), "default": value == dim.default,
                         "n_specifications": int(len(subset)),
                         "flipped_share": flip_share, "median_estimate": estimate,
                         "modal_outcome": outcomes.index[0],
                         "supported_share": supported})
    return per_value
