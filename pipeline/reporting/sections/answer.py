"""The answer at the top of the page and at the end of ``make reproduce``: per claim its
outcome against the first control with the estimate and interval, the other controls'
outcomes, and (when they ran) its robustness, the tuned-vs-tuned outcome and the Appendix-A
track's; the collisions, what the APF and what the MPC contribute to safety, and the
model-validity caveat."""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.analysis.claims import ALL_CLAIMS
from pipeline.config import ClaimsConfig
from pipeline.reporting.format import fmt, unit
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
        if cell:
            extra.append(f"multiverse: {cell['agree']} agree")
        if claim.claim_id in tuned:
            extra.append(f"tuned vs tuned over replicates: {tuned[claim.claim_id]['counts']}"
                         + ("" if tuned[claim.claim_id]["settled"] else " (not settled)"))
        if claim.claim_id in kin:
            extra.append(f"Appendix-A track: {kin[claim.claim_id]['outcome']}")
        out.append({"claim": claim.claim_id, "words": claim.text, "outcome": main["outcome"],
                    "comparison": main["comparison"],
                    "effect": f"{fmt(main['estimate'])} {unit(claim.primary_metric)} "
                              f"[{fmt(main['ci_low'])}, {fmt(main['ci_high'])}]"
                              .replace("  ", " "),
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
    # before the verdicts: the last lines stay the verdicts in words
    lines.insert(0, "Collisions: " + ", ".join(f"{c['method']} {c['collisions']}"
                                               for c in family.counts) + "."
                 + (f" {caveat}" if caveat else ""))
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
    return AnswerSection(tuple(_rows(family, robustness, fair_fight, kinematic, cfg)), caveat,
                         tuple(lines), safety or MISSING_NOTE, bool(safety))
