"""Simulation stage: the closed loop APF -> MPC -> nonlinear plant, logged step by step.

Each step k (time ``t = k Ts``): visible obstacles are read from the scenario; the velocity
planner picks ``V_r``; the APF rolls a path out from the vehicle's position; the path becomes the
MPC's lateral and heading references at its predicted stations and its avoidance vectors orient
the soft half-planes; the MPC's first steering rate drives the nonlinear plant for ``Ts``.
The run ends after ``n_steps`` or when the vehicle reaches the goal line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from pipeline.config import ExperimentConfig
from pipeline.controller import (KinematicLtvMpc, LateralMpc, MpcInputs, MpcStep,
                                 collision_halfplanes,
                                 force_heading_reference, lateral_reference,
                                 pure_pursuit_steering_rate)
from pipeline.model import LateralModelCache, kinematic_plant_step, step_plant
from pipeline.planner import apf_rollout, plan_speed
from pipeline.scenario import ObstacleSnapshot, Scenario


@dataclass(frozen=True)
class SimulationResult:
    """Logged closed-loop run.

    Attributes
    ----------
    trajectory : pandas.DataFrame
        One row per step (see :func:`simulate` for the columns).
    solve_times_s : ndarray
        Wall time of each QP solve (not part of the deterministic log).
    compile_count : int
        Number of times CVXPY compiled the problem (1 expected).
    compile_time_s : float
    goal_reached : bool
    termination : str
        ``"goal_line"``, ``"max_steps"`` or ``"non_finite_state"``.
    """

    trajectory: pd.DataFrame
    solve_times_s: np.ndarray
    compile_count: int
    compile_time_s: float
    goal_reached: bool
    termination: str


def _wrap(angle_rad: float) -> float:
    return float(np.arctan2(np.sin(angle_rad), np.cos(angle_rad)))


def obstacle_columns(snap: ObstacleSnapshot, position_m: np.ndarray,
                     vehicle_radius_m: float) -> tuple[dict, float]:
    """Per-obstacle log columns of a snapshot and the clearance to the nearest visible one."""
    cols: dict = {}
    clearance = np.inf
    for j in range(snap.radii_m.shape[0]):
        cols[f"obs{j}_x_m"] = snap.positions_m[j, 0]
        cols[f"obs{j}_y_m"] = snap.positions_m[j, 1]
        cols[f"obs{j}_radius_m"] = snap.radii_m[j]
        cols[f"obs{j}_visible"] = bool(snap.visible[j])
        if snap.visible[j]:
            gap = (np.linalg.norm(position_m - snap.positions_m[j]) - snap.radii_m[j]
                   - vehicle_radius_m)
            clearance = min(clearance, gap)
    return cols, (float(clearance) if np.isfinite(clearance) else np.nan)


def _termination(state: np.ndarray, along_line_m: float, goal_line_x_m: float,
                 scenario: Scenario, step: int) -> str | None:
    """Why the run ends at this step, or None: non-finite state, goal line, last step."""
    if not np.all(np.isfinite(state)):
        return "non_finite_state"
    if along_line_m >= goal_line_x_m - scenario.goal_tolerance_m:
        return "goal_line"
    return "max_steps" if step == scenario.n_steps else None


def _apf_columns(rollout) -> dict:
    n = rollout.path_m.shape[0]
    f_att = rollout.attraction[0] if n > 1 else np.zeros(2)
    f_rep = rollout.repulsion[0] if n > 1 else np.zeros(2)
    next_point = rollout.path_m[1] if n > 1 else rollout.path_m[0]
    return {"apf_next_x_m": next_point[0], "apf_next_y_m": next_point[1],
            "apf_end_x_m": rollout.path_m[-1, 0], "apf_end_y_m": rollout.path_m[-1, 1],
            "apf_att_x": f_att[0], "apf_att_y": f_att[1],
            "apf_rep_x": f_rep[0], "apf_rep_y": f_rep[1],
            "apf_rep_norm": float(np.linalg.norm(f_rep)),
            "apf_step_capped": bool(rollout.step_cap_active.any()),
            "apf_step_min_used": bool(rollout.step_min_active.any())}


def simulate(cfg: ExperimentConfig, scenario: Scenario) -> SimulationResult:
    """Run the closed loop once.

    Parameters
    ----------
    cfg : ExperimentConfig
    scenario : Scenario

    Returns
    -------
    SimulationResult
        The trajectory has columns ``time_s``, plant states (``X_m, Y_m, psi_rad, vx_mps,
        vy_mps, r_rad_s, delta_rad``), line-frame errors (``e_y_m, e_psi_rad``), the applied input
        ``steering_rate_rad_s``, ``speed_ref_mps``, the references (``y_ref_m, psi_ref_rad``),
        the APF's next point and forces at the vehicle (``apf_*``), per-obstacle columns
        (``obs{j}_x_m, obs{j}_y_m, obs{j}_radius_m, obs{j}_visible``), ``clearance_m`` (smallest
        centre distance minus both radii over visible obstacles) and solver columns
        (``solver_status, solver_iterations, fallback, max_slack_m``).
    """
    if cfg.controller.kind == "kinematic_mpc":
        return simulate_kinematic(cfg, scenario)
    vehicle, planner, ctrl = cfg.vehicle, cfg.planner, cfg.controller
    ts = scenario.sample_time_s
    N = ctrl.horizon
    frame = scenario.line_frame
    goal_line_x = float(frame.to_line(scenario.goal_m)[0])
    cache = LateralModelCache(vehicle, ts, ctrl.b2_heading_entry, ctrl.speed_grid_mps)
    mpc = LateralMpc(ctrl, vehicle) if ctrl.kind == "mpc" else None
    state = np.array([scenario.start_m[0], scenario.start_m[1], scenario.start_heading_rad,
                      scenario.initial_speed_mps, 0.0, 0.0, 0.0])
    rows: list[dict] = []
    solve_times: list[float] = []
    termination = "max_steps"
    steps_ahead_s = np.arange(1, N + 1) * ts
    n_obs = scenario.n_obstacles

    for k in range(scenario.n_steps + 1):
        time_s = k * ts
        position = state[:2].copy()
        line_pos = frame.to_line(position)
        e_psi = _wrap(state[2] - frame.heading_rad)
        snapshot = scenario.obstacles_at(time_s)
        obs_cols, clearance = obstacle_columns(snapshot, state[:2], vehicle.footprint_radius_m)
        row = {"time_s": time_s, "X_m": state[0], "Y_m": state[1], "psi_rad": state[2],
               "vx_mps": state[3], "vy_mps": state[4], "r_rad_s": state[5],
               "delta_rad": state[6], "e_y_m": line_pos[1], "e_psi_rad": e_psi}
        ending = _termination(state, line_pos[0], goal_line_x, scenario, k)
        if ending is not None:
            termination = ending
            rows.append({**row, **obs_cols, "clearance_m": clearance, "fallback": "end",
                         "solver_status": "end"})
            break
        visible = snapshot.only_visible()
        velocity = np.array([state[3] * np.cos(state[2]) - state[4] * np.sin(state[2]),
                             state[3] * np.sin(state[2]) + state[4] * np.cos(state[2])])
        speed_ref = plan_speed(position, state[2], visible, scenario.speed_mps,
                               vehicle.footprint_radius_m, ctrl)
        rollout = apf_rollout(position, scenario.goal_m, visible, planner, N, ts, velocity)
        model = cache.at_speed(speed_ref)
        stations = line_pos[0] + model.speed_mps * steps_ahead_s
        path_line = frame.to_line(rollout.path_m)
        y_ref, psi_ref = lateral_reference(path_line, stations, ctrl)
        force_line = frame.vectors_to_line(rollout.attraction[0] + rollout.repulsion[0]) \
            if N > 1 else np.array([1.0, 0.0])
        if ctrl.heading_reference == "apf_force":
            psi_ref = force_heading_reference(force_line, e_psi, N, ts, ctrl)
        predicted = frame.to_line(visible.predicted_positions(np.concatenate([[0.0],
                                                                              steps_ahead_s])))
        G, h = collision_halfplanes(stations, y_ref, line_pos, predicted[1:], visible.radii_m,
                                    vehicle, ctrl)
        x0 = np.array([line_pos[1], state[4], e_psi, state[5], state[6]])
        if mpc is not None:
            step = mpc.step(MpcInputs(x0, model, y_ref, psi_ref, G, h, np.zeros(N)))
            solve_times.append(step.solve_time_s)
        else:
            rate = pure_pursuit_steering_rate(path_line, line_pos, e_psi, state[6], state[3],
                                              vehicle, ctrl, ts)
            step = MpcStep(rate, np.full(N, rate), None, "pure_pursuit", 0, 0.0, "none", 0.0)
        rows.append({**row, "steering_rate_rad_s": step.steering_rate_rad_s,
                     "speed_ref_mps": speed_ref, "y_ref_m": y_ref[0], "psi_ref_rad": psi_ref[0],
                     **_apf_columns(rollout), **obs_cols, "clearance_m": clearance,
                     "solver_status": step.status, "solver_iterations": step.iterations,
                     "fallback": step.fallback, "max_slack_m": step.max_slack_m})
        state = step_plant(state, step.steering_rate_rad_s, speed_ref, vehicle, ts,
                           scenario.plant_substeps)

    trajectory = pd.DataFrame(rows)
    return SimulationResult(trajectory, np.asarray(solve_times),
                            mpc.compile_count if mpc is not None else 0,
                            mpc.compile_time_s if mpc is not None else 0.0,
                            termination == "goal_line", termination)


def simulate_kinematic(cfg: ExperimentConfig, scenario: Scenario) -> SimulationResult:
    """Appendix A's loop: APF rollout -> kinematic LTV-MPC -> exact kinematic plant.

    The reference handed to the MPC is the APF's time-indexed path ``y_ref = [p_1; ...; p_Np]``
    (as ``nlmpcmove`` receives it); the log has the same columns as :func:`simulate` with
    ``vx_mps`` the speed, ``vy_mps = 0``, ``r_rad_s = v tan(delta) / L``, ``delta_rad`` the
    steering input applied over the step and ``accel_mps2`` the acceleration input.
    """
    vehicle, planner, ctrl = cfg.vehicle, cfg.planner, cfg.controller
    ts, N = scenario.sample_time_s, ctrl.horizon
    frame = scenario.line_frame
    goal_line_x = float(frame.to_line(scenario.goal_m)[0])
    mpc = KinematicLtvMpc(ctrl, vehicle, ts)
    L = vehicle.wheelbase_m
    state = np.array([scenario.start_m[0], scenario.start_m[1], scenario.start_heading_rad,
                      scenario.initial_speed_mps])
    u_prev = np.zeros(2)
    rows: list[dict] = []
    solve_times: list[float] = []
    termination = "max_steps"
    steps_ahead_s = np.arange(1, N + 1) * ts
    for k in range(scenario.n_steps + 1):
        time_s = k * ts
        position = state[:2].copy()
        line_pos = frame.to_line(position)
        e_psi = _wrap(state[2] - frame.heading_rad)
        snapshot = scenario.obstacles_at(time_s)
        obs_cols, clearance = obstacle_columns(snapshot, position, vehicle.footprint_radius_m)
        row = {"time_s": time_s, "X_m": state[0], "Y_m": state[1], "psi_rad": state[2],
               "vx_mps": state[3], "vy_mps": 0.0, "e_y_m": line_pos[1], "e_psi_rad": e_psi}
        ending = _termination(state, line_pos[0], goal_line_x, scenario, k)
        if ending is not None:
            termination = ending
            rows.append({**row, "delta_rad": u_prev[1],
                         "r_rad_s": state[3] * np.tan(u_prev[1]) / L, **obs_cols,
                         "clearance_m": clearance, "fallback": "end", "solver_status": "end"})
            break
        visible = snapshot.only_visible()
        velocity = state[3] * np.array([np.cos(state[2]), np.sin(state[2])])
        rollout = apf_rollout(position, scenario.goal_m, visible, planner, N, ts, velocity)
        rows_index = np.arange(N) if ctrl.reference_alignment == "literal" \
            else np.minimum(np.arange(1, N + 1), N - 1)
        reference = rollout.path_m[rows_index].T
        predicted = visible.predicted_positions(steps_ahead_s)
        step = mpc.step(state, u_prev, reference, predicted, visible.radii_m)
        solve_times.append(step.solve_time_s)
        u = step.control_input
        ref_line = frame.to_line(reference[:, 0])
        rows.append({**row, "delta_rad": u[1], "r_rad_s": state[3] * np.tan(u[1]) / L,
                     "steering_rate_rad_s": (u[1] - u_prev[1]) / ts, "accel_mps2": u[0],
                     "speed_ref_mps": np.nan, "y_ref_m": ref_line[1], "psi_ref_rad": np.nan,
                     **_apf_columns(rollout), **obs_cols, "clearance_m": clearance,
                     "solver_status": step.status, "solver_iterations": step.iterations,
                     "fallback": step.fallback, "max_slack_m": step.max_slack_m,
                     "ltv_passes": step.ltv_passes, "ltv_change": step.ltv_change})
        state = kinematic_plant_step(state, u, L, ts, scenario.plant_substeps)
        u_prev = u
    return SimulationResult(pd.DataFrame(rows), np.asarray(solve_times), mpc.compile_count,
                            mpc.compile_time_s, termination == "goal_line", termination)
