"""The lateral QP's controller step on every backend and each floor, per QP, interleaved on
identical inputs."""

from __future__ import annotations

import gc
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from benchmarks.harness.inputs import (
    KeptClarabelFloor,
    compose_config,
    qp_map,
    step_inputs,
    timed_call,
)
from benchmarks.harness.sparse_floor import sparse_map, sparse_parameter_vector


def bench_lateral(horizons, obstacle_counts, n_steps: int, repeats: int) -> list[dict]:
    """Per QP, interleaved on identical inputs in one process (the order rotating from QP to
    QP): the controller step of the backends (default clarabel_direct: the condensed QP stated
    in CVXPY on a kept Clarabel; daqp) and each floor (the sparse QP and the condensed QP on a
    kept Clarabel), wall and CPU time; the CVXPY backend in a pass of its own over the same
    QPs."""
    rows = []
    for N in horizons:
        for n_obs in obstacle_counts:
            case = LateralCase.build(N, n_obs, n_steps)
            for rep in range(repeats):
                # the garbage collector off while timing (as timeit does): the CVXPY backend's
                # allocations would otherwise trigger collections inside whichever solve
                # happens to allocate next, and charge their cost to it
                gc.collect()
                gc.disable()
                rows.extend(_time_repeat(case, rep))
                gc.enable()
    return rows


@dataclass(frozen=True)
class LateralCase:
    """One configuration of the lateral bench (horizon ``N``, ``n_obs`` obstacles): the lateral
    MPC on every backend, the sparse floor's compiled map, the step inputs and their QPs'
    parameter vectors (sparse and condensed)."""

    N: int
    n_obs: int
    ctrl: Any
    cvxpy: Any
    sparse_map: Any
    direct: Any
    daqp: Any
    steps: list
    sparse_thetas: list
    condensed_thetas: list
    offset_u: int

    @classmethod
    def build(cls, N: int, n_obs: int, n_steps: int) -> LateralCase:
        """The controllers of every backend for this configuration, and ``n_steps`` inputs."""
        from pipeline.loop.controller import LateralMpc
        from pipeline.loop.controller.lateral_qp import condensed_data

        cfg = compose_config(["method=improved", f"controller.horizon={N}",
                              f"controller.max_obstacles={max(n_obs, 1)}"])
        ctrl = cfg.controller
        mpc_cvxpy = LateralMpc(replace(ctrl, backend="cvxpy"), cfg.vehicle)
        mpc_direct = LateralMpc(replace(ctrl, backend="clarabel_direct"), cfg.vehicle)
        mpc_daqp = LateralMpc(replace(ctrl, backend="daqp"), cfg.vehicle)
        floor_map = sparse_map(ctrl, cfg.vehicle)
        steps = step_inputs(cfg, n_obs, n_steps)
        sparse_thetas = [sparse_parameter_vector(inputs) for inputs, *_ in steps]
        condensed_thetas = [condensed_data(mpc_direct.prediction(inputs.model), inputs,
                                           mpc_direct.weights).theta()
                            for inputs, *_ in steps]
        offset_u = floor_map.variables["U"][0]
        return cls(N, n_obs, ctrl, mpc_cvxpy, floor_map, mpc_direct, mpc_daqp, steps,
                   sparse_thetas, condensed_thetas, offset_u)


def _time_repeat(case: LateralCase, rep: int) -> list[dict]:
    """One repeat over the case's QPs: the CVXPY pass, then every other method per QP."""
    sparse_floor = KeptClarabelFloor(case.sparse_map, case.ctrl.solver_max_iter)
    condensed_floor = KeptClarabelFloor(qp_map(case.direct),
                                        case.ctrl.solver_max_iter)
    # the CVXPY backend (a peer, 2 ms of Python per QP) in a pass of its own: inside
    # the interleaving it evicted the caches before whichever step followed it, and
    # charged the steps with most small numpy calls (measured: a 3x3 product took
    # 5-7 us right after it, 1 us otherwise)
    through_cvxpy = []
    for inputs, *_ in case.steps:
        solved, wall, _ = timed_call(lambda: case.cvxpy.solve(inputs))  # noqa: B023 (called at once, in this iteration)
        # the statement of the slots this step used (with no obstacle the 0-slot one: the
        # statement of every slot, case.cvxpy.qp, was never solved and has no stats)
        stats = case.cvxpy.qp_for(inputs).compiled.problem.solver_stats
        through_cvxpy.append((solved, wall, float(stats.solve_time or np.nan)
                              if stats is not None else np.nan))
    rows = []
    for k, (inputs, apf_s, apf_python_s) in enumerate(case.steps):
        # every method timed on this QP, in an order that rotates from QP to QP:
        # what runs just before a solve (and what it left in the caches) is then
        # the same for every method on average
        timers = [
            ("sparse_floor", lambda: sparse_floor.time(case.sparse_thetas[k])),  # noqa: B023 (called at once, in this iteration)
            ("condensed_floor", lambda: condensed_floor.time(case.condensed_thetas[k])),  # noqa: B023 (called at once, in this iteration)
            ("direct", lambda: timed_call(lambda: case.direct.solve(inputs))),  # noqa: B023 (called at once, in this iteration)
            ("daqp", lambda: timed_call(lambda: case.daqp.solve(inputs)))]  # noqa: B023 (called at once, in this iteration)
        shift = (k + rep) % len(timers)
        timed = dict((name, run()) for name, run in timers[shift:] + timers[:shift])
        rows.append(_lateral_row(case, rep, k, apf_s, apf_python_s, timed, through_cvxpy[k]))
    return rows


def _lateral_row(case: LateralCase, rep: int, k: int, apf_s: float, apf_python_s: float,
                 timed: dict, through_cvxpy: tuple) -> dict:
    """The bench's row of one QP in one repeat: every method's times and first input."""
    fs_wall, fs_cpu, fs_x = timed["sparse_floor"]
    fc_wall, fc_cpu, _ = timed["condensed_floor"]
    direct, d_wall, d_cpu = timed["direct"]
    daqp, q_wall, q_cpu = timed["daqp"]
    solution, c_wall, clarabel_s = through_cvxpy
    u_cvxpy = solution.steering_rate_rad_s if solution.fallback == "none" else np.nan
    return {
        "section": "lateral", "N": case.N, "obstacles": case.n_obs, "repeat": rep, "step": k,
        "apf_s": apf_s, "apf_python_s": apf_python_s,
        "direct_python_step_s": apf_python_s + d_wall,
        "cvxpy_solve_s": c_wall, "cvxpy_clarabel_s": clarabel_s,
        "cvxpy_iterations": solution.iterations,
        "cvxpy_step_s": apf_s + c_wall,
        "direct_s": d_wall, "direct_cpu_s": d_cpu,
        "direct_step_s": apf_s + d_wall,
        "daqp_s": q_wall, "daqp_cpu_s": q_cpu, "daqp_step_s": apf_s + q_wall,
        "default_backend": case.ctrl.backend,
        "floor_s": fs_wall, "floor_cpu_s": fs_cpu,
        "condensed_floor_s": fc_wall, "condensed_floor_cpu_s": fc_cpu,
        "u0_cvxpy": u_cvxpy, "u0_direct": direct.steering_rate_rad_s,
        "u0_daqp": daqp.steering_rate_rad_s,
        "u0_floor": float(fs_x[case.offset_u]),
        "cvxpy_status": solution.status,
        "compiles_cvxpy": case.cvxpy.qp.compiled.compile_count,
        "compiles_direct": case.direct.compile_count,
        "compile_time_direct_s": case.direct.compile_time_s}
