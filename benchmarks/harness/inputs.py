"""The bench's inputs and floors: its configurations, a deterministic sequence of realistic
QP inputs and the kept-Clarabel floor (the sparse statement it is handed, and the QPs of a
closed-loop run recorded for it: :mod:`benchmarks.harness.sparse_floor`)."""

from __future__ import annotations

import copy
import functools
import time
from typing import Any

import numpy as np


def compose_config(overrides: list[str], cached: bool = True):
    """The typed experiment config Hydra composes with ``overrides`` (composed once per
    process, as the bench asks for the same few lists many times; a copy each time);
    ``cached=False``: composed again (a figure whose timer holds the composition)."""
    if not cached:
        return _composed.__wrapped__(tuple(overrides))
    return copy.deepcopy(_composed(tuple(overrides)))


@functools.cache
def _composed(overrides: tuple[str, ...]):
    from hydra import compose, initialize_config_dir

    from pipeline.config import CONF_DIR, register_configs, to_experiment_config

    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return to_experiment_config(compose(config_name="config", overrides=list(overrides)))


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


def qp_map(mpc: Any) -> Any:
    """The compiled map (:class:`~pipeline.loop.controller.qp.AffineQpMap`) a lateral MPC on
    ``clarabel_direct`` solves through (the condensed statement's)."""
    from pipeline.loop.controller.lateral_backends import CompiledCondensedQp
    from pipeline.loop.controller.qp import DirectQp

    qp = mpc.qp.compiled if isinstance(mpc.qp, CompiledCondensedQp) else mpc.qp
    if not isinstance(qp, DirectQp):
        raise TypeError(f"the floor needs a clarabel_direct backend, not {type(qp).__name__}")
    return qp.map


class KeptClarabelFloor:
    """The floor: a kept Clarabel solver handed a QP's data (computed outside the timed region),
    timed on ``update + solve`` only, one QP at a time so that it interleaves with the step."""

    def __init__(self, qp_map: Any, max_iter: int) -> None:
        from pipeline.loop.controller.qp import clarabel_settings

        self.map, self.settings = qp_map, clarabel_settings(max_iter)
        self.solver: Any = None  # clarabel.DefaultSolver, made at the first solve

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


def timed_call(call):
    """``call()``'s result with its wall and CPU time (s)."""
    wall, cpu = time.perf_counter(), time.process_time()
    out = call()
    return out, time.perf_counter() - wall, time.process_time() - cpu
