"""The fair fight (``make tune``), if it was run: the rules (convergence, replicates, parity,
the test that settles a claim), per claim the default verdict beside the tuned outcome of every
replicate, their count and the binomial test's p-value, the hypervolume histories and the
Pareto fronts; whether it may write the headline."""

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
    parity: tuple[dict, ...]
    dominance: str
    methods: tuple[str, ...]
    compromise: tuple[dict, ...]
    #: may this tuning write the opening summary (the default budget, every method converged)
    headline: bool
    #: why not ("" when it may)
    label: str
    #: how its trials were stopped early, where its members came from and its use of the cores
    cost: str
    #: the held-out families in words (one per replicate, or one shared by an older tuning)
    heldout: str = ""
    #: the rule that settles a claim, with its alpha, in words
    settle: str = ""
    #: "" or why no claim can be settled with this many replicates (shown, not refused)
    settle_note: str = ""


PART_WORDS = (("training", "training family (where the settings were tuned)"),
              ("heldout", "held-out family (scenarios the tuning never saw)"))


def _figures(result: TuneResult, figures: Figures) -> list[Figure]:
    drawn = []
    history = figures.copy(result.history_figure(), TuneResult.HISTORY_STEM, "fair fight",
                           "Each method's feasible-front hypervolume (fixed bounds shared by "
                           "both methods) after every trial, one line per replicate; a dot "
                           "marks where it converged, a cross a stop by the cap.",
                           "Hypervolume histories of the tuned methods",
                           figure_id="tune_hypervolume_history")
    if history is not None:
        drawn.append(history)
    for part, words in PART_WORDS:
        stem = TuneResult.front_stem(part)
        figure = figures.copy(result.front_figure(part), stem, "fair fight",
                              f"Replicate 0: each method's Pareto settings on the {words}, "
                              "every pair of tuning objectives on shared axes (smaller is "
                              "better).", f"Pareto fronts of the tuned methods, {part}",
                              figure_id=f"tune_{stem}")
        if figure is not None:
            drawn.append(figure)
    return drawn


def fair_fight_section(inputs: ReportInputs, figures: Figures) -> FairFightSection | None:
    result = inputs.tune
    if result is None:
        return None
    summary = result.summary
    methods = summary.methods
    dom_text = []
    for part, words in (("training", "on the training families"),
                        ("heldout", "on the held-out families")):
        d = summary.dominance.get(part)
        if d:
            dom_text.append(f"{words}, {methods[0]}'s Pareto settings (all replicates) dominate "
                            f"{d['treatment_dominates']} of {d['control_points']} of "
                            f"{methods[1]}'s, and {methods[1]}'s dominate "
                            f"{d['control_dominates']} of {d['treatment_points']} of "
                            f"{methods[0]}'s")
    rows = []
    for c in summary.claims:
        cells = [{"outcome": o, "estimate": f"{fmt(e)} {interval(*ci)}"}
                 for o, e, ci in zip(c.tuned_outcomes, c.tuned_estimates, c.tuned_cis,
                                     strict=True)]
        rows.append({**c.to_json(), "cells": cells, "unit": unit(c.metric),
                     "default_fmt": f"{fmt(c.default_estimate)} {unit(c.metric)}",
                     "matched": ", ".join(c.tuned_vs_matched) or "—",
                     "test": _test_cell(c),
                     # the trials themselves: tables/tune_settings_outcomes.csv
                     "holds": (f"{len(c.holds_with_trials)} settings in "
                               f"{len({r for r, _ in c.holds_with_trials})} replicates")
                     if c.holds_with_trials else "none of the judged settings"})
    spaces = tuple({"method": m, "params": [{"key": k, "range": v} for k, v in space.items()]}
                   for m, space in summary.search_spaces.items())
    parity = tuple({"method": p["method"], "dimensions": p["dimensions"],
                    "trials": ", ".join(str(t) for t in p["trials"]),
                    "feasible": f"{100 * p['feasible_share']:.0f} %",
                    "converged": f"{sum(p['converged'])} of {len(p['converged'])}",
                    "at": ", ".join("cap" if a is None else str(a) for a in p["converged_at"]),
                    "members": ", ".join("—" if m is None else f"{m:,}"
                                         for m in p.get("members") or []) or "—",
                    "pruned": f"{100 * p['pruned_share']:.0f} %" if "pruned_share" in p
                    else "—"}
                   for p in summary.parity)
    compromise = tuple(
        {"method": m, "replicate": r,
         "text": ", ".join(f"{k.split('.')[-1]} = {fmt(v) if isinstance(v, float) else v}"
                           for k, v in params.items())}
        for m, by_replicate in summary.compromise.items() for r, params in by_replicate.items())
    return FairFightSection(summary, tuple(rows), tuple(_figures(result, figures)), spaces,
                            parity, "; ".join(dom_text), tuple(methods), compromise,
                            summary.writes_headline, summary.label, _cost(summary),
                            _heldout_words(summary), _settle_words(summary),
                            summary.settle_note)


def _test_cell(claim) -> str:
    """The binomial test's cell: the leading outcome's count among the judged replicates and
    its p-value ("—" for a summary written before the test)."""
    if claim.p_value is None or claim.judged_replicates is None:
        return "—"
    return (f"{claim.leading} {claim.leading_count} of {claim.judged_replicates}, "
            f"p = {claim.p_value:.3g}")


def _heldout_words(summary: TuneSummary) -> str:
    """Where the replicates were judged: each on its own held-out family, or (an older
    tuning) all on one."""
    heldout = summary.families.get("heldout", {})
    size, seeds = heldout.get("size"), heldout.get("seeds")
    if not seeds:
        return f"on one held-out family shared by every replicate (seed {heldout.get('seed')}, " \
               f"{size} scenarios)"
    return (f"each replicate on its own held-out family of {size} scenarios (seeds "
            f"{', '.join(str(s) for s in seeds)}: heldout_seed + heldout_seed_stride × r, none "
            f"of them a training seed); our settings on replicate 0's (seed {seeds[0]})")


def _settle_words(summary: TuneSummary) -> str:
    """The rule that settles a claim, with the alpha it read."""
    if not summary.settle_test:
        share = summary.settings.get("settled_share")
        return (f"settled by the earlier share rule (tune.settled_share = {share}), not by a "
                "test")
    return (f"tune.settled_test = {summary.settle_test}: a one-sided exact binomial test of "
            f"the leading outcome's count among the judged replicates against even odds, at "
            f"claims.alpha = {summary.settle_alpha:g} (from "
            f"{summary.fewest_replicates_to_settle} judged replicates on a claim can settle)")


def _cost(summary: TuneSummary) -> str:
    """One sentence: the pruning rule, the members' origin and the use of the cores."""
    parts = []
    if summary.pruning_rule:
        parts.append(f"Trials were judged on a growing share of their training family: "
                     f"{summary.pruning_rule}.")
    else:
        parts.append("Every trial ran its whole training family (no pruning).")
    members = summary.members
    if members:
        parts.append(f"Family members: {members.get('simulated', 0):,} simulated, "
                     f"{members.get('reused', 0):,} restored from the member cache (the same "
                     f"settings and code, run by another study), {members.get('resumed', 0):,} "
                     "already complete.")
    if summary.core_utilisation is not None:
        parts.append(f"Use of the cores: {summary.core_utilisation:.2f} (CPU-seconds over "
                     "wall-clock seconds times cores).")
    if summary.coordinator_ms_per_trial is not None:
        parts.append(f"The coordinator (asks, tells, compositions, records) spent "
                     f"{summary.coordinator_ms_per_trial:.1f} ms of CPU per trial.")
    if summary.wall_s is not None:
        cores = f" on {summary.cores} cores" if summary.cores else ""
        parts.append(f"It took {summary.wall_s / 60:.1f} minutes{cores} (its last run, from "
                     "the first family to the summary).")
    heldout = summary.settings.get("heldout_backend")
    if heldout and heldout != summary.backend:
        parts.append(f"Training families solved the QP with {summary.backend}, the held-out "
                     f"judgement with {heldout} (make reproduce's).")
    return " ".join(parts)
