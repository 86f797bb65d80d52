"""The lockstep engine against the per-member loop it replaced: whole family members (the
closed loop, metrics and run folder) per CPU-second."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.harness.inputs import compose_config


def bench_engine(n_members: int = 200, repeats: int = 3) -> dict:
    """Members per CPU-second of the default family (improved, path frame, DAQP, compiled
    kernels) as a worker runs them, through the lockstep engine in the worker's tasks
    (:func:`pipeline.studies.experiment._run_chunk`, ``MEMBERS_PER_TASK`` members stepped
    together), over the same members one by one through the per-member loop kept as the
    tests' oracle (``tests/loop/oracle_loop.py``) with the same metrics and folder
    (:func:`~pipeline.studies.experiment.record_run`); interleaved repeats, medians, one
    process."""
    from pipeline.loop.controller import QpCache
    from pipeline.loop.scenario import build_scenario, family_members
    from pipeline.studies.experiment import _run_chunk, record_run
    from pipeline.studies.family_pool import MEMBERS_PER_TASK
    from tests.loop.oracle_loop import oracle_simulate

    cfg = compose_config(["method=improved", "scenario=family", "controller.backend=daqp",
                          f"scenario.family.size={n_members}"])
    scenarios = family_members(cfg.scenario, cfg.vehicle.footprint_radius_m)
    # as run_family hands them to its workers: each with its config hash
    members = [cfg.with_member(member, config_hash) for member, config_hash
               in zip(scenarios, cfg.member_config_hashes(scenarios), strict=True)]
    cache = QpCache(compiled_kernels=True)
    engine_cpu, loop_cpu = [], []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        _run_chunk([(0, members[0], root / "warm_engine")], cache)
        record_run(members[0], root / "warm_loop",
                   oracle_simulate(members[0], build_scenario(members[0].scenario), cache),
                   cache)
        for rep in range(repeats):
            jobs = [(i, member, root / f"engine{rep}" / f"member_{i:04d}")
                    for i, member in enumerate(members)]
            start = time.process_time()
            for first in range(0, len(jobs), MEMBERS_PER_TASK):
                _run_chunk(jobs[first:first + MEMBERS_PER_TASK], cache)
            engine_cpu.append(time.process_time() - start)
            start = time.process_time()
            for i, member in enumerate(members):
                result = oracle_simulate(member, build_scenario(member.scenario), cache)
                record_run(member, root / f"loop{rep}" / f"member_{i:04d}", result, cache)
            loop_cpu.append(time.process_time() - start)
    engine, loop = float(np.median(engine_cpu)), float(np.median(loop_cpu))
    return {"engine_members": len(members), "engine_members_per_task": MEMBERS_PER_TASK,
            "engine_members_per_cpu_s": len(members) / engine,
            "member_loop_members_per_cpu_s": len(members) / loop,
            "engine_members_per_cpu_s_over_member_loop": loop / engine}
