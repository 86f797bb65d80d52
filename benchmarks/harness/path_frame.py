"""The lateral MPC's whole step in each frame (fixed and path), over the sparse floor."""

from __future__ import annotations

import gc
from dataclasses import replace

import numpy as np
import pandas as pd

from benchmarks.harness.inputs import KeptClarabelFloor, compose_config, timed_call
from benchmarks.harness.sparse_floor import sparse_map, sparse_parameter_vector


def bench_path_frame(n_steps: int, repeats: int) -> list[dict]:
    """The lateral MPC's whole step in each frame, per QP, interleaved on identical situations
    (N = 10, one obstacle, the improved APF; the plant, the APF and the path kernels compiled
    as a family's workers run them): the APF rollout, the QP data of the frame
    (``inputs_from``: references and half-planes in the fixed frame; the drivable path,
    stations, projections and references in the path frame) and the solve, by the default
    backend (``clarabel_direct``) and DAQP; over the sparse floor of the same QP (the path
    frame's own data, disturbance and references included). ``*_solve_s`` alone is the
    definition of the head ratios (the data prepared outside), ``*_step_s`` the whole step."""
    from pipeline.loop.controller import LateralMpc, Observation, QpCache
    from pipeline.loop.planner import ApfPlanner
    from pipeline.loop.scenario import LineFrame, ObstacleSnapshot

    rows = []
    cfg = compose_config(["method=improved"])
    ctrl, veh = cfg.controller, cfg.vehicle
    cache = QpCache(compiled_kernels=True)
    from pipeline.loop.compiled import COMPILED_KERNELS

    planner = ApfPlanner(cfg.planner, ctrl.horizon, 0.1, COMPILED_KERNELS)
    goal = np.array([30.0, 0.0])
    obstacle = ObstacleSnapshot(np.array([[9.0, 0.6]]), np.array([[0.0, -0.3]]),
                                np.array([0.5]), np.ones(1, bool))
    frame = LineFrame(np.zeros(2), 0.0)
    mpcs = {(f, b): LateralMpc(replace(ctrl, frame=f, backend=b), veh, cfg.model, 0.1, cache,
                               COMPILED_KERNELS)
            for f in ("fixed", "path") for b in ("clarabel_direct", "daqp")}
    floor_map = sparse_map(ctrl, veh)
    observations = []
    for k in range(n_steps):
        x, y = 3.0 + 0.15 * k, 0.4 * np.sin(0.15 * k)
        state = np.array([x, y, 0.25 * np.cos(0.15 * k), 3.0, 0.05 * np.sin(0.3 * k),
                          0.1 * np.cos(0.2 * k), 0.05 * np.sin(0.25 * k)])
        rollout = planner.rollout(state[:2], goal, obstacle, np.array([3.0, 0.0]))
        observations.append(Observation(0.1 * k, state, frame, frame.to_line(state[:2]),
                                        float(state[2]), rollout, obstacle, 3.0))
    for mpc in mpcs.values():  # numba's cache load and the models, outside the timing
        mpc.step(observations[0])
    for rep in range(repeats):
        gc.collect()
        gc.disable()
        floor = KeptClarabelFloor(floor_map, ctrl.solver_max_iter)
        for k, obs in enumerate(observations):
            apf, apf_s, _ = timed_call(lambda: planner.rollout(obs.plant_state[:2], goal,  # noqa: B023 (called at once, in this iteration)
                                                               obstacle, np.array([3.0, 0.0])))
            row = {"section": "path_frame", "repeat": rep, "step": k, "apf_s": apf_s}
            for (f, b), mpc in mpcs.items():
                (inputs, _), data_s, _ = timed_call(lambda: mpc.inputs_from(obs))  # noqa: B023 (called at once, in this iteration)
                _, solve_s, _ = timed_call(lambda: mpc.solve(inputs))  # noqa: B023 (called at once, in this iteration)
                row[f"{f}_{b}_data_s"], row[f"{f}_{b}_solve_s"] = data_s, solve_s
                if b == "clarabel_direct":
                    row[f"{f}_floor_s"] = floor.time(sparse_parameter_vector(inputs))[0]
            rows.append(row)
        gc.enable()
    return rows


def summarize_path_frame(rows: list[dict]) -> dict:
    """Per frame and backend: the head ratio's definition (APF + solve, the QP data prepared
    outside) and the whole step (APF + the frame's QP data + solve) over the sparse floor of
    the same QP, the median of the per-QP ratios."""
    table = pd.DataFrame(rows)
    out = {}
    for f in ("fixed", "path"):
        floor = table[f"{f}_floor_s"]
        for b, name in (("clarabel_direct", ""), ("daqp", "_daqp")):
            solve, data = table[f"{f}_{b}_solve_s"], table[f"{f}_{b}_data_s"]
            out[f"step_over_sparse_floor_{f}{name}"] = float(np.median(
                (table["apf_s"] + solve) / floor))
            out[f"whole_step_over_sparse_floor_{f}{name}"] = float(np.median(
                (table["apf_s"] + data + solve) / floor))
            out[f"qp_data_us_{f}{name}"] = 1e6 * float(np.median(data))
        out[f"sparse_floor_us_{f}"] = 1e6 * float(np.median(floor))
    return out
