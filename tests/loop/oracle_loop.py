"""The per-member closed loop as it stood before the lockstep engine: a slow, readable test
oracle (issue 58). Every run of the pipeline goes through :mod:`pipeline.loop.engine`; the
tests hold the engine's trajectories equal to this loop's, member by member."""

from __future__ import annotations

import inspect

import numpy as np

from pipeline.loop.controller import ControlStep, Observation, QpCache
from pipeline.loop.horizon import HorizonLog
from pipeline.loop.kernels import Kernels
from pipeline.loop.planner import ApfPlanner
from pipeline.loop.scenario import Scenario
from pipeline.loop.settings import LoopSettings
from pipeline.loop.simulate import (
    SimulationResult,
    TrajectoryLog,
    _add_end_columns,
    _add_model_check,
    _add_step_columns,
    _anchor_due,
    _in_contact,
    _line_constants,
    _loop_stages,
    _planned_speed,
    _pose_row,
    _termination,
    run_kernels,
)
from pipeline.loop.trajectory import HEAD, OBSTACLE_FIELDS, TAIL, obstacle_column


def oracle_simulate(cfg: LoopSettings, scenario: Scenario, qp_cache: QpCache | None = None,
                    kernels: Kernels | None = None, record_horizon: bool = True
                    ) -> SimulationResult:
    """One member's run, member by member, step by step (what the engine must reproduce)."""
    from threadpoolctl import threadpool_limits

    qp_cache = qp_cache if qp_cache is not None else QpCache()
    with threadpool_limits(limits=1, user_api="blas"):
        return _closed_loop(cfg, scenario, qp_cache,
                            kernels if kernels is not None else run_kernels(qp_cache),
                            record_horizon)


def _closed_loop(cfg: LoopSettings, scenario: Scenario, qp_cache: QpCache | None,
                 kernels: Kernels, record_horizon: bool = True) -> SimulationResult:
    """The loop of :func:`simulate`."""
    kinematic, plant, controller, planner = _loop_stages(cfg, scenario, qp_cache, kernels)
    vehicle_radius = cfg.vehicle.footprint_radius_m
    # a planner of one's own may keep speed()'s earlier signature (no path, no speed)
    path_aware = "path_m" in inspect.signature(planner.speed).parameters
    # the kinematic track uses the speed only for reference_alignment=path_speed (Section 3.1)
    plans_speed = not kinematic or cfg.controller.reference_alignment == "path_speed"
    ts = scenario.sample_time_s
    frame = scenario.line_frame
    line = _line_constants(frame)
    goal_line_x = float(frame.to_line(scenario.goal_m)[0])
    obstacle_names = [tuple(obstacle_column(j, f) for f in OBSTACLE_FIELDS)
                      for j in range(scenario.n_obstacles)]
    log = TrajectoryLog(scenario.n_steps + 1)
    planned = HorizonLog(scenario.n_steps + 1, scenario.n_obstacles) if record_horizon \
        else None
    solve_times = np.zeros(scenario.n_steps + 1)
    n_solves = 0
    state = plant.initial_state(scenario)
    command: np.ndarray | None = None
    termination = "max_steps"
    # obstacle_anchor="vehicle": each obstacle is placed relative to the vehicle when it appears
    # (a plain flag keeps the default reading's loop free of the per-step check)
    unanchored = np.full(scenario.n_obstacles, scenario.obstacle_anchor == "vehicle")
    anchoring = bool(unanchored.any())
    senses, follows_road = scenario.senses, scenario.follows_road
    route = scenario.attraction_route
    if route is not None and isinstance(planner, ApfPlanner) \
            and type(planner).rollout is ApfPlanner.rollout:
        planner.follow_route(*route)  # the APF follows the road along its rollout itself
        follows_road = False
    # the vehicle's reach from its logged position: its discs' farthest edge
    reach = vehicle_radius + 0.5 * cfg.vehicle.footprint_span_m
    end_at_contact = scenario.end_at_contact
    road = scenario.road_polygons_m
    # an ego of several discs along its heading touches where any of them does
    disc_offsets = cfg.vehicle.footprint_offsets_m if cfg.vehicle.footprint_discs > 1 else None
    # an obstacle motion that reacts to the platform (reactive walkers) is told where it is
    reacting = scenario.obstacle_motion if hasattr(scenario.obstacle_motion, "react") \
        else None
    for k in range(scenario.n_steps + 1):
        time_s = k * ts
        if anchoring:
            scenario, anchoring = _anchor_due(scenario, unanchored, time_s, state)
        if reacting:  # walkers that avoid the platform learn where it is first
            reacting.react(time_s, state[:2], vehicle_radius)
        snapshot = scenario.obstacles_at(time_s)
        contact = end_at_contact and _in_contact(state, snapshot, vehicle_radius, disc_offsets)
        if senses:  # a sensor range (recorded pedestrians), occlusion (CommonRoad)
            snapshot = scenario.sense(snapshot, state[:2], reach)
        row, along, lateral, psi, e_psi = _pose_row(time_s, state, frame, line)
        log.put_obstacles(k, obstacle_names, snapshot.positions_m, snapshot.radii_m,
                          snapshot.visible)
        ending = "contact" if contact else _termination(state, along, goal_line_x, scenario, k)
        if ending is not None:
            termination = ending
            _add_end_columns(row, plant, state, command)
            log.put(k, row)
            break
        visible = snapshot.only_visible()
        if scenario.nearest_first:
            visible = visible.nearest_first(state[:2])
        position = state[:2].copy()
        goal = scenario.attraction_goal_m(position) if follows_road else scenario.goal_m
        rollout = planner.rollout(position, goal, visible, plant.velocity(state))
        if planned is not None:
            planned.put(k, rollout, snapshot)
        speed_ref = _planned_speed(planner, position, psi, visible, scenario, vehicle_radius,
                                   rollout, state, path_aware) if plans_speed else np.nan
        observation = Observation(time_s, state, frame, np.array([along, lateral]), e_psi,
                                  rollout, visible, speed_ref, road)
        step: ControlStep = controller.step(observation)
        if cfg.controller.kind != "pure_pursuit":
            solve_times[n_solves] = step.solve_time_s
            n_solves += 1
        _add_step_columns(row, plant, state, step, command, kinematic, speed_ref, rollout)
        log.put(k, row)
        command = step.command
        state = plant.step(state, command, speed_ref)
    _add_model_check(controller, log)
    trajectory = log.table(list(HEAD) + [c for names in obstacle_names for c in names]
                           + list(TAIL))
    return SimulationResult(trajectory, solve_times[:n_solves], controller.compile_count,
                            controller.compile_time_s, termination == "goal_line", termination,
                            planned.arrays(controller, log.rows) if planned is not None
                            else {})


