"""Peer without MPC: pure pursuit of the APF path, behind the same ``step`` as the MPCs."""

from __future__ import annotations

import numpy as np

from pipeline.loop.controller.base import ControlStep, Observation
from pipeline.loop.controller.references import lateral_reference
from pipeline.loop.controller_settings import PurePursuitSettings, settings_of
from pipeline.loop.model import model_speed_mps
from pipeline.loop.settings import VehicleConfig


def pure_pursuit_steering_rate(path_line_m: np.ndarray, position_line_m: np.ndarray,
                               heading_line_rad: float, steering_rad: float, speed_mps: float,
                               vehicle: VehicleConfig,
                               controller: PurePursuitSettings,
                               sample_time_s: float) -> float:
    """Pure pursuit of the APF path: steering rate toward the pursuit angle.

    The look-ahead point lies on the path (extended along its last segment) at
    ``max(lookahead_min_m, lookahead_time_s * speed)`` from the vehicle; the pursuit steering
    angle is ``atan(2 L sin(alpha) / L_d)`` (``alpha``: bearing of the point in the vehicle
    frame), saturated; the rate that reaches it in one step is saturated at the rate bound.
    """
    lookahead = max(controller.lookahead_min_m, controller.lookahead_time_s * speed_mps)
    rel = path_line_m - position_line_m[None, :]
    dist = np.linalg.norm(rel, axis=1)
    beyond = np.nonzero(dist >= lookahead)[0]
    if beyond.size:
        target = path_line_m[beyond[0]]
    else:
        end, prev = path_line_m[-1], path_line_m[-2] if len(path_line_m) > 1 else position_line_m
        direction = end - prev
        norm = np.linalg.norm(direction)
        direction = direction / norm if norm > 1e-9 else np.array([1.0, 0.0])
        # extend from the end so that the point is at the look-ahead distance (or beyond)
        target = end + direction * max(lookahead - float(dist[-1]), 0.0)
    bearing = np.arctan2(target[1] - position_line_m[1], target[0] - position_line_m[0])
    alpha = np.arctan2(np.sin(bearing - heading_line_rad), np.cos(bearing - heading_line_rad))
    distance = max(float(np.linalg.norm(target - position_line_m)), 1e-3)
    desired = np.arctan(2.0 * vehicle.wheelbase_m * np.sin(alpha) / distance)
    desired = float(np.clip(desired, -vehicle.steering_max_rad, vehicle.steering_max_rad))
    return float(np.clip((desired - steering_rad) / sample_time_s,
                         -vehicle.steering_rate_max_rad_s, vehicle.steering_rate_max_rad_s))


class PurePursuit:
    """The ``apf_pursuit`` peer: no optimizer, nothing to compile, never falls back.

    Parameters
    ----------
    controller : PurePursuitSettings
        Its settings (its kind's schema, as composed).
    vehicle : VehicleConfig
    sample_time_s : float
    """

    compile_count = 0
    compile_time_s = 0.0

    def __init__(self, controller: PurePursuitSettings,
                 vehicle: VehicleConfig, sample_time_s: float,
                 speed_grid_mps: float = 0.1) -> None:
        controller = settings_of(controller, PurePursuitSettings)
        self.cfg, self.vehicle, self.ts = controller, vehicle, float(sample_time_s)
        self.speed_grid_mps = speed_grid_mps
        self._steps_ahead_s = np.arange(1, controller.horizon + 1) * self.ts

    def step(self, obs: Observation) -> ControlStep:
        line_pos = obs.position_line_m
        state = obs.plant_state
        path_line = obs.frame.to_line(obs.rollout.path_m)
        # references at the stations an MPC would use, for the log only
        speed = model_speed_mps(obs.speed_ref_mps, self.vehicle.min_model_speed_mps,
                                self.speed_grid_mps)
        stations = line_pos[0] + speed * self._steps_ahead_s
        y_ref, psi_ref = lateral_reference(path_line, stations, self.cfg)
        rate = pure_pursuit_steering_rate(path_line, line_pos, obs.heading_line_rad, state[6],
                                          state[3], self.vehicle, self.cfg, self.ts)
        N = self.cfg.horizon
        return ControlStep(np.array([rate]), np.full((1, N), rate), None, "pure_pursuit", 0,
                           0.0, "none", 0.0, {"y_ref_m": y_ref[0], "psi_ref_rad": psi_ref[0]})
