"""Ablation analysis: which revision of the APF does what, and do the verdicts survive the
alternative readings of the interpretation register.

Reads family jobs (``family.json`` + ``family_metrics.csv``) written by
``experiment=ablation`` (labels ``baseline``, ``improved``, ``baseline+<revision>``,
``improved-<revision>``) and ``experiment=interpretations`` (one folder per variant, baseline
and improved inside). Pure functions over tables; the report draws and prints them.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.claims import CLAIMS, bootstrap_median_ci, family_ledger, median_of, paired_differences

REVISIONS = ("normalize", "step", "beta", "exponential", "step_min")
REVISION_TEXT = {
    "normalize": "no normalization of F (with its step cap)",
    "step": "larger step (alpha = 0.2)",
    "beta": "beta sensitivity of H_i",
    "exponential": "exponential repulsion",
    "step_min": "minimum movement threshold",
}


def load_family_jobs(root: Path) -> dict[str, pd.DataFrame]:
    """``{label: family_metrics}`` of every family job below ``root`` (label = its method)."""
    tables = {}
    for info_path in sorted(Path(root).rglob("family.json")):
        info = json.loads(info_path.read_text())
        tables[info["method"]] = pd.read_csv(info_path.parent / "family_metrics.csv")
    return tables


def ablation_effects(tables: dict[str, pd.DataFrame], seed: int = 0) -> pd.DataFrame:
    """Paired effect of every configuration versus the baseline, per claim.

    Returns
    -------
    DataFrame
        Rows ``(configuration, claim)`` with the median paired difference (configuration -
        baseline, signed so that < 0 is the claimed improvement), its 95 % bootstrap interval and
        the share of scenarios where it holds; plus collision and non-recovery counts.
    """
    baseline = tables["baseline"]
    rng = np.random.default_rng(seed)
    order = (["improved"] + [f"baseline+{r}" for r in REVISIONS]
             + [f"improved-{r}" for r in REVISIONS])
    rows = []
    for label in [o for o in order if o in tables]:
        table = tables[label]
        for claim in CLAIMS:
            d = paired_differences(table, baseline, claim)
            low, high = bootstrap_median_ci(d, rng)
            rows.append({"configuration": label, "claim": claim.claim_id,
                         "metric": claim.primary_metric,
                         "median_effect": float(median_of(d)) if d.size else np.nan,
                         "ci_low": low, "ci_high": high,
                         "holds_share": float(np.mean(d < -claim.tolerance)) if d.size else np.nan,
                         "n_pairs": int(d.size),
                         "collisions": int(table["collision"].astype(bool).sum()),
                         "not_recovered": int((~table["recovered"].astype(bool)).sum())})
    return pd.DataFrame(rows)


def attribution_sentences(effects: pd.DataFrame) -> dict[str, str]:
    """One sentence per claim naming the revision that accounts for most of the effect.

    Rule: take the improved bundle's median effect on the claim. Among the revisions added alone
    to the baseline, the one whose median effect has the same sign and the largest size accounts
    for most of it if its interval excludes zero; the leave-one-out row of that revision (the
    improved bundle without it) is quoted beside it. Otherwise no single revision does.
    """
    sentences = {}
    for claim in CLAIMS:
        part = effects[effects["claim"] == claim.claim_id].set_index("configuration")
        if "improved" not in part.index:
            continue
        total = part.loc["improved", "median_effect"]
        direction = "improves" if total < 0 else ("worsens" if total > 0 else "does not change")
        singles = part.loc[[f"baseline+{r}" for r in REVISIONS if f"baseline+{r}" in part.index]]
        same_sign = singles[np.sign(singles["median_effect"]) == np.sign(total)] if total != 0 \
            else singles.iloc[0:0]
        significant = same_sign[(same_sign["ci_high"] < 0) | (same_sign["ci_low"] > 0)]
        text = (f"{claim.claim_id} ({claim.primary_metric}): the improved bundle {direction} it "
                f"(median effect {total:+.3g}).")
        if len(significant):
            best = significant["median_effect"].abs().idxmax()
            revision = best.split("+", 1)[1]
            row = significant.loc[best]
            text += (f" Alone, '{REVISION_TEXT[revision]}' accounts for most of it "
                     f"({row['median_effect']:+.3g} [{row['ci_low']:.3g}, {row['ci_high']:.3g}])")
            loo = f"improved-{revision}"
            if loo in part.index:
                text += f"; without it the bundle's effect is {part.loc[loo, 'median_effect']:+.3g}"
            text += "."
        else:
            text += " No single revision accounts for it (no revision alone has an effect of " \
                    "the same sign whose interval excludes zero)."
            if total != 0:
                # which revisions the effect needs: leaving one out removes the effect
                needed = [r for r in REVISIONS if f"improved-{r}" in part.index
                          and not (np.sign(part.loc[f"improved-{r}", "median_effect"])
                                   == np.sign(total)
                                   and (part.loc[f"improved-{r}", "ci_high"] < 0
                                        or part.loc[f"improved-{r}", "ci_low"] > 0))]
                if needed:
                    text += (" It needs the revisions together: leaving out any of "
                             + ", ".join(f"'{REVISION_TEXT[r]}'" for r in needed)
                             + " removes it.")
        sentences[claim.claim_id] = text
    return sentences


def interpretation_flips(root: Path) -> pd.DataFrame | None:
    """Family verdicts of every interpretation variant and whether they differ from the default.

    ``root`` holds ``<variant>/<method>/family.json`` for methods baseline and improved.
    """
    root = Path(root)
    variants = sorted(p.name for p in root.iterdir() if p.is_dir()) if root.is_dir() else []
    verdicts = {}
    for variant in variants:
        tables = load_family_jobs(root / variant)
        if "baseline" in tables and "improved" in tables:
            ledger, _ = family_ledger(tables)
            verdicts[variant] = {r["claim"]: r["verdict"] for r in ledger}
            verdicts[variant]["collisions_improved"] = int(tables["improved"]["collision"].sum())
    if "default" not in verdicts:
        return None
    rows = []
    for variant, result in verdicts.items():
        row = {"variant": variant}
        flipped = []
        for claim in CLAIMS:
            row[claim.claim_id] = result[claim.claim_id]
            if result[claim.claim_id] != verdicts["default"][claim.claim_id]:
                flipped.append(claim.claim_id)
        row["collisions_improved"] = result["collisions_improved"]
        row["flips"] = ", ".join(flipped) if flipped else "none"
        rows.append(row)
    return pd.DataFrame(rows)
