"""The bench's summary: per QP configuration the medians and the ratios over the floor, the
peers, the kinematic step, the goals, and the headline figures."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

#: The targets the headline figures are read against.
GOALS = {"closed_loop_over_floor": "<= 2.0", "step_over_floor": "<= 1.3 (N=10, "
         "1 obstacle)", "step_over_sparse_floor": "<= 0.5 (default backend)",
         "step_over_sparse_floor_daqp": "<= 0.25",
         "step_over_sparse_floor_path": "<= 0.5 (path frame, Clarabel)",
         "step_over_sparse_floor_path_daqp": "<= 0.25 (path frame, DAQP)",
         "outside_qp_over_qp": "<= 1.0", "compiles_per_family": "4: one statement per number of obstacle slots, 0-3 (40 members, 2 workers)",
         "family_scenarios_per_s": ">= 20 (200 members, 2 workers)",
         "family_member_over_sparse_floor": "<= 1.0 (default backend)",
         "family_member_over_sparse_floor_daqp": "<= 0.15 (issue 58)",
         "engine_members_per_cpu_s_over_member_loop": ">= 8 (issue 58; 200 members, DAQP, "
                                                      "metrics and records included)",
         "multiverse_member_reads_per_member": "1 (at most)"}
#: The lateral table's times whose medians the summary gives (in ms).
LATERAL_TIMES = ("apf_s", "apf_python_s", "direct_python_step_s", "cvxpy_solve_s",
                 "cvxpy_clarabel_s", "cvxpy_step_s", "direct_s", "direct_step_s", "floor_s",
                 "daqp_s", "daqp_step_s", "condensed_floor_s", "direct_cpu_s", "daqp_cpu_s",
                 "floor_cpu_s", "condensed_floor_cpu_s")


def summarize(lateral: pd.DataFrame, peers: pd.DataFrame, kinematic: pd.DataFrame,
              pipeline_figures: dict, closed_loop: dict) -> dict:
    """The summary of the lateral, peer and kinematic tables with the whole-pipeline figures
    and the closed loop: the headline ratios (N = 10, one obstacle), the goals, every table."""
    table = [_lateral_summary(int(N), int(n_obs), part)
             for (N, n_obs), part in lateral.groupby(["N", "obstacles"])]
    per_n = {int(r["N"]): r for r in table if r["obstacles"] == 1}
    peer_rows = [_peer_summary(int(N), part) for N, part in peers.groupby("N")]
    head = per_n.get(10) or table[0]
    return {"closed_loop_over_floor": closed_loop["closed_loop_over_floor"],
            "step_over_floor": head["direct_step_over_floor"],
            "step_over_sparse_floor": head["step_over_sparse_floor"],
            "step_over_sparse_floor_daqp": head["step_over_sparse_floor_daqp"],
            "step_over_sparse_floor_cpu": head["step_over_sparse_floor_cpu"],
            "outside_qp_us_per_step": closed_loop["outside_qp_us_per_step"],
            "qp_us_per_step": closed_loop["qp_us_per_step"],
            "compiles_per_family": pipeline_figures["compiles_per_family"],
            "family_scenarios_per_s": pipeline_figures["family_scenarios_per_s"],
            "goals": dict(GOALS),
            "closed_loop": closed_loop,
            "lateral": table, "peers": peer_rows,
            "kinematic": _stats(kinematic["kinematic_step_s"]),
            "kinematic_recompiles": int(kinematic["kinematic_compiles"].max() - 1),
            "n50_over_n10_direct": per_n[50]["direct_step_median_ms"]
            / per_n[10]["direct_step_median_ms"] if 50 in per_n and 10 in per_n else None,
            "pipeline": pipeline_figures}


def _stats(values) -> dict:
    """Minimum, median, 95th percentile and maximum of times in s, in ms."""
    v = np.asarray(values, float) * 1e3
    return {"min_ms": float(v.min()), "median_ms": float(np.median(v)),
            "p95_ms": float(np.percentile(v, 95)), "max_ms": float(v.max())}


def _lateral_summary(N: int, n_obs: int, part: pd.DataFrame) -> dict:
    """One QP configuration's medians, ratios over the floor, agreement and compilations."""
    row: dict[str, Any] = {"N": N, "obstacles": n_obs}
    for key in LATERAL_TIMES:
        row[key[:-2] + "_median_ms"] = float(np.median(part[key]) * 1e3)
    row["cvxpy_step_over_floor"] = row["cvxpy_step_median_ms"] / row["floor_median_ms"]
    row["direct_step_over_floor"] = row["direct_step_median_ms"] / row["floor_median_ms"]
    # per QP, interleaved: the median of the per-QP ratios (load cancels within a QP); the
    # default backend's step (the lateral MPC's configured backend)
    default = {"daqp": "daqp"}.get(str(part["default_backend"].iloc[0]), "direct")
    row["default_backend"] = str(part["default_backend"].iloc[0])
    row["step_over_sparse_floor"] = float(np.median(part[f"{default}_step_s"]
                                                    / part["floor_s"]))
    row["step_over_sparse_floor_direct"] = float(np.median(part["direct_step_s"]
                                                           / part["floor_s"]))
    # the same step with the APF rollout in Python (a single run's path)
    row["step_over_sparse_floor_python_apf"] = float(np.median(
        part["direct_python_step_s"] / part["floor_s"]))
    row["step_over_sparse_floor_daqp"] = float(np.median(part["daqp_step_s"]
                                                         / part["floor_s"]))
    row["condensed_floor_over_sparse_floor"] = float(np.median(part["condensed_floor_s"]
                                                               / part["floor_s"]))
    row["step_over_sparse_floor_cpu"] = float(np.median(
        (part["apf_s"] + part[f"{default}_cpu_s"]) / part["floor_cpu_s"]))
    row["max_u0_diff_daqp_vs_direct"] = float(np.max(np.abs(part["u0_daqp"]
                                                            - part["u0_direct"])))
    row["iterations_median"] = float(np.median(part["cvxpy_iterations"]))
    row["max_u0_diff_direct_vs_cvxpy"] = float(np.max(np.abs(part["u0_direct"]
                                                             - part["u0_cvxpy"])))
    row["max_u0_diff_floor_vs_cvxpy"] = float(np.max(np.abs(part["u0_floor"]
                                                            - part["u0_cvxpy"])))
    row["recompiles"] = int(part["compiles_cvxpy"].max() - 1 + part["compiles_direct"].max()
                            - 1)
    row["compile_time_direct_s"] = float(part["compile_time_direct_s"].max())
    return row


def _peer_summary(N: int, part: pd.DataFrame) -> dict:
    """One horizon's peers: their time statistics, the ratio to the kept problem, agreement."""
    return {"N": N, "kept_cvxpy": _stats(part["kept_cvxpy_s"]),
            "rebuild_cvxpy": _stats(part["rebuild_cvxpy_s"]),
            "python_control": _stats(part["python_control_s"]),
            "python_control_over_kept": float(np.median(part["python_control_s"])
                                              / np.median(part["kept_cvxpy_s"])),
            "max_u0_diff_python_control": float(np.max(np.abs(
                part["u0_python_control"] - part["u0_kept"]))),
            "max_u0_diff_rebuild": float(np.max(np.abs(part["u0_rebuild"]
                                                       - part["u0_kept"])))}
