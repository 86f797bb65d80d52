"""The lateral MPC as a nonlinear program (``controller.backend=nmpc`` with
``controller.kind=mpc``): CasADi + IPOPT on the plant's own nonlinear single-track model.

The QP of :mod:`~pipeline.loop.controller.lateral` predicts with the paper's linear model; this
controller states the same problem on the nonlinear model, so that ``make nmpc-check`` can say
what the linearization changes on the lateral track:

* the same data: the frame (the drivable path of ``frame=path`` or the start-goal line of
  ``frame=fixed``), stations, references, half-planes, horizon, move blocking and weights,
  all from :meth:`LateralMpc.inputs_from <pipeline.loop.controller.lateral.LateralMpc>`;
* prediction: the single-track model of the plant (:func:`~pipeline.loop.model.plant_derivative`:
  tanh tyres with the plant's friction limits, the first-order speed loop towards the planned
  speed, the ``vy r`` term), integrated by RK4 with ``controller.nmpc_substeps`` steps per
  sample (single shooting: the states are functions of the moves);
* the errors measured as the QP's model reads them, at each step's station on the frame:
  ``e_y = n_k . (p_k - c_k)`` (``c_k``, ``n_k``: the frame's point and left normal at the
  station), ``e_psi = psi_k - psi_frame,k``; the cost and the soft half-planes on them;
* the steering angle within its bound as a constraint, the steering rate as a bound.

One NLP per structure (CasADi's ``nlpsol``, IPOPT), re-solved every step, warm-started from the
previous moves shifted. Why IPOPT: CasADi ships it in its wheel, it is what CasADi and do-mpc
default to, and the program is small (3 moves, 30 slacks).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.loop.controller.base import ControlStep, Observation
from pipeline.loop.controller.frames import PathFrame
from pipeline.loop.controller.lateral import LateralMpc
from pipeline.loop.controller.lateral_qp import LateralQpStructure, MpcInputs, blocking_matrix
from pipeline.loop.controller.nmpc import ipopt_solve
from pipeline.loop.controller.qp import QpCache
from pipeline.loop.controller_settings import Backend, MpcSettings, settings_of
from pipeline.loop.kernels import Kernels
from pipeline.loop.model import single_track_constants
from pipeline.loop.settings import ModelConfig, VehicleConfig


@dataclass(frozen=True)
class LateralNlp:
    """The NLP of one structure: the solver, a prediction function and the bounds."""

    solver: object
    predict: object   # CasADi Function (U, p) -> (plant states (7, N + 1), e_y (N + 1))
    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    n_moves: int


def single_track_ode(ca: Any, x: Any, rate: Any, speed_target: Any,
                     constants: tuple[float, ...]) -> Any:
    """:func:`~pipeline.loop.model.plant_derivative` in CasADi symbols (the steering bound is a
    constraint of the program, not a cut of the rate)."""
    # the dynamic plant (its hand-over to the kinematic one below a speed is not modelled)
    m, iz, a, b, cf, cr, lim_f, lim_r, tau, acc_max = constants[:10]
    brake_max = constants[12]  # single_track_constants' braking limit
    vx, vy, r, delta, psi = x[3], x[4], x[5], x[6], x[2]
    vx_safe = ca.fmax(vx, 0.1)
    fy_front = lim_f * ca.tanh(cf * (delta - ca.atan2(vy + a * r, vx_safe)) / lim_f)
    fy_rear = lim_r * ca.tanh(cr * -ca.atan2(vy - b * r, vx_safe) / lim_r)
    accel = ca.fmin(ca.fmax((speed_target - vx) / tau, -brake_max), acc_max)
    return ca.vertcat(vx * ca.cos(psi) - vy * ca.sin(psi), vx * ca.sin(psi) + vy * ca.cos(psi),
                      r, accel + vy * r, (fy_front * ca.cos(delta) + fy_rear) / m - vx * r,
                      (a * fy_front * ca.cos(delta) - b * fy_rear) / iz, rate)


def build_lateral_nlp(structure: LateralQpStructure, constants: tuple[Any, ...], sample_time_s: float,
                      substeps: int, max_iter: int) -> LateralNlp:
    """The program of :mod:`this module <pipeline.loop.controller.lateral_nmpc>` with parameters
    ``[x0 (7), speed target, prediction step, frame (3 N: c_x, c_y, heading per step),
    references (4 N: e_y, e_psi, r, delta per step), G (N M), h (N M)]`` (step-major) and
    variables ``[U (Nc), S (N M)]``. ``sample_time_s`` is kept for the key only: the step is a
    parameter (``controller.horizon_reach_m`` stretches it at low speed)."""
    import casadi as ca

    N, Nc, M = structure.horizon, structure.control_horizon, structure.max_obstacles
    w = structure.weights
    q_y, q_psi, q_r, q_d, r_u = w.tracking
    w1, w2 = w.slack_linear, w.slack_quadratic
    blocking = blocking_matrix(N, Nc, structure.input_hold)
    U = ca.SX.sym("U", Nc)
    S = ca.SX.sym("S", N * M)
    p = ca.SX.sym("p", 9 + 7 * N + 2 * N * M)
    x, target, step = p[0:7], p[7], p[8] / substeps
    frame = ca.reshape(p[9:9 + 3 * N], 3, N)
    refs = ca.reshape(p[9 + 3 * N:9 + 7 * N], 4, N)
    G = p[9 + 7 * N:9 + 7 * N + N * M]
    h = p[9 + 7 * N + N * M:]
    moves = ca.mtimes(ca.DM(blocking.T), U)
    cost = 0
    rows, lateral, states = [], [ca.SX(0.0)], [x]
    for k in range(N):
        for _ in range(substeps):
            k1 = single_track_ode(ca, x, moves[k], target, constants)
            k2 = single_track_ode(ca, x + 0.5 * step * k1, moves[k], target, constants)
            k3 = single_track_ode(ca, x + 0.5 * step * k2, moves[k], target, constants)
            k4 = single_track_ode(ca, x + step * k3, moves[k], target, constants)
            x = x + step / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        cx, cy, heading = frame[0, k], frame[1, k], frame[2, k]
        e_y = -ca.sin(heading) * (x[0] - cx) + ca.cos(heading) * (x[1] - cy)
        e_psi = x[2] - heading
        lateral.append(e_y)
        states.append(x)
        cost += (q_y * (e_y - refs[0, k]) ** 2 + q_psi * (e_psi - refs[1, k]) ** 2
                 + q_r * (x[5] - refs[2, k]) ** 2 + q_d * (x[6] - refs[3, k]) ** 2
                 + r_u * moves[k] ** 2)
        rows.append(x[6])
        for j in range(M):
            i = k * M + j
            rows.append(G[i] * e_y + S[i] - h[i])
    cost += w1 * ca.sum1(S) + w2 * ca.sumsqr(S)
    nlp = {"x": ca.vertcat(U, S), "p": p, "f": cost, "g": ca.vertcat(*rows)}
    options = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
               "ipopt.max_iter": int(max_iter), "ipopt.tol": 1e-8,
               "ipopt.acceptable_tol": 1e-6}
    solver = ca.nlpsol("lateral_nmpc", "ipopt", nlp, options)
    predict = ca.Function("predict", [U, p], [ca.horzcat(*states), ca.vertcat(*lateral)])
    rate, d_max = structure.steering_rate_max_rad_s, structure.steering_max_rad
    lbx = np.concatenate([np.full(Nc, -rate), np.zeros(N * M)])
    ubx = np.concatenate([np.full(Nc, rate), np.full(N * M, np.inf)])
    lbg = np.tile(np.concatenate([[-d_max], np.zeros(M)]), N)
    ubg = np.tile(np.concatenate([[d_max], np.full(M, np.inf)]), N)
    return LateralNlp(solver, predict, lbx, ubx, lbg, ubg, Nc)


class LateralNmpc(LateralMpc):
    """The lateral MPC's problem on the nonlinear model (see the module docstring).

    Parameters
    ----------
    controller, vehicle, model, sample_time_s, qp_cache
        As :class:`~pipeline.loop.controller.lateral.LateralMpc`; ``qp_cache`` keeps the NLP
        of this process (a CasADi solver does not travel to worker processes: each builds its
        own, once).
    """

    def __init__(self, controller: MpcSettings, vehicle: VehicleConfig,
                 model: ModelConfig | None = None, sample_time_s: float = 0.1,
                 qp_cache: QpCache | None = None, kernels: Kernels | None = None) -> None:
        controller = settings_of(controller, MpcSettings)
        # the QP's data (models, path, references, half-planes) without a QP of its own
        super().__init__(dataclasses.replace(controller, backend=Backend.DAQP), vehicle, model,
                         sample_time_s, qp_cache, kernels)
        self.cfg = controller
        structure = LateralQpStructure.of(controller, vehicle)
        cache = qp_cache if qp_cache is not None else QpCache()
        before_n, before_t = cache.compile_count, cache.compile_time_s
        constants = single_track_constants(vehicle)
        key = ("lateral", "nmpc", structure, self.sample_time_s, constants,
               controller.nmpc_substeps, controller.solver_max_iter)
        self.nlp = cache.get(key, lambda: build_lateral_nlp(
            structure, constants, self.sample_time_s, controller.nmpc_substeps,
            controller.solver_max_iter))
        self.compile_count = cache.compile_count - before_n
        self.compile_time_s = cache.compile_time_s - before_t
        self._moves: np.ndarray | None = None

    def frame_parameters(self) -> np.ndarray:
        """The frame at steps 1..N as ``(3, N)``: point and heading at each station, from the
        last :meth:`inputs_from` (the path, or the line in the fixed frame)."""
        N, record = self.horizon, self.frame.record
        stations = np.asarray(record[-2], float)[1:N + 1]
        if record[0] == "fixed":
            origin, heading = record[1], record[2]
            u = np.array([np.cos(heading), np.sin(heading)])
            points = np.asarray(origin)[None, :] + stations[:, None] * u[None, :]
            return np.vstack([points.T, np.full(N, heading)])
        path = record[1]
        return np.vstack([path.to_global(stations, np.zeros(N)).T, path.heading_at(stations)])

    def step(self, obs: Observation) -> ControlStep:
        """One closed-loop step: the QP's data, then the nonlinear program on them."""
        inputs, log = self.inputs_from(obs)
        refs = np.vstack([inputs.y_ref_m, inputs.psi_ref_rad, inputs.yaw_rate_reference(),
                          inputs.steering_reference()])
        params = np.concatenate([obs.plant_state, [obs.speed_ref_mps, self.frame.record[-1]],
                                 self.frame_parameters().ravel(order="F"),
                                 refs.ravel(order="F"), inputs.constraint_gain.ravel(),
                                 inputs.constraint_bound.ravel()])
        status, iterations, elapsed, values = "not_solved", -1, 0.0, None
        if np.all(np.isfinite(params)):
            status, iterations, elapsed, values = self._solve_nlp(params)
        if status in ("optimal", "optimal_inaccurate") and values is not None \
                and np.all(np.isfinite(values)):
            step, plan_lateral = self._accepted(values, params, inputs, status, iterations,
                                                elapsed, log)
        else:
            step, plan_lateral = self._fell_back(obs, status, iterations, elapsed, log)
        self.keep_record(inputs, plan_lateral)
        return step

    def _solve_nlp(self, params: np.ndarray) -> tuple[str, int, float, np.ndarray | None]:
        """IPOPT on the NLP at ``params``, warm-started from the last moves (shifted)
        (:func:`~pipeline.loop.controller.nmpc.ipopt_solve`)."""
        N, Nc = self.horizon, self.nlp.n_moves
        M = self.cfg.max_obstacles
        moves = np.concatenate([self._moves[1:], self._moves[-1:]]) \
            if self._moves is not None else np.zeros(Nc)
        start = np.concatenate([moves, np.zeros(N * M)])
        start = np.clip(start, self.nlp.lbx, self.nlp.ubx)
        return ipopt_solve(self.nlp.solver, x0=start, p=params, lbx=self.nlp.lbx,
                           ubx=self.nlp.ubx, lbg=self.nlp.lbg, ubg=self.nlp.ubg)

    def _accepted(self, values: np.ndarray, params: np.ndarray, inputs: MpcInputs,
                  status: str, iterations: int, elapsed: float, log: dict[str, Any]
                  ) -> tuple[ControlStep, np.ndarray | None]:
        """The step of a solved NLP (its moves kept for the next start and the fallback), and
        the plan's lateral error at its steps."""
        N, Nc = self.horizon, self.nlp.n_moves
        U = values[:Nc]
        plan = (U @ self.blocking)[None, :]
        self._moves = U
        self.fallback.accept(plan)
        predicted, lateral = (np.asarray(v, dtype=float) for v in
                              self.nlp.predict(U, params))
        lateral = lateral.ravel()
        gaps = inputs.constraint_bound - inputs.constraint_gain * lateral[1:, None]
        states = np.zeros((5, N + 1))
        states[0] = lateral
        step = ControlStep(plan[:, 0].copy(), plan, states, status, iterations, elapsed,
                           "none", float(max(np.max(gaps, initial=0.0), 0.0)), log)
        # the plan's poses, for the next step's stations (as the QP's plan gives them)
        if isinstance(self.frame, PathFrame):
            self.frame.plan_poses((predicted[:2].T, predicted[2] + np.arctan2(
                predicted[4], np.maximum(predicted[3], 0.1))))
        return step, lateral

    def _fell_back(self, obs: Observation, status: str, iterations: int, elapsed: float,
                   log: dict[str, Any]) -> tuple[ControlStep, None]:
        """The fallback's step (steering back toward straight at the rate limit), no plan."""
        self._moves = None
        delta = obs.plant_state[6] if np.isfinite(obs.plant_state[6]) else 0.0
        rate_max = self.vehicle.steering_rate_max_rad_s
        step = self.fallback.step(
            status, iterations, elapsed,
            lambda: np.array([float(np.clip(-delta / self.sample_time_s, -rate_max,
                                            rate_max))]), log)
        if isinstance(self.frame, PathFrame):
            self.frame.plan_poses(None)
        return step, None
