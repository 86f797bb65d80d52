"""Model stage: the MPC's lateral linear model and the nonlinear single-track plant.

The lateral model (paper Section 2) has state
``x = [y, vy, epsi, r, delta]`` (lateral position m, lateral velocity m/s, heading error rad,
yaw rate rad/s, steering angle rad), input ``u = delta_dot`` (rad/s) and disturbance
``d = r_d`` (rad/s). It is built with python-control and discretized zero-order-hold.

The plant is a different, nonlinear model: a single-track vehicle in global coordinates with
saturating (tanh) tyre forces, a first-order speed loop and an integrating steering actuator,
integrated with RK4 substeps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from math import atan2, cos, sin, tan, tanh
from typing import Any

import numpy as np

from pipeline.loop.arrays import KernelValues
from pipeline.loop.settings import VehicleConfig

GRAVITY_MPS2 = 9.81

#: Plant state layout (global frame).
PLANT_STATE_NAMES = ("X_m", "Y_m", "psi_rad", "vx_mps", "vy_mps", "r_rad_s", "delta_rad")
LATERAL_STATE_NAMES = ("y_m", "vy_mps", "epsi_rad", "r_rad_s", "delta_rad")


@dataclass(frozen=True)
class LateralModel:
    """Continuous and zero-order-hold discrete lateral model at one speed.

    Attributes
    ----------
    A, B1, B2 : ndarray
        Continuous matrices, shapes (5, 5), (5, 1), (5, 1).
    Ad, Bd, Ed : ndarray
        Discrete matrices for input and disturbance.
    speed_mps, sample_time_s : float
    """

    A: np.ndarray
    B1: np.ndarray
    B2: np.ndarray
    Ad: np.ndarray
    Bd: np.ndarray
    Ed: np.ndarray
    speed_mps: float
    sample_time_s: float
    #: the kinematic single-track (below ``vehicle.kinematic_below_mps``), not the dynamic one
    kinematic: bool = False

    def to_json(self) -> dict[str, Any]:
        extra = {"model": "kinematic single-track"} if self.kinematic else {}
        return {**extra,
            "state": list(LATERAL_STATE_NAMES),
            "input": "delta_dot_rad_s",
            "disturbance": "r_d_rad_s",
            "speed_mps": self.speed_mps,
            "sample_time_s": self.sample_time_s,
            "discretization": "zoh (control.c2d)",
            "continuous": {"A": self.A.tolist(), "B1": self.B1.tolist(), "B2": self.B2.tolist()},
            "discrete": {"Ad": self.Ad.tolist(), "Bd": self.Bd.tolist(), "Ed": self.Ed.tolist()},
        }


def lateral_matrices(vehicle: VehicleConfig, speed_mps: float,
                     b2_heading_entry: float = -1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Continuous-time ``A, B1, B2`` of the lateral model.

    Parameters
    ----------
    vehicle : VehicleConfig
    speed_mps : float
        Longitudinal speed vx (> 0); the matrix has 1/vx terms.
    b2_heading_entry : float
        Entry of B2 in the heading-error row (-1 by default; see the interpretation register).
    """
    if not np.isfinite(speed_mps) or speed_mps <= 0.0:
        raise ValueError(f"lateral model needs a positive finite speed, got {speed_mps!r}")
    m, iz = vehicle.mass_kg, vehicle.yaw_inertia_kg_m2
    a, b = vehicle.cg_to_front_m, vehicle.cg_to_rear_m
    caf, car = vehicle.cornering_stiffness_front_n_per_rad, vehicle.cornering_stiffness_rear_n_per_rad
    vx = float(speed_mps)
    A = np.array([
        [0.0, 1.0, vx, 0.0, 0.0],
        [0.0, -(caf + car) / (m * vx), 0.0, (b * car - a * caf) / (m * vx) - vx, caf / m],
        [0.0, 0.0, 0.0, 1.0, 0.0],
        [0.0, (b * car - a * caf) / (iz * vx), 0.0, -(a**2 * caf + b**2 * car) / (iz * vx),
         a * caf / iz],
        [0.0, 0.0, 0.0, 0.0, 0.0],
    ])
    B1 = np.array([[0.0], [0.0], [0.0], [0.0], [1.0]])
    B2 = np.array([[0.0], [0.0], [float(b2_heading_entry)], [0.0], [0.0]])
    return A, B1, B2


def kinematic_lateral_matrices(vehicle: VehicleConfig, speed_mps: float,
                               b2_heading_entry: float = -1.0
                               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Continuous-time ``A, B1, B2`` of the kinematic single-track in the lateral model's state
    ``[y, vy, epsi, r, delta]`` (below ``vehicle.kinematic_below_mps``): no tyre slip, so the
    lateral velocity and the yaw rate follow the steering angle, ``vy = b vx delta / L`` and
    ``r = vx delta / L`` (small angles), driven by the steering rate; ``y' = vy + vx epsi``,
    ``epsi' = r - r_d``. No 1/vx term: it holds down to a stop."""
    vx = float(speed_mps)
    b, L = vehicle.cg_to_rear_m, vehicle.wheelbase_m
    A = np.zeros((5, 5))
    A[0, 1], A[0, 2], A[2, 3] = 1.0, vx, 1.0
    B1 = np.array([[0.0], [b * vx / L], [0.0], [vx / L], [1.0]])
    B2 = np.array([[0.0], [0.0], [float(b2_heading_entry)], [0.0], [0.0]])
    return A, B1, B2


def build_lateral_model(vehicle: VehicleConfig, speed_mps: float, sample_time_s: float,
                        b2_heading_entry: float = -1.0) -> LateralModel:
    """Build the lateral model with python-control and discretize it (zero-order hold).

    The speed is floored at ``vehicle.min_model_speed_mps`` because the model has 1/vx terms;
    below ``vehicle.kinematic_below_mps`` (when set) the model is the kinematic single-track
    (:func:`kinematic_lateral_matrices`), as the plant is there.
    """
    speed = max(float(speed_mps), vehicle.min_model_speed_mps)
    kinematic = vehicle.kinematic_below_mps is not None and speed < vehicle.kinematic_below_mps
    A, B1, B2 = kinematic_lateral_matrices(vehicle, speed, b2_heading_entry) if kinematic \
        else lateral_matrices(vehicle, speed, b2_heading_entry)
    import control  # here: python-control costs half a second of start-up to every importer

    sys_c = control.ss(A, np.hstack([B1, B2]), np.eye(5), np.zeros((5, 2)))
    sys_d = control.c2d(sys_c, sample_time_s, method="zoh")
    Bd_all = np.asarray(sys_d.B)
    return LateralModel(A=A, B1=B1, B2=B2, Ad=np.asarray(sys_d.A), Bd=Bd_all[:, :1],
                        Ed=Bd_all[:, 1:], speed_mps=speed, sample_time_s=float(sample_time_s),
                        kinematic=kinematic)


def model_speed_mps(speed_mps: float, floor_mps: float, grid_mps: float) -> float:
    """Speed at which the lateral model is built: floored, rounded to the grid (m/s)."""
    key = round(max(speed_mps, floor_mps) / grid_mps) * grid_mps
    return round(max(key, floor_mps), 6)


def vehicle_key(vehicle: VehicleConfig) -> tuple[Any, ...]:
    """A hashable identity of the vehicle's parameters (for caches of its models); kept with
    a validated (read-only) vehicle, which a run asks for it several times."""
    from dataclasses import asdict

    memo = vehicle.__dict__.get("_vehicle_key_memo")
    if memo is not None:
        return memo
    key = tuple(sorted((k, repr(v)) for k, v in asdict(vehicle).items()))
    if vehicle.__dict__.get("_frozen", False):
        object.__setattr__(vehicle, "_vehicle_key_memo", key)
    return key


@dataclass
class LateralModelCache:
    """Discretized lateral models keyed by speed rounded to ``grid_mps`` (for velocity planning)."""

    vehicle: VehicleConfig
    sample_time_s: float
    b2_heading_entry: float
    grid_mps: float
    models: dict[float, LateralModel] = field(default_factory=dict)

    def at_speed(self, speed_mps: float) -> LateralModel:
        key = model_speed_mps(speed_mps, self.vehicle.min_model_speed_mps, self.grid_mps)
        if key not in self.models:
            self.models[key] = build_lateral_model(self.vehicle, key, self.sample_time_s,
                                                   self.b2_heading_entry)
        return self.models[key]


def tyre_linear_limit(tolerance: float) -> float:
    """The normalized slip ``z = C alpha / (mu Fz)`` beyond which the plant's tanh tyre law
    gives ``tolerance`` (a share) less force than the linear law the MPC's model assumes:
    the root of ``tanh(z) / z = 1 - tolerance`` (0.39 for 5 %)."""
    from scipy.optimize import brentq

    return float(brentq(lambda z: np.tanh(z) / z - (1.0 - tolerance), 1e-6, 100.0,
                        xtol=1e-12))


def _single_track_constants(vehicle: VehicleConfig) -> tuple[float, ...]:
    """Mass, yaw inertia, axle distances, cornering stiffnesses and the tyre force limits
    ``mu Fz`` (static axle loads) of the single-track plant."""
    m, iz = vehicle.mass_kg, vehicle.yaw_inertia_kg_m2
    a, b = vehicle.cg_to_front_m, vehicle.cg_to_rear_m
    L = a + b
    mu = vehicle.tire_friction
    fz_front = m * GRAVITY_MPS2 * b / L
    fz_rear = m * GRAVITY_MPS2 * a / L
    return (m, iz, a, b, vehicle.cornering_stiffness_front_n_per_rad,
            vehicle.cornering_stiffness_rear_n_per_rad, mu * fz_front, mu * fz_rear)


#: Order of :func:`single_track_rk4`'s ``constants``.
SINGLE_TRACK_CONSTANT_NAMES = (
    "mass_kg", "yaw_inertia_kg_m2", "cg_to_front_m", "cg_to_rear_m", "cornering_front_n_per_rad",
    "cornering_rear_n_per_rad", "force_limit_front_n", "force_limit_rear_n",
    "speed_time_constant_s", "accel_max_mps2", "steering_max_rad", "kinematic_below_mps",
    "brake_max_mps2")


def single_track_constants(vehicle: VehicleConfig) -> tuple[float, ...]:
    """The plant's constants as :func:`single_track_rk4` takes them (order
    :data:`SINGLE_TRACK_CONSTANT_NAMES`): those of :func:`_single_track_constants`, then the
    speed loop's time constant and acceleration limit, the steering bound, the hand-over speed
    and the braking limit."""
    return tuple(float(c) for c in _single_track_constants(vehicle)) + (
        float(vehicle.speed_time_constant_s), float(vehicle.accel_max_mps2),
        float(vehicle.steering_max_rad),
        float(vehicle.kinematic_below_mps) if vehicle.kinematic_below_mps is not None
        else -math.inf,  # off: no speed is below it
        vehicle.braking_limit_mps2)


def plant_derivative(state: np.ndarray, steering_rate_rad_s: float, speed_target_mps: float,
                     vehicle: VehicleConfig) -> np.ndarray:
    """Time derivative of the nonlinear single-track plant.

    Parameters
    ----------
    state : ndarray, shape (7,)
        ``[X, Y, psi, vx, vy, r, delta]`` (m, m, rad, m/s, m/s, rad/s, rad).
    steering_rate_rad_s : float
        Commanded steering rate (already saturated by the caller).
    speed_target_mps : float
        Target of the first-order speed loop.
    vehicle : VehicleConfig
    """
    X, Y, psi, vx, vy, r, delta = state
    m, iz, a, b, cf, cr, lim_f, lim_r = _single_track_constants(vehicle)
    vx_safe = max(vx, 0.1)
    slip_front = delta - np.arctan2(vy + a * r, vx_safe)
    slip_rear = -np.arctan2(vy - b * r, vx_safe)
    # tanh saturation: slope C at zero slip, limit mu * Fz
    fy_front = lim_f * np.tanh(cf * slip_front / lim_f)
    fy_rear = lim_r * np.tanh(cr * slip_rear / lim_r)
    accel = np.clip((speed_target_mps - vx) / vehicle.speed_time_constant_s,
                    -vehicle.braking_limit_mps2, vehicle.accel_max_mps2)
    rate = steering_rate_rad_s
    if (delta >= vehicle.steering_max_rad and rate > 0) or (delta <= -vehicle.steering_max_rad
                                                           and rate < 0):
        rate = 0.0
    return np.array([
        vx * np.cos(psi) - vy * np.sin(psi),
        vx * np.sin(psi) + vy * np.cos(psi),
        r,
        accel + vy * r,
        (fy_front * np.cos(delta) + fy_rear) / m - vx * r,
        (a * fy_front * np.cos(delta) - b * fy_rear) / iz,
        rate,
    ])


def step_plant(state: np.ndarray, steering_rate_rad_s: float, speed_target_mps: float,
               vehicle: VehicleConfig, dt_s: float, substeps: int) -> np.ndarray:
    """Advance the plant by ``dt_s`` with ``substeps`` RK4 steps; the input is held (ZOH).

    The steering rate is saturated at the vehicle's limit, then :func:`single_track_rk4`
    integrates :func:`plant_derivative`'s equations (the tests hold the two together)."""
    rate_max = vehicle.steering_rate_max_rad_s
    rate_cmd = min(max(float(steering_rate_rad_s), -rate_max), rate_max)
    # plain floats in (a list, a tuple): CPython's arithmetic on numpy scalars is slower
    return single_track_rk4(state.tolist(), single_track_constants(vehicle), rate_cmd,
                            float(speed_target_mps), dt_s, substeps)


def single_track_rk4(state: KernelValues, constants: KernelValues, rate_cmd: float,
                     target: float, dt_s: float, substeps: int) -> KernelValues:
    """One sample period of the single-track plant: ``substeps`` RK4 steps of ``dt_s /
    substeps`` with the steering rate ``rate_cmd`` (already saturated) and the speed target
    ``target`` held.

    The equations of :func:`plant_derivative` on plain floats, the constants
    (:func:`single_track_constants`) hoisted out of the substeps and the four stages in one
    loop (seven states, forty slope evaluations per step: numpy's per-call overhead, and even a
    Python call per slope, would cost more than the arithmetic). The sums run in RK4's usual
    order (``k1 + 2 k2 + 2 k3 + k4``), so the result is bit for bit the textbook one.

    This one statement runs in CPython (a single run) and compiled by numba
    (:mod:`pipeline.loop.compiled`, the family runner's workers): the same operations on the
    same C library's functions, so the same bits (the tests hold them equal).

    Parameters
    ----------
    state : sequence of 7 floats
        ``[X, Y, psi, vx, vy, r, delta]`` (a list in CPython, an array compiled).
    constants : sequence of 13 floats
        :func:`single_track_constants` (a tuple in CPython, an array compiled).

    Returns
    -------
    ndarray, shape (7,)
        The state one sample period later (a new array).
    """
    m, iz, a, b = constants[0], constants[1], constants[2], constants[3]
    cf, cr, lim_f, lim_r = constants[4], constants[5], constants[6], constants[7]
    tau, acc_max, d_max = constants[8], constants[9], constants[10]
    kinematic_below, brake_max, wheelbase = constants[11], constants[12], a + b
    # the steering rate is cut to 0 at the steering bound (the same rule in every stage)
    rate_at_upper = rate_cmd if rate_cmd <= 0 else 0.0
    rate_at_lower = rate_cmd if rate_cmd >= 0 else 0.0
    h = dt_s / substeps
    sixth = h / 6.0
    X, Y, psi, vx = state[0], state[1], state[2], state[3]
    vy, r, delta = state[4], state[5], state[6]
    for _ in range(substeps):
        if vx < kinematic_below:
            # below the hand-over speed: the kinematic single-track (no tyre slip; the tyre
            # law's 1/vx stiffness would need ever smaller steps), vy and r held to the steering
            kinematic_substep = single_track_kinematic_substep(
                X, Y, psi, vx, delta, rate_cmd, target, tau, acc_max, d_max, b, wheelbase, h,
                brake_max)
            X, Y, psi, vx = kinematic_substep[0], kinematic_substep[1], kinematic_substep[2], \
                kinematic_substep[3]
            vy, r, delta = kinematic_substep[4], kinematic_substep[5], kinematic_substep[6]
            continue
        k2 = k3 = k4 = k5 = k6 = 0.0   # the previous stage's slopes (X, Y never feed back)
        s0 = s1 = s2 = s3 = s4 = s5 = s6 = 0.0
        for stage in range(4):
            # RK4's stages: (fraction of the substep, weight) = (0, 1), (.5, 2), (.5, 2), (1, 1)
            fraction = 0.0 if stage == 0 else (0.5 if stage < 3 else 1.0)
            weight = 2.0 if stage == 1 or stage == 2 else 1.0
            step = fraction * h
            p, u, v = psi + step * k2, vx + step * k3, vy + step * k4
            w, d = r + step * k5, delta + step * k6
            u_safe = u if u > 0.1 else 0.1
            fy_front = lim_f * tanh(cf * (d - atan2(v + a * w, u_safe)) / lim_f)
            fy_rear = lim_r * tanh(cr * -atan2(v - b * w, u_safe) / lim_r)
            accel = (target - u) / tau
            accel = acc_max if accel > acc_max else (-brake_max if accel < -brake_max else accel)
            k6 = rate_at_upper if d >= d_max else (rate_at_lower if d <= -d_max else rate_cmd)
            cos_d, cos_p, sin_p = cos(d), cos(p), sin(p)
            k0, k1, k2 = u * cos_p - v * sin_p, u * sin_p + v * cos_p, w
            k3, k4 = accel + v * w, (fy_front * cos_d + fy_rear) / m - u * w
            k5 = (a * fy_front * cos_d - b * fy_rear) / iz
            s0, s1, s2, s3 = s0 + weight * k0, s1 + weight * k1, s2 + weight * k2, s3 + weight * k3
            s4, s5, s6 = s4 + weight * k4, s5 + weight * k5, s6 + weight * k6
        X, Y, psi, vx = X + sixth * s0, Y + sixth * s1, psi + sixth * s2, vx + sixth * s3
        vy, r = vy + sixth * s4, r + sixth * s5
        delta = delta + sixth * s6
        delta = d_max if delta > d_max else (-d_max if delta < -d_max else delta)
    out = np.empty(7)
    out[0], out[1], out[2], out[3] = X, Y, psi, vx
    out[4], out[5], out[6] = vy, r, delta
    return out



def single_track_rk4_rows(states: np.ndarray, constants: np.ndarray, rates_cmd: np.ndarray,
                          targets: np.ndarray, dt_s: np.ndarray, substeps: np.ndarray
                          ) -> np.ndarray:
    """:func:`single_track_rk4` for each row: the plants of several members stepped at once
    by the lockstep engine (:mod:`pipeline.loop.engine`), each with its own constants, steering
    rate, speed target, sample period and substeps.

    The same statement per row, so the same bits as a member stepped alone (compiled by numba
    in :mod:`pipeline.loop.compiled`, one call for the whole batch instead of one per member).

    Parameters
    ----------
    states : ndarray, shape (n, 7)
    constants : ndarray, shape (n, 13)
        :func:`single_track_constants` of each row's vehicle.
    rates_cmd, targets, dt_s : ndarray, shape (n,)
    substeps : ndarray of int, shape (n,)

    Returns
    -------
    ndarray, shape (n, 7)
    """
    out = np.empty((states.shape[0], 7))
    for i in range(states.shape[0]):
        out[i] = single_track_rk4(states[i], constants[i], rates_cmd[i], targets[i], dt_s[i],
                                  substeps[i])
    return out

def single_track_kinematic_substep(X: float, Y: float, psi: float, vx: float, delta: float,
                                   rate_cmd: float, target: float, tau: float, acc_max: float,
                                   d_max: float, b: float, wheelbase: float, h: float,
                                   brake_max: float
                                   ) -> tuple[float, float, float, float, float, float, float]:
    """One RK4 substep of :func:`single_track_rk4` below the hand-over speed: the kinematic
    single-track about the centre of gravity (side slip ``beta = atan(b tan delta / L)``,
    yaw rate ``vx tan delta / L``), the same speed loop and steering actuator; returns
    ``X, Y, psi, vx, vy, r, delta`` with ``vy = vx tan beta`` and ``r`` the kinematic ones
    (``brake_max``: the speed loop's braking limit)."""
    rate_at_upper = rate_cmd if rate_cmd <= 0 else 0.0
    rate_at_lower = rate_cmd if rate_cmd >= 0 else 0.0
    s0 = s1 = s2 = s3 = s6 = 0.0
    k2 = k3 = k6 = 0.0
    for stage in range(4):
        fraction = 0.0 if stage == 0 else (0.5 if stage < 3 else 1.0)
        weight = 2.0 if stage == 1 or stage == 2 else 1.0
        step = fraction * h
        p, u, d = psi + step * k2, vx + step * k3, delta + step * k6
        accel = (target - u) / tau
        accel = acc_max if accel > acc_max else (-brake_max if accel < -brake_max else accel)
        k6 = rate_at_upper if d >= d_max else (rate_at_lower if d <= -d_max else rate_cmd)
        tan_d = tan(d)
        side = atan2(b * tan_d, wheelbase)
        k0, k1 = u * cos(p + side) / cos(side), u * sin(p + side) / cos(side)
        k2, k3 = u * tan_d / wheelbase, accel
        s0, s1, s2, s3, s6 = s0 + weight * k0, s1 + weight * k1, s2 + weight * k2, \
            s3 + weight * k3, s6 + weight * k6
    sixth = h / 6.0
    X, Y, psi, vx = X + sixth * s0, Y + sixth * s1, psi + sixth * s2, vx + sixth * s3
    delta = delta + sixth * s6
    delta = d_max if delta > d_max else (-d_max if delta < -d_max else delta)
    tan_d = tan(delta)
    return X, Y, psi, vx, vx * b * tan_d / wheelbase, vx * tan_d / wheelbase, delta


#: Kinematic bicycle (paper Appendix A): state [x, y, theta, v], input [a, delta].
KINEMATIC_STATE_NAMES = ("X_m", "Y_m", "psi_rad", "v_mps")


def kinematic_derivative(state: np.ndarray, control_input: np.ndarray,
                         wheelbase_m: float) -> np.ndarray:
    """``f(x, u)`` of Appendix A: ``[v cos th, v sin th, v/L tan delta, a]``."""
    _, _, theta, v = state
    accel, delta = control_input
    return np.array([v * np.cos(theta), v * np.sin(theta), v / wheelbase_m * np.tan(delta),
                     accel])


def kinematic_euler_step(state: np.ndarray, control_input: np.ndarray, wheelbase_m: float,
                         dt_s: float) -> np.ndarray:
    """The MPC's prediction model: one forward-Euler step ``x + Ts f(x, u)`` (as Appendix A's
    loop advances its state)."""
    return np.asarray(state, float) + dt_s * kinematic_derivative(state, control_input,
                                                                  wheelbase_m)


def kinematic_jacobians(state: np.ndarray, control_input: np.ndarray, wheelbase_m: float,
                        dt_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Linearization of :func:`kinematic_euler_step` about ``(state, control_input)``.

    Returns
    -------
    A : ndarray, shape (4, 4)
    B : ndarray, shape (4, 2)
    c : ndarray, shape (4,)
        Offset so that ``x+ ~= A x + B u + c`` near the point.
    """
    _, _, theta, v = state
    accel, delta = control_input
    L = wheelbase_m
    A = np.eye(4)
    A[0, 2] = -dt_s * v * np.sin(theta)
    A[0, 3] = dt_s * np.cos(theta)
    A[1, 2] = dt_s * v * np.cos(theta)
    A[1, 3] = dt_s * np.sin(theta)
    A[2, 3] = dt_s * np.tan(delta) / L
    B = np.zeros((4, 2))
    B[2, 1] = dt_s * v / (L * np.cos(delta) ** 2)
    B[3, 0] = dt_s
    c = kinematic_euler_step(state, control_input, L, dt_s) - A @ state - B @ control_input
    return A, B, c


def kinematic_plant_step(state: np.ndarray, control_input: np.ndarray, wheelbase_m: float,
                         dt_s: float, substeps: int) -> np.ndarray:
    """The plant of the kinematic track: the exact nonlinear model, RK4 with substeps, input
    held over the step (plain floats; the same equations as :func:`kinematic_derivative`)."""
    h = dt_s / substeps
    half, sixth = 0.5 * h, h / 6.0
    accel, delta = float(control_input[0]), float(control_input[1])
    tan_delta = tan(delta)
    X, Y, theta, v = (float(value) for value in state)
    # the four stages written out on scalars (rates: v cos th, v sin th, v / L tan d, a)
    for _ in range(substeps):
        x1, y1, t1 = v * cos(theta), v * sin(theta), v / wheelbase_m * tan_delta
        th2, v2 = theta + half * t1, v + half * accel
        x2, y2, t2 = v2 * cos(th2), v2 * sin(th2), v2 / wheelbase_m * tan_delta
        th3, v3 = theta + half * t2, v + half * accel
        x3, y3, t3 = v3 * cos(th3), v3 * sin(th3), v3 / wheelbase_m * tan_delta
        th4, v4 = theta + h * t3, v + h * accel
        x4, y4, t4 = v4 * cos(th4), v4 * sin(th4), v4 / wheelbase_m * tan_delta
        X = X + sixth * (x1 + 2 * x2 + 2 * x3 + x4)
        Y = Y + sixth * (y1 + 2 * y2 + 2 * y3 + y4)
        theta = theta + sixth * (t1 + 2 * t2 + 2 * t3 + t4)
        v = v + sixth * (accel + 2 * accel + 2 * accel + accel)
    return np.array([X, Y, theta, v])
