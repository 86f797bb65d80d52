"""Is the Appendix-A track's LTV-QP a faithful stand-in for ``nlmpc``? (``make nmpc-check``)

The kinematic track's default controller linearizes the nonlinear program of MATLAB's
``nlmpc`` once per step (:mod:`pipeline.loop.controller.kinematic`); ``controller.backend=nmpc``
solves the program itself (:mod:`pipeline.loop.controller.nmpc`). Both run the paper scenario
and the first ``n_members`` members of the kinematic family for every method of the track; per
run the largest difference of the two paths (same step, metres) and of the applied inputs, and
the NMPC's solve time per step; over the family, the claims ledger under each controller and
whether its outcomes agree. Results: ``agreement.csv`` (one row per run) and ``summary.json``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.analysis.claims import family_ledger
from pipeline.store.runs import json_safe, write_csv_atomic, write_json_atomic

#: Methods of the kinematic track (experiment=kinematic) and the planner preset of each: the
#: baseline under the track's default reading (the printed formula).
TRACK_METHODS = ("baseline", "baseline_matched", "improved")
TRACK_PLANNERS = {"baseline": "baseline_printed"}


def _pair(cfg_ltv, cfg_nmpc, scenario) -> dict:
    """One scenario under both controllers: path and input differences, solve times, and
    both runs' metrics."""
    from pipeline.analysis.metrics import compute_metrics
    from pipeline.loop.simulate import simulate
    from pipeline.studies.experiment import trajectory_context

    runs = {}
    for name, cfg in (("ltv", cfg_ltv), ("nmpc", cfg_nmpc)):
        start = time.perf_counter()
        result = simulate(cfg, scenario)
        metrics = compute_metrics(result.trajectory, trajectory_context(cfg), cfg.metrics)
        runs[name] = (result, metrics, time.perf_counter() - start)
    a, b = runs["ltv"][0].trajectory, runs["nmpc"][0].trajectory
    n = min(len(a), len(b)) - 1  # the last row logs the end, without an input
    path = np.hypot(a["X_m"].to_numpy()[:n] - b["X_m"].to_numpy()[:n],
                    a["Y_m"].to_numpy()[:n] - b["Y_m"].to_numpy()[:n])
    accel = np.abs(a["accel_mps2"].to_numpy(float)[:n] - b["accel_mps2"].to_numpy(float)[:n])
    steer = np.abs(a["delta_rad"].to_numpy(float)[:n] - b["delta_rad"].to_numpy(float)[:n])
    times = runs["nmpc"][0].solve_times_s
    return {"max_path_difference_m": float(np.nanmax(path)) if n > 0 else np.nan,
            "max_accel_difference_mps2": float(np.nanmax(accel)) if n > 0 else np.nan,
            "max_steering_difference_rad": float(np.nanmax(steer)) if n > 0 else np.nan,
            "nmpc_solve_median_ms": 1e3 * float(np.median(times)) if times.size else np.nan,
            "nmpc_solve_max_ms": 1e3 * float(np.max(times)) if times.size else np.nan,
            "ltv_solve_median_ms": 1e3 * float(np.median(runs["ltv"][0].solve_times_s)),
            "nmpc_fallback_steps": int((b["fallback"].fillna("end").isin(
                ["shifted_plan", "safe_input"])).sum()),
            "metrics_ltv": runs["ltv"][1].to_json(), "metrics_nmpc": runs["nmpc"][1].to_json()}


def nmpc_agreement(compose, out_dir: Path, n_members: int = 50, log=print) -> dict:
    """Run the comparison and write its tables (see the module docstring)."""
    import dataclasses

    from pipeline.loop.scenario import build_scenario, family_members

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rows, tables = [], {"ltv": {}, "nmpc": {}}
    for method in TRACK_METHODS:
        base = ["experiment=kinematic", f"planner={TRACK_PLANNERS.get(method, method)}"]
        paper_ltv, paper_nmpc = compose(base), compose(base + ["controller.backend=nmpc"])
        jobs = [("paper", paper_ltv, paper_nmpc, build_scenario(paper_ltv.scenario))]
        family = compose(base + ["scenario=family", f"scenario.family.size={n_members}"])
        family_nmpc = compose(base + ["scenario=family", f"scenario.family.size={n_members}",
                                      "controller.backend=nmpc"])
        for member in family_members(family.scenario, family.vehicle.footprint_radius_m):
            jobs.append((member.name, dataclasses.replace(family, scenario=member),
                         dataclasses.replace(family_nmpc, scenario=member),
                         build_scenario(member)))
        member_rows = {"ltv": [], "nmpc": []}
        for name, cfg_ltv, cfg_nmpc, scenario in jobs:
            pair = _pair(cfg_ltv, cfg_nmpc, scenario)
            m_ltv, m_nmpc = pair.pop("metrics_ltv"), pair.pop("metrics_nmpc")
            rows.append({"method": method, "scenario": name, **pair,
                         "min_clearance_ltv_m": m_ltv.get("min_clearance_m"),
                         "min_clearance_nmpc_m": m_nmpc.get("min_clearance_m")})
            if name != "paper":
                member_rows["ltv"].append({"scenario": name, **m_ltv})
                member_rows["nmpc"].append({"scenario": name, **m_nmpc})
        for backend in ("ltv", "nmpc"):
            tables[backend][method] = pd.DataFrame(member_rows[backend])
        log(f"{method}: {len(jobs)} scenarios under both controllers")
    table = pd.DataFrame(rows)
    write_csv_atomic(out_dir / "agreement.csv", table)
    claims = compose(["experiment=kinematic"]).claims
    ledgers = {b: family_ledger(tables[b], claims, None, "improved",
                                ("baseline", "baseline_matched"), sensitivity=False)
               for b in ("ltv", "nmpc")}
    verdicts = [{"claim": r.claim_id, "comparison": r.comparison, "ltv": str(r.outcome),
                 "nmpc": str(ledgers["nmpc"][r.key].outcome),
                 "ltv_estimate": r.result.estimate,
                 "nmpc_estimate": ledgers["nmpc"][r.key].result.estimate}
                for r in ledgers["ltv"]]
    paper = table[table["scenario"] == "paper"]
    family_part = table[table["scenario"] != "paper"]
    summary = {
        "n_members": n_members, "methods": list(TRACK_METHODS),
        "paper": {"max_path_difference_m": float(paper["max_path_difference_m"].max()),
                  "max_steering_difference_rad": float(paper["max_steering_difference_rad"].max()),
                  "max_accel_difference_mps2": float(paper["max_accel_difference_mps2"].max())},
        "family": {"max_path_difference_m": float(family_part["max_path_difference_m"].max()),
                   "median_of_max_path_difference_m":
                       float(family_part["max_path_difference_m"].median()),
                   "runs": int(len(family_part)),
                   "runs_over_half_metre": int((family_part["max_path_difference_m"]
                                                > 0.5).sum()),
                   "max_steering_difference_rad":
                       float(family_part["max_steering_difference_rad"].max()),
                   "max_accel_difference_mps2":
                       float(family_part["max_accel_difference_mps2"].max())},
        "nmpc_solve_median_ms": float(table["nmpc_solve_median_ms"].median()),
        "nmpc_solve_max_ms": float(table["nmpc_solve_max_ms"].max()),
        "ltv_solve_median_ms": float(table["ltv_solve_median_ms"].median()),
        "nmpc_fallback_steps": int(table["nmpc_fallback_steps"].sum()),
        "verdicts": verdicts,
        "verdicts_agree": all(v["ltv"] == v["nmpc"] for v in verdicts)}
    write_json_atomic(out_dir / "summary.json", json_safe(summary))
    return summary
