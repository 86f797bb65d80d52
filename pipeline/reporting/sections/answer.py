"""The answer at the top of the page and at the end of ``make reproduce``: per claim its
outcome against the declared primary comparison (the first control) with the estimate, its
interval, its pairs and what the interval can resolve against the margin; beside it the judge
of record's outcome (the nonlinear MPC, ``make nmpc-family``), the registered readings under
which the outcome changes (``make multiverse``), and the secondary comparisons after the
answer's family-wise rule (the other control, the APF by itself with its worst-rank outcome
where it rests on few pairs, the tuned-vs-tuned counts, the Appendix-A track); the
collisions, what the APF and what the MPC contribute to safety, and the model-validity
caveat."""

from __future__ import annotations

import math
from dataclasses import dataclass

from pipeline.analysis.claims import claim_level, claims_of
from pipeline.config import ClaimsConfig
from pipeline.reporting.figures.answer import AnswerPanel, AnswerRow, Interval, answer_svg
from pipeline.reporting.format import collision_words, row_effect, unit
from pipeline.reporting.sections.apf_alone import MISSING_NOTE, ApfAloneSection
from pipeline.reporting.sections.fair_fight import FairFightSection
from pipeline.reporting.sections.family import FamilySection
from pipeline.reporting.sections.kinematic import KinematicSection
from pipeline.reporting.sections.peers import PeersSection
from pipeline.reporting.sections.robustness import RobustnessSection
from pipeline.reporting.verdicts import NmpcVerdicts
from pipeline.studies.results.multiverse import ReadingFlip


@dataclass(frozen=True)
class AnswerSection:
    """``rows``: the page's list; ``caveat``: the model-validity caveat; ``lines``: the
    answer in words (``answer.txt``); ``safety``: what the APF and what the MPC contribute to
    safety (one sentence from the ``apf_alone`` families), or, without them, a note saying so
    (``safety_measured`` False; the note stays off ``answer.txt``)."""

    rows: tuple[dict, ...]
    caveat: str
    lines: tuple[str, ...]
    safety: str = ""
    safety_measured: bool = False
    #: the answer as a picture (an SVG document, every interval a link), "" without a family
    figure: str = ""
    #: the collisions in words, never adding up families of different sizes
    collisions: str = ""
    #: the studies present that may not write the opening summary, each with why
    exploratory: tuple[str, ...] = ()
    #: the strength of the evidence, once: the intervals' level in numbers and the rule
    strength: str = ""
    #: which ledger the headline shows and why (the linear MPC, or the nonlinear MPC as the
    #: judge of record)
    judge: str = ""
    #: comparisons whose C1-C5 rest on few of their scenarios, each with its worst-rank outcome
    thin: tuple[str, ...] = ()
    #: every method, control, track and term the answer names, with what it is in one
    #: sentence (the page's glossary and the names' hover text), by name
    glossary: tuple[tuple[str, str], ...] = ()

    def define(self, name: str) -> str:
        """What ``name`` is in one sentence ("" for a name the glossary lacks)."""
        return dict(self.glossary).get(name, "")


#: The words of the answer that are not methods, each in one sentence.
TERMS: tuple[tuple[str, str], ...] = (
    ("lateral track", "The paper's setting: a single-track vehicle at constant speed whose "
                      "steering a linear MPC computes in the APF path's own frame."),
    ("Appendix-A track", "The paper's Appendix A: a kinematic bicycle whose acceleration and "
                         "steering an MPC computes (MATLAB's nlmpc there, a linearized QP "
                         "here)."),
    ("APF alone", "The same runs with the MPC's collision half-planes switched off, so that "
                  "only the APF's path keeps the vehicle off the obstacle."),
    ("pairs", "Scenarios where both methods ran and neither collided: C1-C5 compare the two "
              "runs of each pair; C0 counts collisions over every scenario."),
    ("margin", "A claim's smallest effect of interest, in its metric's units, with its reason "
               "(the Methods section): inside it a difference is too small to matter."),
    ("half-planes", "The MPC's soft collision constraints: one linear bound per obstacle and "
                    "predicted step keeping the vehicle on its side of the obstacle."),
    ("step cap", "The longest step the improved APF's rollout takes per iteration "
                 "(planner.step_max_m), which keeps its unnormalized rollout bounded."),
)


def glossary_entries(names: list[str]) -> tuple[tuple[str, str], ...]:
    """What each method of ``names`` is (its preset's ``run.description``; a method without
    one is left out), then every :data:`TERMS` entry."""
    from pipeline.methods import method_info

    methods = []
    for name in dict.fromkeys(names):
        info = method_info(name)
        if info.description:
            label = f"{info.label} ({info.citation})" if info.citation else info.label
            methods.append((name, f"{label}: {info.description}" if label else info.description))
    return tuple(methods) + TERMS


def validity_caveat(counts) -> str:
    """How often each method left the MPC model's small-angle validity (family counts)."""
    parts = [f"{c['method']} in {c['heading_validity_exceeded']} of {c['scenarios']}"
             for c in counts if c.get("heading_validity_exceeded")]
    if not parts:
        return ""
    return ("Caveat: the MPC's model leaves its small-angle validity bound "
            "(model.validity_heading_rad: the plant's heading error in the model's own frame "
            "over a prediction's second) in some scenarios: " + ", ".join(parts)
            + "; the predictions there are the linear model's, not the plant's (see "
            "\"Does the MPC's model hold?\").")


@dataclass(frozen=True)
class AnswerContext:
    """What the answer reads besides the sections: the judge of record's verdicts (None
    without ``make nmpc-family``), the registered readings that change an outcome (None
    without a multiverse; ``flips_label``: why that multiverse may not write the headline)."""

    nmpc: NmpcVerdicts | None = None
    flips: tuple[ReadingFlip, ...] | None = None
    flips_label: str = ""
    #: per judged method, the share of its steps on which the linear MPC's model left its
    #: small-angle bound (:func:`~pipeline.reporting.verdicts.beyond_bound_shares`)
    beyond_share: dict[str, float] | None = None


def _level_words(cfg: ClaimsConfig) -> str:
    """The intervals' level and the family-wise rule in numbers, said once."""
    level = 1.0 - cfg.alpha / 7 if cfg.interval_adjustment != "none" else 1.0 - cfg.alpha
    return (f"every interval at {100 * level:.1f} % (alpha = {cfg.alpha:g} shared by the 7 "
            f"claims); a direction also needs Holm over all of a claim's rows in this answer "
            f"below alpha/7 = {claim_level(cfg):.3g}")


def _pairs_words(row: dict) -> str:
    """``161 of 200 pairs`` (C0: every scenario)."""
    n, total = int(row.get("n_pairs") or 0), int(row.get("n_scenarios") or 0)
    return f"{n} of {total} pairs" if total else f"{n} pairs"


def resolution_words(row: dict) -> str:
    """What a row's interval can resolve against its margin; for a claim that cannot be
    decided at this size, how many scenarios would (the square-root law)."""
    resolvable, margin = row.get("resolvable_effect"), row.get("margin")
    if resolvable is None or not math.isfinite(float(resolvable)) or margin is None:
        return ""
    resolvable, margin = float(resolvable), float(margin)
    units = unit(str(row.get("metric", "")))
    units = f" {units}" if units else ""
    words = f"resolves {resolvable:.2g}{units} against a margin of {margin:g}{units}"
    n = int(row.get("n_pairs") or 0)
    if margin > 0 and resolvable > margin and n and row.get("outcome") == "inconclusive":
        needed = int(math.ceil(n * (resolvable / margin) ** 2 / 100.0) * 100)
        words += (f": it cannot be decided at this size (about {needed:,} scenarios would "
                  "resolve the margin)")
    reach = margin_reach(row)
    if reach:
        words += f"; {reach}"
    return words


def margin_reach(row: dict) -> str:
    """For a directional outcome whose interval reaches into the margin (its end nearer zero
    lies within +-margin): that the direction is clear but not whether the difference is
    larger than the margin ("" otherwise)."""
    outcome = str(row.get("outcome", ""))
    if outcome not in ("supported", "contradicted"):
        return ""
    try:
        low, high, margin = (float(row[k]) for k in ("ci_low", "ci_high", "margin"))
    except (KeyError, TypeError, ValueError):
        return ""
    if not (math.isfinite(low) and math.isfinite(high)) or margin <= 0:
        return ""
    nearer = low if abs(low) < abs(high) else high
    if abs(nearer) >= margin:
        return ""
    way = "better" if outcome == "supported" else "worse"
    return (f"its interval reaches into the margin (its end {nearer:.2g} within {margin:g}): "
            f"{way} than the control, perhaps by less than the margin")


def _thin(ledger_rows: tuple[dict, ...], cfg: ClaimsConfig, what: str, comparison: str
          ) -> str:
    """A comparison's C1-C5 resting on fewer than ``claims.min_pair_share`` of its scenarios,
    said with its worst-rank outcome per claim ("" when none is thin)."""
    paired = [r for r in ledger_rows if r["claim"] != "C0" and r.get("n_scenarios")
              and r["comparison"] == comparison]
    if not paired:
        return ""
    most = max(int(r["n_pairs"]) for r in paired)
    total = max(int(r["n_scenarios"]) for r in paired)
    if most >= cfg.min_pair_share * total:
        return ""
    outcomes = "; ".join(f"{r['claim']} {r['outcome']} on {r['n_pairs']}, "
                         f"{r.get('outcome_worst_rank') or '—'} over all" for r in paired)
    return (f"{what} against {comparison} rests on at most {most} of its {total} scenarios "
            f"(the pairs where neither method collided; below claims.min_pair_share = "
            f"{cfg.min_pair_share:g}); over all {total}, a collision ranked worse than any run "
            f"without one: {outcomes}")


def _flip_words(flips: tuple[ReadingFlip, ...] | None, claim: str, comparison: str,
                label: str) -> str:
    if flips is None:
        return "hangs on a reading: not measured at the default budget (make multiverse)"
    mine = [f.words for f in flips if f.claim == claim and f.comparison == comparison]
    suffix = f" ({label})" if label else ""
    return ("hangs on a reading: " + "; ".join(mine) + suffix) if mine else \
        ("no registered reading changes it" + suffix)


def _rows(family: FamilySection, robustness: RobustnessSection | None,
          fair_fight: FairFightSection | None, kinematic: KinematicSection | None,
          cfg: ClaimsConfig, apf_alone: ApfAloneSection | None, context: AnswerContext
          ) -> list[dict]:
    by_claim: dict[str, list[dict]] = {}
    for row in family.ledger:
        by_claim.setdefault(row["claim"], []).append(row)
    robust = {r["claim"]: r["cells"] for r in (robustness.rows if robustness else ())}
    # only a tuning at the default budget with every method converged writes the headline
    headline = fair_fight is not None and fair_fight.headline
    tuned = {r["claim"]: r for r in (fair_fight.rows if headline and fair_fight else ())}
    kin_family = kinematic.family if kinematic is not None else None
    first = cfg.controls[0] if cfg.controls else "baseline"
    kin = {r["claim"]: r for r in (kin_family.rows if kin_family else ())
           if r["comparison"] == first}
    alone = {r["claim"]: r for r in (apf_alone.ledger if apf_alone is not None else ())
             if r["comparison"] == first}
    nmpc = {(r.claim_id, r.comparison): r for r in context.nmpc.ledger} \
        if context.nmpc is not None else {}
    out = []
    for claim in claims_of(cfg):
        rows = by_claim.get(claim.claim_id)
        if not rows:
            continue
        main = next((r for r in rows if r["comparison"] == first), rows[0])
        others = [r for r in rows if r is not main]
        judged = nmpc.get((claim.claim_id, main["comparison"]))
        beside = []
        if judged is not None:
            differs = str(judged.outcome) != main["outcome"]
            beside.append(f"nonlinear MPC: {judged.outcome}"
                          + (" (differs from the linear MPC's: its model leaves its "
                             "small-angle bound on part of the steps)" if differs else ""))
        beside.append(_flip_words(context.flips, claim.claim_id, main["comparison"],
                                  context.flips_label))
        secondary = [f"vs {r['comparison']} {r['outcome']}" for r in others]
        cell = robust.get(claim.claim_id, {}).get(main["comparison"])
        if cell and robustness is not None and robustness.headline:
            secondary.append(f"multiverse: {cell['agree']} agree")
        if claim.claim_id in alone:
            r = alone[claim.claim_id]
            worst = r.get("outcome_worst_rank")
            secondary.append(f"APF alone {r['outcome']} ({_pairs_words(r)}"
                             + (f"; worst-rank over all: {worst}" if worst and
                                claim.claim_id != "C0" else "") + ")")
        if claim.claim_id in tuned:
            secondary.append(f"tuned vs tuned over replicates: {tuned[claim.claim_id]['counts']}"
                             + ("" if tuned[claim.claim_id]["settled"] else " (not settled)"))
        if claim.claim_id in kin:
            secondary.append(f"Appendix-A track {kin[claim.claim_id]['outcome']}")
        family_size = main.get("holm_family_size") or 0
        extra = "; ".join(beside)
        if secondary:
            extra += (f". Secondary (Holm over the {family_size} rows of {claim.claim_id}): "
                      if family_size else ". Secondary: ") + "; ".join(secondary)
        out.append({"claim": claim.claim_id, "words": claim.text, "outcome": main["outcome"],
                    "comparison": main["comparison"], "effect": row_effect(main),
                    "pairs": _pairs_words(main), "resolution": resolution_words(main),
                    "id": main.get("id", ""), "role": main.get("role", "primary"),
                    "extra": extra})
    return out


def judge_words(context: AnswerContext, family: FamilySection, cfg: ClaimsConfig) -> str:
    """Which ledger the headline shows, and why."""
    nmpc = context.nmpc
    treatment = family.treatment
    share = (context.beyond_share or {}).get(treatment)
    share_words = (f"the linear MPC's model leaves its small-angle bound on "
                   f"{100 * float(share):.1f} % of {treatment}'s steps"
                   if share is not None and math.isfinite(float(share)) else "")
    if nmpc is None:
        if share is not None and math.isfinite(float(share)) and share > cfg.nmpc_judge_share:
            return (f"The outcomes are the linear MPC's; {share_words}, above "
                    f"claims.nmpc_judge_share = {cfg.nmpc_judge_share:g}, so the judge of record "
                    "is the nonlinear MPC (make nmpc-family), not run here.")
        return "The outcomes are the linear MPC's" + (f" ({share_words})." if share_words
                                                      else ".")
    differ = [r.claim_id for r in nmpc.ledger
              if (row := next((x for x in family.ledger if x["claim"] == r.claim_id
                               and x["comparison"] == r.comparison), None)) is not None
              and str(r.outcome) != row["outcome"]]
    head = ("Judge of record: the nonlinear MPC (CasADi + IPOPT on the plant's model, "
            f"make nmpc-family), because {share_words}" if nmpc.judge_of_record else
            f"The linear MPC's model holds ({share_words}); the nonlinear MPC agrees")
    tail = (f"; its outcome stands beside each claim and differs on {', '.join(differ)}."
            if differ else "; its outcomes equal the linear MPC's on every claim.")
    return head + tail


def answer_section(family: FamilySection | None, robustness: RobustnessSection | None,
                   fair_fight: FairFightSection | None, kinematic: KinematicSection | None,
                   cfg: ClaimsConfig, apf_alone: ApfAloneSection | None = None,
                   peers: PeersSection | None = None,
                   context: AnswerContext | None = None) -> AnswerSection:
    if family is None:
        return AnswerSection((), "", ())
    context = context or AnswerContext()
    safety = apf_alone.sentence if apf_alone is not None else ""
    caveat = validity_caveat(family.counts)
    rows = tuple(_rows(family, robustness, fair_fight, kinematic, cfg, apf_alone, context))
    strength = _level_words(cfg)
    judge = judge_words(context, family, cfg)
    first = cfg.controls[0] if cfg.controls else "baseline"
    thin = tuple(t for t in (
        _thin(apf_alone.ledger, cfg, "The APF-alone column", first)
        if apf_alone is not None else "",) if t)
    lines = [f"{r['claim']} {r['words']}: {r['outcome']} vs {r['comparison']} "
             f"({r['effect']}, {r['pairs']}" + (f"; {r['resolution']}" if r["resolution"]
                                                 else "") + f"); {r['extra']}"
             for r in rows]
    if fair_fight and fair_fight.headline:
        lines += [c["sentence"] for c in fair_fight.rows]
    collisions = collision_words(family.counts)
    # before the verdicts: the last lines stay the verdicts in words
    head = [f"Collisions {collisions}." + (f" {caveat}" if caveat else "")]
    if safety:
        head.append(safety)
    head.append(f"Primary comparison: {family.treatment} vs {cfg.controls[0]}; {strength}. "
                f"{judge}")
    head += list(thin)
    if family.apf_adds is not None:
        lines.append(family.apf_adds.sentence)
    lines = head + lines
    kf = kinematic.family if kinematic is not None else None
    if kf is not None:
        lines.append(f"Appendix-A track ({kf.size} scenarios): {kf.treatment} vs baseline "
                     + "; ".join(f"{r['claim']} {r['outcome']}" for r in kf.rows
                                 if r["comparison"] == "baseline")
                     + (f". {kf.apf_adds.sentence}" if kf.apf_adds else "."))
    if peers is not None:
        lines += list(peers.sentences)
    exploratory = tuple(
        f"{name} ({label}): shown in its own section, marked exploratory; it writes nothing "
        "here or in answer.txt" for name, study, label in (
            ("the fair fight (make tune)", fair_fight,
             fair_fight.label if fair_fight is not None else ""),
            ("the multiverse (make multiverse)", robustness,
             robustness.label if robustness is not None else ""))
        if study is not None and not study.headline)
    named = [family.treatment, *cfg.controls, *(r["comparison"] for r in rows)]
    return AnswerSection(rows, caveat, tuple(lines), safety or MISSING_NOTE, bool(safety),
                         answer_figure(family, fair_fight, apf_alone, cfg), collisions,
                         exploratory, strength, judge, thin, glossary_entries(named))


def _interval(row: dict, href: str, what: str) -> Interval:
    return Interval(row["estimate"], row["ci_low"], row["ci_high"], row["outcome"], href,
                    f"{what}: {row['outcome']}, d = {row_effect(row)}"
                    + ("; click: the scenario that moves it most" if href.startswith(
                        "explorer") else ""))


def _href(row: dict) -> str:
    """The explorer link of the member that moves the row's estimate most (its own way), or
    the row's ledger anchor."""
    movers = row.get("movers")
    estimate = row.get("estimate")
    mover = movers.toward(float(estimate) if estimate is not None else math.nan) \
        if movers is not None else None
    return mover.href if mover is not None else f"#{row.get('id', 'claims')}"


def _short(words: str, limit: int = 46) -> str:
    """``words`` cut at a word boundary within ``limit`` characters (an ellipsis marks a
    cut)."""
    if len(words) <= limit:
        return words
    return words[:limit].rsplit(" ", 1)[0] + " …"


def answer_figure(family: FamilySection, fair_fight: FairFightSection | None,
                  apf_alone: ApfAloneSection | None, cfg: ClaimsConfig) -> str:
    """The answer as a picture (:func:`pipeline.reporting.figures.answer.answer_svg`): per
    claim, our settings against each control, both methods tuned (each replicate's interval,
    counted; only a tuning that may write the headline) and the APF by itself (the MPC's
    collision half-planes off) against the first control."""
    tuned = {c["claim"]: c for c in (fair_fight.rows if fair_fight is not None
                                     and fair_fight.headline else ())}
    first = cfg.controls[0] if cfg.controls else "baseline"
    alone = {r["claim"]: r for r in (apf_alone.ledger if apf_alone is not None else ())
             if r["comparison"] == first}
    panels = []
    for claim in claims_of(cfg):
        ours = [r for r in family.ledger if r["claim"] == claim.claim_id]
        if not ours:
            continue
        rows = [AnswerRow(f"ours vs {r['comparison']}",
                          (_interval(r, _href(r), f"ours vs {r['comparison']}"),), r["outcome"])
                for r in ours]
        if claim.claim_id in tuned:
            t = tuned[claim.claim_id]
            rows.append(AnswerRow(
                f"tuned, {len(t['tuned_outcomes'])} replicates",
                tuple(Interval(e, ci[0], ci[1], o, "#fairfight",
                               f"tuned, replicate {i}: {o}, d = {e:.3g}")
                      for i, (o, e, ci) in enumerate(zip(t["tuned_outcomes"],
                                                        t["tuned_estimates"],
                                                        t["tuned_cis"], strict=True))
                      if e is not None),  # a replicate not judged has no interval
                t["counts"]))
        if claim.claim_id in alone:
            r = alone[claim.claim_id]
            rows.append(AnswerRow(f"APF alone vs {first}",
                                  (_interval(r, _href(r), f"APF alone vs {first}"),),
                                  r["outcome"]))
        panels.append(AnswerPanel(claim.claim_id, _short(claim.text.split(" (")[0]),
                                  unit(claim.primary_metric), float(ours[0]["margin"]),
                                  tuple(rows), f"#{ours[0].get('id', 'claims')}"))
    return answer_svg(tuple(panels)) if panels else ""
