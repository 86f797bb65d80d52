"""What the lateral MPC's state is measured against (``controller.frame``): one class per
frame, each turning an observation into one step's QP data (:class:`MpcInputs`).

* :class:`FixedFrame` (``fixed``, the earlier reading): the position and heading against the
  start-goal line, the references interpolated on the APF rollout, ``r_d = 0``.
* :class:`PathFrame` (``path``, the default): the offset and heading error from a reference
  path built from the APF rollout each step (the rollout itself, or a pursuit of it:
  ``controller.path_reference``, :mod:`~pipeline.loop.controller.path`), its curvature
  previewed as ``r_d``, the model's equilibrium on it as the references, the stations at the
  predicted speed, the obstacles in path coordinates.

Both hand the same QP other data; the models they predict with come from one
:class:`ModelBank` (per speed and prediction step, shared across runs through the QP cache).
"""

from __future__ import annotations

from math import atan2, pi
from typing import Any

import numpy as np

from pipeline.loop.controller.base import ControlStep, Observation
from pipeline.loop.controller.lateral_qp import MpcInputs
from pipeline.loop.controller.path import ReferencePath, heading_ramp_path, steady_state_gains
from pipeline.loop.controller.qp import QpCache
from pipeline.loop.controller.references import (
    collision_halfplanes,
    force_heading_reference,
    lateral_reference,
)
from pipeline.loop.controller_settings import MpcSettings
from pipeline.loop.kernels import Kernels
from pipeline.loop.model import LateralModel, LateralModelCache, model_speed_mps, vehicle_key
from pipeline.loop.settings import ModelConfig, VehicleConfig


class ModelBank:
    """The lateral models a controller predicts with: at the sample time by speed, and at a
    stretched prediction step (``controller.horizon_reach_m``) by step and speed; their
    steady-state gains by speed. Shared by every run handed the same QP cache (python-control's
    ``c2d`` is paid once per speed and step, not once per family member)."""

    def __init__(self, vehicle: VehicleConfig, model: ModelConfig, sample_time_s: float,
                 qp_cache: QpCache | None) -> None:
        self.vehicle, self.model_cfg = vehicle, model
        self.sample_time_s = float(sample_time_s)
        self._qp_cache = qp_cache
        self.models = self._cache(self.sample_time_s)
        self._stretched: dict[float, LateralModelCache] = {}
        self._gains: dict[float, np.ndarray] = {}

    def _cache(self, step_s: float) -> LateralModelCache:
        cfg = self.model_cfg
        shared = self._qp_cache.memo(("lateral_models", vehicle_key(self.vehicle), step_s,
                                      cfg.b2_heading_entry, cfg.speed_grid_mps), dict) \
            if self._qp_cache is not None else {}
        return LateralModelCache(self.vehicle, step_s, cfg.b2_heading_entry,
                                 cfg.speed_grid_mps, shared)

    def at(self, speed_mps: float, step_s: float | None = None) -> LateralModel:
        """The model at ``speed_mps`` discretized with ``step_s`` (the sample time when
        omitted)."""
        if step_s is None or step_s == self.sample_time_s:
            return self.models.at_speed(speed_mps)
        cache = self._stretched.get(step_s)
        if cache is None:
            cache = self._stretched[step_s] = self._cache(step_s)
        return cache.at_speed(speed_mps)

    def gains(self, model: LateralModel) -> np.ndarray:
        """:func:`~pipeline.loop.controller.path.steady_state_gains` of ``model`` (of its
        continuous matrices: one per speed)."""
        gains = self._gains.get(model.speed_mps)
        if gains is None:
            gains = self._gains[model.speed_mps] = steady_state_gains(model)
        return gains


class FixedFrame:
    """``controller.frame=fixed``: the state against the start-goal line (see the module
    docstring). ``record`` holds the last step's frame for its prediction record: the line
    from the vehicle's projection on it, as a straight path, and the stations."""

    def __init__(self, controller: MpcSettings, vehicle: VehicleConfig, bank: ModelBank,
                 kernels: Kernels | None) -> None:
        self.cfg, self.vehicle, self.bank, self.kernels = controller, vehicle, bank, kernels
        self.horizon = controller.horizon
        self.sample_time_s = bank.sample_time_s
        self._steps_ahead_s = np.arange(1, controller.horizon + 1) * self.sample_time_s
        self._times_s = np.concatenate([[0.0], self._steps_ahead_s])
        self.record: tuple[Any, ...] = ()

    def inputs(self, obs: Observation) -> tuple[MpcInputs, dict[str, Any]]:
        """The QP data against the start-goal line: references interpolated on the APF path,
        half-planes about them, no disturbance."""
        ctrl, N = self.cfg, self.horizon
        model = self.bank.at(obs.speed_ref_mps)
        line_pos = obs.position_line_m
        stations = line_pos[0] + model.speed_mps * self._steps_ahead_s
        path_line = obs.frame.to_line(obs.rollout.path_m)
        y_ref, psi_ref = lateral_reference(path_line, stations, ctrl, self.kernels)
        if ctrl.heading_reference == "apf_force":
            rollout = obs.rollout
            force_line = obs.frame.vectors_to_line(rollout.attraction[0] + rollout.repulsion[0]) \
                if N > 1 else np.array([1.0, 0.0])
            psi_ref = force_heading_reference(force_line, obs.heading_line_rad, N,
                                              self.sample_time_s, ctrl)
        visible = obs.obstacles
        if visible.radii_m.shape[0]:
            predicted = obs.frame.to_line(visible.predicted_positions(self._times_s))[1:]
        else:
            predicted = np.zeros((N, 0, 2))
        G, h = collision_halfplanes(stations, y_ref, line_pos, predicted, visible.radii_m,
                                    self.vehicle, ctrl)
        s = obs.plant_state
        x0 = np.array([line_pos[1], s[4], obs.heading_line_rad, s[5], s[6]])
        log = {"y_ref_m": y_ref[0], "psi_ref_rad": psi_ref[0],
               "path_beyond_limit": bool(abs(np.tan(psi_ref[0]))
                                         >= np.tan(ctrl.heading_ref_max_rad) - 1e-12)
               if ctrl.heading_reference == "path_slope" else False}
        self.record = ("fixed", obs.frame.to_global(np.array([line_pos[0], 0.0])),
                       obs.frame.heading_rad, model.speed_mps * self._times_s,
                       self.sample_time_s)
        return MpcInputs(x0, model, y_ref, psi_ref, G, h, np.zeros(N)), log

    def after_step(self, step: ControlStep) -> None:
        """Nothing to keep: the line does not depend on the plan."""

    @property
    def plan_xy_m(self) -> None:
        """The last plan's global positions: not kept in this frame (None)."""
        return None


class PathFrame:
    """``controller.frame=path``: the state as errors from a drivable path built from the APF
    rollout each step (see the module docstring). ``record`` holds the last step's frame for
    its prediction record (the path, the stations, the prediction step); the last plan's
    poses are kept for the next step's stations (:meth:`after_step`)."""

    def __init__(self, controller: MpcSettings, vehicle: VehicleConfig, bank: ModelBank,
                 kernels: Kernels | None) -> None:
        from pipeline.loop.python_kernels import PYTHON_KERNELS

        self.cfg, self.vehicle, self.bank = controller, vehicle, bank
        self.kernels = kernels if kernels is not None else PYTHON_KERNELS
        self.horizon = controller.horizon
        self.sample_time_s = bank.sample_time_s
        self.record: tuple[Any, ...] = ()
        self._plan_poses: tuple[Any, ...] | None = None   # the last plan's global poses
        self._speeds = np.zeros(0)              # the last step's predicted speeds
        self._step_times: dict[float, np.ndarray] = {}  # prediction times by step
        self._no_points, self._no_values = np.zeros((0, 2)), np.zeros(0)
        # the half-planes by the kernels' statement where it is the rule (lateral_side, an ego
        # of one disc: every default run), else by collision_halfplanes
        self._halfplanes_kernel = controller.halfplane_normal == "lateral_side" \
            and vehicle.footprint_discs == 1
        self._zeros = self.kernels.prepare(np.zeros(controller.horizon))

    def prediction_step(self, speed_mps: float, speed_ref_mps: float) -> float:
        """The prediction step (s): the sample time, stretched where the horizon would cover
        less than ``controller.horizon_reach_m`` at the slower of the measured and the planned
        speed (on the model's speed grid), so that the half-planes see as far ahead in space
        at low speed as at the nominal one."""
        reach = self.cfg.horizon_reach_m
        if reach is None:
            return self.sample_time_s
        vehicle, cfg = self.vehicle, self.bank.model_cfg
        slow = model_speed_mps(min(speed_mps, speed_ref_mps), vehicle.min_model_speed_mps,
                               cfg.speed_grid_mps)
        step = reach / (self.horizon * slow)
        return self.sample_time_s if step <= self.sample_time_s else round(step, 6)

    def inputs(self, obs: Observation) -> tuple[MpcInputs, dict[str, Any]]:
        """The QP data in path coordinates about the drivable path from the vehicle's pose
        towards the APF rollout (:meth:`reference_path`; :meth:`inputs_about`)."""
        _, dt, ds, n_intervals = self.step_geometry(obs)
        return self.inputs_about(obs, self.reference_path(obs, ds, n_intervals), dt)

    def step_geometry(self, obs: Observation) -> tuple[float, float, float, int]:
        """One step's model speed, prediction step, path arc and number of path intervals:
        ``speed, dt, ds, n_intervals`` (the path reaches what the horizon can cover at the
        faster of the measured and the planned speed, accelerating)."""
        vehicle = self.vehicle
        speed = max(float(obs.plant_state[3]), vehicle.min_model_speed_mps)
        dt = self.prediction_step(speed, float(obs.speed_ref_mps))
        reach = max(speed, float(obs.speed_ref_mps)) + vehicle.accel_max_mps2 * dt
        return speed, dt, speed * dt, int(np.ceil(self.horizon * reach / speed)) + 1

    def horizon_times(self, dt: float) -> np.ndarray:
        """The prediction times ``dt, 2 dt, ..., N dt`` (kept per step length)."""
        times = self._step_times.get(dt)
        if times is None:
            times = self._step_times[dt] = dt * np.arange(1, self.horizon + 1)
        return times

    def inputs_about(self, obs: Observation, path: ReferencePath, dt: float
                     ) -> tuple[MpcInputs, dict[str, Any]]:
        """The QP data about ``path`` with prediction step ``dt``: the state as errors from it
        (the vehicle projected on it), its curvature previewed as ``r_d`` at the stations the
        predicted speed reaches (:func:`~pipeline.loop.controller.path.frame_step_arrays`),
        the model's equilibrium on it as the references, and each predicted obstacle projected
        to ``(s, d)`` for half-planes in ``e_y``. On a path built from the vehicle's pose
        along its velocity (its course) ``s0 = e_y = 0`` and the heading error is minus the
        sideslip (what it is in a steady turn on the path)."""
        ctrl, N, vehicle, kernels = self.cfg, self.horizon, self.vehicle, self.kernels
        st = obs.plant_state
        speed = max(float(st[3]), vehicle.min_model_speed_mps)
        gains = self.bank.gains(self.bank.at(speed))
        visible = obs.obstacles
        n_obs = visible.radii_m.shape[0]
        obstacles = visible.predicted_positions(self.horizon_times(dt)).reshape(-1, 2) \
            if n_obs else self._no_points
        plan_xy, plan_course = self._plan_poses if self._plan_poses is not None \
            else (self._no_points, self._no_values)
        settings = (path.ds_m, path.n_intervals, float(st[0]), float(st[1]), speed,
                    float(obs.speed_ref_mps), float(gains[1]), dt, N,
                    vehicle.speed_time_constant_s, vehicle.accel_max_mps2,
                    vehicle.braking_limit_mps2, self.curvature_limit_1_per_m())
        prepare = kernels.prepare
        s0, d0, heading0, stations, r_d, vx, s_o, d_o = kernels.frame_step(
            prepare(path.points_m), prepare(path.headings_rad),
            prepare(path.curvature_1_per_m), *settings, prepare(plan_xy), prepare(plan_course),
            prepare(obstacles))
        if self._halfplanes_kernel:  # lateral_side, one disc: the kernel's statement
            G, h = kernels.halfplanes(
                prepare(stations[1:]), self._zeros, s0, d0, prepare(s_o), prepare(d_o), n_obs,
                prepare(visible.radii_m),
                ctrl.max_obstacles, vehicle.footprint_radius_m, ctrl.safety_margin_m,
                ctrl.constraint_activation_m, ctrl.collision_constraints)
        else:
            projected = np.empty((N, n_obs, 2))
            projected[:, :, 0] = s_o.reshape(N, n_obs)
            projected[:, :, 1] = d_o.reshape(N, n_obs)
            G, h = collision_halfplanes(stations[1:], np.zeros(N), np.array([s0, d0]),
                                        projected, visible.radii_m, vehicle, ctrl)
        if ctrl.road_edge_weight is not None:
            G, h = self._with_road(G, h, path, stations[1:], obs.road_polygons_m)
        return self.finish_inputs(obs, path, dt, (d0, heading0), stations, r_d, vx, G, h)

    def finish_inputs(self, obs: Observation, path: ReferencePath, dt: float,
                      offset_heading: tuple[float, float], stations: np.ndarray,
                      r_d: np.ndarray, vx: np.ndarray, G: np.ndarray, h: np.ndarray
                      ) -> tuple[MpcInputs, dict[str, Any]]:
        """The QP data and log once the frame's arithmetic is done (:meth:`inputs_about`'s, or
        the lockstep engine's for many members at once,
        :mod:`~pipeline.loop.controller.lateral_rows`): the model of the predicted speeds,
        the state as errors from the path (``offset_heading``: the vehicle's offset from it
        and the path's heading there), the references, the step's record."""
        N, st = self.horizon, obs.plant_state
        d0, heading0 = offset_heading
        self._speeds = vx
        model = self.bank.at(sum(vx.tolist()) / vx.shape[0], dt)
        heading_error = (float(st[2]) - heading0 + pi) % (2.0 * pi) - pi
        x0 = np.array([d0, st[4], heading_error, st[5], st[6]])
        if self.cfg.path_state_reference == "steady_state":
            refs = self.bank.gains(model)[:, None] * r_d[None, :]  # the state holding r_d
            psi_ref, r_ref, delta_ref = refs[2], refs[3], refs[4]
        else:
            psi_ref = r_ref = delta_ref = np.zeros(N)
        first = obs.frame.to_line(path.points_m[1]) if N else obs.position_line_m
        log = {"y_ref_m": first[1], "psi_ref_rad": path.headings_rad[1] - obs.frame.heading_rad,
               "path_beyond_limit": bool(np.count_nonzero(
                   path.beyond_limit[:int(np.ceil(stations[-1] / path.ds_m - 1e-9))])),
               "path_curvature_1_per_m": path.curvature_1_per_m[0], "r_d_rad_s": r_d[0]}
        self.record = ("path", path, stations, dt)
        return MpcInputs(x0, model, np.zeros(N), psi_ref, G, h, r_d, r_ref, delta_ref), log

    @property
    def predicted_speeds(self) -> np.ndarray:
        """The last step's predicted speeds along the path (its stations' ``vx``)."""
        return self._speeds

    @property
    def last_plan_poses(self) -> tuple[Any, ...] | None:
        """The last plan's global poses and courses (None after a fallback or before a plan):
        the next step's stations start from them."""
        return self._plan_poses

    def _with_road(self, G: np.ndarray, h: np.ndarray, path: ReferencePath,
                   stations: np.ndarray, road: tuple[np.ndarray, ...]
                   ) -> tuple[np.ndarray, np.ndarray]:
        """``G, h`` with the road's two columns after the obstacles'
        (:func:`~pipeline.loop.controller.road.road_halfplanes`: the ego's disc plus the
        safety margin inside the road's edges along the path's normal at each station)."""
        from pipeline.loop.controller.road import road_halfplanes

        points = path.to_global(stations, np.zeros_like(stations))
        G_road, h_road = road_halfplanes(points, path.heading_at(stations), road,
                                         self.vehicle.footprint_radius_m
                                         + self.cfg.safety_margin_m,
                                         float(self.cfg.road_edge_weight or 0.0))
        return np.hstack([G, G_road]), np.hstack([h, h_road])

    def reference_path(self, obs: Observation, ds_m: float, n_intervals: int
                       ) -> ReferencePath:
        """The reference path of one observation: ``n_intervals`` arcs of ``ds_m``, the APF
        rollout itself (``path_reference=rollout``) or its pursuit from the vehicle
        (``pursuit``); Section 3.1's heading ramp with ``heading_reference=apf_force``."""
        ctrl, kernels = self.cfg, self.kernels
        kappa_max = self.curvature_limit_1_per_m()
        line = obs.frame.heading_rad
        st = obs.plant_state
        course = float(st[2]) + atan2(float(st[4]), max(float(st[3]), 0.1))
        if ctrl.heading_reference == "apf_force":
            # Section 3.1's psi_apf / omega_ref as the path's heading (the reading's path)
            rollout = obs.rollout
            force = rollout.attraction[0] + rollout.repulsion[0] \
                if rollout.attraction.shape[0] else np.array([np.cos(line), np.sin(line)])
            limits = (line - ctrl.heading_ref_max_rad, line + ctrl.heading_ref_max_rad)
            arrays = heading_ramp_path(float(st[0]), float(st[1]), course,
                                       float(np.arctan2(force[1], force[0])),
                                       ctrl.yaw_rate_ref_max_rad_s, limits, float(kappa_max),
                                       float(ds_m), self.sample_time_s, int(n_intervals))
            return ReferencePath(*arrays, float(ds_m))
        cos_line, sin_line = obs.frame.cos_sin
        extend = ctrl.path_beyond_end == "extend"
        if ctrl.path_reference == "rollout":
            points, headings, curvature, beyond = kernels.rollout_path(
                kernels.prepare(obs.rollout.path_m), float(cos_line), float(sin_line), extend,
                float(kappa_max), float(ds_m), int(n_intervals))
        else:
            points, headings, curvature, beyond = kernels.chase_path(
                float(st[0]), float(st[1]), course, kernels.prepare(obs.rollout.path_m),
                float(cos_line), float(sin_line), extend, float(ctrl.path_lookahead_m),
                float(kappa_max), float(ds_m), int(n_intervals), ctrl.path_curvature_clip)
        return ReferencePath(points, headings, curvature, beyond, float(ds_m))

    def curvature_limit_1_per_m(self) -> float:
        """The vehicle's curvature limit: ``controller.path_curvature_max_1_per_m``, by default
        the kinematic one ``tan(steering_max) / wheelbase``."""
        limit = self.cfg.path_curvature_max_1_per_m
        vehicle = self.vehicle
        return float(limit) if limit is not None else \
            float(np.tan(vehicle.steering_max_rad) / vehicle.wheelbase_m)

    def after_step(self, step: ControlStep) -> None:
        """Keep the plan's global poses for the next step's stations (none after a
        fallback)."""
        self._plan_poses = None
        if step.predicted_states is None or step.fallback != "none":
            return
        _, path, stations, _ = self.record
        states = step.predicted_states
        prepare = self.kernels.prepare
        self._plan_poses = self.kernels.plan_poses(
            prepare(path.points_m), prepare(path.headings_rad),
            prepare(path.curvature_1_per_m), path.ds_m, path.n_intervals, prepare(stations),
            prepare(states[0]), prepare(states[2]), prepare(states[1]), prepare(self._speeds))

    @property
    def plan_xy_m(self) -> np.ndarray | None:
        """The last plan's global positions, shape (N + 1, 2) (:meth:`after_step`'s; None
        after a fallback)."""
        return self._plan_poses[0] if self._plan_poses is not None else None

    def plan_poses(self, poses: tuple[Any, ...] | None) -> None:
        """Set the plan poses the next step's stations start from (the nonlinear MPC keeps its
        own plan's)."""
        self._plan_poses = poses


def make_frame(controller: MpcSettings, vehicle: VehicleConfig, bank: ModelBank,
               kernels: Kernels | None) -> FixedFrame | PathFrame:
    """The frame ``controller.frame`` names."""
    frame = PathFrame if controller.frame == "path" else FixedFrame
    return frame(controller, vehicle, bank, kernels)
