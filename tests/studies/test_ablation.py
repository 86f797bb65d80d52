"""Ablation analysis on synthetic family tables with a known answer."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pipeline.analysis.ablation import (
    REVISIONS,
    ablation_effects,
    attribution_sentences,
    interpretation_flips,
)
from pipeline.analysis.claims.catalogue import CLAIMS
from pipeline.config import ClaimsConfig
from pipeline.store.collection import interpretation_tables
from pipeline.store.runs import write_family

CFG = ClaimsConfig(n_resamples=199)


def family_table(shift: dict[str, float], n: int = 60, seed: int = 0) -> pd.DataFrame:
    """Per-scenario metrics: a common random base plus a per-claim shift of the primary metric."""
    rng = np.random.default_rng(seed)
    table = pd.DataFrame({"scenario": [f"s{i}" for i in range(n)],
                          "collision": False, "recovered": True})
    for claim in CLAIMS:
        table[claim.primary_metric] = rng.uniform(1.0, 2.0, n) + shift.get(claim.claim_id, 0.0)
    return table


def tables_with_known_cause() -> dict[str, pd.DataFrame]:
    """C1 improves by 0.5 through the larger step alone; C2 worsens through the exponential law."""
    base = family_table({})
    tables = {"baseline": base}
    effect = {"step": {"C1": -0.5}, "exponential": {"C2": +0.3}}
    for r in REVISIONS:
        tables[f"baseline+{r}"] = family_table(effect.get(r, {}))
        rest = {}
        for other in REVISIONS:
            if other != r:
                for claim, value in effect.get(other, {}).items():
                    rest[claim] = rest.get(claim, 0.0) + value
        tables[f"improved-{r}"] = family_table(rest)
    tables["improved"] = family_table({"C1": -0.5, "C2": +0.3})
    return tables


def test_effects_recover_the_planted_shifts():
    effects = ablation_effects(tables_with_known_cause(), CFG).set_index(["configuration",
                                                                         "claim"])
    assert effects.loc[("improved", "C1"), "effect"] == -0.5
    assert effects.loc[("improved", "C1"), "outcome"] == "supported"
    assert effects.loc[("baseline+step", "C1"), "ci_high"] < 0
    assert effects.loc[("baseline+beta", "C1"), "effect"] == 0.0
    assert effects.loc[("improved-step", "C1"), "effect"] == 0.0
    assert effects.loc[("baseline+exponential", "C2"), "ci_low"] > 0
    assert effects.loc[("baseline+exponential", "C2"), "outcome"] == "contradicted"


def test_attribution_names_the_planted_revision():
    tables = tables_with_known_cause()
    sentences = attribution_sentences(ablation_effects(tables, CFG), tables, CFG)
    assert "larger step" in sentences["C1"] and "improves" in sentences["C1"]
    assert "exponential repulsion" in sentences["C2"] and "worsens" in sentences["C2"]
    assert "No single active revision" in sentences["C3a"]


def test_a_tiny_effect_is_not_credited_and_an_interaction_is_named():
    """C1 improves by 0.5 only with beta and the exponential law together: each alone moves it
    by a hair (clear of zero but far below half), leaving either out removes it."""
    tables = tables_with_known_cause()
    base = family_table({})
    tables["improved"] = family_table({"C1": -0.5})
    tables["baseline+beta"] = family_table({"C1": -0.001})
    tables["baseline+exponential"] = family_table({"C1": -0.002})
    tables["baseline+step"] = base.copy()
    tables["improved-beta"] = family_table({"C1": -0.01})
    tables["improved-exponential"] = family_table({"C1": -0.01})
    sentences = attribution_sentences(ablation_effects(tables, CFG), tables, CFG)
    assert "accounts for most" not in sentences["C1"]
    assert "needs the revisions together" in sentences["C1"]
    assert "'beta sensitivity of H_i' the bundle's effect is -0.01" in sentences["C1"]


def test_attribution_agrees_with_the_look_ahead_control_when_the_cap_binds():
    """When the cap binds on most steps, the step revisions are not credited and an effect the
    look-ahead-matched baseline shares is called look-ahead length."""
    tables = tables_with_known_cause()
    tables["improved"]["step_cap_binding_share"] = 0.9
    tables["baseline_matched"] = family_table({"C1": -0.5})
    sentences = attribution_sentences(ablation_effects(tables, CFG), tables, CFG)
    assert "larger step" not in sentences["C1"].split("binds")[0].split("No single")[0] \
        .replace("'a larger step'", "")
    assert "look-ahead length" in sentences["C1"] and "binds on 90 %" in sentences["C1"]
    # without a binding cap the larger step is credited again
    tables["improved"]["step_cap_binding_share"] = 0.1
    assert "Alone, 'larger step" in attribution_sentences(ablation_effects(tables, CFG), tables,
                                                           CFG)["C1"]


def test_interpretation_flips(tmp_path):
    for variant, improved_shift in (("default", {"C1": -0.5}), ("alt", {"C1": +0.5})):
        for method, shift in (("baseline", {}), ("improved", improved_shift)):
            write_family(tmp_path / variant / method, family_table(shift), {"method": method},
                         "synthetic", [])
    flips = interpretation_flips(interpretation_tables(tmp_path), CFG).set_index("variant")
    assert flips.loc["default", "C1"] == "supported" and flips.loc["default", "flips"] == "none"
    assert flips.loc["alt", "C1"] == "contradicted" and flips.loc["alt", "flips"] == "C1"


def test_the_ablation_takes_its_treatment_and_reference_from_the_claims_settings():
    """claims.treatment / claims.controls[0] become the ablation's bundle and reference when the
    ablation ran them: a user's method planted 0.4 s faster than baseline_matched on C1."""
    import dataclasses

    tables = tables_with_known_cause()
    tables["baseline_matched"] = family_table({"C1": +0.2})
    tables["mine"] = family_table({"C1": -0.2})
    cfg = dataclasses.replace(CFG, treatment="mine", controls=["baseline_matched", "baseline"])
    effects = ablation_effects(tables, cfg).set_index(["configuration", "claim"])
    assert ("baseline_matched", "C1") not in effects.index  # the reference itself
    assert np.isclose(effects.loc[("mine", "C1"), "effect"], -0.4)
    assert np.isclose(effects.loc[("improved", "C1"), "effect"], -0.7)
    sentences = attribution_sentences(ablation_effects(tables, cfg), tables, cfg)
    assert sentences["C1"].startswith("C1 (reaction_delay_s): mine improves it (effect -0.4")
    # without a user's method in the ablation, the paper's roles as before
    plain = ablation_effects(tables_with_known_cause(), cfg).set_index(["configuration", "claim"])
    assert plain.loc[("improved", "C1"), "effect"] == -0.5
