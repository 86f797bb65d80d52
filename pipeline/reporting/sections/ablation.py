"""The ablations (``make ablation``): each revision of the APF alone and left out, with the
sentences that attribute each claim's effect, and whether the verdicts survive the register's
alternative readings."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pipeline.analysis.ablation import attribution_sentences
from pipeline.analysis.tally import Tally
from pipeline.reporting.figure import Figure, Figures
from pipeline.reporting.figures import ablation_forest_figure
from pipeline.reporting.inputs import ReportInputs
from pipeline.reporting.verdicts import Verdicts


@dataclass(frozen=True)
class AblationSection:
    effects: tuple[dict, ...]
    sentences: dict[str, str]
    figures: tuple[Figure, ...]
    counts: tuple[dict, ...]
    flips: tuple[dict, ...]
    bundle: str
    reference: str


def ablation_section(inputs: ReportInputs, verdicts: Verdicts, figures: Figures
                     ) -> AblationSection | None:
    tables = inputs.ablation
    bundle, reference = verdicts.ablation_roles
    if reference not in tables and verdicts.flips is None:
        return None
    effects: tuple[dict[str, Any], ...] = ()
    sentences: dict[str, str] = {}
    drawn: tuple[Figure, ...] = ()
    counts: tuple[dict[str, Any], ...] = ()
    if verdicts.ablation_effects is not None:
        frame = verdicts.ablation_effects
        sentences = attribution_sentences(frame, tables, verdicts.claims)
        effects = tuple(frame.to_dict("records"))
        counts = tuple({"configuration": label, "collisions": Tally.of(t).collisions,
                        "not_recovered": Tally.of(t).not_recovered, "scenarios": len(t)}
                       for label, t in tables.items())
        drawn = (figures.draw(ablation_forest_figure(frame, reference, bundle),
                              "ablation_forest", "ablation",
                              "Median paired effect versus the baseline with its 95 % bootstrap "
                              "interval, per claim: the improved bundle (blue), each revision "
                              "added alone to the baseline (green), the bundle without each "
                              "revision (orange).", "Forest plot of ablation effects per claim"),)
    flips = tuple(verdicts.flips.to_dict("records")) if verdicts.flips is not None else ()
    return AblationSection(effects, sentences, drawn, counts, flips, bundle, reference)
