"""The dynamic window approach on the Appendix-A track (Fox, Burgard and Thrun, "The dynamic
window approach to collision avoidance", IEEE Robotics & Automation Magazine 4(1), 1997).

A controller plug-in (``controller._target_``) for the kinematic bicycle of Appendix A (state
``[x, y, psi, v]``, command ``[a, delta]``): it replaces the kinematic MPC. Each step it searches
the velocities ``(v, omega)`` reachable within one sample, keeps the admissible ones and applies
the one that maximizes Fox's objective.

Readings (each number is a ``controller.params`` key, or the configuration's own):

* **Dynamic window.** ``v`` in ``[max(0, v0 + a_lo Ts), min(max_speed_mps, v0 + a_hi Ts)]``
  (``controller.accel_bounds_mps2``, no reversing; if ``v0`` exceeds the speed limit by more
  than one sample's braking, the window is the fastest braking alone). The kinematic plant
  takes the steering angle directly (Appendix A bounds ``delta``, not its rate), so within one
  sample every yaw rate the steering bound allows at speed ``v`` is reachable:
  ``|omega| <= v tan(vehicle.steering_max_rad) / L``. The grid: ``speed_samples`` speeds evenly
  over the ``v`` window, and at each speed ``yaw_rate_samples`` yaw rates evenly over its
  ``omega`` window (evenly in curvature ``omega / v``; odd counts include driving straight).
* **Prediction.** Each pair is held constant (a circular arc, closed form) over
  ``prediction_time_s``, sampled every ``prediction_step_s``; the visible obstacles move with
  their velocities (constant). A sample collides when the vehicle's centre is within ``R_j +
  vehicle.footprint_radius_m + margin_m`` of an obstacle's centre.
* **dist.** The arc length to the last collision-free sample before the first colliding one (0
  when the vehicle is in collision now): the sampled distance to collision along the arc, short
  by at most one sample (conservative). A pair whose arc stays free is at ``inf`` for the
  admissibility test and at Fox's "large constant", ``max_speed_mps * prediction_time_s`` (the
  longest arc in any window), in the objective.
* **Admissible** (Fox et al.'s admissible velocities): ``v <= sqrt(2 dist' a_brake)`` with
  ``a_brake = -controller.accel_bounds_mps2[0]`` (the car's full braking, 3 m/s^2 by Appendix
  A) and ``dist' = dist - (v0 + v) Ts / 2``: Fox's condition assumes braking starts at once,
  but the command is held for one sample (the speed ramps from ``v0`` to ``v``) before the
  next step can brake, so ``dist`` is counted from there. With ``dist`` itself (the printed
  condition) a car can stop up to the held sample's distance (``v Ts``, 0.3 m at 3 m/s)
  further than it planned: measured, 0.19 m into the 0.2 m margin in front of a wall; with
  ``dist'``, full braking from any admissible choice stops within ``dist`` (straight arc,
  static obstacles). Against a moving obstacle ``dist`` is where the obstacle meets the arc:
  the method's own reading of distance (it was written for static surroundings).
* **Objective** (Fox et al.'s objective function): ``G = alpha heading + beta dist + gamma
  velocity`` with ``heading = pi - |theta|``, ``theta`` the bearing of the target seen from
  the pose the vehicle reaches when it follows the pair for one sample and then brakes at
  ``a_brake`` to a stop on the same arc (Fox's reading of where heading is judged), ``dist``
  as above and ``velocity = v``. Fox et al. state that the three terms are normalized to
  [0, 1] without printing the operation; here each term is divided by its sum over the
  admissible pairs (a term that is 0 everywhere stays 0). Their additional smoothing
  ``sigma`` of the weighted sum over the velocity space is not applied. Defaults ``alpha = 2,
  beta = 0.2, gamma = 0.2``: the weights usually quoted from Fox et al.'s experiments (from
  memory of the paper: not checked against its text here). Ties: the faster pair, then the
  straighter one.
* **Target.** The Observation carries no goal; the straight-to-goal planner's rollout points
  at it, so the target is on the ray from the vehicle through ``obs.rollout.path_m[-1]``, at
  least ``max_speed_mps * prediction_time_s`` out (the rollout ends 2.7 m ahead, nearer than
  the predicted stops could reach at higher speed limits). A rollout that does not leave the
  vehicle leaves the target straight ahead.
* **Command.** ``a = (v* - v0) / Ts`` and ``delta = atan(omega* L / max(v*,
  min_steering_speed_mps))``, each clipped to its bound. **No admissible pair:** full braking
  (``a = max(a_lo, -v0 / Ts)``) with the steering of the pair with the longest ``dist``,
  logged as ``solver_status = dwa_no_admissible``, ``fallback = safe_input``.
* There is no MPC on this method's path, so none of its collision half-planes either: the
  window's admissibility and clearance are all that avoid the obstacles.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, fields
from math import atan, hypot, isfinite, pi, tan
from typing import Any, ClassVar

import numpy as np

from pipeline.errors import ConfigError
from pipeline.loop.controller.base import ControlStep, Observation
from pipeline.loop.controller_settings import KinematicMpcSettings, settings_of
from pipeline.loop.settings import ControllerConfig, VehicleConfig

_TINY = 1e-9


@dataclass(frozen=True)
class DwaSettings:
    """The dynamic window's settings (``controller.params``).

    Attributes
    ----------
    max_speed_mps : float
        Speed limit of the window.
    speed_samples : int
        Speeds in the grid over the window's ``v`` range.
    yaw_rate_samples : int
        Yaw rates in the grid at each speed (odd: driving straight is one of them).
    prediction_time_s : float
        How long each pair is held in the prediction.
    prediction_step_s : float
        Sampling of the predicted arcs.
    margin_m : float
        Clearance added to every combined radius.
    alpha_heading, beta_clearance, gamma_velocity : float
        Weights of the objective's three terms.
    min_steering_speed_mps : float
        The ``small`` of ``delta = atan(omega L / max(v, small))``.
    """

    max_speed_mps: float = 3.0
    speed_samples: int = 7
    yaw_rate_samples: int = 21
    prediction_time_s: float = 3.0
    prediction_step_s: float = 0.1
    margin_m: float = 0.2
    alpha_heading: float = 2.0
    beta_clearance: float = 0.2
    gamma_velocity: float = 0.2
    min_steering_speed_mps: float = 0.1

    #: each number's allowed range: (low, high, low excluded)
    RANGES: ClassVar[Mapping[str, tuple[float, float, bool]]] = {
        "max_speed_mps": (0.0, 40.0, True), "prediction_time_s": (0.0, 60.0, True),
        "prediction_step_s": (0.0, 10.0, True), "margin_m": (0.0, 20.0, False),
        "alpha_heading": (0.0, 1e6, False), "beta_clearance": (0.0, 1e6, False),
        "gamma_velocity": (0.0, 1e6, False), "min_steering_speed_mps": (0.0, 40.0, True)}
    #: each count's allowed range
    COUNTS: ClassVar[Mapping[str, tuple[int, int]]] = {"speed_samples": (1, 201),
                                                        "yaw_rate_samples": (1, 401)}

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> DwaSettings:
        """Settings from ``controller.params``; a :class:`~pipeline.errors.ConfigError` (a
        ``ValueError``, one line) naming ``controller.params.<key>`` and its allowed range for
        an unknown key or a value out of range."""
        known = [f.name for f in fields(cls)]
        for key in params:
            if key not in known:
                raise ConfigError(f"controller.params.{key}", params[key],
                                  "a key of the dynamic window: " + ", ".join(sorted(known)))
        values = {**{f.name: f.default for f in fields(cls)}, **dict(params)}
        for key, (low, high, low_open) in cls.RANGES.items():
            value = values[key]
            allowed = f"a number in {'(' if low_open else '['}{low}, {high}]"
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not isfinite(float(value)) or not low <= float(value) <= high \
                    or (low_open and float(value) == low):
                raise ConfigError(f"controller.params.{key}", value, allowed)
        for key, (low_n, high_n) in cls.COUNTS.items():
            value = values[key]
            if isinstance(value, bool) or not isinstance(value, int) \
                    or not low_n <= value <= high_n:
                raise ConfigError(f"controller.params.{key}", value,
                                  f"an integer in [{low_n}, {high_n}]")
        if values["prediction_step_s"] > values["prediction_time_s"]:
            raise ConfigError("controller.params.prediction_step_s", values["prediction_step_s"],
                              f"a number in (0, prediction_time_s={values['prediction_time_s']}]")
        return cls(float(values["max_speed_mps"]), int(values["speed_samples"]),
                   int(values["yaw_rate_samples"]), float(values["prediction_time_s"]),
                   float(values["prediction_step_s"]), float(values["margin_m"]),
                   float(values["alpha_heading"]), float(values["beta_clearance"]),
                   float(values["gamma_velocity"]), float(values["min_steering_speed_mps"]))


def dynamic_window(speed_mps: float, settings: DwaSettings, accel_bounds_mps2: tuple[float, float],
                   max_curvature_1_per_m: float, sample_time_s: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The grid over the dynamic window.

    Parameters
    ----------
    speed_mps : float
        The vehicle's speed now, ``v0``.
    settings : DwaSettings
    accel_bounds_mps2 : (float, float)
        ``[a_lo, a_hi]``.
    max_curvature_1_per_m : float
        ``tan(steering_max) / L``.
    sample_time_s : float

    Returns
    -------
    speeds_mps, yaw_rates_rad_s : ndarray, shape (P,)
        The pairs, speeds descending, then yaw rates from right to left.
    """
    a_lo, a_hi = accel_bounds_mps2
    low = max(0.0, speed_mps + a_lo * sample_time_s)
    high = min(settings.max_speed_mps, speed_mps + a_hi * sample_time_s)
    high = max(high, low)  # above the limit by more than one sample's braking: brake
    n_v = settings.speed_samples if high - low > _TINY else 1
    speeds = high - (high - low) * (np.arange(n_v) / max(n_v - 1, 1))
    n_w = settings.yaw_rate_samples
    curvature = max_curvature_1_per_m * (
        (2.0 * np.arange(n_w) - (n_w - 1)) / (n_w - 1) if n_w > 1 else np.zeros(1))
    v = np.repeat(speeds, n_w)
    return v, v * np.tile(curvature, n_v)


def arc_points(pose: np.ndarray, speeds_mps: np.ndarray, yaw_rates_rad_s: np.ndarray,
               times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions and headings along constant-``(v, omega)`` arcs (exact, closed form).

    The chord of an arc of length ``s = v t`` and turn ``phi = omega t`` has length
    ``s sin(phi / 2) / (phi / 2)`` and direction ``psi0 + phi / 2``.

    Parameters
    ----------
    pose : ndarray, shape (3,)
        ``[x, y, psi]`` now.
    speeds_mps, yaw_rates_rad_s : ndarray, shape (P,)
    times_s : ndarray, shape (M,)

    Returns
    -------
    points_m : ndarray, shape (P, M, 2)
    headings_rad : ndarray, shape (P, M)
    """
    t = np.asarray(times_s, float)[None, :]
    half = 0.5 * yaw_rates_rad_s[:, None] * t
    chord = speeds_mps[:, None] * t * np.sinc(half / pi)
    direction = pose[2] + half
    points = np.empty(chord.shape + (2,))
    points[..., 0] = pose[0] + chord * np.cos(direction)
    points[..., 1] = pose[1] + chord * np.sin(direction)
    return points, pose[2] + 2.0 * half


def distance_to_collision_m(points_m: np.ndarray, speeds_mps: np.ndarray, times_s: np.ndarray,
                            obstacle_positions_m: np.ndarray, obstacle_velocities_mps: np.ndarray,
                            combined_radii_m: np.ndarray, now_in_collision: bool) -> np.ndarray:
    """Arc length to the last collision-free sample before the first colliding one.

    Parameters
    ----------
    points_m : ndarray, shape (P, M, 2)
        The arcs at ``times_s``.
    speeds_mps : ndarray, shape (P,)
    times_s : ndarray, shape (M,)
    obstacle_positions_m, obstacle_velocities_mps : ndarray, shape (n, 2)
        Now; obstacles move at constant velocity.
    combined_radii_m : ndarray, shape (n,)
    now_in_collision : bool
        Whether the vehicle is within a combined radius now (every ``dist`` is then 0).

    Returns
    -------
    ndarray, shape (P,)
        ``inf`` where the arc stays free over ``times_s``.
    """
    P = points_m.shape[0]
    if now_in_collision:
        return np.zeros(P)
    if obstacle_positions_m.shape[0] == 0:
        return np.full(P, np.inf)
    centres = obstacle_positions_m[None, :, :] + times_s[:, None, None] \
        * obstacle_velocities_mps[None, :, :]                                  # (M, n, 2)
    diff = points_m[:, :, None, :] - centres[None, :, :, :]                  # (P, M, n, 2)
    hit = (np.einsum("pmnk,pmnk->pmn", diff, diff)
           < combined_radii_m[None, None, :] ** 2).any(axis=2)                # (P, M)
    any_hit = hit.any(axis=1)
    first = np.argmax(hit, axis=1)
    free_times = np.concatenate([[0.0], times_s])[first]  # the sample before the first hit
    return np.where(any_hit, speeds_mps * free_times, np.inf)


def heading_term_rad(pose: np.ndarray, speeds_mps: np.ndarray, yaw_rates_rad_s: np.ndarray,
                     target_m: np.ndarray, sample_time_s: float, brake_mps2: float) -> np.ndarray:
    """Fox's ``heading = pi - |theta|``: ``theta`` the target's bearing relative to the
    vehicle's heading at the pose reached by one sample at ``(v, omega)`` and then braking at
    ``brake_mps2`` to a stop on the same arc.

    Returns
    -------
    ndarray, shape (P,)
    """
    v = speeds_mps
    arc = v * sample_time_s + v * v / (2.0 * brake_mps2)
    with np.errstate(invalid="ignore", divide="ignore"):
        curvature = np.where(v > _TINY, yaw_rates_rad_s / v, 0.0)
    turn = curvature * arc
    chord = arc * np.sinc(0.5 * turn / pi)
    direction = pose[2] + 0.5 * turn
    x = pose[0] + chord * np.cos(direction)
    y = pose[1] + chord * np.sin(direction)
    bearing = np.arctan2(target_m[1] - y, target_m[0] - x)
    theta = np.angle(np.exp(1j * (bearing - (pose[2] + turn))))
    return pi - np.abs(theta)


def _normalized(term: np.ndarray, admissible: np.ndarray) -> np.ndarray:
    """``term`` divided by its sum over the admissible pairs (0 where that sum is 0)."""
    total = float(term[admissible].sum())
    return term / total if total > 0.0 else np.zeros_like(term)


class DynamicWindow:
    """Fox, Burgard and Thrun's dynamic window as the controller of the kinematic track.

    Parameters
    ----------
    controller : KinematicMpcSettings
        ``accel_bounds_mps2``, ``horizon`` (the length of the logged plan) and ``params``
        (:class:`DwaSettings`).
    vehicle : VehicleConfig
        ``wheelbase_m``, ``steering_max_rad``, ``footprint_radius_m``.
    sample_time_s : float
    qp_cache : object, optional
        Unused (no QP); accepted for the controller protocol.
    """

    compile_count = 0
    compile_time_s = 0.0

    def __init__(self, controller: ControllerConfig, vehicle: VehicleConfig,
                 sample_time_s: float, qp_cache: Any = None) -> None:
        controller = settings_of(controller, KinematicMpcSettings)  # the kinematic track's
        self.settings = DwaSettings.from_params(controller.params)
        self.vehicle, self.ts = vehicle, float(sample_time_s)
        self.horizon = int(controller.horizon)
        lo, hi = (float(a) for a in controller.accel_bounds_mps2)
        if lo >= 0.0:
            raise ConfigError("controller.accel_bounds_mps2", [lo, hi],
                              "a lower bound < 0 (the dynamic window brakes with it)")
        self.accel_bounds_mps2 = (lo, hi)
        self.brake_mps2 = -lo
        self.wheelbase_m = float(vehicle.wheelbase_m)
        self.steering_max_rad = float(vehicle.steering_max_rad)
        self.max_curvature_1_per_m = tan(self.steering_max_rad) / self.wheelbase_m
        s = self.settings
        n = max(int(np.ceil(s.prediction_time_s / s.prediction_step_s - 1e-9)), 1)
        self.times_s = s.prediction_step_s * np.arange(1, n + 1)
        self.clearance_cap_m = s.max_speed_mps * s.prediction_time_s
        self.u_prev = np.zeros(2)

    def target(self, obs: Observation) -> np.ndarray:
        """The point the heading term aims at: on the ray from the vehicle through the
        rollout's end, at least ``max_speed_mps * prediction_time_s`` out."""
        x, y, psi = (float(v) for v in obs.plant_state[:3])
        end = np.asarray(obs.rollout.path_m[-1], float)
        dx, dy = float(end[0]) - x, float(end[1]) - y
        length = hypot(dx, dy)
        reach = max(length, self.clearance_cap_m, 1.0)
        if length <= _TINY:
            return np.array([x + reach * np.cos(psi), y + reach * np.sin(psi)])
        return np.array([x + reach * dx / length, y + reach * dy / length])

    def choose(self, obs: Observation) -> tuple[float, float, bool, dict[str, Any]]:
        """The pair ``(v*, omega*)``, whether it was admissible, and what to log."""
        state = np.asarray(obs.plant_state, float)
        pose, v0 = state[:3], float(state[3])
        s = self.settings
        speeds, yaw_rates = dynamic_window(v0, s, self.accel_bounds_mps2,
                                           self.max_curvature_1_per_m, self.ts)
        obstacles = obs.obstacles
        radii = obstacles.radii_m + self.vehicle.footprint_radius_m + s.margin_m
        now = obstacles.positions_m - pose[None, :2]
        in_collision = bool(np.any(np.einsum("nk,nk->n", now, now) < radii ** 2))
        points, _ = arc_points(pose, speeds, yaw_rates, self.times_s)
        dist = distance_to_collision_m(points, speeds, self.times_s, obstacles.positions_m,
                                       obstacles.velocities_mps, radii, in_collision)
        # v <= sqrt(2 a (dist - (v0 + v) Ts / 2)), squared: the ramp over the held sample, then
        # full braking, ends within dist
        admissible = 0.5 * (v0 + speeds) * self.ts + speeds * speeds / (2.0 * self.brake_mps2) \
            <= dist + 1e-12
        log = {"dwa_pairs": int(speeds.size), "dwa_admissible": int(admissible.sum())}
        if not admissible.any():
            best = int(np.argmax(dist))
            return float(speeds[best]), float(yaw_rates[best]), False, log
        heading = heading_term_rad(pose, speeds, yaw_rates, self.target(obs), self.ts,
                                   self.brake_mps2)
        clearance = np.minimum(dist, self.clearance_cap_m)
        score = (s.alpha_heading * _normalized(heading, admissible)
                 + s.beta_clearance * _normalized(clearance, admissible)
                 + s.gamma_velocity * _normalized(speeds, admissible))
        score = np.where(admissible, score, -np.inf)
        top = np.flatnonzero(score >= score.max() - 1e-12)
        # ties: the faster pair, then the straighter one
        best = int(top[np.lexsort((np.abs(yaw_rates[top]), -speeds[top]))[0]])
        return float(speeds[best]), float(yaw_rates[best]), True, log

    def step(self, obs: Observation) -> ControlStep:
        """One closed-loop step: the chosen pair as ``[a, delta]``.

        Parameters
        ----------
        obs : Observation
            ``plant_state = [x, y, psi, v]``, the visible obstacles and the planner's rollout.

        Returns
        -------
        ControlStep
            ``command = [a m/s^2, delta rad]``; ``status`` ``dwa`` (or ``dwa_no_admissible``,
            the full-braking fallback); ``solve_time_s`` the wall time of the search.
        """
        started = time.perf_counter()
        state = np.asarray(obs.plant_state, float)
        v0 = float(state[3]) if isfinite(float(state[3])) else 0.0
        lo, hi = self.accel_bounds_mps2
        if not np.all(np.isfinite(state)):
            command = np.array([float(np.clip(-v0 / self.ts, lo, hi)), 0.0])
            status, fallback = "not_solved", "safe_input"
            log: dict[str, Any] = {}
        else:
            v_star, w_star, ok, log = self.choose(obs)
            small = self.settings.min_steering_speed_mps
            delta = atan(w_star * self.wheelbase_m / max(v_star, small))
            delta = float(np.clip(delta, -self.steering_max_rad, self.steering_max_rad))
            if ok:
                accel = float(np.clip((v_star - v0) / self.ts, lo, hi))
                status, fallback = "dwa", "none"
            else:
                accel = max(lo, -v0 / self.ts)
                status, fallback = "dwa_no_admissible", "safe_input"
            command = np.array([accel, delta])
        elapsed = time.perf_counter() - started
        # the kinematic MPC's log columns: the applied acceleration, the steering's change per
        # second, and the reference it was handed (row 0 of the rollout, as its literal alignment)
        log.update(accel_mps2=float(command[0]),
                   steering_rate_rad_s=(float(command[1]) - float(self.u_prev[1])) / self.ts,
                   y_ref_m=float(obs.frame.to_line(np.asarray(obs.rollout.path_m[0], float))[1]),
                   psi_ref_rad=np.nan)
        self.u_prev = command
        return ControlStep(command, np.repeat(command[:, None], self.horizon, axis=1), None,
                           status, 0, elapsed, fallback, 0.0, log)

