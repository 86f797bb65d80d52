"""The scenario family: the claims ledger (C0-C5 against each control), the outcome counts
per method, what the baseline's APF adds, the distributions, and a gallery of members chosen
by rule."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.analysis.claims import ALL_CLAIMS, Ledger, claims_of
from pipeline.errors import RunFolderError
from pipeline.loop.scenario import build_scenario
from pipeline.reporting.figure import Figure, Figures
from pipeline.reporting.figures import (
    claim_differences_figure,
    family_distribution_figure,
    paths_figure,
)
from pipeline.reporting.format import effect, unit
from pipeline.reporting.gallery import gallery_members
from pipeline.reporting.inputs import FamilyInputs, ReportInputs, ordered
from pipeline.reporting.movers import Movers, ledger_movers
from pipeline.reporting.verdicts import FamilyVerdicts, Verdicts
from pipeline.store.runs import read_member


@dataclass(frozen=True)
class ApfAdds:
    """The baseline against ``mpc_no_apf``: per claim its outcome and estimate, and the
    sentence (indistinguishable from no APF when nothing is supported, contradicted or mixed)."""

    rows: tuple[dict, ...]
    sentence: str
    indistinguishable: bool


@dataclass(frozen=True)
class FamilySection:
    """What the page shows of the lateral family."""

    size: int
    seed: object
    treatment: str
    methods: tuple[str, ...]
    ledger: tuple[dict, ...]
    by_claim: dict[str, dict]
    solvers: str
    counts: tuple[dict, ...]
    cap_note: str
    apf_adds: ApfAdds | None
    figures: tuple[Figure, ...]
    gallery: tuple[Figure, ...]
    answer: tuple[str, ...]
    #: C2 on each run's own window and on one common to both runs of a pair, per comparison
    c2_windows: tuple[dict, ...] = ()
    c2_windows_note: str = ""
    #: why the gallery is empty, in words ("" when it has members)
    gallery_note: str = ""


def apf_adds(ledger: Ledger | None) -> ApfAdds | None:
    """What the paper's baseline APF contributes at all (see :class:`ApfAdds`)."""
    if ledger is None:
        return None
    rows = tuple({"claim": r.claim_id, "outcome": str(r.outcome),
                  "estimate": effect(r.result.estimate, r.result.ci_low, r.result.ci_high,
                                     unit(r.claim.primary_metric), r.result.n_pairs,
                                     r.result.n_tied)}
                 for r in ledger)
    decisive = [r["claim"] for r in rows
                if r["outcome"] in ("supported", "contradicted", "mixed")]
    if decisive:
        sentence = ("The baseline's APF against no APF (mpc_no_apf, the same MPC on a "
                    "straight-to-goal reference): it differs on " + ", ".join(
                        f"{r['claim']} ({r['outcome']})" for r in rows
                        if r["claim"] in decisive) + ".")
    else:
        sentence = ("The baseline's APF is indistinguishable from having no APF (mpc_no_apf): "
                    "no claim is supported, contradicted or mixed against it, so 'improved vs "
                    "baseline' is close to 'improved APF vs no APF'.")
    return ApfAdds(rows, sentence, not decisive)


def answer_lines(ledger: Ledger) -> list[str]:
    """The answer in words: one line per claim, its outcome against each comparison with the
    estimate, its unit and interval (what ``make reproduce`` prints at its end)."""
    lines = []
    # the package's claims in their order, then any other the ledger judged (a user's)
    claims = {c.claim_id: c for c in ALL_CLAIMS}
    for row in ledger:
        claims.setdefault(row.claim_id, row.claim)
    for claim in claims.values():
        parts = []
        for row in ledger:
            if row.claim_id != claim.claim_id:
                continue
            r = row.result
            parts.append(f"{row.outcome} vs {row.comparison} ("
                         + effect(r.estimate, r.ci_low, r.ci_high, unit(claim.primary_metric),
                                  r.n_pairs, r.n_tied) + ")")
        if parts:
            lines.append(f"{claim.claim_id} {claim.text}: " + "; ".join(parts))
    return lines


def ledger_groups(ledger: Ledger, movers: dict[tuple[str, str], Movers] | None = None,
                  anchor: str = "ledger") -> list[dict]:
    """The ledger's records, grouped by claim (one row group per claim: ``first``, ``span``),
    each with its metric's ``unit``, its anchor ``id`` and (given ``movers``) the members that
    move it most (``movers``: a :class:`~pipeline.reporting.movers.Movers`, or None)."""
    movers = movers or {}
    records = [{**r, "unit": unit(r["metric"]), "id": f"{anchor}-{r['claim']}-{r['comparison']}",
                "movers": movers.get((r["claim"], r["comparison"]))} for r in ledger.records()]
    by_claim: dict[str, list[dict]] = {}
    for row in records:
        by_claim.setdefault(row["claim"], []).append(row)
    return [{**row, "first": i == 0, "span": len(rows)}
            for rows in by_claim.values() for i, row in enumerate(rows)]


def _cap_note(counts: tuple[dict, ...], cap_binding_share: float) -> str:
    """What the improved rollout's step cap does over the family."""
    share = {c["method"]: c["step_cap_binding_share"] for c in counts}.get("improved")
    if share is None or not np.isfinite(share):
        return ""
    note = (f"The improved rollout's step cap binds on {100 * share:.0f} % of its steps "
            f"over the family.")
    if share >= cap_binding_share:
        note += (" On those steps two of the paper's revisions are inactive: 'no "
                 "normalization' and 'a larger step' change nothing, and the rollout is a "
                 "normalized step of the cap's length; the comparison with "
                 "baseline_matched isolates the remaining revisions.")
    return note


def family_section(inputs: ReportInputs, verdicts: Verdicts, figures: Figures
                   ) -> FamilySection | None:
    family, judged = inputs.family, verdicts.family
    if family is None or judged is None:
        return None
    cfg = verdicts.claims
    tables = judged.tables
    ledger = judged.ledger
    names = {c.claim_id: c.primary_metric for c in ALL_CLAIMS}
    names.update({r.claim_id: r.claim.primary_metric for r in ledger if r.claim_id not in names})
    intervals = {row.key: (row.result.ci_low, row.result.ci_high, row.result.estimate)
                 for row in ledger}
    drawn = [
        figures.draw(claim_differences_figure(ledger.differences, names, intervals),
                     "claim_differences", "claims",
                     "Per-scenario paired differences improved − comparison on each claim's "
                     "primary metric (below zero: improved better), with the estimate's "
                     "bootstrap interval (at the ledger's level, 1 - alpha / 7), against each comparison.",
                     "Scatter of paired differences per claim with estimate and confidence "
                     "interval"),
        figures.draw(family_distribution_figure(
            tables, [c.primary_metric for c in ALL_CLAIMS[1:]] + ["min_clearance_m"]),
            "family_distributions", "family",
            "Distribution of each claim's metric and of the minimum clearance per method "
            "over the scenario family (missing values, e.g. never recovered, are "
            "left out of the boxes and counted in the outcomes table).",
            "Box plots of metrics per method over the scenario family")]
    first: dict[str, Any] = next(iter(family.info.values())) if family.info else {
        "seed": "?", "size": len(next(iter(tables.values())))}
    adds = apf_adds(judged.apf_adds)
    records = ledger.records()
    gallery, gallery_note = _gallery(family, judged, cfg, figures)
    return FamilySection(
        size=first["size"], seed=first["seed"], treatment=cfg.treatment,
        methods=tuple(ordered(tables)),
        ledger=tuple(ledger_groups(ledger, ledger_movers(tables, cfg.treatment,
                                                         ledger.comparisons, "family",
                                                         claims_of(cfg)))),
        by_claim={r["claim"]: r for r in records if r["comparison"] == cfg.controls[0]},
        solvers=_solvers(family, tables), counts=judged.counts,
        cap_note=_cap_note(judged.counts, cfg.cap_binding_share), apf_adds=adds,
        figures=tuple(drawn), gallery=gallery,
        answer=tuple(answer_lines(ledger) + ([adds.sentence] if adds else [])),
        c2_windows=tuple({**r, "unit": unit(r["metric"])} for r in judged.c2_windows.rows())
        if judged.c2_windows is not None else (),
        c2_windows_note=judged.c2_windows.note if judged.c2_windows is not None else "",
        gallery_note=gallery_note)


def _solvers(family: FamilyInputs, tables: dict) -> str:
    """Each family's controller and its QP backend."""
    return "; ".join(
        f"{label}: {s.controller.kind}"
        + (f" ({s.controller.formulation} QP, {s.controller.backend})"
           if s.controller.kind == "mpc" else f" ({s.controller.backend})"
           if s.controller.kind == "kinematic_mpc" else "")
        for label, s in (family.settings or {}).items() if label in tables) or "not recorded"


def _gallery(family: FamilyInputs, judged: FamilyVerdicts, cfg, figures: Figures
             ) -> tuple[tuple[Figure, ...], str]:
    """Family members picked by :func:`pipeline.reporting.gallery.gallery_members`, each drawn
    as the Figure 2/3 analogue (first control above the treatment). Members that cannot be
    read are left out."""
    if not cfg.controls:
        return (), "no control is named (claims.controls), so no pair of runs to draw"
    treatment, control = cfg.treatment, cfg.controls[0]
    picks = gallery_members(judged.tables, treatment, control,
                            {c.claim_id: c.primary_metric for c in ALL_CLAIMS})
    if not picks:
        return (), (f"no member to show: {treatment} and {control} share no scenario the "
                    "rule can pick")
    out = []
    unread = []
    for pick in picks:
        member = pick["member"]
        try:
            # each method's judged family (an extra family of a method has its own label)
            runs = {m: read_member(Path(family.info[family.label_of(m) or m]["dir"]), member)
                    for m in (control, treatment)}
        except (RunFolderError, KeyError, OSError):
            unread.append(member)
            continue
        first = runs[treatment]
        # the first obstacle's appearance, whichever source built the member's scenario
        appear = build_scenario(first.config.scenario).obstacle_appear_s
        # built in the writer's child (the parent goes on to the next member)
        goal = first.config.scenario.goal_xy_m
        fig = functools.partial(paths_figure, {m: r.trajectory for m, r in runs.items()},
                                (float(goal[0]), float(goal[1])),
                                first.config.vehicle.footprint_radius_m,
                                float(appear[0]) if appear.size else None,
                                titles={m: f"{m}, member {member}" for m in runs},
                                width_in=6.0)
        out.append(figures.draw(
            fig, f"gallery_member_{member:04d}", "gallery",
            f"Family member {member} ({first.config.scenario.name}): "
            + "; ".join(pick["why"]) + ".",
            f"Paths of {control} and {treatment} on family member {member}",
            member=member, why="; ".join(pick["why"])))
    note = "" if out else (
        f"the {len(unread)} members the rule picks (" + ", ".join(map(str, unread))
        + f") could not be read from the judged families of {control} and {treatment} "
        "(their member folders are missing)")
    return tuple(out), note
