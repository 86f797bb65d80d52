"""The closed loop and a family member, whole, over the sparse floor of the same QPs."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from benchmarks.harness.inputs import KeptClarabelFloor, compose_config, floor_times
from benchmarks.harness.sparse_floor import recorded_sparse_qps


def bench_closed_loop(repeats: int = 5, backend: str | None = None,
                      compiled_kernels: bool = True) -> dict:
    """One complete paper-scenario run of the improved method in this process (the QP compiled
    inside the timed region, a fresh cache each time), over the sparse floor of the same QPs
    (the run's steps recorded and restated with the states as variables,
    :func:`~benchmarks.harness.sparse_floor.recorded_sparse_qps`), and its time outside the QP
    per step.

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

    cfg = compose_config(["method=improved"]
                         + ([f"controller.backend={backend}"] if backend else []))
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
    qp_map, thetas = recorded_sparse_qps(cfg, scenario)
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
                [w - q - c for w, q, c in zip(walls, qp_s, compile_s, strict=True)])) / steps}


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

    cfg = compose_config(["method=improved", "scenario=family",
                          f"scenario.family.size={n_members}"]
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
            qp_map, thetas = recorded_sparse_qps(member_cfg, build_scenario(member))
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
