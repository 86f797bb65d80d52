"""The lockstep engine: the closed loops of many members stepped together, one step at a time.

Every run goes through here: a family's members (a worker's share of them), the members of
several tuning trials at once (each with its own settings), the explorer's single run (a
family of one). Each step ``k`` the engine

1. observes every active member (:meth:`MemberLoop.observe`: its obstacles, sensing,
   termination; a member that ends leaves the batch there, and nothing it holds touches the
   others),
2. runs each active member's planner and controller (:meth:`MemberLoop.control`: the APF
   rollout, the speed rule, the controller's step, the log row),
3. steps the plants of all active members: the single-track plants with compiled kernels in
   one call of :func:`pipeline.loop.model.single_track_rk4_rows` (the same statement per row,
   the same bits as one member alone), any other plant (the kinematic one, CPython's kernels)
   member by member.

Stages that are not written for batches (a planner or controller plugged in by ``_target_``,
the peers, the nonlinear MPC) run member by member inside the same step: one engine, not two.
What a member computes depends only on its own settings, scenario and state, so a member's
trajectory is the same bits in any batch, alone or with others (the tests hold it equal to
the readable per-member loop kept in ``tests/loop/oracle_loop.py``).
"""

from __future__ import annotations

import functools
import inspect
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from pipeline.loop.controller import ControlStep, Observation, QpCache
from pipeline.loop.controller.lateral_rows import batch_key, lateral_steps
from pipeline.loop.horizon import HorizonLog
from pipeline.loop.kernels import Kernels
from pipeline.loop.model import SINGLE_TRACK_CONSTANT_NAMES
from pipeline.loop.planner import ApfPlanner
from pipeline.loop.scenario import Scenario
from pipeline.loop.settings import LoopSettings
from pipeline.loop.simulate import (
    SimulationResult,
    SingleTrackPlant,
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

__all__ = ["MemberLoop", "simulate_members", "step_members"]

#: :func:`~pipeline.loop.model.single_track_constants`' length
N_PLANT_CONSTANTS = len(SINGLE_TRACK_CONSTANT_NAMES)


class MemberLoop:
    """One member's closed loop as the engine steps it: its stages, state, log and what each
    step planned.

    Parameters
    ----------
    cfg : LoopSettings
    scenario : Scenario
    qp_cache : QpCache or None
        Compiled QPs shared with the other members.
    kernels : Kernels
    record_horizon : bool
        Keep what each step planned (:mod:`pipeline.loop.horizon`).
    """

    def __init__(self, cfg: LoopSettings, scenario: Scenario, qp_cache: QpCache | None,
                 kernels: Kernels, record_horizon: bool = True) -> None:
        self.cfg, self.scenario, self.kernels = cfg, scenario, kernels
        self.kinematic, self.plant, self.controller, self.planner = \
            _loop_stages(cfg, scenario, qp_cache, kernels)
        self.vehicle_radius = cfg.vehicle.footprint_radius_m
        # a planner of one's own may keep speed()'s earlier signature (no path, no speed)
        self.path_aware = "path_m" in inspect.signature(self.planner.speed).parameters
        # the kinematic track uses the speed only for reference_alignment=path_speed (3.1)
        self.plans_speed = not self.kinematic \
            or cfg.controller.reference_alignment == "path_speed"
        self.frame = scenario.line_frame
        self.line = _line_constants(self.frame)
        # a road's route: a planner that follows it along its rollout gets it once (and the
        # goal each step); any other is handed the point ahead on it each step
        self.goal_moves = follows_route(self.planner, scenario)
        self.goal_line_x = float(self.frame.to_line(scenario.goal_m)[0])
        self.obstacle_names = [tuple(obstacle_column(j, f) for f in OBSTACLE_FIELDS)
                               for j in range(scenario.n_obstacles)]
        self.log = TrajectoryLog(scenario.n_steps + 1)
        self.planned = HorizonLog(scenario.n_steps + 1, scenario.n_obstacles) \
            if record_horizon else None
        self.solve_times = np.zeros(scenario.n_steps + 1)
        self.n_solves = 0
        self.state = self.plant.initial_state(scenario)
        self.command: np.ndarray | None = None
        self.speed_ref = float("nan")
        self.termination = "max_steps"
        # obstacle_anchor="vehicle": each obstacle placed relative to the vehicle when it
        # appears (a plain flag keeps the default reading's loop free of the per-step check)
        self.unanchored = np.full(scenario.n_obstacles, scenario.obstacle_anchor == "vehicle")
        self.anchoring = bool(self.unanchored.any())
        # the vehicle's reach from its logged position: its discs' farthest edge
        self.reach = self.vehicle_radius + 0.5 * cfg.vehicle.footprint_span_m
        # an ego of several discs along its heading touches where any of them does
        self.disc_offsets = cfg.vehicle.footprint_offsets_m \
            if cfg.vehicle.footprint_discs > 1 else None
        # an obstacle motion that reacts to the platform (reactive walkers) is told where it is
        self.reacting = scenario.obstacle_motion \
            if hasattr(scenario.obstacle_motion, "react") else None
        self.counts_solves = cfg.controller.kind != "pure_pursuit"
        #: whether the log already holds the model check (a group's member: computed from the
        #: group's arrays, :mod:`~pipeline.loop.lateral_group`)
        self.model_checked = False
        #: this step's pending observation (set by observe, used by plan) and plan (set by
        #: plan, used by apply)
        self._pending: tuple[Any, ...] | None = None
        self._planned: tuple[Any, ...] | None = None
        #: the key of the members whose controllers are stepped together
        #: (:func:`~pipeline.loop.controller.lateral_rows.batch_key`); None: stepped alone
        self.batch_key = batch_key(self.controller, kernels)
        #: the single-track plant's part of the batched step (its constants, steering-rate
        #: bound, sample period and substeps); None: its plant is stepped alone
        self.batch_plant: tuple[np.ndarray, float, float, int] | None = None
        if isinstance(self.plant, SingleTrackPlant) and kernels.compiled:
            self.batch_plant = (np.asarray(self.plant.constants), self.plant.rate_max_rad_s,
                                self.plant.ts, self.plant.substeps)

    def observe(self, k: int) -> bool:
        """Step ``k``'s observation; False when the run ends here (its last row logged)."""
        scenario, state = self.scenario, self.state
        time_s = k * scenario.sample_time_s
        if self.anchoring:
            self.scenario, self.anchoring = _anchor_due(scenario, self.unanchored, time_s,
                                                        state)
            scenario = self.scenario
        if self.reacting:  # walkers that avoid the platform learn where it is first
            self.reacting.react(time_s, state[:2], self.vehicle_radius)
        snapshot = scenario.obstacles_at(time_s)
        contact = scenario.end_at_contact and _in_contact(state, snapshot, self.vehicle_radius,
                                                          self.disc_offsets)
        if scenario.senses:  # a sensor range (recorded pedestrians), occlusion (CommonRoad)
            snapshot = scenario.sense(snapshot, state[:2], self.reach)
        row, along, lateral, psi, e_psi = _pose_row(time_s, state, self.frame, self.line)
        self.log.put_obstacles(k, self.obstacle_names, snapshot.positions_m, snapshot.radii_m,
                               snapshot.visible)
        ending = "contact" if contact else _termination(state, along, self.goal_line_x,
                                                        scenario, k)
        if ending is not None:
            self.termination = ending
            _add_end_columns(row, self.plant, state, self.command)
            self.log.put(k, row)
            return False
        self._pending = (k, time_s, snapshot, row, along, lateral, psi, e_psi)
        return True

    def control(self) -> None:
        """The planner's and controller's part of the observed step, and its log row (the
        controller stepped alone)."""
        self.apply(self.controller.step(self.plan()))

    def plan(self) -> Observation:
        """The planner's part of the observed step: the APF rollout and the speed rule; the
        controller's observation."""
        if self._pending is None:
            raise RuntimeError("plan() before observe()")
        k, time_s, snapshot, row, along, lateral, psi, e_psi = self._pending
        scenario, state, planner = self.scenario, self.state, self.planner
        visible = snapshot.only_visible()
        if scenario.nearest_first:
            visible = visible.nearest_first(state[:2])
        position = state[:2].copy()
        goal = scenario.attraction_goal_m(position) if self.goal_moves else scenario.goal_m
        rollout = planner.rollout(position, goal, visible, self.plant.velocity(state))
        if self.planned is not None:
            self.planned.put(k, rollout, snapshot)
        speed_ref = _planned_speed(planner, position, psi, visible, scenario,
                                   self.vehicle_radius, rollout, state, self.path_aware) \
            if self.plans_speed else np.nan
        self._planned = (k, row, rollout, speed_ref)
        return Observation(time_s, state, self.frame, np.array([along, lateral]), e_psi,
                           rollout, visible, speed_ref, scenario.road_polygons_m)

    def apply(self, step: ControlStep) -> None:
        """The controller's step taken: its solve time and the step's log row."""
        if self._planned is None:
            raise RuntimeError("apply() before plan()")
        k, row, rollout, speed_ref = self._planned
        self._pending = self._planned = None
        if self.counts_solves:
            self.solve_times[self.n_solves] = step.solve_time_s
            self.n_solves += 1
        _add_step_columns(row, self.plant, self.state, step, self.command, self.kinematic,
                          speed_ref, rollout)
        self.log.put(k, row)
        self.command, self.speed_ref = step.command, float(speed_ref)

    def advance(self) -> None:
        """This member's plant stepped alone (the engine batches the compiled single-track
        plants instead)."""
        if self.command is None:
            raise RuntimeError("advance() before control()")
        self.state = self.plant.step(self.state, self.command, self.speed_ref)

    def result(self) -> SimulationResult:
        """The finished run."""
        log, controller = self.log, self.controller
        if not self.model_checked:
            _add_model_check(controller, log)
        trajectory = log.table(list(HEAD) + [c for names in self.obstacle_names for c in names]
                               + list(TAIL))
        return SimulationResult(trajectory, self.solve_times[:self.n_solves],
                                controller.compile_count, controller.compile_time_s,
                                self.termination == "goal_line", self.termination,
                                self.planned.arrays(controller, log.rows)
                                if self.planned is not None else {})


def follows_route(planner: Any, scenario: Scenario) -> bool:
    """Hand ``scenario``'s route (:attr:`~pipeline.loop.scenario.Scenario.attraction_route`)
    to a planner that follows it along its rollout (the APF's own rollout,
    :meth:`~pipeline.loop.planner.ApfPlanner.follow_route`); returns whether the loop must
    hand the planner the point ahead on the road each step instead: any other planner on a
    road, a subclass that overrides ``rollout`` too (the VO peer, a planner of one's own),
    which would not read the route."""
    route = scenario.attraction_route
    if route is None:
        return scenario.follows_road
    if not follows_route_itself(planner):
        return True
    planner.follow_route(*route)
    return False


def follows_route_itself(planner: Any) -> bool:
    """Whether ``planner``'s rollout is the APF's, which follows a route handed to it."""
    return isinstance(planner, ApfPlanner) and type(planner).rollout is ApfPlanner.rollout


def _advance_plants(members: Sequence[MemberLoop]) -> None:
    """Step every member's plant: the compiled single-track plants in one batched call, the
    others one by one."""
    batch = [m for m in members if m.batch_plant is not None]
    for member in members:
        if member.batch_plant is None:
            member.advance()
    if not batch:
        return
    n = len(batch)
    states, constants = np.empty((n, 7)), np.empty((n, N_PLANT_CONSTANTS))
    rates, targets, periods = np.empty(n), np.empty(n), np.empty(n)
    substeps = np.empty(n, dtype=np.int64)
    for i, member in enumerate(batch):
        row_constants, rate_max, period, steps = member.batch_plant  # type: ignore[misc]
        if member.command is None:
            raise RuntimeError("a plant stepped before its controller")
        states[i], constants[i] = member.state, row_constants
        # the steering rate saturated as SingleTrackPlant.step does
        rates[i] = min(max(float(member.command[0]), -rate_max), rate_max)
        targets[i], periods[i], substeps[i] = member.speed_ref, period, steps
    stepped = batch[0].kernels.plant_rk4_rows(states, constants, rates, targets, periods,
                                              substeps)
    for i, member in enumerate(batch):
        member.state = stepped[i]


def step_members(members: Sequence[MemberLoop]) -> list[SimulationResult]:
    """Step ``members`` together until each has ended; their results in the same order.

    A member that ends (goal line, last step, contact, a non-finite state) leaves the batch at
    that step; the others go on. The members of the default statement go as groups of arrays
    (:class:`~pipeline.loop.lateral_group.LateralGroup`, one per
    :func:`~pipeline.loop.lateral_group.group_key`), the others through their own loops."""
    from pipeline.loop.lateral_group import LateralGroup, group_key

    groups: dict[tuple[Any, ...], list[MemberLoop]] = {}
    others = []
    for member in members:
        key = group_key(member)
        if key is None:
            others.append(member)
        else:
            groups.setdefault(key, []).append(member)
    for group in groups.values():
        LateralGroup(group).run()
    active = others
    k = 0
    while active:
        active = [member for member in active if member.observe(k)]
        _control(active)
        _advance_plants(active)
        k += 1
    return [member.result() for member in members]


def _control(members: Sequence[MemberLoop]) -> None:
    """Every member's planner and controller: the lateral MPCs of one batch key stepped
    together (:func:`~pipeline.loop.controller.lateral_rows.lateral_steps`), the others alone."""
    groups: dict[tuple[Any, ...], list[MemberLoop]] = {}
    for member in members:
        if member.batch_key is None:
            member.control()
        else:
            groups.setdefault(member.batch_key, []).append(member)
    for group in groups.values():
        if len(group) == 1:
            group[0].control()
            continue
        observations = [member.plan() for member in group]
        steps = lateral_steps([member.controller for member in group],  # type: ignore[misc]
                              observations, group[0].kernels)
        for member, step in zip(group, steps, strict=True):
            member.apply(step)


@functools.lru_cache(maxsize=1)
def _threadpool_controller(n_modules: int) -> Any:
    """threadpoolctl's controller of this process's libraries when ``n_modules`` modules are
    loaded (the key: another import may load another BLAS)."""
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


def simulate_members(runs: Sequence[tuple[LoopSettings, Scenario]],
                     qp_cache: QpCache | None = None, kernels: Kernels | None = None,
                     record_horizon: bool = True) -> list[SimulationResult]:
    """Run the closed loops of ``runs`` (settings and scenario each) in lockstep, with BLAS on
    one thread (every product in the loop is tiny: OpenBLAS would start threads for some and
    leave them spinning on the other core, measured at twice a run's CPU time).

    Parameters
    ----------
    runs : sequence of (LoopSettings, Scenario)
        Each member's settings (they may differ: a tune's trials) and scenario.
    qp_cache : QpCache, optional
        Compiled QPs shared by the members (a private cache when omitted).
    kernels : Kernels, optional
        The loop's kernels; by default :func:`~pipeline.loop.simulate.run_kernels` of the
        cache.
    record_horizon : bool
        Keep what each step planned (the report's scenario explorer).

    Returns
    -------
    list of SimulationResult
        In the order of ``runs``.
    """
    qp_cache = qp_cache if qp_cache is not None else QpCache()
    # one controller per process (a scan of the loaded libraries, ~2 ms), built again whenever
    # modules were imported since (a new module may have loaded another BLAS): not in the
    # cache's process-local part, which a worker's task receives empty with each cache shipped
    # to it (the scan was 6-7 % of a tune's worker time)
    threads = _threadpool_controller(len(sys.modules))
    kernels = kernels if kernels is not None else run_kernels(qp_cache)
    with threads.limit(limits=1, user_api="blas"):
        members = [MemberLoop(cfg, scenario, qp_cache, kernels, record_horizon)
                   for cfg, scenario in runs]
        return step_members(members)
