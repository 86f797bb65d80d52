"""The lockstep engine's compiled path: the members of the default statement stepped as one
group of arrays, three or four compiled calls a step for all of them
(:mod:`pipeline.loop.group_rows`).

A member joins a group (:func:`group_key`) when every stage of its loop is the default one
the compiled calls state: a scripted scenario (constant-velocity obstacles from their
appearance, no sensor range, no anchoring, no contact ending, no road), the APF's own rollout
towards a fixed goal without velocity planning, the path frame's lateral MPC on the rollout
(:func:`~pipeline.loop.controller.lateral_rows.batch_key`) on a kept native DAQP workspace or
kept Clarabel solvers (``clarabel_direct``) with two moves or more, and the compiled
single-track plant. Every other member steps through :class:`~pipeline.loop.engine.MemberLoop`
as before.

The group holds each member's state, its last plan (for the fallback) and its plan's poses
(for the next step's stations) in arrays, writes its log and its prediction records into
arrays, and hands each member's :class:`~pipeline.loop.engine.MemberLoop` its log with the
model check, its solve times and termination, and where it keeps one its horizon record, at
the end, so that :meth:`MemberLoop.result <pipeline.loop.engine.MemberLoop.result>` gives the
run as before. Between the calls it looks up in Python what comes from caches of Python
objects: the prediction step of a speed, the model of a speed and step and its condensed
prediction (a few dictionary reads per member and step). Every number is the one the member's
own loop gives (the same statements in the same order; the tests hold them equal bit for bit).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from pipeline.loop import group_rows as rows
from pipeline.loop.controller.frames import PathFrame
from pipeline.loop.controller.lateral import LateralMpc
from pipeline.loop.controller.lateral_backends import DaqpCondensedQp
from pipeline.loop.controller.lateral_qp import (
    direct_pack_offsets,
    direct_theta_size,
    pack_offsets,
)
from pipeline.loop.controller.lateral_rows import _direct, _native_daqp
from pipeline.loop.controller.path import ReferencePath
from pipeline.loop.controller.prediction_check import MODEL_CHECK_COLUMNS, PredictionRecord
from pipeline.loop.controller.qp import NON_FINITE_DATA, QpSolution
from pipeline.loop.planner import ApfPlanner, apf_kernel_settings
from pipeline.loop.scenario import Scenario
from pipeline.loop.simulate import SingleTrackPlant, TrajectoryLog

__all__ = ["LateralGroup", "group_key"]


def group_key(member: Any) -> tuple[Any, ...] | None:
    """The key of the members a :class:`LateralGroup` steps together (the same backend,
    horizon, obstacle slots and moves), or None where ``member`` (a
    :class:`~pipeline.loop.engine.MemberLoop`) steps through its own loop (see the module
    docstring)."""
    kernels, mpc, scenario = member.kernels, member.controller, member.scenario
    if member.batch_key is None or getattr(kernels, "observe_plan_rows", None) is None \
            or type(mpc) is not LateralMpc \
            or not isinstance(member.plant, SingleTrackPlant) or member.batch_plant is None:
        return None
    backend = "daqp" if _native_daqp(mpc) else "clarabel_direct" if _direct(mpc) else None
    if backend is None:
        return None
    planner = member.planner
    if type(planner) is not ApfPlanner or planner.settings.velocity_planning \
            or member.goal_moves or scenario.attraction_route is not None:
        return None
    if type(scenario) is not Scenario or scenario.obstacle_motion is not None \
            or member.anchoring or scenario.senses or scenario.nearest_first \
            or scenario.end_at_contact or member.reacting is not None \
            or scenario.road_polygons_m or member.disc_offsets is not None \
            or not member.counts_solves \
            or not member.plans_speed or member.kinematic:
        return None
    cfg = mpc.cfg
    return ("lateral_group", backend, cfg.horizon, cfg.max_obstacles, cfg.control_horizon)


class _RecordModels:
    """The models the group's prediction records keep (each at the log's sample time), one row
    each: the records hold their rows, and the model check reads ``Ad`` and the ``Bd``, ``Ed``
    columns of all of them stacked."""

    def __init__(self) -> None:
        self.models: list[Any] = []
        self._rows: dict[int, int] = {}

    def row(self, model: Any) -> int:
        row = self._rows.get(id(model))
        if row is None:
            row = self._rows[id(model)] = len(self.models)
            self.models.append(model)
        return row

    def stacked(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``Ad (U, 5, 5)``, ``Bd[:, 0] (U, 5)``, ``Ed[:, 0] (U, 5)`` of the ``U`` models."""
        if not self.models:
            return np.zeros((0, 5, 5)), np.zeros((0, 5)), np.zeros((0, 5))
        return (np.array([m.Ad for m in self.models], dtype=float),
                np.array([m.Bd[:, 0] for m in self.models], dtype=float),
                np.array([m.Ed[:, 0] for m in self.models], dtype=float))


class _MemberLookups:
    """What a member's step reads from caches of Python objects, by integer key: the
    prediction step of a slow-speed key, the lateral-velocity gain of a speed key, and the
    model (its condensed prediction's pack, Hessian and steady-state gains, the model its
    record keeps) of a mean-speed key and step."""

    def __init__(self, mpc: LateralMpc, direct: bool, table: _RecordModels) -> None:
        frame = mpc.frame
        self.direct, self.table = direct, table
        assert isinstance(frame, PathFrame)
        self.mpc, self.frame, self.bank = mpc, frame, frame.bank
        self.floor = frame.vehicle.min_model_speed_mps
        self.grid = frame.bank.model_cfg.speed_grid_mps
        self.steps: dict[int, float] = {}
        self.vy_gains: dict[int, float] = {}
        self.models: dict[tuple[int, float], tuple[Any, ...]] = {}

    def model_speed(self, key: int) -> float:
        """:func:`~pipeline.loop.model.model_speed_mps` of a speed whose grid index is
        ``key``."""
        return round(max(key * self.grid, self.floor), 6)

    def step(self, key: int) -> float:
        """:meth:`PathFrame.prediction_step` at a slower speed of grid index ``key`` (a
        speed on the grid is its own model speed)."""
        dt = self.steps.get(key)
        if dt is None:
            speed = self.model_speed(key)
            dt = self.steps[key] = self.frame.prediction_step(speed, speed)
        return dt

    def vy_gain(self, key: int) -> float:
        gain = self.vy_gains.get(key)
        if gain is None:
            bank = self.bank
            gain = self.vy_gains[key] = float(bank.gains(bank.at(self.model_speed(key)))[1])
        return gain

    def off_grid(self, speed_mps: float, speed_ref_mps: float) -> tuple[float, float]:
        """The prediction step and the vy gain of a measured speed whose grid index is no
        integer key (beyond about 1e14 m/s, or not a number), as
        :meth:`PathFrame.step_geometry` reads them (uncached)."""
        frame, bank = self.frame, self.bank
        speed = max(speed_mps, frame.vehicle.min_model_speed_mps)
        return (frame.prediction_step(speed, speed_ref_mps),
                float(bank.gains(bank.at(speed))[1]))

    def model_at(self, mean_mps: float, dt: float) -> tuple[Any, ...]:
        """:meth:`model` of a mean speed whose grid index is no integer key (uncached)."""
        return self._entry(self.bank.at(mean_mps, dt))

    def model(self, key: int, dt: float) -> tuple[Any, ...]:
        """``(pack address, hessian_u, steady-state gains, the record's model's row in the
        group's table, address of the clarabel_direct statement's pack or 0)``."""
        entry = self.models.get((key, dt))
        if entry is None:
            entry = self.models[(key, dt)] = self._entry(
                self.bank.at(self.model_speed(key), dt))
        return entry

    def _entry(self, model: Any) -> tuple[Any, ...]:
        """:meth:`model`'s entry of ``model``."""
        mpc = self.mpc
        prediction = mpc.prediction(model)
        record_model = model if model.sample_time_s == mpc.sample_time_s \
            else mpc.models.at_speed(model.speed_mps)
        direct = prediction.direct_pack.ctypes.data if self.direct else 0
        return (prediction.pack.ctypes.data, prediction.hessian_u, self.bank.gains(model),
                self.table.row(record_model), direct)


class LateralGroup:
    """Members of one :func:`group_key` stepped as arrays until each has ended.

    Parameters
    ----------
    members : sequence of MemberLoop
        Each freshly built (step 0 not yet observed).
    """

    def __init__(self, members: Sequence[Any]) -> None:
        self.members = list(members)
        n = len(self.members)
        first = self.members[0]
        mpc0 = first.controller
        self.kernels = first.kernels
        self.N, self.M, self.nc = mpc0.horizon, mpc0.cfg.max_obstacles, \
            mpc0.cfg.control_horizon
        N, M = self.N, self.M
        self.rows = max(m.scenario.n_steps for m in self.members) + 1
        J = max(max(m.scenario.n_obstacles for m in self.members), 1)
        R = self.rows
        #: ``daqp`` (the compiled calls solve) or ``clarabel_direct`` (each member's kept
        #: Clarabel solver between the compiled data and read-out)
        self.backend = group_key(first)[1]  # type: ignore[index]
        direct = self.backend == "clarabel_direct"
        self.record_models = _RecordModels()
        self.lookups = [_MemberLookups(m.controller, direct, self.record_models)
                        for m in self.members]
        #: the log's solver statuses by code (the fixed ones, then those met here)
        self.status_names = list(rows.STATUS_CODES)
        self.status_codes = {name: code for code, name in enumerate(self.status_names)}
        f = np.empty
        self.states = np.array([m.state for m in self.members], dtype=float).reshape(n, 7)
        self.sample_times = f(n)
        self.last_steps = np.empty(n, dtype=np.int64)
        self.lines, self.line_cos_sin = f((n, 5)), f((n, 2))
        self.goal_line_x, self.goal_tolerance, self.goals = f(n), f(n), f((n, 2))
        self.obstacle_starts, self.obstacle_velocities = np.zeros((n, J, 2)), np.zeros((n, J, 2))
        self.obstacle_radii, self.obstacle_appear = np.zeros((n, J)), np.zeros((n, J))
        self.n_obstacles = np.zeros(n, dtype=np.int64)
        self.plant_constants = np.array([m.batch_plant[0] for m in self.members], dtype=float)
        self.substeps = np.empty(n, dtype=np.int64)
        self.apf_settings = f((n, 17))
        self.nominal_speeds, self.speed_floors, self.grids = f(n), f(n), f(n)
        self.accel_max, self.time_constants, self.brake_max = f(n), f(n), f(n)
        self.extend, self.kappa = np.empty(n, dtype=np.bool_), f(n)
        self.reach, self.margins, self.activation = f(n), f(n), f(n)
        self.constrained = np.empty(n, dtype=np.bool_)
        self.rate_max = f(n)
        #: each member's kept DAQP workspace of every statement, by its obstacle slots
        self.workspaces = np.zeros((n, self.M + 1, 5), dtype=np.int64)
        self.blockings = f((n, self.nc, N))
        self.steering_max, self.iter_limits = f(n), np.empty(n, dtype=np.int64)
        for i, member in enumerate(self.members):
            scenario, mpc = member.scenario, member.controller
            vehicle, cfg = mpc.vehicle, mpc.cfg
            qp = mpc.qp
            self.sample_times[i], self.last_steps[i] = scenario.sample_time_s, scenario.n_steps
            origin_x, origin_y, c_line, s_line = member.line
            self.lines[i] = (origin_x, origin_y, c_line, s_line, member.frame.heading_rad)
            self.line_cos_sin[i] = member.frame.cos_sin
            self.goal_line_x[i], self.goal_tolerance[i] = member.goal_line_x, \
                scenario.goal_tolerance_m
            self.goals[i] = scenario.goal_m
            j = scenario.n_obstacles
            self.n_obstacles[i] = j
            self.obstacle_starts[i, :j] = scenario.obstacle_start_m
            self.obstacle_velocities[i, :j] = scenario.obstacle_velocity_mps
            self.obstacle_radii[i, :j] = scenario.obstacle_radius_m
            self.obstacle_appear[i, :j] = scenario.obstacle_appear_s
            self.substeps[i] = member.batch_plant[3]
            self.apf_settings[i] = [float(v) for v in apf_kernel_settings(member.planner.settings)]
            self.nominal_speeds[i] = float(scenario.speed_mps)
            self.speed_floors[i] = vehicle.min_model_speed_mps
            self.grids[i] = mpc.frame.bank.model_cfg.speed_grid_mps
            self.accel_max[i], self.time_constants[i] = vehicle.accel_max_mps2, \
                vehicle.speed_time_constant_s
            self.brake_max[i] = vehicle.braking_limit_mps2
            self.extend[i] = cfg.path_beyond_end == "extend"
            frame = mpc.frame
            assert isinstance(frame, PathFrame)
            self.kappa[i] = frame.curvature_limit_1_per_m()
            self.reach[i], self.margins[i] = vehicle.footprint_radius_m, cfg.safety_margin_m
            self.activation[i], self.constrained[i] = cfg.constraint_activation_m, \
                cfg.collision_constraints
            self.rate_max[i] = vehicle.steering_rate_max_rad_s
            self.blockings[i] = mpc.blocking
            if isinstance(qp, DaqpCondensedQp) and qp.native is not None:
                for slots, kept in mpc.qp_by_slots.items():
                    self.workspaces[i, slots, :4] = kept.native.addresses
                    self.workspaces[i, slots, 4] = kept.native.ready[0]
                self.steering_max[i], self.iter_limits[i] = qp.s.steering_max_rad, qp.max_iter
        native = getattr(mpc0.qp, "native", None)
        self.functions = native.functions.arguments if native is not None and not direct \
            else np.zeros(7, dtype=np.int64)
        self.offsets = np.asarray(pack_offsets(N, self.nc), dtype=np.int64)
        self.direct_offsets = np.asarray(direct_pack_offsets(N, self.nc), dtype=np.int64)
        self.theta_size = {slots: direct_theta_size(N, self.nc, slots) for slots in range(M + 1)}
        #: the Hessian each member's workspace of each statement holds (DAQP; None: none)
        self.held: list[list[Any]] = [
            [getattr(m.controller.qp_by_slots.get(slots), "_hessian_of", None)
             for slots in range(M + 1)] for m in self.members]
        # the loop's state and what it writes: the arrays by row (the log's and the records')
        # hold ROWS_AT_FIRST rows and grow as the runs go on (_ensure_rows), so that a long step
        # budget costs the rows run, not the rows allowed
        self.capacity = min(R, ROWS_AT_FIRST)
        C = self.capacity
        self.terminations = np.zeros(n, dtype=np.int64)
        self.log = np.full((n, C, rows.N_LOG_COLUMNS), np.nan)
        self.obstacle_log = np.full((n, C, J, 3), np.nan)
        self.visible_log = np.zeros((n, C, J), dtype=np.bool_)
        self.rollouts = np.zeros((n, C, N, 2))
        self.visible_positions, self.visible_velocities = f((n, J, 2)), f((n, J, 2))
        self.visible_radii, self.visible_counts = f((n, J)), np.zeros(n, dtype=np.int64)
        self.speed_keys = np.zeros((n, 2), dtype=np.int64)
        self.steps_s, self.vy_gains = np.zeros(n), np.zeros(n)
        self.last_plans, self.plan_ages = np.zeros((n, N)), np.zeros(n, dtype=np.int64)
        self.has_plan = np.zeros(n, dtype=np.bool_)
        self.plans_xy, self.plans_course = np.zeros((n, N + 1, 2)), np.zeros((n, N + 1))
        self.plan_lengths = np.zeros(n, dtype=np.int64)
        self.solve_times, self.n_solves = np.zeros((n, C)), np.zeros(n, dtype=np.int64)
        self.record_model_rows = np.zeros((n, C), dtype=np.int64)
        self.record_width = 0
        self.record_points, self.record_headings = np.zeros((n, C, 1, 2)), np.zeros((n, C, 1))
        self.record_curvature = np.zeros((n, C, 0))
        self.record_beyond = np.zeros((n, C, 0), dtype=np.bool_)
        self._grow_records(4 * N)
        self.record_sizes = np.zeros((n, C), dtype=np.int64)
        self.record_scalars = np.zeros((n, C, 3))
        self.record_stations, self.record_x0 = np.zeros((n, C, N + 1)), np.zeros((n, C, 5))
        self.record_r_d, self.record_plan = np.zeros((n, C, N)), np.zeros((n, C, N + 1))
        self.record_G, self.record_h = np.zeros((n, C, N, M)), np.zeros((n, C, N, M))
        self.record_xy = np.zeros((n, C, N + 1, 2))
        self.ended_at = np.full(n, -1, dtype=np.int64)

    def _ensure_rows(self, k: int) -> None:
        """The arrays by row long enough for row ``k`` (doubled, at most the group's rows)."""
        if k < self.capacity:
            return
        old = self.capacity
        self.capacity = min(max(2 * old, k + 1), self.rows)
        for name in _BY_ROW:
            array = getattr(self, name)
            fill = np.nan if name in ("log", "obstacle_log") else 0
            grown = np.full((array.shape[0], self.capacity) + array.shape[2:], fill,
                            dtype=array.dtype)
            grown[:, :old] = array
            setattr(self, name, grown)

    def _grow_records(self, width: int) -> None:
        """The record buffers of the paths wide enough for ``width`` intervals."""
        if width <= self.record_width:
            return
        n, R = len(self.members), self.capacity
        old = self.record_width
        grown = (np.zeros((n, R, width + 1, 2)), np.zeros((n, R, width + 1)),
                 np.zeros((n, R, width)), np.zeros((n, R, width), dtype=np.bool_))
        if old:
            grown[0][:, :, :old + 1] = self.record_points
            grown[1][:, :, :old + 1] = self.record_headings
            grown[2][:, :, :old] = self.record_curvature
            grown[3][:, :, :old] = self.record_beyond
        self.record_points, self.record_headings, self.record_curvature, \
            self.record_beyond = grown
        self.record_width = width

    def run(self) -> None:
        """Step every member until it has ended, then hand each its run
        (:meth:`_hand_over`)."""
        kernels = self.kernels
        active = np.arange(len(self.members), dtype=np.int64)
        k = 0
        while active.size:
            self._ensure_rows(k)
            going = kernels.observe_plan_rows(
                k, active, self.states, self.sample_times, self.last_steps, self.lines,
                self.goal_line_x, self.goal_tolerance, self.goals, self.obstacle_starts,
                self.obstacle_velocities, self.obstacle_radii, self.obstacle_appear,
                self.n_obstacles, self.plant_constants, self.apf_settings, self.N,
                self.nominal_speeds, self.speed_floors, self.grids, self.log,
                self.obstacle_log, self.visible_log, self.terminations, self.rollouts,
                self.visible_positions, self.visible_velocities, self.visible_radii,
                self.visible_counts, self.speed_keys)
            if going < active.size:
                ended = active[self.terminations[active] != 0]
                self.ended_at[ended] = k
                active = active[self.terminations[active] == 0]
            if not going:
                break
            self._step(k, active)
            k += 1
        stacked = self.record_models.stacked()
        for i, member in enumerate(self.members):
            self._hand_over(i, member, stacked)

    def _step(self, k: int, active: np.ndarray) -> None:
        """Step ``k`` of the members ``active`` after their observation."""
        kernels = self.kernels
        lookups, keys = self.lookups, self.speed_keys
        members = active.tolist()
        steps = []
        for i in members:
            lookup = lookups[i]
            slow, speed = keys[i].tolist()
            if slow < 0 or speed < 0:  # a speed off the grid's integer keys
                dt, gain = lookup.off_grid(float(self.states[i, 3]),
                                           float(self.nominal_speeds[i]))
            else:
                dt, gain = lookup.step(slow), lookup.vy_gain(speed)
            steps.append(dt)
            self.steps_s[i], self.vy_gains[i] = dt, gain
        (points, headings, curvature, beyond, frame, stations, r_d, vx, G, h, x0s, ds,
         n_intervals, mean_keys, means) = kernels.frame_rows(
            active, self.states, self.nominal_speeds, self.steps_s, self.speed_floors,
            self.accel_max, self.N, self.rollouts, k, self.line_cos_sin, self.lines,
            self.extend, self.kappa, self.vy_gains, self.time_constants, self.brake_max,
            self.plans_xy, self.plans_course, self.plan_lengths, self.visible_positions,
            self.visible_velocities, self.visible_radii, self.visible_counts, self.M,
            self.reach, self.margins, self.activation, self.constrained, self.grids, self.log)
        n = active.size
        packs, direct_packs = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
        gains = np.empty((n, 5))
        hessian_new = np.empty((n, self.M + 1), dtype=np.bool_)
        hessians = []
        held, record_rows = self.held, self.record_model_rows
        for r, (i, key, dt) in enumerate(zip(members, mean_keys.tolist(), steps, strict=True)):
            pack, hessian, model_gains, model_row, direct = lookups[i].model(key, dt) \
                if key >= 0 else lookups[i].model_at(float(means[r]), dt)
            packs[r], direct_packs[r], gains[r] = pack, direct, model_gains
            hessian_new[r] = [hessian is not kept for kept in held[i]]
            hessians.append(hessian)
            record_rows[i, k] = model_row
        if self.backend == "daqp":
            codes, iterations, ok, plans, predicted, slacks, plan_finite, solve_s = \
                self._daqp(active, members, packs, x0s, r_d, gains, G, h, hessian_new, hessians)
        else:
            codes, iterations, ok, plans, predicted, slacks, plan_finite, solve_s = \
                self._clarabel(active, members, packs, direct_packs, x0s, r_d, gains, G, h)
        self._grow_records(int(n_intervals.max()))
        kernels.apply_rows(
            k, active, self.N, self.states, x0s, codes, iterations, ok, plans, predicted,
            slacks, plan_finite, solve_s, self.last_plans, self.plan_ages, self.has_plan,
            self.sample_times, self.rate_max, points, headings, curvature, beyond, ds,
            n_intervals, stations, vx, self.plans_xy, self.plans_course, self.plan_lengths, r_d,
            G, h, self.steps_s, self.record_points, self.record_headings,
            self.record_curvature, self.record_beyond, self.record_sizes, self.record_scalars,
            self.record_stations, self.record_x0, self.record_r_d, self.record_plan,
            self.record_G, self.record_h, self.record_xy, self.solve_times, self.n_solves,
            self.plant_constants, self.substeps, self.log)

    def _daqp(self, active: np.ndarray, members: list[int], packs: np.ndarray,
              x0s: np.ndarray, r_d: np.ndarray, gains: np.ndarray, G: np.ndarray,
              h: np.ndarray, hessian_new: np.ndarray, hessians: list[Any]
              ) -> tuple[np.ndarray, ...]:
        """The step's QPs on the members' kept DAQP workspaces (one compiled call); each
        member's solve time is the call's time over the members it solved (what its share
        cost)."""
        start = time.perf_counter()
        exitflags, codes, iterations, ok, plans, predicted, slacks, plan_finite, used = \
            self.kernels.solve_rows(self.functions, self.workspaces, active, packs,
                                    self.offsets, self.nc, self.N, self.M, self.blockings, x0s,
                                    r_d, gains, G, h, self.steering_max, hessian_new,
                                    self.iter_limits)
        elapsed = time.perf_counter() - start
        flags = exitflags.tolist()
        solved = [flag != rows.NOT_SOLVED_FLAG for flag in flags]
        share = elapsed / max(sum(solved), 1)
        held = self.held
        for r, (i, flag, slots) in enumerate(zip(members, flags, used.tolist(), strict=True)):
            if flag == rows.NOT_SOLVED_FLAG or flag == rows.NON_FINITE_FLAG:
                continue
            if self.workspaces[i, slots, 4]:
                native = self.members[i].controller.qp_by_slots[slots].native
                if not native.ready[0]:  # set up on this step
                    native.ready[0] = 1
                    native.check_layout()
            held[i][slots] = None if flag == rows.SETUP_FAILED_FLAG else hessians[r]
        solve_s = np.where(solved, share, 0.0)
        return codes, iterations, ok, plans, predicted, slacks, plan_finite, solve_s

    def _clarabel(self, active: np.ndarray, members: list[int], packs: np.ndarray,
                  direct_packs: np.ndarray, x0s: np.ndarray, r_d: np.ndarray,
                  gains: np.ndarray, G: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, ...]:
        """The step's QPs on the members' kept Clarabel solvers (``clarabel_direct``): the
        parameter vectors in one compiled call, each member's solve of the statement of the
        slots it uses, the read-out in another call."""
        kernels, N, nc, M = self.kernels, self.N, self.nc, self.M
        chosen, thetas, used, frees, finite = kernels.theta_rows(
            active, packs, self.offsets, direct_packs, self.direct_offsets, nc, N, M,
            self.blockings, x0s, r_d, gains, G, h)
        n = active.size
        codes = np.full(n, rows.S_NOT_SOLVED, dtype=np.int64)
        iterations = np.full(n, -1, dtype=np.int64)
        ok, solve_s, Ws = np.zeros(n, dtype=np.bool_), np.zeros(n), np.zeros((n, nc))
        status_codes = self.status_codes
        for r, (i, solved, slots, good) in enumerate(zip(
                members, chosen.tolist(), used.tolist(), finite.tolist(), strict=True)):
            if not solved:
                continue
            qp = self.members[i].controller.qp_by_slots[slots]
            if good:
                solution = qp.compiled.solve(thetas[r, :self.theta_size[slots]])
            else:  # what DirectQp.solve answers to non-finite parameters, without its clock
                solution = QpSolution(NON_FINITE_DATA, -1, 0.0, None)
            code = status_codes.get(solution.status)
            if code is None:
                code = status_codes[solution.status] = len(self.status_names)
                self.status_names.append(solution.status)
            codes[r], iterations[r] = code, solution.iterations
            solve_s[r] = solution.solve_time_s
            if solution.ok:
                ok[r] = True
                Ws[r] = np.asarray(solution.value("W"), float).reshape(-1)
        plans, predicted, slacks, plan_finite = kernels.readout_rows(
            active, packs, self.offsets, direct_packs, self.direct_offsets, nc, N, M, Ws,
            self.blockings, x0s, frees, G, h)
        return codes, iterations, ok, plans, predicted, slacks, plan_finite, solve_s

    def _hand_over(self, i: int, member: Any,
                   models: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
        """Member ``i``'s run into its :class:`~pipeline.loop.engine.MemberLoop`: the log with
        its model check (:func:`~pipeline.loop.group_rows.check_rows` on ``models``, the
        record models' stacked matrices), the solve times, the termination, the state its
        loop leaves; the prediction records and the horizon record where it keeps one."""
        last = int(self.ended_at[i])
        member.log = log = self._log_of(i, member, last)
        self._model_check(i, member, last, log, models)
        member.termination = rows.TERMINATIONS[int(self.terminations[i])]
        member.state = self.states[i].copy()
        count = int(self.n_solves[i])
        member.solve_times[:count] = self.solve_times[i, :count]
        member.n_solves = count
        mpc = member.controller
        if isinstance(mpc.qp, DaqpCondensedQp):
            for slots, qp in mpc.qp_by_slots.items():
                qp.solved_with(self.held[i][slots])
        if member.planned is not None and last:
            # the explorer's view of each step's plan reads the records
            mpc.records = [self._record(i, k) for k in range(last)]
            # MemberLoop.plan's HorizonLog.put of each stepped row: the rollout, the
            # obstacles' velocities
            planned = member.planned
            planned.apf_path_m = np.full((planned.n_rows, self.N, 2), np.nan)
            planned.apf_path_m[:last] = self.rollouts[i, :last]
            planned.obstacle_velocity_mps[:last] = member.scenario.obstacle_velocity_mps

    def _model_check(self, i: int, member: Any, last: int, log: TrajectoryLog,
                     models: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
        """:func:`pipeline.loop.simulate._add_model_check` of member ``i`` from the group's
        arrays (its result then skips it)."""
        rows_logged = log.rows
        if rows_logged:
            mpc = member.controller
            ts = mpc.sample_time_s
            one, half = int(round(1.0 / ts)), int(round(0.5 / ts))
            columns = log.columns
            xy = np.ascontiguousarray(np.column_stack([columns["X_m"][:rows_logged],
                                                       columns["Y_m"][:rows_logged]]))
            psi = np.ascontiguousarray(columns["psi_rad"][:rows_logged], dtype=float)
            delta = np.ascontiguousarray(columns["delta_rad"][:rows_logged], dtype=float)
            which = self.record_model_rows[i, :last]
            Ad, Bd, Ed = models
            out = self.kernels.check_rows(
                self.record_points[i], self.record_headings[i], self.record_curvature[i],
                self.record_sizes[i], self.record_scalars[i], self.record_stations[i],
                self.record_x0[i], Ad[which], Bd[which], Ed[which], self.record_plan[i], last,
                xy, psi, delta, half, one, ts)
            for column, name in enumerate(MODEL_CHECK_COLUMNS):
                columns[name] = out[:, column]
        member.model_checked = True

    def _log_of(self, i: int, member: Any, last: int) -> TrajectoryLog:
        """Member ``i``'s log of rows ``0 .. last`` as :class:`TrajectoryLog` holds it (the
        obstacles' columns as views of one block per field; flags as booleans, statuses as
        words, NaN where nothing was logged; a run that ended at its first row has only that
        row's columns)."""
        n_rows = last + 1
        log = TrajectoryLog(member.scenario.n_steps + 1)
        size = log.n_rows
        J = member.scenario.n_obstacles
        if J:
            blocks = (np.full((size, J), np.nan), np.full((size, J), np.nan),
                      np.full((size, J), np.nan), np.zeros((size, J), dtype=bool))
            for f in range(3):
                blocks[f][:n_rows] = self.obstacle_log[i, :n_rows, :J, f]
            blocks[3][:n_rows] = self.visible_log[i, :n_rows, :J]
            for j, names in enumerate(member.obstacle_names):
                for name, block in zip(names, blocks, strict=True):
                    log.columns[name] = block[:, j]
            log._obstacle_blocks = blocks
        values = self.log[i]
        stepped = last > 0
        for c, name in enumerate(rows.LOG_COLUMNS):
            if not stepped and c not in _END_COLUMNS:
                continue
            column = values[:, c]
            if name == "path_beyond_limit":
                out = np.zeros(size, dtype=bool)
                out[:n_rows] = column[:n_rows] == 1.0
            elif name in TrajectoryLog.TEXT:
                out = np.full(size, np.nan, dtype=object)
                names = self.status_names if name == "solver_status" else \
                    rows.FALLBACK_CODES if name == "fallback" else None
                for k, value in enumerate(column[:n_rows].tolist()):
                    if value == value:  # logged
                        out[k] = names[int(value)] if names is not None else value == 1.0
            else:
                out = np.full(size, np.nan)
                out[:n_rows] = column[:n_rows]
            log.columns[name] = out
        log.rows = n_rows
        return log

    def _record(self, i: int, k: int) -> PredictionRecord:
        """Member ``i``'s prediction record of step ``k``
        (:meth:`~pipeline.loop.controller.lateral.LateralMpc.keep_record`)."""
        K = int(self.record_sizes[i, k])
        ds, dt, accepted = self.record_scalars[i, k].tolist()
        path = ReferencePath(self.record_points[i, k, :K + 1], self.record_headings[i, k, :K + 1],
                             self.record_curvature[i, k, :K], self.record_beyond[i, k, :K], ds)
        plan = self.record_plan[i, k] if accepted else None
        model = self.record_models.models[int(self.record_model_rows[i, k])]
        return PredictionRecord(("path", path, self.record_stations[i, k], dt),
                                self.record_x0[i, k], model,
                                self.record_r_d[i, k], plan, self.record_G[i, k],
                                self.record_h[i, k], self.record_xy[i, k] if accepted else None)


#: The group's arrays by row (:meth:`LateralGroup._ensure_rows`)
_BY_ROW = ("log", "obstacle_log", "visible_log", "rollouts", "solve_times", "record_model_rows",
           "record_points", "record_headings", "record_curvature", "record_beyond",
           "record_sizes", "record_scalars", "record_stations", "record_x0", "record_r_d",
           "record_plan", "record_G", "record_h", "record_xy")
#: The rows the group's arrays hold at first (a family run's are about 100 to 300)
ROWS_AT_FIRST = 512

#: The log columns of a run's last row (:func:`pipeline.loop.simulate._add_end_columns`): a run
#: that ends at its first step has no others
_END_COLUMNS = frozenset((rows.C_TIME, rows.C_X, rows.C_Y, rows.C_PSI, rows.C_EY, rows.C_EPSI,
                          rows.C_VX, rows.C_VY, rows.C_R, rows.C_DELTA, rows.C_SLIP,
                          rows.C_STATUS, rows.C_FALLBACK))
