"""The fair fight (``make tune``), if it was run: the budget and search spaces, per claim the
default verdict beside the tuned-vs-tuned verdict on held-out scenarios, the settings that make
each claim hold, the Pareto fronts on shared axes."""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.reporting.figure import Figure, Figures
from pipeline.reporting.format import fmt, interval, unit
from pipeline.reporting.inputs import ReportInputs
from pipeline.studies.results import TuneResult
from pipeline.studies.results.tune import TuneSummary


@dataclass(frozen=True)
class FairFightSection:
    summary: TuneSummary
    rows: tuple[dict, ...]
    figures: tuple[Figure, ...]
    spaces: tuple[dict, ...]
    dominance: str
    methods: tuple[str, ...]
    compromise: dict[str, str]


PART_WORDS = (("training", "training family (where the settings were tuned)"),
              ("heldout", "held-out family (scenarios the tuning never saw)"))


def fair_fight_section(inputs: ReportInputs, figures: Figures) -> FairFightSection | None:
    result = inputs.tune
    if result is None:
        return None
    summary = result.summary
    drawn = []
    for part, words in PART_WORDS:
        stem = TuneResult.front_stem(part)
        figure = figures.copy(result.front_figure(part), stem, "fair fight",
                              f"Each method's Pareto settings on the {words}, every pair of "
                              "tuning objectives on shared axes (smaller is better).",
                              f"Pareto fronts of the tuned methods, {part}",
                              figure_id=f"tune_{stem}")
        if figure is not None:
            drawn.append(figure)
    methods = summary.methods
    dom_text = []
    for part, words in (("training", "on the training family"),
                        ("heldout", "on the held-out family")):
        d = summary.dominance.get(part)
        if d:
            dom_text.append(f"{words}, {methods[0]}'s Pareto settings dominate "
                            f"{d['treatment_dominates']} of {d['control_points']} of "
                            f"{methods[1]}'s, and {methods[1]}'s dominate "
                            f"{d['control_dominates']} of {d['treatment_points']} of "
                            f"{methods[0]}'s")
    rows = []
    for c in summary.claims:
        rows.append({**c.to_json(),
                     "tuned_fmt": f"{fmt(c.tuned_estimate)} {interval(*c.tuned_ci)} "
                                  f"{unit(c.metric)}",
                     "default_fmt": f"{fmt(c.default_estimate)} {unit(c.metric)}",
                     "holds": ("trials " + ", ".join(str(t) for t in c.holds_with_trials))
                     if c.holds_with_trials else "none of the judged settings"})
    spaces = tuple({"method": m, "params": [{"key": k, "range": v} for k, v in space.items()]}
                   for m, space in summary.search_spaces.items())
    compromise = {m: ", ".join(f"{k.split('.')[-1]} = {fmt(v) if isinstance(v, float) else v}"
                               for k, v in p.items())
                  for m, p in summary.compromise.items()}
    return FairFightSection(summary, tuple(rows), tuple(drawn), spaces, "; ".join(dom_text),
                            tuple(methods), compromise)
