"""The Appendix-A track (the paper's kinematic bicycle MPC): its paper-scenario figures,
metrics and claims beside the lateral track's, the check against a nonlinear MPC, the claims
under other readings of the baseline, and its own ledger over the scenario family."""

from __future__ import annotations

from dataclasses import dataclass

import pandas as pd

from pipeline.reporting.figure import Figure, Figures
from pipeline.reporting.format import collision_words, fmt, interval, unit
from pipeline.reporting.inputs import ReportInputs, ordered
from pipeline.reporting.sections.family import ApfAdds, apf_adds
from pipeline.reporting.sections.paper import MetricRow, claim_rows, metric_rows, paper_figures
from pipeline.reporting.verdicts import Verdicts


@dataclass(frozen=True)
class NmpcCheck:
    """The kinematic track's part of ``make nmpc-check``."""

    paper_path: float
    paper_steer: float
    paper_accel: float
    family_path: float
    family_median: float
    family_apart: int | None
    family_runs: int | None
    n_members: int
    agree: bool
    differ: str
    solve_median: float
    solve_max: float
    ltv_median: float


@dataclass(frozen=True)
class KinematicFamily:
    """The track's ledger over its family, its collisions, and whether each outcome agrees
    with the lateral family's."""

    rows: tuple[dict, ...]
    grid: tuple[dict, ...]
    columns: tuple[str, ...]
    collisions: tuple[dict, ...]
    apf_adds: ApfAdds | None
    size: int
    notes: tuple[str, ...]
    n_agree: int
    n_compared: int
    treatment: str

    @property
    def collision_words(self) -> str:
        """The collisions in words, never adding up families of different sizes."""
        return collision_words([{**c, "scenarios": c["members"]} for c in self.collisions])


@dataclass(frozen=True)
class KinematicSection:
    methods: tuple[str, ...]
    figures: tuple[Figure, ...]
    metric_rows: tuple[MetricRow, ...]
    claims: tuple[dict, ...]
    comparison: tuple[dict, ...]
    comparability: tuple[str, ...]
    comparable_clearance: float
    n_steps: int
    initial_speed: float | None
    nmpc: NmpcCheck | None
    family: KinematicFamily | None
    readings: tuple[dict, ...]


def kinematic_section(inputs: ReportInputs, verdicts: Verdicts, figures: Figures
                      ) -> KinematicSection | None:
    runs, track, paper = inputs.kinematic, verdicts.kinematic, verdicts.paper
    if runs is None or track is None or paper is None:
        return None
    cfg = verdicts.claims
    config = next(iter(runs.by_method.values())).config
    claims = claim_rows(track, runs.methods)
    lateral = {r["claim"]: r.get("vs baseline", "n/a") for r in paper.rows}
    comparison = []
    for r in claims:
        ours = r.get("vs baseline", "n/a")
        agree = "n/a" if ours == "not comparable" else ("yes" if lateral.get(r["claim"]) == ours
                                                        else "no")
        comparison.append({"claim": r["claim"], "lateral": lateral.get(r["claim"], "n/a"),
                           "other": ours, "agree": agree})
    family = verdicts.family
    lateral_outcomes = {c: str(r.get("outcome")) for c, r in
                        ({r["claim"]: r for r in family.ledger.records()
                          if r["comparison"] == cfg.controls[0]}.items() if family else ())}
    return KinematicSection(
        methods=tuple(runs.methods),
        figures=tuple(paper_figures(runs, figures, prefix="kinematic_",
                                    group_prefix="kinematic_")),
        metric_rows=metric_rows(runs), claims=claims, comparison=tuple(comparison),
        comparability=track.comparability,
        comparable_clearance=cfg.comparable_clearance_m, n_steps=config["scenario"]["n_steps"],
        initial_speed=config["scenario"].get("initial_speed_mps"),
        nmpc=_nmpc(inputs), family=_family(inputs, verdicts, lateral_outcomes),
        readings=tuple({"reading": name, "cells": [o.get(c, "n/a") for c in list(
            verdicts.readings[0][1])], "claims": list(verdicts.readings[0][1])}
            for name, o in verdicts.readings))


def _nmpc(inputs: ReportInputs) -> NmpcCheck | None:
    """The LTV-QP against the nonlinear MPC on this track (``make nmpc-check``)."""
    part = inputs.nmpc.track("kinematic") if inputs.nmpc is not None else None
    if not part:
        return None  # the check ran on the lateral track only
    differ = [f"{v['claim']} vs {v['comparison']}: {v['ltv']} (LTV) / {v['nmpc']} (NMPC)"
              for v in part["verdicts"] if v["ltv"] != v["nmpc"]]
    return NmpcCheck(
        part["paper"]["max_path_difference_m"], part["paper"]["max_steering_difference_rad"],
        part["paper"]["max_accel_difference_mps2"], part["family"]["max_path_difference_m"],
        part["family"]["median_of_max_path_difference_m"],
        part["family"].get("runs_over_half_metre"), part["family"].get("runs"),
        part["n_members"], part["verdicts_agree"], "; ".join(differ),
        part["nmpc_solve_median_ms"], part["nmpc_solve_max_ms"], part["ltv_solve_median_ms"])


def _family(inputs: ReportInputs, verdicts: Verdicts, lateral_by_claim: dict[str, str]
            ) -> KinematicFamily | None:
    """The track's own ledger over its family (the default reading): the treatment against
    each control, the baseline against mpc_no_apf, collision counts per method, and whether
    each outcome agrees with the lateral family's."""
    judged, found = verdicts.kinematic_family, inputs.kinematic_family
    if judged is None or found is None:
        return None
    cfg = verdicts.claims
    tables = judged.tables
    first_control = cfg.controls[0]
    rows = tuple({"claim": r.claim_id, "words": r.claim.text, "comparison": r.comparison,
                  "outcome": str(r.outcome),
                  "estimate": f"{fmt(r.result.estimate)} "
                              f"{interval(r.result.ci_low, r.result.ci_high)} "
                              f"{unit(r.claim.primary_metric)}",
                  "n_pairs": r.result.n_pairs,
                  "lateral": lateral_by_claim.get(r.claim_id, "n/a")
                  if r.comparison == first_control else "",
                  "agree": ("yes" if lateral_by_claim.get(r.claim_id) == str(r.outcome)
                            else "no")
                  if r.comparison == first_control and r.claim_id in lateral_by_claim
                  else ""}
                 for r in judged.ledger)
    collisions = tuple({"method": m, "collisions": int(pd.to_numeric(
        t.get("collision"), errors="coerce").fillna(0).sum()) if "collision" in t else "n/a",
        "members": len(t)} for m, t in ((m, tables[m]) for m in ordered(tables)))
    adds = apf_adds(judged.apf_adds)
    size = next(iter(found.info.values()), {}).get("size", len(tables[cfg.treatment]))
    agree = [r for r in rows if r["agree"]]
    # one row per claim: each comparison a column (and the baseline against no APF)
    columns = tuple(c for c in cfg.controls if any(r["comparison"] == c for r in rows))
    apf = {r["claim"]: r for r in (adds.rows if adds else ())}
    grid = []
    for claim in dict.fromkeys(r["claim"] for r in rows):
        cells = {r["comparison"]: r for r in rows if r["claim"] == claim}
        first = cells.get(columns[0], {}) if columns else {}
        grid.append({"claim": claim, "words": first.get("words", ""),
                     "cells": [cells.get(c) for c in columns], "apf": apf.get(claim),
                     "lateral": first.get("lateral", ""), "agree": first.get("agree", "")})
    return KinematicFamily(rows, tuple(grid), columns, collisions, adds, size, found.notes,
                           sum(r["agree"] == "yes" for r in agree), len(agree), cfg.treatment)
