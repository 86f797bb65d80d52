"""'Does it look like the paper?': each phrase of the paper about its figures as a measured
feature, present or absent, for baseline and improved on each track and reading; the rule
that picks the Appendix-A reading (both methods meet the obstacle, most phrases matched) and
whether the configured default is its pick."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from pipeline.analysis.features import FEATURES, FeatureConfig, feature_row, paper_likeness
from pipeline.reporting.inputs import ReportInputs, reading_of
from pipeline.reporting.verdicts import Verdicts
from pipeline.store.collection import LabelledRun


@dataclass(frozen=True)
class LooksSection:
    columns: tuple[dict, ...]
    rows: tuple[dict, ...]
    n: int
    rule_note: str
    clearance: str


def _pair(runs: Iterable[LabelledRun]) -> dict[str, LabelledRun]:
    return {r.method: r for r in runs if r.method in ("baseline", "improved")}


def looks_section(inputs: ReportInputs, verdicts: Verdicts) -> LooksSection | None:
    if inputs.lateral is None:
        return None
    clearance_m = verdicts.claims.comparable_clearance_m
    lateral = inputs.lateral.by_method
    columns: list[tuple[str, str, dict[str, LabelledRun]]] = [
        ("lateral track", "default", {m: lateral[m] for m in ("baseline", "improved")
                                      if m in lateral})]
    kinematic_runs = list(inputs.kinematic.runs) if inputs.kinematic is not None else []
    kin = _pair(kinematic_runs)
    if "baseline" in kin:
        columns.append(("Appendix-A track", reading_of(kin["baseline"].config) + " (default)",
                        kin))
    for variant, runs in inputs.readings.items():
        columns.append(("Appendix-A track", variant, _pair(runs)))
    columns = [c for c in columns if {"baseline", "improved"} <= set(c[2])]
    if not columns:
        return None
    settings = columns[0][2]["improved"].config.get("features") or {}
    cfg = FeatureConfig(**settings)
    cells: list[dict[str, Any]] = []
    for track, reading, pair in columns:
        rows = {m: feature_row(pair[m].metrics(), cfg) for m in ("baseline", "improved")}
        met = all((pair[m].metrics().get("min_clearance_m") or math.inf) <= clearance_m
                  for m in ("baseline", "improved"))
        cells.append({"track": track, "reading": reading, "rows": rows, "met": met,
                      "score": paper_likeness(rows["baseline"], rows["improved"])})
    word = {True: "yes", False: "no", None: "—"}
    table = tuple({"phrase": f.phrase, "describes": f.describes, "rule": f.rule,
                   "cells": [[word[c["rows"][m][f.key]] for m in ("baseline", "improved")]
                             for c in cells]} for f in FEATURES)
    return LooksSection(
        tuple({"track": c["track"], "reading": c["reading"], "score": c["score"],
               "met": "yes" if c["met"] else "no"} for c in cells),
        table, len(FEATURES), _rule_note(cells, clearance_m), f"{clearance_m:g}")


def _rule_note(cells: list[dict], clearance_m: float) -> str:
    """Which Appendix-A reading the register's rule picks, and whether it is the default."""
    kinematic = [c for c in cells if c["track"] == "Appendix-A track"]
    eligible = [c for c in kinematic if c["met"]]
    pick = max(eligible, key=lambda c: c["score"]) if eligible else None
    default = next((c for c in kinematic if c["reading"].endswith("(default)")), None)
    rule = ("The register's rule for the Appendix-A reading: among the readings under which "
            "both methods meet the obstacle, the one whose runs match most of the paper's "
            "phrases. ")
    if pick is None:
        return (rule + "No Appendix-A reading lets both methods meet the obstacle (within "
                f"{clearance_m:g} m).") if kinematic else ""
    if default is not None and pick["score"] == default["score"] and default["met"]:
        return rule + ("It picks the configured default ("
                       + default["reading"].replace(" (default)", "") + ").")
    return (rule + f"It picks <code>{pick['reading']}</code> ({pick['score']} of "
            f"{len(FEATURES)} phrases); the configured default "
            + (f"({default['reading']}) " if default else "") + "differs: change "
            "conf/experiment/kinematic.yaml.")
