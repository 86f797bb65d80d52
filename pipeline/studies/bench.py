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
"""

from __future__ import annotations

import gc
import resource
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.store.runs import read_family
from pipeline.studies.results.bench import BenchResult


def _config(overrides: list[str]):
    from hydra import compose, initialize_config_dir

    from pipeline.config import register_configs, to_experiment_config
    from pipeline.config import CONF_DIR

    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return to_experiment_config(compose(config_name="config", overrides=overrides))


def step_inputs(cfg, n_obstacles: int, n_steps: int, seed: int = 0) -> list:
    """A deterministic sequence of realistic QP inputs: a vehicle passing ``n_obstacles``
    obstacles near its path, references from the improved APF, active half-planes; with each
    the APF rollout's wall time as the studies run it (the compiled kernel, see
    :mod:`pipeline.loop.compiled`) and as a single run does (Python)."""
    from pipeline.loop.controller import MpcInputs, collision_halfplanes, lateral_reference
    from pipeline.loop.model import build_lateral_model
    from pipeline.loop.planner import ApfPlanner, apf_rollout
    from pipeline.loop.scenario import ObstacleSnapshot

    rng = np.random.default_rng(seed)
    ctrl, veh = cfg.controller, cfg.vehicle
    model = build_lateral_model(veh, 3.0, 0.1)
    N = ctrl.horizon
    obstacles = np.column_stack([np.linspace(8.0, 8.0 + 2.5 * (n_obstacles - 1), n_obstacles),
                                 rng.uniform(-1.5, 1.5, n_obstacles)])
    snap = ObstacleSnapshot(obstacles, np.zeros_like(obstacles), np.full(n_obstacles, 0.5),
                            np.ones(n_obstacles, bool))
    from pipeline.loop.compiled import COMPILED_KERNELS

    compiled = ApfPlanner(cfg.planner, N, 0.1, COMPILED_KERNELS)
    goal = np.array([30.0, 0.0])
    compiled.rollout(np.zeros(2), goal, snap)  # numba's cache load, outside the timing
    out = []
    for k in range(n_steps):
        position = np.array([4.0 + 0.3 * k, 0.3 * np.sin(0.2 * k)])
        started = time.perf_counter()
        rollout = apf_rollout(position, goal, snap, cfg.planner, N, 0.1)
        apf_python_s = time.perf_counter() - started
        started = time.perf_counter()
        compiled.rollout(position, goal, snap)
        apf_s = time.perf_counter() - started
        stations = position[0] + 0.3 * np.arange(1, N + 1)
        y_ref, psi_ref = lateral_reference(rollout.path_m, stations, ctrl)
        predicted = np.repeat(obstacles[None, :, :], N, axis=0)
        G, h = collision_halfplanes(stations, y_ref, position, predicted, snap.radii_m, veh, ctrl)
        x0 = np.array([position[1], 0.0, 0.06 * np.cos(0.2 * k), 0.0, 0.05 * np.sin(0.3 * k)])
        out.append((MpcInputs(x0, model, y_ref, psi_ref, G, h, np.zeros(N)), apf_s,
                    apf_python_s))
    return out


class KeptClarabelFloor:
    """The floor: a kept Clarabel solver handed a QP's data (computed outside the timed region),
    timed on ``update + solve`` only, one QP at a time so that it interleaves with the step."""

    def __init__(self, qp_map, max_iter: int) -> None:
        from pipeline.loop.controller.qp import clarabel_settings

        self.map, self.settings, self.solver = qp_map, clarabel_settings(max_iter), None

    def time(self, theta: np.ndarray) -> tuple[float, float, np.ndarray]:
        """Wall and CPU time (s) of one solve, and its primal solution."""
        import clarabel

        q, a, b = self.map.data(theta)
        if self.solver is None:
            self.solver = clarabel.DefaultSolver(self.map.P, q, self.map.matrix_A(a), b,
                                                 self.map.cones(), self.settings)
            wall, cpu = time.perf_counter(), time.process_time()
        else:
            wall, cpu = time.perf_counter(), time.process_time()
            self.solver.update(q=q, A=a, b=b)
        solution = self.solver.solve()
        return time.perf_counter() - wall, time.process_time() - cpu, np.asarray(solution.x)


def floor_times(qp_map, thetas: list, max_iter: int) -> tuple[np.ndarray, list]:
    """Wall time of the floor for each parameter vector in turn, and the solutions."""
    floor = KeptClarabelFloor(qp_map, max_iter)
    times, solutions = [], []
    for theta in thetas:
        wall, _, x = floor.time(theta)
        times.append(wall)
        solutions.append(x)
    return np.asarray(times), solutions


def _timed(call):
    """``call()``'s result with its wall and CPU time (s)."""
    wall, cpu = time.perf_counter(), time.process_time()
    out = call()
    return out, time.perf_counter() - wall, time.process_time() - cpu


def bench_lateral(horizons, obstacle_counts, n_steps: int, repeats: int) -> list[dict]:
    """Per QP, interleaved on identical inputs in one process (the order rotating from QP to
    QP): the controller step of every backend (default clarabel_direct: the condensed QP stated
    in CVXPY on a kept Clarabel; clarabel_dense: its numpy data on a kept Clarabel; daqp) and
    each floor (the sparse QP and the condensed QP on a kept Clarabel), wall and CPU time; the
    CVXPY backend on the sparse QP in a pass of its own over the same QPs."""
    from pipeline.loop.controller import LateralMpc
    from pipeline.loop.controller.lateral_qp import condensed_data

    rows = []
    for N in horizons:
        for n_obs in obstacle_counts:
            cfg = _config(["method=improved", f"controller.horizon={N}",
                           f"controller.max_obstacles={max(n_obs, 1)}"])
            ctrl = cfg.controller
            mpc_cvxpy = LateralMpc(replace(ctrl, backend="cvxpy", formulation="sparse"),
                                   cfg.vehicle)
            mpc_sparse = LateralMpc(replace(ctrl, backend="clarabel_direct",
                                            formulation="sparse"), cfg.vehicle)
            mpc_direct = LateralMpc(replace(ctrl, backend="clarabel_direct",
                                            formulation="condensed"), cfg.vehicle)
            mpc_daqp = LateralMpc(replace(ctrl, backend="daqp", formulation="condensed"),
                                  cfg.vehicle)
            mpc_dense = LateralMpc(replace(ctrl, backend="clarabel_dense",
                                           formulation="condensed"), cfg.vehicle)
            steps = step_inputs(cfg, n_obs, n_steps)
            sparse_thetas = [mpc_sparse.parameter_vector(inputs) for inputs, *_ in steps]
            condensed_thetas = [condensed_data(mpc_direct.prediction(inputs.model), inputs,
                                               mpc_direct.weights).theta()
                                for inputs, *_ in steps]
            offset_u = mpc_sparse.qp.map.variables["U"][0]
            for rep in range(repeats):
                # the garbage collector off while timing (as timeit does): the CVXPY backend's
                # allocations would otherwise trigger collections inside whichever solve
                # happens to allocate next, and charge their cost to it
                gc.collect()
                gc.disable()
                sparse_floor = KeptClarabelFloor(mpc_sparse.qp.map, ctrl.solver_max_iter)
                condensed_floor = KeptClarabelFloor(mpc_direct.qp.compiled.map,
                                                    ctrl.solver_max_iter)
                # the CVXPY backend (a peer, 2 ms of Python per QP) in a pass of its own: inside
                # the interleaving it evicted the caches before whichever step followed it, and
                # charged the steps with most small numpy calls (measured: a 3x3 product took
                # 5-7 us right after it, 1 us otherwise)
                through_cvxpy = []
                for theta in sparse_thetas:
                    solved, wall, _ = _timed(lambda: mpc_cvxpy.qp.solve(theta))
                    stats = mpc_cvxpy.qp.problem.solver_stats
                    through_cvxpy.append((solved, wall, float(stats.solve_time or np.nan)))
                for k, (inputs, apf_s, apf_python_s) in enumerate(steps):
                    # every method timed on this QP, in an order that rotates from QP to QP:
                    # what runs just before a solve (and what it left in the caches) is then
                    # the same for every method on average
                    timers = [
                        ("sparse_floor", lambda: sparse_floor.time(sparse_thetas[k])),
                        ("condensed_floor", lambda: condensed_floor.time(condensed_thetas[k])),
                        ("direct", lambda: _timed(lambda: mpc_direct.solve(inputs))),
                        ("daqp", lambda: _timed(lambda: mpc_daqp.solve(inputs))),
                        ("dense", lambda: _timed(lambda: mpc_dense.solve(inputs)))]
                    shift = (k + rep) % len(timers)
                    timed = dict((name, run()) for name, run in timers[shift:] + timers[:shift])
                    fs_wall, fs_cpu, fs_x = timed["sparse_floor"]
                    fc_wall, fc_cpu, _ = timed["condensed_floor"]
                    direct, d_wall, d_cpu = timed["direct"]
                    daqp, q_wall, q_cpu = timed["daqp"]
                    dense, n_wall, n_cpu = timed["dense"]
                    solution, c_wall, clarabel_s = through_cvxpy[k]
                    u_cvxpy = float(np.asarray(solution.values["U"]).ravel()[0]) \
                        if solution.values is not None else np.nan
                    rows.append({
                        "section": "lateral", "N": N, "obstacles": n_obs, "repeat": rep, "step": k,
                        "apf_s": apf_s, "apf_python_s": apf_python_s,
                        "direct_python_step_s": apf_python_s + d_wall,
                        "cvxpy_solve_s": c_wall, "cvxpy_clarabel_s": clarabel_s,
                        "cvxpy_iterations": solution.iterations,
                        "cvxpy_step_s": apf_s + c_wall,
                        "direct_s": d_wall, "direct_cpu_s": d_cpu,
                        "direct_step_s": apf_s + d_wall,
                        "daqp_s": q_wall, "daqp_cpu_s": q_cpu, "daqp_step_s": apf_s + q_wall,
                        "dense_s": n_wall, "dense_cpu_s": n_cpu, "dense_step_s": apf_s + n_wall,
                        "default_backend": ctrl.backend,
                        "floor_s": fs_wall, "floor_cpu_s": fs_cpu,
                        "condensed_floor_s": fc_wall, "condensed_floor_cpu_s": fc_cpu,
                        "u0_cvxpy": u_cvxpy, "u0_direct": direct.steering_rate_rad_s,
                        "u0_daqp": daqp.steering_rate_rad_s,
                        "u0_dense": dense.steering_rate_rad_s,
                        "u0_floor": float(fs_x[offset_u]),
                        "cvxpy_status": solution.status,
                        "compiles_cvxpy": mpc_cvxpy.qp.compile_count,
                        "compiles_direct": mpc_direct.compile_count,
                        "compile_time_direct_s": mpc_direct.compile_time_s})
                gc.enable()
    return rows


class _RecordingMap:
    """A compiled map that remembers every parameter vector it is applied to (the bench's way
    to hand the floor solver exactly the QPs of a closed-loop run)."""

    def __init__(self, qp_map) -> None:
        self._map = qp_map
        self.recorded: list[np.ndarray] = []

    def data(self, theta):
        self.recorded.append(np.array(theta, copy=True))
        return self._map.data(theta)

    def __getattr__(self, name):
        return getattr(self._map, name)


def bench_closed_loop(repeats: int = 5, backend: str | None = None,
                      compiled_kernels: bool = True) -> dict:
    """One complete paper-scenario run of the improved method in this process (the QP compiled
    inside the timed region, a fresh cache each time), over the sparse floor of the same QPs
    (the run's steps replayed as the sparse QP, recorded from a sparse run of the same
    configuration: the same QPs to ~1e-7), and its time outside the QP per step.

    Each repeat runs twice: with a fresh cache (what one run costs, compilation, discretized
    models and the BLAS thread limit's library scan included) and again with the cache it just
    filled (what every step costs: ``outside_qp_us_per_step`` comes from this run, so one-off
    set-up is not spread over the steps; ``setup_ms`` is the difference of the two runs'
    time outside the QP, compilation excluded).

    With ``compiled_kernels`` (the default) the plant and the APF rollout run as the family
    runner's workers run them, compiled (:mod:`pipeline.loop.compiled`; numba's cache is
    loaded before the first repeat); without, as a single run does."""
    from pipeline.loop.controller import QpCache
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate

    cfg = _config(["method=improved"] + ([f"controller.backend={backend}"] if backend else []))
    scenario = build_scenario(cfg.scenario)
    if compiled_kernels:
        # numba's import and the kernels' cache load, once per process: outside the timing
        simulate(cfg, scenario, QpCache(compiled_kernels=True))
    walls, cpus, compile_s, qp_s, steps = [], [], [], [], 0
    outside_warm, qp_warm, setup = [], [], []
    for _ in range(repeats):
        cache = QpCache(compiled_kernels=compiled_kernels)
        wall, cpu = time.perf_counter(), time.process_time()
        result = simulate(cfg, scenario, cache)
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
        compile_s.append(result.compile_time_s)
        qp_s.append(float(np.sum(result.solve_times_s)))
        steps = max(len(result.solve_times_s), 1)
        wall = time.perf_counter()
        warm = simulate(cfg, scenario, cache)
        warm_wall = time.perf_counter() - wall
        qp_warm.append(float(np.sum(warm.solve_times_s)))
        outside_warm.append(warm_wall - qp_warm[-1])
        setup.append((walls[-1] - qp_s[-1] - compile_s[-1]) - outside_warm[-1])
    qp_map, thetas = _recorded_sparse_qps(cfg, scenario)
    floors = [floor_times(qp_map, thetas,
                          cfg.controller.solver_max_iter)[0] for _ in range(repeats)]
    floor_sum = float(np.median([f.sum() for f in floors]))
    wall = float(np.median(walls))
    return {"backend": cfg.controller.backend, "compiled_kernels": compiled_kernels,
            "closed_loop_wall_s": wall,
            "closed_loop_cpu_s": float(np.median(cpus)),
            "closed_loop_compile_s": float(np.median(compile_s)),
            "closed_loop_qps": len(thetas), "floor_sum_s": floor_sum,
            "closed_loop_over_floor": wall / floor_sum,
            "qp_us_per_step": 1e6 * float(np.median(qp_warm)) / steps,
            "outside_qp_us_per_step": 1e6 * float(np.median(outside_warm)) / steps,
            "setup_ms": 1e3 * float(np.median(setup)),
            "outside_qp_us_per_step_fresh_run": 1e6 * float(np.median(
                [w - q - c for w, q, c in zip(walls, qp_s, compile_s)])) / steps}


def bench_peers(n_steps: int) -> list[dict]:
    """Rebuild-every-step CVXPY and python-control's optimizer on the same (obstacle-free) QP."""
    import warnings

    import control
    import control.optimal as opt
    from scipy.optimize import OptimizeWarning

    from pipeline.loop.controller import LateralMpc

    # python-control passes the unbounded rows of its state range to SciPy, which says so
    warnings.simplefilter("ignore", OptimizeWarning)
    rows = []
    for N in (10, 20):
        cfg = _config(["method=improved", f"controller.horizon={N}",
                       f"controller.control_horizon={N}"])
        ctrl, veh = cfg.controller, cfg.vehicle
        kept = LateralMpc(ctrl, veh)
        steps = step_inputs(cfg, 1, n_steps, seed=1)
        model = steps[0][0].model
        sys_d = control.ss(model.Ad, model.Bd, np.eye(5), np.zeros((5, 1)), dt=0.1)
        Q = np.diag([ctrl.q_lateral, 0.0, ctrl.q_heading, ctrl.q_yaw_rate, ctrl.q_steering])
        R = np.array([[ctrl.r_steering_rate]])
        lower = [-np.inf] * 4 + [-veh.steering_max_rad]
        upper = [np.inf] * 4 + [veh.steering_max_rad]
        constraints = [opt.input_range_constraint(sys_d, [-veh.steering_rate_max_rad_s],
                                                  [veh.steering_rate_max_rad_s]),
                       opt.state_range_constraint(sys_d, lower, upper)]
        for k, (inputs, *_) in enumerate(steps):
            # constant references so that python-control's quadratic_cost states the same QP
            y_ref, psi_ref = float(inputs.y_ref_m[-1]), float(inputs.psi_ref_rad[-1])
            flat = replace(inputs, y_ref_m=np.full(N, y_ref), psi_ref_rad=np.full(N, psi_ref),
                           constraint_gain=np.zeros_like(inputs.constraint_gain),
                           constraint_bound=np.zeros_like(inputs.constraint_bound))
            t0 = time.perf_counter()
            u_kept = kept.solve(flat).steering_rate_rad_s
            t1 = time.perf_counter()
            # PythonRobotics style: a new CVXPY problem every step, solved through CVXPY
            rebuilt = LateralMpc(replace(ctrl, backend="cvxpy"), veh).solve(flat).steering_rate_rad_s
            t2 = time.perf_counter()
            x_ref = np.array([y_ref, 0.0, psi_ref, 0.0, 0.0])
            result = opt.solve_ocp(sys_d, np.arange(N + 1) * 0.1, flat.x0,
                                   opt.quadratic_cost(sys_d, Q, R, x0=x_ref), constraints,
                                   print_summary=False)
            t3 = time.perf_counter()
            rows.append({"section": "peers", "N": N, "step": k, "kept_cvxpy_s": t1 - t0,
                         "rebuild_cvxpy_s": t2 - t1, "python_control_s": t3 - t2,
                         "u0_kept": u_kept, "u0_rebuild": rebuilt,
                         "u0_python_control": float(np.asarray(result.inputs).ravel()[0]),
                         "python_control_success": bool(result.success)})
    return rows


def bench_kinematic(n_steps: int) -> list[dict]:
    from pipeline.loop.controller import KinematicLtvMpc

    cfg = _config(["controller=kinematic"])
    mpc = KinematicLtvMpc(cfg.controller, cfg.vehicle, 0.1)
    rows = []
    state = np.array([0.0, 0.0, 0.0, 2.0])
    empty = np.zeros((cfg.controller.horizon, 0, 2))
    for k in range(n_steps):
        reference = np.vstack([state[0] + 0.3 * np.arange(1, 11), 0.2 * np.sin(0.1 * k)
                               * np.ones(10)])
        t0 = time.perf_counter()
        step = mpc.solve(state, np.zeros(2), reference, empty, np.zeros(0))
        rows.append({"section": "kinematic", "N": 10, "step": k,
                     "kinematic_step_s": time.perf_counter() - t0,
                     "kinematic_compiles": mpc.compile_count, "status": step.status})
        state = state + np.array([0.3, 0.0, 0.0, 0.0])
    return rows


def _recorded_sparse_qps(cfg, scenario) -> tuple[object, list]:
    """The sparse QPs of a run of ``cfg`` (its closed loop with the states as variables, which
    agrees with the condensed one to ~1e-7), as the compiled map and the parameter vectors."""
    from pipeline.loop.controller import QpCache
    from pipeline.loop.controller.lateral_qp import LateralQpStructure
    from pipeline.loop.simulate import simulate

    sparse_cfg = replace(cfg, controller=replace(cfg.controller, backend="clarabel_direct",
                                                 formulation="sparse"))
    cache = QpCache()
    simulate(sparse_cfg, scenario, cache)
    key = ("lateral", "map", LateralQpStructure.of(sparse_cfg.controller, sparse_cfg.vehicle))
    recorder = _RecordingMap(cache.entries[key])
    cache.entries[key] = recorder
    simulate(sparse_cfg, scenario, cache)
    return recorder._map, recorder.recorded


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
    cfg = _config(["method=improved"])
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
    sparse = LateralMpc(replace(ctrl, formulation="sparse"), veh, cfg.model, 0.1, cache)
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
        floor = KeptClarabelFloor(sparse.qp.map, ctrl.solver_max_iter)
        for k, obs in enumerate(observations):
            apf, apf_s, _ = _timed(lambda: planner.rollout(obs.plant_state[:2], goal, obstacle,
                                                            np.array([3.0, 0.0])))
            row = {"section": "path_frame", "repeat": rep, "step": k, "apf_s": apf_s}
            for (f, b), mpc in mpcs.items():
                (inputs, _), data_s, _ = _timed(lambda: mpc.inputs_from(obs))
                _, solve_s, _ = _timed(lambda: mpc.solve(inputs))
                row[f"{f}_{b}_data_s"], row[f"{f}_{b}_solve_s"] = data_s, solve_s
                if b == "clarabel_direct":
                    row[f"{f}_floor_s"] = floor.time(sparse.parameter_vector(inputs))[0]
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


def bench_family_member(backend: str | None = None, n_members: int = 8,
                        repeats: int = 3) -> dict:
    """CPU time of whole family members, everything included (simulation, metrics, writing the
    run folder; the QP compiled beforehand, as a family's workers receive it), over the CPU
    time of the sparse floor of the same members' QPs, measured in this process, member by
    member interleaved with its floor."""
    import dataclasses
    import tempfile

    from pipeline.loop.controller import QpCache
    from pipeline.loop.scenario import build_scenario, family_members
    from pipeline.studies.experiment import run_experiment

    cfg = _config(["method=improved", "scenario=family", f"scenario.family.size={n_members}"]
                  + ([f"controller.backend={backend}"] if backend else []))
    members = family_members(cfg.scenario, cfg.vehicle.footprint_radius_m)
    # as a family's workers run them: the plant and the APF rollout compiled
    cache = QpCache(compiled_kernels=True)
    member_cpu, floor_cpu, steps = [], [], 0
    with tempfile.TemporaryDirectory() as tmp:
        run_experiment(dataclasses.replace(cfg, scenario=members[0]), Path(tmp) / "warm",
                       resume=False, qp_cache=cache)
        for i, member in enumerate(members):
            member_cfg = dataclasses.replace(cfg, scenario=member)
            qp_map, thetas = _recorded_sparse_qps(member_cfg, build_scenario(member))
            steps += len(thetas)
            cpu_runs, cpu_floors = [], []
            for rep in range(repeats):
                cpu = time.process_time()
                run_experiment(member_cfg, Path(tmp) / f"m{i}_{rep}", resume=False,
                               qp_cache=cache)
                cpu_runs.append(time.process_time() - cpu)
                floor = KeptClarabelFloor(qp_map, cfg.controller.solver_max_iter)
                floor.time(thetas[0])  # the solver set up outside the timed sum
                cpu_floors.append(sum(floor.time(theta)[1] for theta in thetas))
            member_cpu.append(float(np.median(cpu_runs)))
            floor_cpu.append(float(np.median(cpu_floors)))
    return {"backend": cfg.controller.backend, "members": len(members),
            "member_cpu_ms": 1e3 * float(np.mean(member_cpu)),
            "sparse_floor_cpu_ms": 1e3 * float(np.mean(floor_cpu)),
            "qps_per_member": steps / len(members),
            "family_member_over_sparse_floor": float(np.sum(member_cpu) / np.sum(floor_cpu))}


def bench_multiverse_reads() -> dict:
    """The quick multiverse (conf/multiverse/quick.yaml) run once into a temporary folder: how
    many member trajectories its re-scoring read per member (goal 1: every metric reading of a
    member computed in one pass)."""
    import contextlib
    import io
    import tempfile

    from pipeline.config import CONF_DIR
    from pipeline.studies.multiverse import load_space, run_multiverse

    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(io.StringIO()):
        start = time.perf_counter()
        result = run_multiverse(load_space(CONF_DIR / "multiverse" / "quick.yaml"), Path(tmp),
                                log=lambda message: None)
        wall = time.perf_counter() - start
    return {"multiverse_member_reads_per_member": result.info.member_reads_per_member,
            "quick_multiverse_wall_s": wall}


def bench_pipeline(family_size: int, compile_family_size: int = 40) -> dict:
    """Import time, one paper-scenario run (with its files), compilations over a family, a
    family's throughput on two workers (worker start included), peak memory."""
    import tempfile

    from pipeline.studies.experiment import run_experiment, run_family

    code = "import time; t = time.perf_counter(); import pipeline.studies.experiment; print(time.perf_counter() - t)"
    imports = float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                   check=True).stdout.strip())
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        run_experiment(_config(["method=improved"]), Path(tmp) / "one", resume=False)
        one_run = time.perf_counter() - start
        run_family(_config(["method=improved", "scenario=family",
                            f"scenario.family.size={compile_family_size}",
                            "scenario.family.n_jobs=2"]), Path(tmp) / "compiles", progress=False)
        compiles = read_family(Path(tmp) / "compiles", members=False).timing["compiles"]
        start = time.perf_counter()
        run_family(_config(["method=improved", "scenario=family",
                            f"scenario.family.size={family_size}", "scenario.family.n_jobs=2"]),
                   Path(tmp) / "timed", progress=False)
        family = time.perf_counter() - start
    return {"import_s": imports, "one_paper_run_s": one_run, "family_size": family_size,
            "family_wall_s": family, "family_scenarios_per_s": family_size / family,
            "compile_family_size": compile_family_size, "compiles_per_family": int(compiles),
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


def summarize(lateral: pd.DataFrame, peers: pd.DataFrame, kinematic: pd.DataFrame,
              pipeline_figures: dict, closed_loop: dict) -> dict:
    def stats(values) -> dict:
        v = np.asarray(values, float) * 1e3
        return {"min_ms": float(v.min()), "median_ms": float(np.median(v)),
                "p95_ms": float(np.percentile(v, 95)), "max_ms": float(v.max())}

    table = []
    for (N, n_obs), part in lateral.groupby(["N", "obstacles"]):
        row = {"N": int(N), "obstacles": int(n_obs)}
        for key in ("apf_s", "apf_python_s", "direct_python_step_s", "cvxpy_solve_s", "cvxpy_clarabel_s", "cvxpy_step_s", "direct_s",
                    "direct_step_s", "floor_s", "daqp_s", "daqp_step_s", "condensed_floor_s",
                    "direct_cpu_s", "daqp_cpu_s", "floor_cpu_s", "condensed_floor_cpu_s",
                    "dense_s", "dense_step_s", "dense_cpu_s"):
            row[key[:-2] + "_median_ms"] = float(np.median(part[key]) * 1e3)
        row["cvxpy_step_over_floor"] = row["cvxpy_step_median_ms"] / row["floor_median_ms"]
        row["direct_step_over_floor"] = row["direct_step_median_ms"] / row["floor_median_ms"]
        # per QP, interleaved: the median of the per-QP ratios (load cancels within a QP); the
        # default backend's step (the lateral MPC's configured backend)
        default = {"clarabel_dense": "dense", "daqp": "daqp"}.get(
            str(part["default_backend"].iloc[0]), "direct")
        row["default_backend"] = str(part["default_backend"].iloc[0])
        row["step_over_sparse_floor"] = float(np.median(part[f"{default}_step_s"]
                                                        / part["floor_s"]))
        row["step_over_sparse_floor_direct"] = float(np.median(part["direct_step_s"]
                                                               / part["floor_s"]))
        # the same step with the APF rollout in Python (a single run's path)
        row["step_over_sparse_floor_python_apf"] = float(np.median(
            part["direct_python_step_s"] / part["floor_s"]))
        row["step_over_sparse_floor_dense"] = float(np.median(part["dense_step_s"]
                                                              / part["floor_s"]))
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
        table.append(row)
    per_n = {int(r["N"]): r for r in table if r["obstacles"] == 1}
    peer_rows = []
    for N, part in peers.groupby("N"):
        peer_rows.append({"N": int(N), "kept_cvxpy": stats(part["kept_cvxpy_s"]),
                          "rebuild_cvxpy": stats(part["rebuild_cvxpy_s"]),
                          "python_control": stats(part["python_control_s"]),
                          "python_control_over_kept": float(np.median(part["python_control_s"])
                                                            / np.median(part["kept_cvxpy_s"])),
                          "max_u0_diff_python_control": float(np.max(np.abs(
                              part["u0_python_control"] - part["u0_kept"]))),
                          "max_u0_diff_rebuild": float(np.max(np.abs(part["u0_rebuild"]
                                                                     - part["u0_kept"])))})
    head = per_n.get(10) or table[0]
    return {"closed_loop_over_floor": closed_loop["closed_loop_over_floor"],
            "step_over_floor": head["direct_step_over_floor"],
            "step_over_sparse_floor": head["step_over_sparse_floor"],
            "step_over_sparse_floor_daqp": head["step_over_sparse_floor_daqp"],
            "step_over_sparse_floor_dense": head["step_over_sparse_floor_dense"],
            "step_over_sparse_floor_cpu": head["step_over_sparse_floor_cpu"],
            "outside_qp_us_per_step": closed_loop["outside_qp_us_per_step"],
            "qp_us_per_step": closed_loop["qp_us_per_step"],
            "compiles_per_family": pipeline_figures["compiles_per_family"],
            "family_scenarios_per_s": pipeline_figures["family_scenarios_per_s"],
            "goals": {"closed_loop_over_floor": "<= 2.0", "step_over_floor": "<= 1.3 (N=10, "
                      "1 obstacle)", "step_over_sparse_floor": "<= 0.5 (default backend)",
                      "step_over_sparse_floor_daqp": "<= 0.25",
                      "step_over_sparse_floor_path": "<= 0.5 (path frame, Clarabel)",
                      "step_over_sparse_floor_path_daqp": "<= 0.25 (path frame, DAQP)",
                      "outside_qp_over_qp": "<= 1.0", "compiles_per_family": "1 (40 members, 2 workers)",
                      "family_scenarios_per_s": ">= 20 (200 members, 2 workers)",
                      "family_member_over_sparse_floor": "<= 1.0 (default backend)",
                      "family_member_over_sparse_floor_daqp": "<= 0.6",
                      "multiverse_member_reads_per_member": "1 (at most)"},
            "closed_loop": closed_loop,
            "lateral": table, "peers": peer_rows,
            "kinematic": stats(kinematic["kinematic_step_s"]),
            "kinematic_recompiles": int(kinematic["kinematic_compiles"].max() - 1),
            "n50_over_n10_direct": per_n[50]["direct_step_median_ms"]
            / per_n[10]["direct_step_median_ms"] if 50 in per_n and 10 in per_n else None,
            "pipeline": pipeline_figures}


def run_benchmark(out: Path, steps: int = 40, repeats: int = 3, quick: bool = False,
                  family_size: int = 200) -> BenchResult:
    """The benchmark (see the module docstring), on one BLAS thread as the closed loop runs
    (OpenBLAS's idle threads would otherwise spin and inflate every CPU time): its result
    written into ``out`` and returned (with the lateral table, the command's scaling
    figure's data)."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        return _measure(Path(out), steps, repeats, quick, family_size)


def _measure(out: Path, steps: int, repeats: int, quick: bool, family_size: int
             ) -> BenchResult:
    """:func:`run_benchmark` inside its thread limit."""
    horizons = (10,) if quick else (10, 20, 30, 50)
    counts = (1,) if quick else (1, 3, 5)
    lateral = pd.DataFrame(bench_lateral(horizons, counts, steps, repeats))
    peers = pd.DataFrame(bench_peers(10 if quick else 20))
    kinematic = pd.DataFrame(bench_kinematic(steps))
    closed_loop = bench_closed_loop(3 if quick else 7)
    closed_loop_python = bench_closed_loop(3 if quick else 7, compiled_kernels=False)
    closed_loop_daqp = bench_closed_loop(3 if quick else 7, backend="daqp")
    pipeline_figures = bench_pipeline(8 if quick else family_size,
                                      8 if quick else 40)
    summary = summarize(lateral, peers, kinematic, pipeline_figures, closed_loop)
    summary["closed_loop_daqp"] = closed_loop_daqp
    summary["closed_loop_python_kernels"] = closed_loop_python
    summary["outside_qp_over_qp_python_kernels"] = \
        closed_loop_python["outside_qp_us_per_step"] / closed_loop_python["qp_us_per_step"]
    summary["outside_qp_over_qp_daqp"] = \
        closed_loop_daqp["outside_qp_us_per_step"] / closed_loop_daqp["qp_us_per_step"]
    member = bench_family_member(n_members=4 if quick else 8)
    member_daqp = bench_family_member("daqp", n_members=4 if quick else 8)
    summary["family_member"] = {"default": member, "daqp": member_daqp}
    summary["family_member_over_sparse_floor"] = member["family_member_over_sparse_floor"]
    summary["family_member_over_sparse_floor_daqp"] = \
        member_daqp["family_member_over_sparse_floor"]
    path_rows = bench_path_frame(steps, repeats)
    summary["path_frame"] = summarize_path_frame(path_rows)
    summary["step_over_sparse_floor_path"] = \
        summary["path_frame"]["step_over_sparse_floor_path"]
    summary["step_over_sparse_floor_path_daqp"] = \
        summary["path_frame"]["step_over_sparse_floor_path_daqp"]
    summary.update(bench_multiverse_reads())
    summary["outside_qp_over_qp"] = closed_loop["outside_qp_us_per_step"] \
        / closed_loop["qp_us_per_step"]
    summary["setup_ms"] = closed_loop["setup_ms"]
    table = pd.concat([lateral, peers, kinematic, pd.DataFrame(path_rows)], ignore_index=True)
    return BenchResult(summary, table, lateral).write(out)
