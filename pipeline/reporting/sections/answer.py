"""The answer at the top of the page and at the end of ``make reproduce``: per claim its
outcome against the first control with the estimate and interval, the other controls'
outcomes, and (when they ran) its robustness, the tuned-vs-tuned outcome and the Appendix-A
track's; the collisions, what the APF and what the MPC contribute to safety, and the
model-validity caveat."""

from __future__ import annotations

import math
from dataclasses import dataclass

from pipeline.analysis.claims import ALL_CLAIMS
from pipeline.config import ClaimsConfig
from pipeline.reporting.figures.answer import AnswerPanel, AnswerRow, Interval, answer_svg
from pipeline.reporting.format import collision_words, row_effect, unit
from pipeline.reporting.sections.apf_alone import MISSING_NOTE, ApfAloneSection
from pipeline.reporting.sections.fair_fight import FairFightSection
from pipeline.reporting.sections.family import FamilySection
from pipeline.reporting.sections.kinematic import KinematicSection
from pipeline.reporting.sections.peers import PeersSection
from pipeline.reporting.sections.robustness import RobustnessSection


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


def _rows(family: FamilySection, robustness: RobustnessSection | None,
          fair_fight: FairFightSection | None, kinematic: KinematicSection | None,
          cfg: ClaimsConfig) -> list[dict]:
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
    out = []
    for claim in ALL_CLAIMS:
        rows = by_claim.get(claim.claim_id)
        if not rows:
            continue
        main, others = rows[0], rows[1:]
        extra = [f"vs {r['comparison']}: {r['outcome']}" for r in others]
        cell = robust.get(claim.claim_id, {}).get(main["comparison"])
        if cell and robustness is not None and robustness.headline:
            extra.append(f"multiverse: {cell['agree']} agree")
        if claim.claim_id in tuned:
            extra.append(f"tuned vs tuned over replicates: {tuned[claim.claim_id]['counts']}"
                         + ("" if tuned[claim.claim_id]["settled"] else " (not settled)"))
        if claim.claim_id in kin:
            extra.append(f"Appendix-A track: {kin[claim.claim_id]['outcome']}")
        out.append({"claim": claim.claim_id, "words": claim.text, "outcome": main["outcome"],
                    "comparison": main["comparison"],
                    "effect": row_effect(main), "id": main.get("id", ""),
                    "extra": "; ".join(extra)})
    return out


def answer_section(family: FamilySection | None, robustness: RobustnessSection | None,
                   fair_fight: FairFightSection | None, kinematic: KinematicSection | None,
                   cfg: ClaimsConfig, apf_alone: ApfAloneSection | None = None,
                   peers: PeersSection | None = None) -> AnswerSection:
    if family is None:
        return AnswerSection((), "", ())
    safety = apf_alone.sentence if apf_alone is not None else ""
    caveat = validity_caveat(family.counts)
    lines = list(family.answer)
    if fair_fight and fair_fight.headline:
        lines += [c["sentence"] for c in fair_fight.rows]
    collisions = collision_words(family.counts)
    # before the verdicts: the last lines stay the verdicts in words
    lines.insert(0, f"Collisions {collisions}." + (f" {caveat}" if caveat else ""))
    if safety:
        lines.insert(1, safety)
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
    return AnswerSection(tuple(_rows(family, robustness, fair_fight, kinematic, cfg)), caveat,
                         tuple(lines), safety or MISSING_NOTE, bool(safety),
                         answer_figure(family, fair_fight, apf_alone, cfg), collisions,
                         exploratory)


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
    for claim in ALL_CLAIMS:
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
