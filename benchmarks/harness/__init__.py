"""Benchmark of the controller step against the solver's floor and the peers: ``make bench``.

Everything runs in one process, methods interleaved on identical inputs, each repeated:

* the lateral QP for N in {10, 20, 30, 50} and 1, 3, 5 obstacles: the APF rollout, the CVXPY
  backend (parameter update, ``problem.solve`` split into Clarabel's own time and the rest),
  the ``clarabel_direct`` backend, and the floor — the identical QP data handed to a kept
  Clarabel solver (``update`` + ``solve`` only);
* peers on the same QP: CVXPY rebuilding the problem every step (as PythonRobotics does) and
  python-control's ``control.optimal.solve_ocp`` (no obstacles, Nc = N, N = 10 and 20);
* the kinematic LTV-QP step;
* the lateral MPC's whole step in each frame (``controller.frame``): the APF, the frame's QP
  data and the solve, over the sparse floor of the same QP (:func:`bench_path_frame`);
* whole-pipeline figures: import time, one paper-scenario run, a family's throughput on both
  cores, peak memory.

Results: ``reports/bench/bench.csv`` (every sample), ``bench_summary.json`` and
``scaling.png/svg``. No timing is asserted anywhere in the tests.

``quick`` (``python -m pipeline.bench --quick``, a minute or so on two cores): N = 10 and one
obstacle, fewer repeats and members, and neither of the two measurements that take minutes:
``make install`` into two fresh venvs (``install_over_pip``) and a small tune
(``tune_core_utilisation``), whose keys are then None with ``quick_note`` saying so.
``--quick --smoke`` runs each quick measurement at its smallest size (the test suite's run: every
figure written, none worth reading).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from benchmarks.harness.closed_loop import bench_closed_loop, bench_family_member
from benchmarks.harness.engine import bench_engine
from benchmarks.harness.install import measure_install
from benchmarks.harness.lateral import bench_lateral
from benchmarks.harness.named_peers import bench_named_peers
from benchmarks.harness.path_frame import bench_path_frame, summarize_path_frame
from benchmarks.harness.peers import bench_kinematic, bench_peers
from benchmarks.harness.studies import (
    measure_coordinator,
    measure_member_cache_reuse,
    measure_tune_core_utilisation,
    pruning_comparison,
)
from benchmarks.harness.summary import summarize
from benchmarks.harness.whole_pipeline import bench_multiverse_reads, bench_pipeline
from pipeline.store.layout import OutputsLayout
from pipeline.studies.results.bench import BenchResult

__all__ = ["NOT_QUICK", "QUICK_KEYS", "run_benchmark"]

#: The headline figures a quick run measures (each a finite number; the ratios positive).
QUICK_KEYS = ("closed_loop_over_floor", "step_over_floor", "step_over_sparse_floor",
              "step_over_sparse_floor_daqp", "step_over_sparse_floor_path",
              "step_over_sparse_floor_path_daqp", "step_over_sparse_floor_cpu",
              "outside_qp_us_per_step", "qp_us_per_step", "outside_qp_over_qp",
              "outside_qp_over_qp_daqp", "outside_qp_over_qp_python_kernels", "setup_ms",
              "compiles_per_family", "family_scenarios_per_s",
              "family_member_over_sparse_floor", "family_member_over_sparse_floor_daqp",
              "multiverse_member_reads_per_member", "member_cache_reuse",
              "coordinator_ms_per_trial", "engine_members_per_cpu_s_over_member_loop")
#: What a quick run leaves out (minutes each), None in its summary.
NOT_QUICK = {"install_over_pip": None, "tune_core_utilisation": None,
             "quick_note": "--quick: make install into two fresh venvs and the small tune "
                           "(install_over_pip, tune_core_utilisation) were not measured"}


def run_benchmark(out: Path, steps: int = 40, repeats: int = 3, quick: bool = False,
                  family_size: int = 200, smoke: bool = False) -> BenchResult:
    """The benchmark (see the module docstring), on one BLAS thread as the closed loop runs
    (OpenBLAS's idle threads would otherwise spin and inflate every CPU time): its result
    written into ``out`` and returned (with the lateral table, the command's scaling
    figure's data). ``smoke`` (with ``quick``): each quick measurement at its smallest size,
    every figure still measured, none worth reading (the test suite's run of the harness)."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        return _measure(Path(out), steps, repeats, quick, family_size, smoke and quick)


def _measure(out: Path, steps: int, repeats: int, quick: bool, family_size: int,
             smoke: bool = False) -> BenchResult:
    """:func:`run_benchmark` inside its thread limit."""
    horizons = (10,) if quick else (10, 20, 30, 50)
    counts = (1,) if quick else (1, 3, 5)
    lateral = pd.DataFrame(bench_lateral(horizons, counts, steps, repeats))
    peers = pd.DataFrame(bench_peers(10 if quick else 20))
    kinematic = pd.DataFrame(bench_kinematic(steps))
    loops = 1 if smoke else 3 if quick else 7
    closed_loop = bench_closed_loop(loops)
    closed_loop_python = bench_closed_loop(loops, compiled_kernels=False)
    closed_loop_daqp = bench_closed_loop(loops, backend="daqp")
    pipeline_figures = bench_pipeline(8 if quick else family_size,
                                      8 if quick else 40)
    summary = summarize(lateral, peers, kinematic, pipeline_figures, closed_loop)
    summary["closed_loop_daqp"] = closed_loop_daqp
    summary["closed_loop_python_kernels"] = closed_loop_python
    summary["outside_qp_over_qp_python_kernels"] = \
        closed_loop_python["outside_qp_us_per_step"] / closed_loop_python["qp_us_per_step"]
    summary["outside_qp_over_qp_daqp"] = \
        closed_loop_daqp["outside_qp_us_per_step"] / closed_loop_daqp["qp_us_per_step"]
    members, member_repeats = (2, 1) if smoke else (4 if quick else 8, 3)
    member = bench_family_member(n_members=members, repeats=member_repeats)
    member_daqp = bench_family_member("daqp", n_members=members, repeats=member_repeats)
    summary["family_member"] = {"default": member, "daqp": member_daqp}
    summary["family_member_over_sparse_floor"] = member["family_member_over_sparse_floor"]
    summary["family_member_over_sparse_floor_daqp"] = \
        member_daqp["family_member_over_sparse_floor"]
    engine_size = (8, 1) if smoke else (24, 2) if quick else (family_size, 3)
    summary["engine"] = bench_engine(*engine_size)
    summary["engine_members_per_cpu_s_over_member_loop"] = \
        summary["engine"]["engine_members_per_cpu_s_over_member_loop"]
    path_rows = bench_path_frame(steps, repeats)
    summary["path_frame"] = summarize_path_frame(path_rows)
    summary["step_over_sparse_floor_path"] = \
        summary["path_frame"]["step_over_sparse_floor_path"]
    summary["step_over_sparse_floor_path_daqp"] = \
        summary["path_frame"]["step_over_sparse_floor_path_daqp"]
    summary["named_peers"] = bench_named_peers(1 if smoke else 2 if quick else 5)
    summary.update({key: value for key, value in summary["named_peers"].items()
                    if key.startswith("peer_step_over_")})
    summary.update(bench_multiverse_reads(smoke))
    summary.update(measure_member_cache_reuse())
    summary.update(measure_coordinator(4 if smoke else 24))
    if quick:
        summary.update(NOT_QUICK)
    else:
        summary.update(measure_install())
        # its coordinator figure (40-member families, the default rungs) beside the quick one
        small_tune = measure_tune_core_utilisation(16)
        summary["tune_core_utilisation"] = small_tune["tune_core_utilisation"]
        summary["coordinator_ms_per_trial_default_space"] = \
            small_tune["coordinator_ms_per_trial"]
    summary["quick"] = quick
    summary["smoke"] = smoke
    layout = OutputsLayout.load(Path("outputs"))
    summary.update(pruning_comparison(layout.folder("tune"), layout.folder("tune_unpruned")))
    summary["outside_qp_over_qp"] = closed_loop["outside_qp_us_per_step"] \
        / closed_loop["qp_us_per_step"]
    summary["setup_ms"] = closed_loop["setup_ms"]
    table = pd.concat([lateral, peers, kinematic, pd.DataFrame(path_rows)], ignore_index=True)
    return BenchResult(summary, table, lateral).write(out)
