"""The benchmark (``make bench``), if it was run: the controller step against the solver's
floor, the peers, the whole pipeline."""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.reporting.figure import Figure, Figures
from pipeline.reporting.inputs import ReportInputs

#: The headline ratios the section quotes (``bench_summary.json`` holds them all).
HEADLINE = ("closed_loop_over_floor", "step_over_floor", "compiles_per_family",
            "family_scenarios_per_s", "step_over_sparse_floor", "step_over_sparse_floor_daqp",
            "outside_qp_over_qp", "outside_qp_over_qp_python_kernels",
            "family_member_over_sparse_floor", "family_member_over_sparse_floor_daqp")


@dataclass(frozen=True)
class PerformanceSection:
    rows: tuple[dict, ...]
    peers: tuple[dict, ...]
    figures: tuple[Figure, ...]
    pipeline: dict
    kinematic: dict
    n50: float | None
    headline: dict


def performance_section(inputs: ReportInputs, figures: Figures) -> PerformanceSection | None:
    result = inputs.bench
    if result is None:
        return None
    figure = figures.copy(result.scaling_figure(), "bench_scaling", "performance",
                          "Median controller step (APF rollout + QP) of both backends and the "
                          "Clarabel floor versus the horizon N, per obstacle count.",
                          "Step time versus horizon")
    peers = tuple({"N": p["N"], "kept": p["kept_cvxpy"]["median_ms"],
                   "rebuild": p["rebuild_cvxpy"]["median_ms"],
                   "python_control": p["python_control"]["median_ms"],
                   "ratio": p["python_control_over_kept"],
                   "diff": p["max_u0_diff_python_control"]} for p in result["peers"])
    return PerformanceSection(
        tuple(result["lateral"]), peers, (figure,) if figure is not None else (),
        dict(result["pipeline"]), dict(result["kinematic"]),
        result.get("n50_over_n10_direct"), {k: result.get(k) for k in HEADLINE})
