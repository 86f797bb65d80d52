"""Are the linear MPCs faithful stand-ins for nonlinear ones? (``make nmpc-check``)

Two tracks, each under its linear MPC and the same problem on the nonlinear model:

* ``kinematic`` (Appendix A): the LTV-QP (:mod:`pipeline.loop.controller.kinematic`) against
  ``controller.backend=nmpc`` (:mod:`pipeline.loop.controller.nmpc`, MATLAB's ``nlmpc`` stated
  on the kinematic bicycle itself);
* ``lateral`` (the paper's Section 2-3 model): the QP (:mod:`pipeline.loop.controller.lateral`,
  in its configured frame) against ``controller.backend=nmpc``
  (:mod:`pipeline.loop.controller.lateral_nmpc`, the same cost, constraints and references on
  the plant's nonlinear single-track model).

Both run the paper scenario and the first ``n_members`` members of the track's family for every
method of the track; per run the largest difference of the two paths (same step, metres) and
of the applied inputs, and the NMPC's solve time per step; over the family, the claims ledger
under each controller and whether its outcomes agree. Runs are spread over
``scenario.family.n_jobs`` worker processes (each builds its nonlinear program once). Results:
``agreement.csv`` (one row per run, with its ``track``) and ``summary.json`` (one section per
track).
"""

from __future__ import annotations

import dataclasses
import logging
import os
import time
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.analysis.claims import family_ledger
from pipeline.studies.results.nmpc_check import NmpcCheckResult

logger = logging.getLogger(__name__)

#: Methods of each track and the planner preset of each method: on the kinematic track the
#: baseline under the track's default reading (the printed formula).
TRACK_METHODS = ("baseline", "baseline_matched", "improved")
TRACK_PLANNERS = {"kinematic": {"baseline": "baseline_printed"}, "lateral": {}}
#: The experiment each track's runs are composed from, and its base overrides.
TRACK_BASE = {"kinematic": ["experiment=kinematic"], "lateral": []}
#: A run's paths "agree" when they stay within this distance of each other (m).
PATH_AGREEMENT_M = 0.2


def _pair(cfg_linear, cfg_nmpc, scenario_cfg, cache) -> dict:
    """One scenario under both controllers: path and input differences, solve times, and
    both runs' metrics."""
    from pipeline.analysis.metrics import compute_metrics
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate
    from pipeline.studies.experiment import trajectory_context

    scenario = build_scenario(scenario_cfg)
    runs = {}
    for name, cfg in (("linear", cfg_linear), ("nmpc", cfg_nmpc)):
        result = simulate(cfg, scenario, cache)
        metrics = compute_metrics(result.table, trajectory_context(cfg), cfg.metrics)
        runs[name] = (result, metrics)
    a, b = runs["linear"][0].trajectory, runs["nmpc"][0].trajectory
    n = min(len(a), len(b)) - 1  # the last row logs the end, without an input
    path = np.hypot(a["X_m"].to_numpy()[:n] - b["X_m"].to_numpy()[:n],
                    a["Y_m"].to_numpy()[:n] - b["Y_m"].to_numpy()[:n])
    steer = np.abs(a["delta_rad"].to_numpy(float)[:n] - b["delta_rad"].to_numpy(float)[:n])
    accel = np.abs(a["accel_mps2"].to_numpy(float)[:n] - b["accel_mps2"].to_numpy(float)[:n]) \
        if "accel_mps2" in a and "accel_mps2" in b else np.full(max(n, 0), np.nan)
    times = runs["nmpc"][0].solve_times_s

    def largest(values):
        return float(np.nanmax(values)) if n > 0 and np.isfinite(values).any() else np.nan

    return {"max_path_difference_m": largest(path),
            "max_accel_difference_mps2": largest(accel),
            "max_steering_difference_rad": largest(steer),
            "nmpc_solve_median_ms": 1e3 * float(np.median(times)) if times.size else np.nan,
            "nmpc_solve_max_ms": 1e3 * float(np.max(times)) if times.size else np.nan,
            "ltv_solve_median_ms": 1e3 * float(np.median(runs["linear"][0].solve_times_s)),
            "nmpc_fallback_steps": int((b["fallback"].fillna("end").isin(
                ["shifted_plan", "safe_input"])).sum()),
            "metrics_ltv": runs["linear"][1].to_json(), "metrics_nmpc": runs["nmpc"][1].to_json()}


def _run_chunk(jobs: list[tuple], parent_pid: int | None = None) -> list[dict]:
    """A few pairs in one worker, with one cache for its compiled problems (the nonlinear
    program is built once per worker); a worker leaves Ctrl-C to ``parent_pid``
    (:func:`~pipeline.errors.leave_interrupts_to`)."""
    from pipeline.errors import leave_interrupts_to
    from pipeline.loop.controller import QpCache

    leave_interrupts_to(parent_pid)
    cache = QpCache()
    out = []
    for track, method, name, cfg_linear, cfg_nmpc, scenario_cfg in jobs:
        started = time.perf_counter()
        pair = _pair(cfg_linear, cfg_nmpc, scenario_cfg, cache)
        out.append({"track": track, "method": method, "scenario": name, **pair,
                    "wall_s": time.perf_counter() - started})
    return out


def _jobs(compose, track: str, n_members: int) -> list[tuple]:
    """Every (method, scenario) pair of ``track``: the paper scenario, then the members."""
    from pipeline.loop.scenario import family_members

    jobs = []
    for method in TRACK_METHODS:
        planner = TRACK_PLANNERS[track].get(method, method)
        base = TRACK_BASE[track] + [f"method={method}", f"planner={planner}"]
        paper_linear, paper_nmpc = compose(base), compose(base + ["controller.backend=nmpc"])
        jobs.append((track, method, "paper", paper_linear, paper_nmpc, paper_linear.scenario))
        members = ["scenario=family", f"scenario.family.size={n_members}"]
        family = compose(base + members)
        family_nmpc = compose(base + members + ["controller.backend=nmpc"])
        for member in family_members(family.scenario, family.vehicle.footprint_radius_m):
            jobs.append((track, method, member.name, dataclasses.replace(family, scenario=member),
                         dataclasses.replace(family_nmpc, scenario=member), member))
    return jobs


def _track_summary(table: pd.DataFrame, compose, track: str, n_members: int) -> dict:
    """One track's figures: path and input differences, solve times, the two ledgers."""
    tables: dict[str, dict[str, pd.DataFrame]] = {"ltv": {}, "nmpc": {}}
    members = table[table["scenario"] != "paper"]
    for method in TRACK_METHODS:
        part = members[members["method"] == method]
        for backend in ("ltv", "nmpc"):
            tables[backend][method] = pd.DataFrame(
                [{"scenario": row["scenario"], **row[f"metrics_{backend}"]}
                 for _, row in part.iterrows()])
    claims = compose(TRACK_BASE[track]).claims
    ledgers = {b: family_ledger(tables[b], claims, None, "improved",
                                ("baseline", "baseline_matched"), sensitivity=False)
               for b in ("ltv", "nmpc")}
    verdicts = [{"claim": r.claim_id, "comparison": r.comparison, "ltv": str(r.outcome),
                 "nmpc": str(ledgers["nmpc"][r.key].outcome),
                 "ltv_estimate": r.result.estimate,
                 "nmpc_estimate": ledgers["nmpc"][r.key].result.estimate}
                for r in ledgers["ltv"]]
    paper = table[table["scenario"] == "paper"]
    within = table["max_path_difference_m"] <= PATH_AGREEMENT_M
    beyond = np.array([bool(m.get("heading_validity_exceeded")) for m in table["metrics_ltv"]],
                      dtype=bool)
    return {
        "n_members": n_members, "methods": list(TRACK_METHODS),
        "paper": {"max_path_difference_m": float(paper["max_path_difference_m"].max()),
                  "max_steering_difference_rad": float(paper["max_steering_difference_rad"].max()),
                  "max_accel_difference_mps2": float(paper["max_accel_difference_mps2"].max())},
        "family": {"max_path_difference_m": float(members["max_path_difference_m"].max()),
                   "median_of_max_path_difference_m":
                       float(members["max_path_difference_m"].median()),
                   "runs": int(len(members)),
                   "runs_over_half_metre": int((members["max_path_difference_m"]
                                                > 0.5).sum()),
                   "max_steering_difference_rad":
                       float(members["max_steering_difference_rad"].max()),
                   "max_accel_difference_mps2":
                       float(members["max_accel_difference_mps2"].max())},
        "path_agreement_m": PATH_AGREEMENT_M,
        "runs": int(len(table)), "runs_paths_within": int(within.sum()),
        "runs_apart_linear_beyond_bound": int((~within.to_numpy() & beyond).sum()),
        "share_paths_within": float(within.mean()) if len(table) else float("nan"),
        "nmpc_solve_median_ms": float(table["nmpc_solve_median_ms"].median()),
        "nmpc_solve_max_ms": float(table["nmpc_solve_max_ms"].max()),
        "ltv_solve_median_ms": float(table["ltv_solve_median_ms"].median()),
        "nmpc_fallback_steps": int(table["nmpc_fallback_steps"].sum()),
        "verdicts": verdicts,
        "outcomes_agreeing": int(sum(v["ltv"] == v["nmpc"] for v in verdicts)),
        "outcomes": len(verdicts),
        "verdicts_agree": all(v["ltv"] == v["nmpc"] for v in verdicts)}


def nmpc_agreement(compose, out_dir: Path, n_members: int = 50, log=logger.info,
                   tracks: tuple[str, ...] = ("lateral", "kinematic"), n_jobs: int = 2
                   ) -> NmpcCheckResult:
    """Run the comparison; its result written into ``out_dir`` and returned (see the module
    docstring)."""
    from pipeline.store.lock import folder_lock
    from pipeline.store.manifest import refuse_other_record

    out_dir = Path(out_dir)
    refuse_other_record(out_dir, ("nmpc_check",))
    # a second check, or a tune or multiverse, on the same folder is refused at once
    with folder_lock(out_dir, "nmpc_check"):
        return _agreement(compose, out_dir, n_members, log, tracks, n_jobs)


def _agreement(compose, out_dir: Path, n_members: int, log, tracks: tuple[str, ...],
               n_jobs: int) -> NmpcCheckResult:
    """:func:`nmpc_agreement` in its locked folder."""
    from joblib import Parallel, delayed

    from pipeline.errors import workers_start_deaf_to_ctrl_c
    from pipeline.studies.experiment import _chunks

    jobs = [job for track in tracks for job in _jobs(compose, track, n_members)]
    rows: list[dict] = []
    done = 0
    chunks = _chunks(jobs, n_jobs)
    with workers_start_deaf_to_ctrl_c():  # the workers start with Ctrl-C blocked
        parts = Parallel(n_jobs=n_jobs, return_as="generator_unordered")(
            delayed(_run_chunk)(chunk, os.getpid()) for chunk in chunks)
    for part in parts:
        rows.extend(part)
        done += len(part)
        log(f"nmpc-check: {done} of {len(jobs)} runs under both controllers")
    # in the jobs' order (track, method, paper first, then the members)
    order = {(j[0], j[1], j[2]): i for i, j in enumerate(jobs)}
    rows.sort(key=lambda row: order[(row["track"], row["method"], row["scenario"])])
    table = pd.DataFrame(rows)
    summary = {"tracks": {track: _track_summary(table[table["track"] == track], compose,
                                                track, n_members)
                          for track in tracks}}
    table["min_clearance_ltv_m"] = [m.get("min_clearance_m") for m in table["metrics_ltv"]]
    table["min_clearance_nmpc_m"] = [m.get("min_clearance_m") for m in table["metrics_nmpc"]]
    table["ltv_beyond_bound"] = [bool(m.get("heading_validity_exceeded"))
                                 for m in table["metrics_ltv"]]
    return NmpcCheckResult(summary["tracks"], table.drop(columns=["metrics_ltv",
                                                                  "metrics_nmpc"])).write(out_dir)
