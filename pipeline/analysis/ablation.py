"""Ablation analysis: which revision of the APF does what, and do the verdicts survive the
alternative readings of the interpretation register.

Pure functions over the family tables of ``experiment=ablation`` (labels ``baseline``,
``improved``, ``baseline+<revision>``, ``improved-<revision>``) and of
``experiment=interpretations`` (per variant, baseline and improved), which the store reads
(:func:`pipeline.store.collection.family_tables_by_method`); the report draws and prints them.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from pipeline.analysis.claims import ALL_CLAIMS, CLAIMS, Claim, compare, family_ledger, judge
from pipeline.analysis.settings import ClaimsConfig
from pipeline.analysis.tally import Tally

REVISIONS = ("normalize", "step", "beta", "exponential", "step_min")
REVISION_TEXT = {
    "normalize": "no normalization of F (with its step cap)",
    "step": "larger step (alpha = 0.2)",
    "beta": "beta sensitivity of H_i",
    "exponential": "exponential repulsion",
    "step_min": "minimum movement threshold",
}


def ablation_roles(tables: Mapping[str, object], cfg: ClaimsConfig | None) -> tuple[str, str]:
    """The bundle and the reference of the ablation: the claims' treatment and first control
    (``claims.treatment``, ``claims.controls[0]``) when the ablation has them, else the
    paper's improved and baseline."""
    treatment = getattr(cfg, "treatment", "improved")
    controls = list(getattr(cfg, "controls", None) or ["baseline"])
    bundle = treatment if treatment in tables else "improved"
    reference = controls[0] if controls[0] in tables else "baseline"
    return bundle, reference


def ablation_effects(tables: dict[str, pd.DataFrame], cfg: ClaimsConfig) -> pd.DataFrame:
    """Paired effect of every configuration versus the reference (:func:`ablation_roles`:
    the first control, by default the baseline), per claim, computed as the
    claims ledger does (:func:`pipeline.analysis.claims.compare`: pairs where neither collided, missing
    values apart, Hodges-Lehmann estimate, bootstrap interval, unadjusted test).

    Returns
    -------
    DataFrame
        Rows ``(configuration, claim)``: ``effect`` (configuration - baseline, < 0 is the
        claimed improvement), ``ci_low``, ``ci_high``, ``outcome`` against the claim's margin,
        counts; plus collision and non-recovery counts of the configuration.
    """
    bundle, reference = ablation_roles(tables, cfg)
    baseline = tables[reference]
    order = ([bundle, "improved", "baseline_matched"] + [f"baseline+{r}" for r in REVISIONS]
             + [f"improved-{r}" for r in REVISIONS])
    # a user's own configurations (any other label) follow the paper's, in sorted order
    order = list(dict.fromkeys(order + sorted(tables)))
    rows = []
    for label in [o for o in order if o in tables and o != reference]:
        table = tables[label]
        for claim in CLAIMS:
            result = compare(table, baseline, claim, cfg)
            outcome, _ = judge(result, cfg.margins[claim.claim_id], cfg, claim)
            tally = Tally.of(table)
            rows.append({"configuration": label, "claim": claim.claim_id,
                         "metric": claim.primary_metric, "effect": result.estimate,
                         "ci_low": result.ci_low, "ci_high": result.ci_high,
                         "outcome": str(outcome), "n_pairs": result.n_pairs,
                         "collisions": tally.collisions, "not_recovered": tally.not_recovered})
    return pd.DataFrame(rows)


def _clear(row: pd.Series) -> bool:
    return bool(row["ci_high"] < 0 or row["ci_low"] > 0)


def attribution_sentences(effects: pd.DataFrame, tables: dict[str, pd.DataFrame] | None = None,
                          cfg: ClaimsConfig | None = None) -> dict[str, str]:
    """One sentence per claim naming the revision that accounts for most of the effect, checked
    against the look-ahead-matched control.

    Rule: take the improved bundle's effect on the claim. Among the revisions added alone to the
    baseline, the one whose effect has the same sign and the largest size accounts for most of
    it if its interval excludes zero; the leave-one-out row of that revision is quoted beside
    it. Otherwise no single revision does. When the improved rollout's step cap binds on at
    least ``cfg.cap_binding_share`` of its steps, the sentence says that 'no normalization' and
    'a larger step' are inactive there, and quotes ``baseline_matched`` (the baseline with the
    cap's normalized step): an effect that ``baseline_matched`` shares is look-ahead length, not
    the other revisions.
    """
    sentences = {}
    cap_share = None
    bundle = ablation_roles(tables, cfg)[0] if tables is not None and cfg is not None \
        else "improved"
    if tables is not None and bundle in tables \
            and "step_cap_binding_share" in tables[bundle]:
        cap_share = float(tables[bundle]["step_cap_binding_share"].mean())
    binding = cap_share is not None and cfg is not None and cap_share >= cfg.cap_binding_share
    for claim in CLAIMS:
        part = effects[effects["claim"] == claim.claim_id].set_index("configuration")
        if bundle not in part.index:
            continue
        sentences[claim.claim_id] = _attribution_sentence(claim, part, bundle, binding,
                                                          cap_share)
    return sentences


def _attribution_sentence(claim: Claim, part: pd.DataFrame, bundle: str, binding: bool,
                          cap_share: float | None) -> str:
    """The attribution sentence of one claim (``part``: its effects by configuration)."""
    total = part.loc[bundle, "effect"]
    direction = "improves" if total < 0 else ("worsens" if total > 0 else "does not change")
    name = "the improved bundle" if bundle == "improved" else f"{bundle}"
    text = (f"{claim.claim_id} ({claim.primary_metric}): {name} {direction} it "
            f"(effect {total:+.3g}, {part.loc[bundle, 'outcome']}).")
    singles = part.loc[[f"baseline+{r}" for r in REVISIONS if f"baseline+{r}" in part.index]]
    if binding:
        # the cap makes these two revisions inactive: do not credit them
        singles = singles.drop(index=[i for i in ("baseline+normalize", "baseline+step")
                                      if i in singles.index])
    same_sign = singles[np.sign(singles["effect"]) == np.sign(total)] if total != 0 \
        else singles.iloc[0:0]
    significant = same_sign[same_sign.apply(_clear, axis=1)] if len(same_sign) else same_sign
    if "baseline_matched" in part.index:
        text += _matched_baseline_text(part.loc["baseline_matched"], total)
    # a revision accounts for most of the effect only when, alone, it has at least half
    # of the bundle's effect (same sign, interval clear of zero)
    large = significant[significant["effect"].abs() >= 0.5 * abs(total)] \
        if len(significant) else significant
    if len(large):
        text += _accounting_revision_text(part, large)
    else:
        text += _no_single_revision_text(part, total, binding)
    if binding and cap_share is not None:
        text += (f" The step cap binds on {100 * cap_share:.0f} % of improved's rollout "
                 "steps, so 'no normalization' and 'a larger step' are inactive there and "
                 "are not credited.")
    return text


def _matched_baseline_text(matched: pd.Series, total: float) -> str:
    """Whether the look-ahead-matched baseline alone shares the bundle's effect."""
    shares = np.sign(matched["effect"]) == np.sign(total) and _clear(matched) \
        and total != 0
    return (f" The look-ahead-matched baseline alone {'shares' if shares else 'does not share'}"
            f" it (effect {matched['effect']:+.3g}, {matched['outcome']})"
            + (": the effect is look-ahead length, not the other revisions." if shares
               and abs(matched["effect"]) >= 0.5 * abs(total) else "."))


def _accounting_revision_text(part: pd.DataFrame, large: pd.DataFrame) -> str:
    """The revision that alone accounts for most of the effect, and the bundle without it."""
    best = large["effect"].abs().idxmax()
    revision = best.split("+", 1)[1]
    row = large.loc[best]
    text = (f" Alone, '{REVISION_TEXT[revision]}' accounts for most of it "
            f"({row['effect']:+.3g} [{row['ci_low']:.3g}, {row['ci_high']:.3g}])")
    loo = f"improved-{revision}"
    if loo in part.index:
        text += f"; without it the bundle's effect is {part.loc[loo, 'effect']:+.3g}"
    return text + "."


def _no_single_revision_text(part: pd.DataFrame, total: float, binding: bool) -> str:
    """No single revision accounts for the effect; the revisions without which it shrinks."""
    text = (" No single active revision accounts for it (none alone has at least half "
            "of the effect, of the same sign, with an interval clear of zero).")
    if total != 0:
        needed = [r for r in REVISIONS if f"improved-{r}" in part.index
                  and not (binding and r in ("normalize", "step"))
                  and abs(part.loc[f"improved-{r}", "effect"]) < 0.5 * abs(total)]
        if needed:
            text += (" It needs the revisions together: without "
                     + ", or without ".join(
                         f"'{REVISION_TEXT[r]}' the bundle's effect is "
                         f"{part.loc[f'improved-{r}', 'effect']:+.3g}" for r in needed)
                     + ".")
    return text


def interpretation_flips(variants: dict[str, dict[str, pd.DataFrame]], cfg: ClaimsConfig
                         ) -> pd.DataFrame | None:
    """Family verdicts of every interpretation variant and whether they differ from the default.

    ``variants``: per variant (in name order), its family tables by method (baseline and
    improved; :func:`pipeline.store.collection.interpretation_tables`).
    """
    verdicts: dict[str, dict[str, Any]] = {}
    for variant, tables in variants.items():
        bundle, reference = ablation_roles(tables, cfg)
        if reference in tables and bundle in tables:
            ledger = family_ledger(tables, cfg, improved=bundle, comparisons=(reference,))
            verdicts[variant] = {r.claim_id: str(r.outcome) for r in ledger}
            verdicts[variant]["collisions_improved"] = Tally.of(tables[bundle]).collisions
    if "default" not in verdicts:
        return None
    rows = []
    for variant, result in verdicts.items():
        row = {"variant": variant}
        flipped = []
        for claim in ALL_CLAIMS:
            row[claim.claim_id] = result[claim.claim_id]
            if result[claim.claim_id] != verdicts["default"][claim.claim_id]:
                flipped.append(claim.claim_id)
        row["collisions_improved"] = result["collisions_improved"]
        row["flips"] = ", ".join(flipped) if flipped else "none"
        rows.append(row)
    return pd.DataFrame(rows)
