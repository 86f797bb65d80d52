"""Simulation stage: one closed loop for every controller, do-mpc style, logged step by step.

Each step k (time ``t = k Ts``)::

    obstacles = scenario.obstacles_at(t)            # one snapshot per step
    V_r       = plan_speed(...)                     # velocity planning (planner settings)
    rollout   = apf_rollout(...)                    # the APF's reference path
    step      = controller.step(observation)        # lateral MPC, kinematic MPC, pure pursuit
    x         = plant.step(x, step.command, V_r)    # nonlinear single-track or kinematic plant

The run ends after ``n_steps`` or when the vehicle reaches the goal line. The log is written
into preallocated arrays, handed over as one table of arrays at the end (a DataFrame when
asked for).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from math import atan2, cos, isfinite, sin, sqrt
from typing import Any

import numpy as np
import pandas as pd

from pipeline.loop.controller import Controller, ControlStep, QpCache, make_controller
from pipeline.loop.controller.prediction_check import MODEL_CHECK_COLUMNS
from pipeline.loop.kernels import Kernels
from pipeline.loop.model import kinematic_plant_step, single_track_constants
from pipeline.loop.planner import ApfPlanner, ApfRollout, make_planner
from pipeline.loop.python_kernels import PYTHON_KERNELS
from pipeline.loop.scenario import LineFrame, ObstacleSnapshot, Scenario
from pipeline.loop.settings import LoopSettings
from pipeline.loop.trajectory import TrajectoryTable


@dataclass(frozen=True)
class SimulationResult:
    """Logged closed-loop run.

    Attributes
    ----------
    table : TrajectoryTable
        One row per step (see :func:`simulate` for the columns), as arrays: what the metrics
        and the trajectory file read.
    solve_times_s : ndarray
        Wall time of each QP solve (not part of the deterministic log).
    compile_count : int
        Compilations this run caused (0 when the QP came from the cache).
    compile_time_s : float
    goal_reached : bool
    termination : str
        ``"goal_line"``, ``"max_steps"`` or ``"non_finite_state"``.
    horizon : dict of str to ndarray
        What each step planned (:mod:`pipeline.loop.horizon`; one row per trajectory row),
        for the report's scenario explorer.
    """

    table: TrajectoryTable
    solve_times_s: np.ndarray
    compile_count: int
    compile_time_s: float
    goal_reached: bool
    termination: str
    horizon: dict[str, np.ndarray] = field(default_factory=dict)

    @cached_property
    def trajectory(self) -> pd.DataFrame:
        """:attr:`table` as a pandas DataFrame, built when first asked for (a tune's training
        member, whose metrics alone are kept, never builds it)."""
        return self.table.to_frame()


class SingleTrackPlant:
    """The nonlinear single-track plant of the lateral track; command ``[steering rate]``."""

    def __init__(self, cfg: LoopSettings, scenario: Scenario,
                 kernels: Kernels | None = None) -> None:
        self.vehicle, self.ts, self.substeps = cfg.vehicle, scenario.sample_time_s, \
            scenario.plant_substeps
        self.rate_max_rad_s = cfg.vehicle.steering_rate_max_rad_s
        kernels = kernels if kernels is not None else PYTHON_KERNELS
        # model.single_track_rk4 by the kernels: plain floats in for CPython (what step_plant
        # calls), arrays for numba; the same bits
        self.compiled = kernels.compiled
        self._kernel = kernels.plant_rk4
        constants = single_track_constants(cfg.vehicle)
        #: single_track_constants as the kernels take them (an array compiled, a tuple in CPython)
        self.constants = np.array(constants) if kernels.compiled else constants
        self._tyres = (constants[2], constants[3], constants[4], constants[5], constants[6],
                       constants[7])

    @staticmethod
    def initial_state(scenario: Scenario) -> np.ndarray:
        return np.array([scenario.start_m[0], scenario.start_m[1], scenario.start_heading_rad,
                         scenario.initial_speed_mps, 0.0, 0.0, 0.0])

    @staticmethod
    def velocity(state: np.ndarray) -> np.ndarray:
        c, s = cos(state[2]), sin(state[2])
        return np.array([state[3] * c - state[4] * s, state[3] * s + state[4] * c])

    def log_columns(self, state: np.ndarray, command: np.ndarray | None,
                    previous: np.ndarray | None) -> dict[str, Any]:
        return {"vx_mps": state[3], "vy_mps": state[4], "r_rad_s": state[5],
                "delta_rad": state[6], "tyre_slip_norm": tyre_slip_norm(state, self._tyres)}

    def step(self, state: np.ndarray, command: np.ndarray, speed_ref_mps: float) -> np.ndarray:
        """:func:`~pipeline.loop.model.step_plant` with this plant's constants hoisted."""
        rate_max = self.rate_max_rad_s
        rate = min(max(float(command[0]), -rate_max), rate_max)
        return self._kernel(state if self.compiled else state.tolist(), self.constants, rate,
                            float(speed_ref_mps), self.ts, self.substeps)


def tyre_slip_norm(state: np.ndarray, tyres: tuple[Any, ...]) -> float:
    """The larger of the two axles' ``C alpha / (mu Fz)``: how far into its tanh law a tyre
    is (0: no slip; the force falls 5 % short of the linear law at about 0.39).

    ``tyres`` is ``(a, b, C_f, C_r, mu Fz_f, mu Fz_r)``; slip angles as the plant computes
    them."""
    a, b, cf, cr, lim_f, lim_r = tyres
    vx, vy, r, delta = float(state[3]), float(state[4]), float(state[5]), float(state[6])
    vx = vx if vx > 0.1 else 0.1
    front = abs(cf * (delta - atan2(vy + a * r, vx)) / lim_f)
    rear = abs(cr * atan2(vy - b * r, vx) / lim_r)
    return front if front > rear else rear


class KinematicPlant:
    """Appendix A's kinematic bicycle, integrated exactly; command ``[a, delta]``."""

    def __init__(self, cfg: LoopSettings, scenario: Scenario) -> None:
        self.L, self.ts, self.substeps = cfg.vehicle.wheelbase_m, scenario.sample_time_s, \
            scenario.plant_substeps

    @staticmethod
    def initial_state(scenario: Scenario) -> np.ndarray:
        return np.array([scenario.start_m[0], scenario.start_m[1], scenario.start_heading_rad,
                         scenario.initial_speed_mps])

    @staticmethod
    def velocity(state: np.ndarray) -> np.ndarray:
        return state[3] * np.array([cos(state[2]), sin(state[2])])

    def log_columns(self, state: np.ndarray, command: np.ndarray | None,
                    previous: np.ndarray | None) -> dict[str, Any]:
        # the steering angle is an input here: the one applied over the step (or the last one)
        applied = command if command is not None else previous
        if applied is None:
            raise ValueError("no steering applied yet: neither this step's command nor a "
                             "previous one")
        delta = applied[1]
        return {"vx_mps": state[3], "vy_mps": 0.0, "r_rad_s": state[3] * np.tan(delta) / self.L,
                "delta_rad": delta}

    def step(self, state: np.ndarray, command: np.ndarray, speed_ref_mps: float) -> np.ndarray:
        return kinematic_plant_step(state, command, self.L, self.ts, self.substeps)


class TrajectoryLog:
    """Preallocated per-column arrays, one row per step, handed over once as a
    :class:`~pipeline.loop.trajectory.TrajectoryTable`.

    Float columns start as NaN; text and flag columns hold NaN where nothing was logged
    (written as empty cells).
    """

    TEXT = ("solver_status", "fallback", "apf_step_capped", "apf_step_min_used")

    def __init__(self, n_rows: int) -> None:
        self.n_rows = n_rows
        self.columns: dict[str, np.ndarray] = {}
        self.rows = 0
        #: the obstacles' columns as blocks, one column per obstacle (:meth:`put_obstacles`)
        self._obstacle_blocks: tuple[np.ndarray, ...] | None = None

    def put_obstacles(self, k: int, names: list[tuple[Any, ...]], positions_m: np.ndarray,
                      radii_m: np.ndarray, visible: np.ndarray) -> None:
        """Row ``k``'s obstacle columns (``names[j]``: obstacle ``j``'s x, y, radius and
        visibility columns), one assignment per field for every obstacle: the columns are
        views of one block per field (among walkers, 50 obstacles are 200 columns)."""
        blocks = self._obstacle_blocks
        if blocks is None:
            n = len(names)
            blocks = (np.full((self.n_rows, n), np.nan), np.full((self.n_rows, n), np.nan),
                      np.full((self.n_rows, n), np.nan), np.zeros((self.n_rows, n), dtype=bool))
            for j, column_names in enumerate(names):
                for name, block in zip(column_names, blocks, strict=True):
                    self.columns[name] = block[:, j]
            self._obstacle_blocks = blocks
        n = positions_m.shape[0]
        if n > blocks[0].shape[1] or radii_m.shape[0] != n or visible.shape[0] != n:
            raise ValueError(f"{n} obstacles logged where the log has {blocks[0].shape[1]}")
        xs, ys, radii, seen = blocks
        xs[k, :n], ys[k, :n] = positions_m[:, 0], positions_m[:, 1]
        radii[k, :n], seen[k, :n] = radii_m, visible
        self.rows = max(self.rows, k + 1)

    def put(self, k: int, values: dict[str, Any]) -> None:
        columns = self.columns
        for name, value in values.items():
            column = columns.get(name)
            if column is None:
                if name in self.TEXT:
                    column = np.full(self.n_rows, np.nan, dtype=object)
                elif isinstance(value, (bool, np.bool_)):
                    column = np.zeros(self.n_rows, dtype=bool)
                else:
                    column = np.full(self.n_rows, np.nan)
                columns[name] = column
            column[k] = value
        self.rows = max(self.rows, k + 1)

    def table(self, order: list[str]) -> TrajectoryTable:
        """The logged rows, the columns of ``order`` first (in that order), then the others
        in the order they were first logged; the arrays are views of the log's."""
        names = [c for c in order if c in self.columns] \
            + [c for c in self.columns if c not in order]
        return TrajectoryTable({c: self.columns[c][:self.rows] for c in names}, self.rows)


def _apf_columns(rollout: ApfRollout) -> dict[str, Any]:
    n = rollout.path_m.shape[0]
    if n > 1:
        (ax, ay), (rx, ry) = rollout.attraction[0].tolist(), rollout.repulsion[0].tolist()
        nx, ny = rollout.path_m[1].tolist()
    else:
        ax = ay = rx = ry = 0.0
        nx, ny = rollout.path_m[0].tolist()
    ex, ey = rollout.path_m[-1].tolist()
    # counts, not .any()/.mean(): the same values without a ufunc reduction each
    capped, steps = int(np.count_nonzero(rollout.step_cap_active)), rollout.step_cap_active.size
    return {"apf_next_x_m": nx, "apf_next_y_m": ny, "apf_end_x_m": ex, "apf_end_y_m": ey,
            "apf_att_x": ax, "apf_att_y": ay, "apf_rep_x": rx, "apf_rep_y": ry,
            "apf_rep_norm": sqrt(rx * rx + ry * ry),
            "apf_step_capped": capped > 0,
            "apf_step_min_used": bool(np.count_nonzero(rollout.step_min_active)),
            "apf_step_cap_share": capped / steps if steps else 0.0}


def run_kernels(qp_cache: QpCache | None) -> Kernels:
    """The kernels a run uses: compiled where the runner of many runs asked for them
    (:attr:`QpCache.compiled_kernels <pipeline.loop.controller.qp.QpCache>`), else CPython's."""
    if qp_cache is not None and qp_cache.compiled_kernels:
        from pipeline.loop.compiled import COMPILED_KERNELS

        return COMPILED_KERNELS
    return PYTHON_KERNELS


def simulate(cfg: LoopSettings, scenario: Scenario, qp_cache: QpCache | None = None,
             kernels: Kernels | None = None, record_horizon: bool = True) -> SimulationResult:
    """Run the closed loop once: a family of one through the lockstep engine
    (:func:`pipeline.loop.engine.simulate_members`, with BLAS on one thread).

    Parameters
    ----------
    cfg : LoopSettings
    scenario : Scenario
    qp_cache : QpCache, optional
        Compiled QPs shared with other runs (a private cache when omitted).
    kernels : Kernels, optional
        The loop's kernels; by default :func:`run_kernels` of the cache.
    record_horizon : bool
        Keep what each step planned (:mod:`pipeline.loop.horizon`, the report's scenario
        explorer); False leaves ``horizon`` empty and changes no other number (a tune's
        training members, which no report shows: about 7 % of a member's CPU time).

    Returns
    -------
    SimulationResult
        The trajectory has columns ``time_s``, plant states (``X_m, Y_m, psi_rad, vx_mps,
        vy_mps, r_rad_s, delta_rad``), line-frame errors (``e_y_m, e_psi_rad``), the applied input
        ``steering_rate_rad_s`` (and ``accel_mps2`` on the kinematic track), ``speed_ref_mps``,
        the references (``y_ref_m, psi_ref_rad``), the APF's next point and forces at the vehicle
        and whether its step cap bound (``apf_*``), per-obstacle columns (``obs{j}_x_m,
        obs{j}_y_m, obs{j}_radius_m, obs{j}_visible``) and solver columns (``solver_status,
        solver_iterations, fallback, max_slack_m``; ``ltv_passes, ltv_change`` on the kinematic
        track).
    """
    # one member through the lockstep engine: the same loop a family's members go through
    from pipeline.loop.engine import simulate_members

    return simulate_members([(cfg, scenario)], qp_cache, kernels, record_horizon)[0]


def _loop_stages(cfg: LoopSettings, scenario: Scenario, qp_cache: QpCache | None,
                 kernels: Kernels) -> tuple[bool, SingleTrackPlant | KinematicPlant, Controller,
                                            ApfPlanner]:
    """The run's stages: whether it is the kinematic track, its plant, controller and
    planner."""
    kinematic = cfg.controller.kind == "kinematic_mpc"
    plant = KinematicPlant(cfg, scenario) if kinematic else \
        SingleTrackPlant(cfg, scenario, kernels)
    controller = make_controller(cfg, scenario.sample_time_s, qp_cache, kernels)
    planner = make_planner(cfg.planner, cfg.controller.horizon, scenario.sample_time_s,
                           kernels)
    if cfg.planner._target_ or cfg.controller._target_:
        controller, planner = _checked_plugins(cfg, kinematic, controller, planner)
    return kinematic, plant, controller, planner


def _checked_plugins(cfg: LoopSettings, kinematic: bool, controller: Controller,
                     planner: ApfPlanner) -> tuple[Controller, ApfPlanner]:
    """A user's planner or controller (``_target_``) behind the checks of its outputs
    (:mod:`pipeline.loop.plugins`); the built-ins as they are."""
    from pipeline.loop.plugins import CheckedController, CheckedPlanner
    from pipeline.loop.settings import ScenarioConfig

    if cfg.planner._target_:
        planner = CheckedPlanner(planner, cfg.planner._target_, cfg.controller.horizon,
                                 ScenarioConfig.SPEED_BOUNDS_MPS[1])  # type: ignore[assignment]
    if cfg.controller._target_:
        vehicle = cfg.vehicle
        bounds: tuple[tuple[float, float, str], ...] = (
            (float(cfg.controller.accel_bounds_mps2[0]),
             float(cfg.controller.accel_bounds_mps2[1]), "acceleration m/s^2"),
            (-vehicle.steering_max_rad, vehicle.steering_max_rad, "steering angle rad")) \
            if kinematic else ((-vehicle.steering_rate_max_rad_s,
                                vehicle.steering_rate_max_rad_s, "steering rate rad/s"),)
        controller = CheckedController(controller, cfg.controller._target_,
                                       bounds)  # type: ignore[assignment]
    return controller, planner


def _line_constants(frame: LineFrame) -> tuple[float, float, float, float]:
    """The start-goal line's origin and the cosine and sine of its heading, as plain floats."""
    origin_x, origin_y = frame.origin_m.tolist()
    return origin_x, origin_y, cos(frame.heading_rad), sin(frame.heading_rad)


def _anchor_due(scenario: Scenario, unanchored: np.ndarray, time_s: float,
                state: np.ndarray) -> tuple[Scenario, bool]:
    """``obstacle_anchor="vehicle"``: the obstacles that appear now placed relative to the
    vehicle (``unanchored`` updated in place); the scenario, and whether any is left."""
    due = unanchored & (time_s + 1e-9 >= scenario.obstacle_appear_s)
    if due.any():
        scenario = scenario.anchored(due, state[:2])
        unanchored &= ~due
    return scenario, bool(unanchored.any())


def _pose_row(time_s: float, state: np.ndarray, frame: LineFrame,
              line: tuple[float, float, float, float]
              ) -> tuple[dict[str, Any], float, float, float, float]:
    """A step's log row so far (time, pose, line-frame errors; the obstacles' columns go in
    by :meth:`TrajectoryLog.put_obstacles`); and the vehicle's place along and across the
    line, its heading and its heading error to the line."""
    origin_x, origin_y, c_line, s_line = line
    X, Y, psi = float(state[0]), float(state[1]), float(state[2])
    dx, dy = X - origin_x, Y - origin_y
    along, lateral = c_line * dx + s_line * dy, -s_line * dx + c_line * dy
    e_psi = atan2(sin(psi - frame.heading_rad), cos(psi - frame.heading_rad))
    row = {"time_s": time_s, "X_m": X, "Y_m": Y, "psi_rad": psi, "e_y_m": lateral,
           "e_psi_rad": e_psi}
    return row, along, lateral, psi, e_psi


def _planned_speed(planner: ApfPlanner, position: np.ndarray, psi: float,
                   visible: ObstacleSnapshot, scenario: Scenario,
                   vehicle_radius: float, rollout: ApfRollout, state: np.ndarray,
                   path_aware: bool) -> float:
    """The planner's speed reference (the path and the speed only to a ``path_aware`` one)."""
    if path_aware:
        return planner.speed(position, psi, visible, scenario.speed_mps, vehicle_radius,
                             path_m=rollout.path_m, speed_mps=float(state[3]))
    return planner.speed(position, psi, visible, scenario.speed_mps, vehicle_radius)


def _add_end_columns(row: dict[str, Any], plant: SingleTrackPlant | KinematicPlant,
                     state: np.ndarray, command: np.ndarray | None) -> None:
    """The last row's columns after the observation's: the plant's, no solve."""
    row.update(plant.log_columns(state, None, command if command is not None
                                 else np.zeros(2)))
    row.update(fallback="end", solver_status="end")


def _add_step_columns(row: dict[str, Any], plant: SingleTrackPlant | KinematicPlant,
                      state: np.ndarray, step: ControlStep,
                      command: np.ndarray | None, kinematic: bool, speed_ref: float,
                      rollout: ApfRollout) -> None:
    """A step's columns after the observation's, into ``row``: the plant's, the applied input,
    the speed reference, the controller's own, the APF's and the solver's."""
    row.update(plant.log_columns(state, step.command, command))
    if not kinematic:
        row["steering_rate_rad_s"] = step.command[0]
    row["speed_ref_mps"] = speed_ref
    row.update(step.log)
    row.update(_apf_columns(rollout))
    row.update(solver_status=step.status, solver_iterations=step.iterations,
               fallback=step.fallback, max_slack_m=step.max_slack_m)


def _add_model_check(controller: Controller, log: TrajectoryLog) -> None:
    """The model-check columns of a finished run (NaN for a controller without a model)."""
    check = getattr(controller, "model_check", None)
    if check is not None and log.rows:
        # how each step's prediction held against what the plant then did (model validity)
        for name, values in check({name: column[:log.rows]
                                   for name, column in log.columns.items()}).items():
            log.columns[name] = values
    elif log.rows:
        # a controller without a model (pure pursuit): nothing to check, nothing left
        for name in MODEL_CHECK_COLUMNS:
            log.columns[name] = np.full(log.rows, np.nan)


def _in_contact(state: np.ndarray, snapshot: ObstacleSnapshot, vehicle_radius_m: float,
                disc_offsets_m: np.ndarray | None = None) -> bool:
    """Whether the vehicle's footprint overlaps a present obstacle (the true positions,
    before the sensor range): its disc at the logged position, or with ``disc_offsets_m``
    (``vehicle.footprint_discs`` > 1) any of its discs along its heading."""
    present = snapshot.visible
    if not present.any():
        return False
    ox, oy = snapshot.positions_m[present, 0], snapshot.positions_m[present, 1]
    radii = snapshot.radii_m[present]
    if disc_offsets_m is None:
        gap = np.hypot(ox - state[0], oy - state[1]) - radii - vehicle_radius_m
        return bool(np.min(gap) < 0.0)
    cx = state[0] + disc_offsets_m * cos(state[2])
    cy = state[1] + disc_offsets_m * sin(state[2])
    gap = np.hypot(ox[:, None] - cx[None, :], oy[:, None] - cy[None, :]) \
        - radii[:, None] - vehicle_radius_m
    return bool(np.min(gap) < 0.0)


def _termination(state: np.ndarray, along_line_m: float, goal_line_x_m: float,
                 scenario: Scenario, step: int) -> str | None:
    """Why the run ends at this step, or None: non-finite state, goal line, last step."""
    if not isfinite(sum(state.tolist())):  # inf or nan anywhere makes the sum non-finite
        return "non_finite_state"
    if along_line_m >= goal_line_x_m - scenario.goal_tolerance_m:
        return "goal_line"
    return "max_steps" if step == scenario.n_steps else None
