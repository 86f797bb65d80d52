"""The lateral MPCs of many members stepped together: what the lockstep engine
(:mod:`pipeline.loop.engine`) runs each step for the members whose controller is the default
statement (path frame on the rollout itself, the half-planes' lateral-side rule, one disc, no
road; compiled kernels).

:func:`lateral_steps` is, for each member, :meth:`LateralMpc.step
<pipeline.loop.controller.lateral.LateralMpc.step>` with the path frame's arithmetic of all
members in one compiled call (:func:`~pipeline.loop.controller.path_rows.path_frame_rows`)
and the plans' poses in another (:func:`~pipeline.loop.controller.path_rows.plan_poses_rows`);
each member's state (its fallback, kept plan, records) stays in its own controller, and every
number is the one the member's own step gives (the same statements in the same order; the
tests hold the two equal bit for bit). Any other controller steps alone.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from math import isfinite
from typing import Any

import numpy as np

from pipeline.loop.controller.base import ControlStep, Observation
from pipeline.loop.controller.daqp_native import NON_FINITE_FLAG, SETUP_FAILED_FLAG
from pipeline.loop.controller.frames import PathFrame
from pipeline.loop.controller.lateral import LateralMpc
from pipeline.loop.controller.lateral_backends import CompiledCondensedQp, DaqpCondensedQp
from pipeline.loop.controller.lateral_qp import (
    CondensedPrediction,
    MpcInputs,
    direct_pack_offsets,
    direct_theta_size,
    pack_offsets,
)
from pipeline.loop.controller.path import ReferencePath
from pipeline.loop.controller.qp import NON_FINITE_DATA, DirectQp, QpSolution
from pipeline.loop.kernels import Kernels

__all__ = ["batch_key", "lateral_steps"]


def batch_key(controller: object, kernels: Kernels) -> tuple[Any, ...] | None:
    """The key of the members whose lateral MPCs :func:`lateral_steps` steps together (the
    same horizon and obstacle slots), or None where ``controller`` steps alone: another
    controller, a frame, path, reference or half-plane rule other than the default's, an ego
    of several discs, the road's rows, a steering bound by the speed, CPython's kernels."""
    if type(controller) is not LateralMpc or not kernels.compiled:
        return None
    frame, cfg = controller.frame, controller.cfg
    if type(frame) is not PathFrame or cfg.path_reference != "rollout" \
            or cfg.heading_reference != "path_slope" \
            or cfg.path_state_reference != "steady_state" or cfg.road_edge_weight is not None \
            or cfg.halfplane_normal != "lateral_side" or controller.vehicle.footprint_discs != 1 \
            or cfg.steering_friction_share is not None or cfg.horizon < 1:
        return None
    return ("lateral_rows", cfg.horizon, cfg.max_obstacles)


def lateral_steps(controllers: Sequence[LateralMpc], observations: Sequence[Observation],
                  kernels: Kernels) -> list[ControlStep]:
    """One step of each controller (all of one :func:`batch_key`) on its observation."""
    n = len(controllers)
    N = controllers[0].horizon
    M = controllers[0].cfg.max_obstacles
    # what each member's PathFrame.inputs computes before its kernels
    targets = np.empty((n, N, 2))
    line_cos_sin, extend = np.empty((n, 2)), np.empty(n, dtype=np.bool_)
    kappa, ds, speeds, speed_refs = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    vy_gains, steps_s, n_intervals = np.empty(n), np.empty(n), np.empty(n, dtype=np.int64)
    positions, time_constants, accel_max = np.empty((n, 2)), np.empty(n), np.empty(n)
    brake_max = np.empty(n)
    plans_xy, plans_course = np.zeros((n, N + 1, 2)), np.zeros((n, N + 1))
    plan_lengths = np.zeros(n, dtype=np.int64)
    reach, margins, activation = np.empty(n), np.empty(n), np.empty(n)
    constrained = np.empty(n, dtype=np.bool_)
    starts = np.zeros(n + 1, dtype=np.int64)
    obstacle_blocks, radius_blocks = [], []
    step_times = []
    for i, (mpc, obs) in enumerate(zip(controllers, observations, strict=True)):
        frame, vehicle, cfg = mpc.frame, mpc.vehicle, mpc.cfg
        assert isinstance(frame, PathFrame)
        st = obs.plant_state
        speed, dt, ds[i], n_intervals[i] = frame.step_geometry(obs)
        speed_ref = float(obs.speed_ref_mps)
        targets[i] = obs.rollout.path_m
        line_cos_sin[i] = obs.frame.cos_sin
        extend[i] = cfg.path_beyond_end == "extend"
        kappa[i] = frame.curvature_limit_1_per_m()
        speeds[i], speed_refs[i], steps_s[i] = speed, speed_ref, dt
        vy_gains[i] = float(frame.bank.gains(frame.bank.at(speed))[1])
        positions[i, 0], positions[i, 1] = float(st[0]), float(st[1])
        time_constants[i], accel_max[i] = vehicle.speed_time_constant_s, vehicle.accel_max_mps2
        brake_max[i] = vehicle.braking_limit_mps2
        poses = frame.last_plan_poses
        if poses is not None:
            length = poses[0].shape[0]
            plans_xy[i, :length], plans_course[i, :length] = poses[0], poses[1]
            plan_lengths[i] = length
        visible = obs.obstacles
        step_times.append(dt)
        if visible.radii_m.shape[0]:
            obstacle_blocks.append(
                visible.predicted_positions(frame.horizon_times(dt)).reshape(-1, 2))
            radius_blocks.append(visible.radii_m)
        starts[i + 1] = starts[i] + N * visible.radii_m.shape[0]
        reach[i], margins[i] = vehicle.footprint_radius_m, cfg.safety_margin_m
        activation[i], constrained[i] = cfg.constraint_activation_m, cfg.collision_constraints
    obstacles = np.ascontiguousarray(np.concatenate(obstacle_blocks)) if obstacle_blocks \
        else np.zeros((0, 2))
    radii = np.ascontiguousarray(np.concatenate(radius_blocks), dtype=float) \
        if radius_blocks else np.zeros(0)
    (points, headings, curvature, beyond, frame_values, stations, r_d, vx, obstacle_s,
     obstacle_d, G, h) = kernels.path_frame_rows(
        targets, line_cos_sin, extend, kappa, ds, n_intervals, positions, speeds, speed_refs,
        vy_gains, steps_s, N, time_constants, accel_max, brake_max, plans_xy, plans_course,
        plan_lengths, obstacles, starts, radii, M, reach, margins, activation, constrained)
    inputs_of, logs = [], []
    for i, (mpc, obs) in enumerate(zip(controllers, observations, strict=True)):
        inputs, log = _inputs(mpc, obs, i, points, headings, curvature, beyond, frame_values,
                              stations, r_d, vx, G, h, float(ds[i]), int(n_intervals[i]),
                              step_times[i])
        inputs_of.append(inputs)
        logs.append(log)
    steps: list[ControlStep | None] = [None] * n
    finite = [isfinite(sum(inputs.x0.tolist())) for inputs in inputs_of]
    native = [i for i, mpc in enumerate(controllers)
              if kernels.daqp_rows is not None and finite[i] and _native_daqp(mpc)]
    direct = [i for i, mpc in enumerate(controllers)
              if kernels.direct_theta_rows is not None and finite[i] and _direct(mpc)]
    for chosen, solve in ((native, _daqp_steps), (direct, _direct_steps)):
        if not chosen:
            continue
        for i, step in zip(chosen, _by_move_count(solve, [controllers[i] for i in chosen],
                                                  [inputs_of[i] for i in chosen],
                                                  [logs[i] for i in chosen], kernels),
                           strict=True):
            steps[i] = step
    for i, mpc in enumerate(controllers):
        if steps[i] is None:
            steps[i] = mpc.solve(inputs_of[i], logs[i])
    return _finish(controllers, inputs_of, [s for s in steps if s is not None], kernels)


def _finish(controllers: Sequence[LateralMpc], inputs_of: Sequence[MpcInputs],
            steps: list[ControlStep], kernels: Kernels) -> list[ControlStep]:
    """After the solves: the frames' plans (:func:`_after_steps`) and the records."""
    _after_steps(controllers, steps, kernels)
    for mpc, inputs, step in zip(controllers, inputs_of, steps, strict=True):
        mpc.keep_record(inputs, step.predicted_states[0] if step.predicted_states is not None
                        and step.fallback == "none" else None)
    return steps


def _inputs(mpc: LateralMpc, obs: Observation, i: int, points: np.ndarray,
            headings: np.ndarray, curvature: np.ndarray, beyond: np.ndarray,
            frame_values: np.ndarray, stations: np.ndarray, r_d: np.ndarray, vx: np.ndarray,
            G: np.ndarray, h: np.ndarray, ds: float, n_intervals: int, dt: float
            ) -> tuple[MpcInputs, dict[str, Any]]:
    """Member ``i``'s QP data from the batched arithmetic: its path (its rows of the padded
    arrays) and :meth:`~pipeline.loop.controller.frames.PathFrame.finish_inputs`."""
    frame = mpc.frame
    assert isinstance(frame, PathFrame)
    path = ReferencePath(points[i, :n_intervals + 1], headings[i, :n_intervals + 1],
                         curvature[i, :n_intervals], beyond[i, :n_intervals], ds)
    _, d0, heading0 = frame_values[i].tolist()
    return frame.finish_inputs(obs, path, dt, (d0, heading0), stations[i], r_d[i], vx[i],
                               G[i], h[i])


def _after_steps(controllers: Sequence[LateralMpc], steps: Sequence[ControlStep],
                 kernels: Kernels) -> None:
    """:meth:`PathFrame.after_step <pipeline.loop.controller.frames.PathFrame.after_step>` of
    every member, the plans' poses in one call."""
    solved = [i for i, step in enumerate(steps)
              if step.predicted_states is not None and step.fallback == "none"]
    frames = [mpc.frame for mpc in controllers]
    for frame in frames:
        assert isinstance(frame, PathFrame)
        frame.plan_poses(None)
    if not solved:
        return
    n = len(solved)
    widest = max(frames[i].record[1].n_intervals for i in solved)
    m = steps[solved[0]].predicted_states.shape[1]  # type: ignore[union-attr]
    points, headings = np.zeros((n, widest + 1, 2)), np.zeros((n, widest + 1))
    curvature, ds = np.zeros((n, widest)), np.empty(n)
    n_intervals = np.empty(n, dtype=np.int64)
    stations, lateral, heading_error = np.empty((n, m)), np.empty((n, m)), np.empty((n, m))
    vy, vx = np.empty((n, m)), np.empty((n, m))
    for row, i in enumerate(solved):
        frame = controllers[i].frame
        assert isinstance(frame, PathFrame)
        _, path, member_stations, _ = frame.record
        k = path.n_intervals
        points[row, :k + 1], headings[row, :k + 1] = path.points_m, path.headings_rad
        curvature[row, :k], ds[row], n_intervals[row] = path.curvature_1_per_m, path.ds_m, k
        states = steps[i].predicted_states
        assert states is not None
        stations[row], lateral[row], heading_error[row] = member_stations, states[0], states[2]
        vy[row], vx[row] = states[1], frame.predicted_speeds
    xy, course = kernels.plan_poses_rows(points, headings, curvature, ds, n_intervals,
                                         stations, lateral, heading_error, vy, vx)
    for row, i in enumerate(solved):
        frames[i].plan_poses((xy[row], course[row]))  # type: ignore[union-attr]


def _native_daqp(mpc: LateralMpc) -> bool:
    """Whether ``mpc`` solves on a kept native DAQP workspace (backend ``daqp``, the DAQP
    release whose structures we know, no road rows) with at least two moves and two steps
    (numpy's product of a one-row matrix is not BLAS's, so such a member steps alone)."""
    qp = mpc.qp
    return isinstance(qp, DaqpCondensedQp) and qp.native is not None \
        and qp.s.max_obstacles == mpc.cfg.max_obstacles and mpc.cfg.control_horizon >= 2 \
        and mpc.horizon >= 2


def _direct(mpc: LateralMpc) -> bool:
    """Whether ``mpc`` solves every statement on a kept Clarabel solver (backend
    ``clarabel_direct``) with at least two moves and two steps (as :func:`_native_daqp`: a
    horizon of one makes a one-row product too)."""
    return mpc.cfg.control_horizon >= 2 and mpc.horizon >= 2 and all(
        isinstance(qp, CompiledCondensedQp) and isinstance(qp.compiled, DirectQp)
        for qp in mpc.qp_by_slots.values())


def _by_move_count(solve: Callable[..., list[ControlStep]], controllers: Sequence[LateralMpc],
                   inputs_of: Sequence[MpcInputs], logs: Sequence[dict[str, Any]],
                   kernels: Kernels) -> list[ControlStep]:
    """``solve`` (:func:`_daqp_steps`, :func:`_direct_steps`) of ``controllers``, those of
    other move counts (a tune's trials) in calls of their own."""
    nc = controllers[0].cfg.control_horizon
    if all(mpc.cfg.control_horizon == nc for mpc in controllers):
        return solve(controllers, inputs_of, logs, kernels)
    groups: dict[int, list[int]] = {}
    for i, mpc in enumerate(controllers):
        groups.setdefault(mpc.cfg.control_horizon, []).append(i)
    out: list[ControlStep | None] = [None] * len(controllers)
    for members in groups.values():
        for i, step in zip(members, solve([controllers[i] for i in members],
                                          [inputs_of[i] for i in members],
                                          [logs[i] for i in members], kernels), strict=True):
            out[i] = step
    return [step for step in out if step is not None]


def _condensing_arrays(controllers: Sequence[LateralMpc], inputs_of: Sequence[MpcInputs],
                       predictions: Sequence[CondensedPrediction]) -> dict[str, np.ndarray]:
    """What the compiled callers read of each member (one move count): the address of its
    prediction's pack, its blocking, measured state, disturbance, references and half-planes
    (the arguments of :func:`~pipeline.loop.controller.daqp_rows.daqp_condensed_rows` by
    name)."""
    if any(prediction.steering_bound_rad is not None for prediction in predictions):
        # the compiled statements know the vehicle's steering bound alone (batch_key keeps a
        # member with controller.steering_friction_share out of the batches)
        raise RuntimeError("a member with a steering bound by friction in a compiled batch")
    n = len(controllers)
    first = controllers[0]
    N, nc, M = first.horizon, first.cfg.control_horizon, first.cfg.max_obstacles
    arrays = {"packs": np.empty(n, dtype=np.int64), "blockings": np.empty((n, nc, N)),
              "x0s": np.empty((n, 5)), "disturbances": np.empty((n, N)),
              "disturbed": np.empty(n, dtype=np.bool_), "y_refs": np.empty((n, N)),
              "psi_refs": np.empty((n, N)), "r_refs": np.zeros((n, N)),
              "has_r": np.zeros(n, dtype=np.bool_), "delta_refs": np.zeros((n, N)),
              "has_delta": np.zeros(n, dtype=np.bool_), "gains": np.empty((n, N, M)),
              "bounds": np.empty((n, N, M))}
    for i, (mpc, prediction, inputs) in enumerate(zip(controllers, predictions, inputs_of,
                                                      strict=True)):
        arrays["packs"][i] = prediction.pack.ctypes.data
        arrays["blockings"][i], arrays["x0s"][i] = mpc.blocking, inputs.x0
        arrays["disturbances"][i] = inputs.disturbance_rad_s
        arrays["disturbed"][i] = bool(np.count_nonzero(inputs.disturbance_rad_s))
        arrays["y_refs"][i], arrays["psi_refs"][i] = inputs.y_ref_m, inputs.psi_ref_rad
        if inputs.r_ref_rad_s is not None:
            arrays["r_refs"][i], arrays["has_r"][i] = inputs.r_ref_rad_s, True
        if inputs.delta_ref_rad is not None:
            arrays["delta_refs"][i], arrays["has_delta"][i] = inputs.delta_ref_rad, True
        arrays["gains"][i], arrays["bounds"][i] = inputs.constraint_gain, \
            inputs.constraint_bound
    return arrays


def _direct_steps(controllers: Sequence[LateralMpc], inputs_of: Sequence[MpcInputs],
                  logs: Sequence[dict[str, Any]], kernels: Kernels) -> list[ControlStep]:
    """:meth:`LateralMpc.solve <pipeline.loop.controller.lateral.LateralMpc.solve>` of each
    member (finite measured state, ``clarabel_direct``, one move count): the QP data of all
    of them in one compiled call (:func:`~pipeline.loop.controller.direct_rows.
    direct_theta_rows`), each member's kept Clarabel solver on the statement of the slots it
    uses (:meth:`~pipeline.loop.controller.qp.DirectQp.solve`), the read-out of all of them in
    another call."""
    assert kernels.direct_theta_rows is not None and kernels.direct_readout_rows is not None
    first = controllers[0]
    N, nc, M = first.horizon, first.cfg.control_horizon, first.cfg.max_obstacles
    predictions = [mpc.prediction(inputs.model) for mpc, inputs in
                   zip(controllers, inputs_of, strict=True)]
    arrays = _condensing_arrays(controllers, inputs_of, predictions)
    direct_packs = np.array([prediction.direct_pack.ctypes.data for prediction in predictions],
                            dtype=np.int64)
    offsets = np.asarray(pack_offsets(N, nc), dtype=np.int64)
    direct_offsets = np.asarray(direct_pack_offsets(N, nc), dtype=np.int64)
    thetas, used, frees, finite = kernels.direct_theta_rows(
        arrays["packs"], offsets, direct_packs, direct_offsets, nc, N, M, arrays["x0s"],
        arrays["disturbances"], arrays["disturbed"], arrays["y_refs"], arrays["psi_refs"],
        arrays["r_refs"], arrays["has_r"], arrays["delta_refs"], arrays["has_delta"],
        arrays["gains"], arrays["bounds"])
    solutions, Ws = [], np.zeros((len(controllers), nc))
    for i, mpc in enumerate(controllers):
        slots = int(used[i])
        qp = mpc.qp_by_slots[slots]
        assert isinstance(qp, CompiledCondensedQp) and isinstance(qp.compiled, DirectQp)
        if finite[i]:
            solution = qp.compiled.solve(thetas[i, :direct_theta_size(N, nc, slots)])
        else:  # what DirectQp.solve answers to non-finite parameters, without its clock
            solution = QpSolution(NON_FINITE_DATA, -1, 0.0, None)
        if solution.ok:
            Ws[i] = np.asarray(solution.value("W"), float).reshape(-1)
        solutions.append(solution)
    _, plans, states, slacks, plan_finite = kernels.direct_readout_rows(
        arrays["packs"], offsets, direct_packs, direct_offsets, nc, N, M, Ws,
        arrays["blockings"], arrays["x0s"], frees, arrays["gains"], arrays["bounds"])
    steps = []
    for i, (mpc, solution) in enumerate(zip(controllers, solutions, strict=True)):
        if solution.ok and plan_finite[i]:
            steps.append(mpc.accepted(plans[i], states[i], solution, float(slacks[i]),
                                      logs[i]))
        else:
            steps.append(mpc.fall_back(inputs_of[i], solution, logs[i]))
    return steps


def _daqp_steps(controllers: Sequence[LateralMpc], inputs_of: Sequence[MpcInputs],
                logs: Sequence[dict[str, Any]], kernels: Kernels) -> list[ControlStep]:
    """:meth:`LateralMpc.solve <pipeline.loop.controller.lateral.LateralMpc.solve>` of each
    member (finite measured state, native DAQP, one move count: :func:`_by_move_count`) with
    the condensing, DAQP's calls and the plan's read-out of all of them in one compiled call
    (:func:`~pipeline.loop.controller.daqp_rows.daqp_condensed_rows`); each member's solve
    time is the call's time over the members (what its share cost)."""
    assert kernels.daqp_rows is not None
    n = len(controllers)
    first = controllers[0]
    N, nc, M = first.horizon, first.cfg.control_horizon, first.cfg.max_obstacles
    predictions = [mpc.prediction(inputs.model) for mpc, inputs in
                   zip(controllers, inputs_of, strict=True)]
    arrays = _condensing_arrays(controllers, inputs_of, predictions)
    # each member's workspace of every statement (by its slots: LateralMpc.qp_for's choice is
    # made in the compiled call)
    workspaces = np.empty((n, M + 1, 5), dtype=np.int64)
    steering_max, hessian_new = np.empty(n), np.empty((n, M + 1), dtype=np.bool_)
    iter_limits = np.empty(n, dtype=np.int64)
    for i, (mpc, prediction) in enumerate(zip(controllers, predictions, strict=True)):
        for slots, qp in mpc.qp_by_slots.items():
            assert isinstance(qp, DaqpCondensedQp) and qp.native is not None
            workspaces[i, slots, :4] = qp.native.addresses
            workspaces[i, slots, 4] = qp.native.ready[0]
            hessian_new[i, slots] = not qp.holds_hessian(prediction.hessian_u)
        steering_max[i] = mpc.qp.s.steering_max_rad  # type: ignore[attr-defined]
        iter_limits[i] = mpc.qp.max_iter  # type: ignore[attr-defined]
    first_qp = first.qp
    assert isinstance(first_qp, DaqpCondensedQp) and first_qp.native is not None
    functions = first_qp.native.functions.arguments
    start = time.perf_counter()
    exitflags, iterations, _, plans, states, slacks, plan_finite, used = kernels.daqp_rows(
        functions, workspaces, arrays["packs"], np.asarray(pack_offsets(N, nc), dtype=np.int64),
        nc, N, M, arrays["blockings"], arrays["x0s"], arrays["disturbances"],
        arrays["disturbed"], arrays["y_refs"], arrays["psi_refs"], arrays["r_refs"],
        arrays["has_r"], arrays["delta_refs"], arrays["has_delta"], arrays["gains"],
        arrays["bounds"], steering_max, hessian_new, iter_limits)
    share = (time.perf_counter() - start) / n
    steps = []
    for i, (mpc, prediction, inputs, slots) in enumerate(zip(
            controllers, predictions, inputs_of, used.tolist(), strict=True)):
        qp = mpc.qp_by_slots[slots]
        assert isinstance(qp, DaqpCondensedQp) and qp.native is not None
        flag = int(exitflags[i])
        if flag == NON_FINITE_FLAG:  # not solved, the workspace untouched
            solution = QpSolution(NON_FINITE_DATA, -1, share, None)
        else:
            if workspaces[i, slots, 4] and not qp.native.ready[0]:  # set up on this step
                qp.native.ready[0] = 1
                qp.native.check_layout()
            failed = flag == SETUP_FAILED_FLAG
            qp.solved_with(None if failed else prediction.hessian_u)
            status = "solver_error" if failed else qp.STATUS.get(flag, "solver_error")
            solution = QpSolution(status, -1 if failed else int(iterations[i]), share,
                                  {} if status == "optimal" else None)
        if solution.ok and plan_finite[i]:
            steps.append(mpc.accepted(plans[i], states[i], solution, float(slacks[i]),
                                      logs[i]))
        else:
            steps.append(mpc.fall_back(inputs, solution, logs[i]))
    return steps

