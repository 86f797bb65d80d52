"""The methods the paper names (``pipeline.peers``): each one's closed-loop step on the paper
scenario over improved's on the same track and over the sparse QP floor of improved's run."""

from __future__ import annotations

import time

import numpy as np

from benchmarks.harness.inputs import compose_config, floor_times
from benchmarks.harness.sparse_floor import recorded_sparse_qps


def named_peers() -> dict[str, tuple[list[str], dict[str, list[str]]]]:
    """Per track: improved's overrides, then each peer's method preset: every method whose
    role is ``peer`` (:mod:`pipeline.methods`), on the lateral track through its preset of its
    own name and on the Appendix-A track through ``<name>_kinematic`` (where it has one)."""
    from pipeline.methods import method_registry

    peers = sorted((info for info in method_registry().values() if info.role == "peer"),
                   key=lambda info: info.order)
    return {
        "lateral": (["method=improved"], {p.name: [f"method={p.name}"] for p in peers
                                          if p.name in p.presets}),
        "kinematic": (["experiment=kinematic", "planner=improved"],
                      {p.name: ["experiment=kinematic", f"method={p.name}_kinematic"]
                       for p in peers if f"{p.name}_kinematic" in p.presets}),
    }


def _step_s(overrides: list[str], repeats: int) -> tuple[float, int]:
    """Median wall time per step of the paper-scenario run (controller, planner and plant:
    the whole step), each repeat timed with the cache the previous run filled (compilation
    and one-off set-up outside), and the run's step count."""
    from pipeline.loop.controller import QpCache
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate

    cfg = compose_config(overrides)
    scenario = build_scenario(cfg.scenario)
    cache = QpCache()
    steps = max(len(simulate(cfg, scenario, cache).solve_times_s), 1)
    walls = []
    for _ in range(repeats):
        wall = time.perf_counter()
        simulate(cfg, scenario, cache)
        walls.append(time.perf_counter() - wall)
    return float(np.median(walls)) / steps, steps


def bench_named_peers(repeats: int = 3) -> dict:
    """``peer_step_over_improved_<track>_<peer>``: a peer's step over improved's on the same
    track (goal: at most 2); ``peer_step_over_sparse_floor_<peer>``: the lateral peers' step
    over the sparse floor per step of improved's QPs (improved's own under
    ``improved_step_over_sparse_floor``)."""
    found: dict = {}
    for track, (improved, peers) in named_peers().items():
        improved_s, _ = _step_s(improved, repeats)
        found[f"improved_step_us_{track}"] = 1e6 * improved_s
        floor_s = None
        if track == "lateral":
            cfg = compose_config(improved)
            from pipeline.loop.scenario import build_scenario

            qp_map, thetas = recorded_sparse_qps(cfg, build_scenario(cfg.scenario))
            floor_s = float(np.median([floor_times(qp_map, thetas,
                                                   cfg.controller.solver_max_iter)[0].sum()
                                       for _ in range(repeats)])) / max(len(thetas), 1)
            found["improved_step_over_sparse_floor"] = improved_s / floor_s
        for name, overrides in peers.items():
            peer_s, _ = _step_s(overrides, repeats)
            found[f"peer_step_us_{track}_{name}"] = 1e6 * peer_s
            found[f"peer_step_over_improved_{track}_{name}"] = peer_s / improved_s
            if floor_s is not None:
                found[f"peer_step_over_sparse_floor_{name}"] = peer_s / floor_s
    return found
