"""The report's "Does the MPC's model hold?" section: one function of the run folders returning
a frozen section value (the page renders it).

It reads, through the store, every scenario family of ``make reproduce``'s outputs: the default
frame's (``family/``), the other frame's (``frames/``, ``controller.frame=fixed``) and the
Appendix-A track's (``kinematic_family/``); pools each family's per-step model checks into one
row of ``tables/model_validity.csv`` (:mod:`pipeline.analysis.validity`); judges the claims
again on the scenarios where both methods' models held, and in the other frame; and reads the
lateral track's nonlinear-MPC check (``make nmpc-check``) when it was run.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.analysis.claims import family_ledger
from pipeline.analysis.validity import ValidityTable, valid_scenario_ledgers
from pipeline.store.collection import model_validity_table, trusted_families

#: What the goals of the lateral MPC's model are (the issue that set them; shown beside the
#: measured figures).
GOALS = {"share_steps_beyond_bound": 0.02, "runs_beyond_bound_per_200": 20,
         "prediction_error_1s_p95_m": 0.10, "plan_error_1s_p95_m": 0.15}


@dataclass(frozen=True)
class ValiditySection:
    """What the page shows: the table (formatted rows), the claims in the other frame and on
    the valid scenarios, the nonlinear-MPC check of the lateral track, and a summary line."""

    rows: tuple[dict, ...]
    claims: tuple[dict, ...]
    comparisons: tuple[str, ...]
    frame: str
    other_frame: str | None
    nmpc: dict | None
    summary: str
    bound_rad: float
    speed: dict | None = None


def _fmt(value, digits: str = ".3g") -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "—"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    return format(float(value), digits)


def validity_section(run_root: Path, tables: dict[str, pd.DataFrame], claims,
                     table_dir: Path, nmpc_dir: Path | None = None) -> ValiditySection | None:
    """The section (see the module docstring); None when no family carries model checks.

    Parameters
    ----------
    run_root : Path
        ``make reproduce``'s outputs.
    tables : dict of method -> DataFrame
        The default frame's family tables the ledger judges (``family_metrics.csv``).
    claims : ClaimsConfig
        The settings the claims are judged with (treatment, controls, margins).
    """
    run_root = Path(run_root)
    table = model_validity_table(run_root)
    rows = table.rows
    if not rows or not any(np.isfinite(r.prediction_error_1s_p95_m) for r in rows):
        return None
    table.to_frame().to_csv(table_dir / "model_validity.csv", index=False)
    families = trusted_families(run_root / "family")
    others = trusted_families(run_root / "frames")
    frame = families[0].config.controller.frame if families else "path"
    other_frame = others[0].config.controller.frame if others else None
    comparisons = tuple(c for c in claims.controls if c in tables)
    # the claims: the default ledger, on the scenarios where both models held, in the other frame
    default = family_ledger(tables, claims, None, claims.treatment, comparisons,
                            sensitivity=False) if claims.treatment in tables else None
    valid = valid_scenario_ledgers(tables, claims, claims.treatment, comparisons)
    other_tables = {f.info.get("method"): f.table for f in others}
    other = family_ledger(other_tables, claims, None, claims.treatment, comparisons,
                          sensitivity=False) if claims.treatment in other_tables else None
    claim_rows = []
    for row in (default or ()):
        key = row.key
        valid_ledger, n_valid = valid.get(row.comparison, (None, 0))
        valid_row = valid_ledger.get(key) if valid_ledger is not None else None
        other_row = other.get(key) if other is not None else None
        claim_rows.append({
            "claim": row.claim_id, "comparison": row.comparison, "outcome": str(row.outcome),
            "n": row.result.n_pairs,
            "valid_outcome": str(valid_row.outcome) if valid_row else "—",
            "valid_n": valid_row.result.n_pairs if valid_row else 0,
            "valid_scenarios": n_valid,
            "other_outcome": str(other_row.outcome) if other_row else "—",
            "other_n": other_row.result.n_pairs if other_row else 0})
    pd.DataFrame(claim_rows).to_csv(table_dir / "claims_model_validity.csv", index=False)
    formatted = []
    for r in rows:
        beyond = "—" if r.runs_beyond_bound < 0 else f"{r.runs_beyond_bound} of {r.runs}"
        formatted.append({
            "track": r.track, "frame": r.frame, "method": r.method, "runs": r.runs,
            "beyond_runs": beyond,
            "beyond_share": _fmt(100 * r.share_steps_beyond_bound, ".2g"),
            "tyre": _fmt(100 * r.share_steps_tyre_nonlinear, ".2g"),
            "clipped": _fmt(100 * r.share_steps_path_clipped, ".2g"),
            "model": f"{_fmt(r.prediction_error_1s_p50_m, '.2f')} / "
                     f"{_fmt(r.prediction_error_1s_p95_m, '.2f')}",
            "plan": f"{_fmt(r.plan_error_1s_p50_m, '.2f')} / "
                    f"{_fmt(r.plan_error_1s_p95_m, '.2f')}",
            "meets": r.track == "lateral" and r.frame == "path"
            and np.isfinite(r.prediction_error_1s_p95_m)
            and r.prediction_error_1s_p95_m <= GOALS["prediction_error_1s_p95_m"]})
    nmpc = _lateral_nmpc(nmpc_dir if nmpc_dir is not None else run_root / "nmpc_check")
    summary = _summary(table, frame, other_frame, claim_rows)
    return ValiditySection(tuple(formatted), tuple(claim_rows), comparisons, frame,
                           other_frame, nmpc, summary, float(families[0].config.model
                                                             .validity_heading_rad)
                           if families else float("nan"), _speed(run_root / "speed"))


def _speed(folder: Path) -> dict | None:
    """``make speed-check``'s table and checks (None when it was not run)."""
    path = Path(folder) / "summary.json"
    if not path.is_file():
        return None
    summary = json.loads(path.read_text())
    rows = summary["rows"]
    variants = list(dict.fromkeys(r["variant"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    cells = {(r["variant"], r["method"]): r for r in rows}
    grid = [{"variant": v, "what": next(r["what"] for r in rows if r["variant"] == v),
             "cells": [f"{cells[(v, m)]['collisions']} ({cells[(v, m)]['collisions_unavoidable']})"
                       if (v, m) in cells else "—" for m in methods]} for v in variants]
    checks = summary["checks"]
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
    return {"n_members": summary["n_members"], "methods": methods, "grid": grid,
            "checks": checks, "reason": reason}


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


def _lateral_nmpc(folder: Path) -> dict | None:
    """The lateral track's part of ``make nmpc-check`` (None when it was not run)."""
    path = Path(folder) / "summary.json"
    if not path.is_file():
        return None
    summary = json.loads(path.read_text())
    part = summary.get("tracks", {}).get("lateral")
    if not part:
        return None
    differ = [f"{v['claim']} vs {v['comparison']}: {v['ltv']} (QP) / {v['nmpc']} (NMPC)"
              for v in part["verdicts"] if v["ltv"] != v["nmpc"]]
    return {"n_members": part["n_members"], "runs": part["runs"],
            "within": part["runs_paths_within"], "share": _fmt(100 * part["share_paths_within"],
                                                                ".3g"),
            "apart": part["runs"] - part["runs_paths_within"],
            "apart_beyond": part.get("runs_apart_linear_beyond_bound"),
            "agreement_m": part["path_agreement_m"],
            "paper_path": _fmt(part["paper"]["max_path_difference_m"]),
            "family_median": _fmt(part["family"]["median_of_max_path_difference_m"]),
            "agreeing": part["outcomes_agreeing"], "outcomes": part["outcomes"],
            "differ": "; ".join(differ), "solve_median": _fmt(part["nmpc_solve_median_ms"]),
            "qp_median": _fmt(part["ltv_solve_median_ms"])}
