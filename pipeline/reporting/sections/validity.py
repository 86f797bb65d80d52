"""'Does the MPC's model hold?': the pooled model checks of ``make reproduce``'s families (the
default frame's, the other frame's and the Appendix-A track's; ``tables/model_validity.csv``),
the claims again where both methods' models held and in the other frame, the lateral track's
nonlinear-MPC check (``make nmpc-check``) and the speed check (``make speed-check``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.analysis.validity import ValidityTable
from pipeline.reporting.inputs import ReportInputs
from pipeline.reporting.tables import has_validity
from pipeline.reporting.verdicts import Verdicts
from pipeline.studies.results import SpeedCheckResult

#: What the goals of the lateral MPC's model are (the issue that set them; shown beside the
#: measured figures).
GOALS = {"share_steps_beyond_bound": 0.02, "runs_beyond_bound_per_200": 20,
         "prediction_error_1s_p95_m": 0.10, "plan_error_1s_p95_m": 0.15}


@dataclass(frozen=True)
class SpeedCheck:
    """``make speed-check``: per variant and method the collisions, the checks, the reason."""

    n_members: int
    methods: tuple[str, ...]
    grid: tuple[dict, ...]
    checks: tuple[dict, ...]
    reason: str


@dataclass(frozen=True)
class LateralNmpc:
    """The lateral track's part of ``make nmpc-check``."""

    n_members: int
    runs: int
    within: int
    share_percent: float
    apart: int
    apart_beyond: int | None
    agreement_m: float
    paper_path: float
    family_median: float
    agreeing: int
    outcomes: int
    differ: str
    solve_median: float
    qp_median: float


@dataclass(frozen=True)
class ValiditySection:
    """What the page shows: the table's rows, the claims in the other frame and on the valid
    scenarios, the nonlinear-MPC check of the lateral track, and a summary line."""

    rows: tuple[dict, ...]
    claims: tuple[dict, ...]
    comparisons: tuple[str, ...]
    frame: str
    other_frame: str | None
    nmpc: LateralNmpc | None
    summary: str
    bound_rad: float
    speed: SpeedCheck | None = None


def validity_section(inputs: ReportInputs, verdicts: Verdicts) -> ValiditySection | None:
    """The section; None when no family carries model checks."""
    if verdicts.validity is None or inputs.validity is None or not has_validity(inputs):
        return None
    table = inputs.validity.table
    families, others = inputs.validity.families, inputs.validity.other_frame
    config = families[0].config if families else None
    other = others[0].config if others else None
    # (a kinematic or pursuit run has no frame: read as the default)
    frame = getattr(config.controller, "frame", "path") if config is not None else "path"
    other_frame = getattr(other.controller, "frame", None) if other is not None else None
    claim_rows = verdicts.validity.rows()
    rows = tuple({
        "track": r.track, "frame": r.frame, "method": r.method, "runs": r.runs,
        "beyond_runs": "—" if r.runs_beyond_bound < 0 else f"{r.runs_beyond_bound} of {r.runs}",
        "beyond_percent": 100 * r.share_steps_beyond_bound,
        "tyre_percent": 100 * r.share_steps_tyre_nonlinear,
        "beyond_limit_percent": 100 * r.share_steps_path_beyond_limit,
        "model_p50": r.prediction_error_1s_p50_m, "model_p95": r.prediction_error_1s_p95_m,
        "plan_p50": r.plan_error_1s_p50_m, "plan_p95": r.plan_error_1s_p95_m,
        "meets": r.track == "lateral" and r.frame == "path"
        and np.isfinite(r.prediction_error_1s_p95_m)
        and r.prediction_error_1s_p95_m <= GOALS["prediction_error_1s_p95_m"]}
        for r in table.rows)
    return ValiditySection(
        rows, tuple(claim_rows), verdicts.validity.comparisons, frame, other_frame,
        _lateral_nmpc(inputs), _summary(table, frame, other_frame, claim_rows),
        float(config.model.validity_heading_rad) if config is not None else float("nan"),
        _speed(inputs.speed) if inputs.speed is not None else None)


def _speed(result: SpeedCheckResult) -> SpeedCheck:
    """``make speed-check``'s table and checks, and why slower is less safe where it is."""
    rows = result.rows
    variants = list(dict.fromkeys(r["variant"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    cells = {(r["variant"], r["method"]): r for r in rows}
    grid = tuple({"variant": v, "what": next(r["what"] for r in rows if r["variant"] == v),
                  "cells": [f"{cells[(v, m)]['collisions']} "
                            f"({cells[(v, m)]['collisions_unavoidable']})"
                            if (v, m) in cells else "—" for m in methods]} for v in variants)
    checks = result.checks
    scaled = [c for c in checks if c["variant"] == "slow_time_scaled"]
    slow = [c for c in checks if c["variant"] == "slow"]
    if scaled and all(c["holds"] for c in scaled):
        remains = ("met at half their speed too (the same encounters in space), the slower "
                   "vehicle is the safer one for every method")
    elif scaled:
        remains = ("even met at half their speed (the same encounters in space) the slower "
                   "vehicle collides more for " + ", ".join(c["method"] for c in scaled
                                                            if not c["holds"]))
    else:
        remains = ""
    reason = ("" if not slow or all(c["holds"] for c in slow) else
              "What remains at 1.5 m/s on the same obstacles is the obstacles' relative "
              "speed: a crossing obstacle at up to 0.8 m/s moves at half the slower "
              "vehicle's speed and can follow it sideways; " + remains + ".")
    return SpeedCheck(result.n_members, tuple(methods), grid, tuple(checks), reason)


def _summary(table: ValidityTable, frame: str, other_frame: str | None,
             claims: list[dict]) -> str:
    """One sentence: how often the treatment's model held in each frame, and how many outcomes
    hold on the valid scenarios."""
    parts = []
    for f in (frame, other_frame):
        row = table.row("lateral", f, "improved") if f else None
        if row is not None and row.runs_beyond_bound >= 0:
            parts.append(f"In the {f} frame improved leaves the small-angle bound in "
                         f"{row.runs_beyond_bound} of {row.runs} runs "
                         f"({100 * row.share_steps_beyond_bound:.2g} % of steps) and its "
                         f"model is {row.prediction_error_1s_p95_m:.2f} m off 1 s ahead "
                         f"(p95)")
    same = sum(c["valid_outcome"] == c["outcome"] for c in claims)
    if claims:
        parts.append(f"{same} of {len(claims)} outcomes are the same on the scenarios where "
                     "both methods' models held")
    return ". ".join(p[0].upper() + p[1:] for p in parts) + "." if parts else ""


def _lateral_nmpc(inputs: ReportInputs) -> LateralNmpc | None:
    """The lateral track's part of ``make nmpc-check`` (None when it was not run)."""
    part = inputs.nmpc.track("lateral") if inputs.nmpc is not None else None
    if not part:
        return None
    differ = [f"{v['claim']} vs {v['comparison']}: {v['ltv']} (QP) / {v['nmpc']} (NMPC)"
              for v in part["verdicts"] if v["ltv"] != v["nmpc"]]
    return LateralNmpc(
        part["n_members"], part["runs"], part["runs_paths_within"],
        100 * part["share_paths_within"], part["runs"] - part["runs_paths_within"],
        part.get("runs_apart_linear_beyond_bound"), part["path_agreement_m"],
        part["paper"]["max_path_difference_m"],
        part["family"]["median_of_max_path_difference_m"], part["outcomes_agreeing"],
        part["outcomes"], "; ".join(differ), part["nmpc_solve_median_ms"],
        part["ltv_solve_median_ms"])

