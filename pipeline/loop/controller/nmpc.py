"""Appendix A's ``nlmpc`` as a nonlinear MPC (``controller.backend=nmpc``): CasADi + IPOPT.

MATLAB's ``nlmpc`` solves the nonlinear program itself (``fmincon``); the LTV-QP of
:mod:`~pipeline.loop.controller.kinematic` linearizes it. This controller states the same
program without linearization, so the two can be compared:

* prediction: the kinematic bicycle of Appendix A, forward-Euler steps
  ``x_{k+1} = x_k + Ts [v cos th, v sin th, v/L tan delta, a]`` (single shooting: the states are
  functions of the inputs, as ``nlmpc`` treats them);
* moves ``U`` (2 x Nc), held after the control horizon (``input_hold``), ``a`` and ``delta`` within
  their bounds;
* cost as MATLAB writes it, weights squared: ``sum |w_y (y_k - y_ref,k)|^2 + |w_u u_k|^2 +
  |w_du (u_k - u_{k-1})|^2``, plus the soft half-planes' slack penalty;
* the obstacle constraints of the other tracks: one soft half-plane per obstacle slot and step
  (:func:`~pipeline.loop.controller.references.kinematic_halfplanes`), built about the previous
  plan's rollout.

The NLP is built once per structure (CasADi function, IPOPT through ``nlpsol``) and re-solved
every step, warm-started from the previous plan shifted by one step. Why IPOPT: CasADi ships it
in its wheel (no system library), it is the interior-point method CasADi and do-mpc default to,
and the program is small (6 moves, 30 slacks); ``fmincon``'s SQP would need a QP solver plugin.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.errors import signals_kept
from pipeline.loop.controller.base import ControlStep, PlanFallback
from pipeline.loop.controller.kinematic import KinematicQpStructure, KinematicTrack
from pipeline.loop.controller.lateral_qp import blocking_matrix
from pipeline.loop.controller.qp import QpCache
from pipeline.loop.controller.references import kinematic_halfplanes
from pipeline.loop.controller_settings import KinematicMpcSettings, settings_of
from pipeline.loop.settings import VehicleConfig

#: IPOPT's return status mapped to the status words the log uses (CVXPY's).
IPOPT_STATUS = {"Solve_Succeeded": "optimal", "Solved_To_Acceptable_Level": "optimal_inaccurate",
                "Infeasible_Problem_Detected": "infeasible",
                "Maximum_Iterations_Exceeded": "user_limit",
                "Maximum_CpuTime_Exceeded": "user_limit"}
#: IPOPT's statuses of a solve stopped from outside (no callback of ours ever asks it to
#: stop): an interrupt, raised as one.
INTERRUPTED_STATUSES = ("User_Requested_Stop",)


def ipopt_solve(solver: Any, **arguments: Any) -> tuple[str, int, float, np.ndarray | None]:
    """A CasADi IPOPT ``solver`` called on ``arguments``: its status (:data:`IPOPT_STATUS`),
    iterations, wall time and solution vector (None, with status ``error:RuntimeError``, where
    CasADi raised on an evaluation error)."""
    status, iterations, values = "not_solved", -1, None
    began = time.perf_counter()
    with signals_kept():  # Ctrl-C inside IPOPT: an interrupt, never a failed solve
        try:
            result = solver(**arguments)
            stats = solver.stats()
            returned = stats.get("return_status", "")
            if returned in INTERRUPTED_STATUSES:
                raise KeyboardInterrupt(f"IPOPT stopped: {returned}")
            status = IPOPT_STATUS.get(returned, "solver_error")
            iterations = int(stats.get("iter_count", -1))
            values = np.asarray(result["x"], dtype=float).ravel()
        except RuntimeError:  # CasADi raises on evaluation errors (NaN in the NLP)
            status = "error:RuntimeError"
        except SystemError as exc:
            # a signal while numpy converts CasADi's result: numpy reports the interrupt the
            # conversion raised as a SystemError caused by it (seen on a loaded machine)
            cause = exc.__cause__ or exc.__context__
            if isinstance(cause, KeyboardInterrupt):
                raise cause from None
            raise
    elapsed = time.perf_counter() - began
    return status, iterations, elapsed, values


@dataclass(frozen=True)
class NmpcProblem:
    """The NLP of one structure: the CasADi solver and how its vectors are laid out."""

    solver: object
    horizon: int
    control_horizon: int
    max_obstacles: int
    lbx: np.ndarray
    ubx: np.ndarray
    n_constraints: int


def nmpc_cost_terms(structure: KinematicQpStructure
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Weights of the cost (squared, as MATLAB applies them) and the move-blocking matrix."""
    wy = np.asarray(structure.output_weights, float) ** 2
    wu = np.asarray(structure.input_weights, float) ** 2
    wdu = np.asarray(structure.input_rate_weights, float) ** 2
    blocking = blocking_matrix(structure.horizon, structure.control_horizon,
                               structure.input_hold)
    return wy, wu, wdu, blocking


def build_nmpc_problem(structure: KinematicQpStructure, sample_time_s: float,
                       wheelbase_m: float, max_iter: int) -> NmpcProblem:
    """The nonlinear program of :mod:`this module <pipeline.loop.controller.nmpc>` as a CasADi
    ``nlpsol`` with parameters ``[x0 (4), u_prev (2), y_ref (2 N, step-major), Gx, Gy, h
    (N M each, step-major)]`` and variables ``[U (2 Nc, column-major), S (N M)]``."""
    import casadi as ca

    N, Nc, M = structure.horizon, structure.control_horizon, structure.max_obstacles
    wy, wu, wdu, blocking = nmpc_cost_terms(structure)
    w1, w2 = structure.slack_weights
    U = ca.SX.sym("U", 2, Nc)
    S = ca.SX.sym("S", N * M)
    p = ca.SX.sym("p", 6 + 2 * N + 3 * N * M)
    x, u_prev = p[0:4], p[4:6]
    ref = ca.reshape(p[6:6 + 2 * N], 2, N)
    base = 6 + 2 * N
    Gx, Gy, h = (p[base + i * N * M: base + (i + 1) * N * M] for i in range(3))
    u_seq = ca.mtimes(U, ca.DM(blocking))
    cost, constraints = 0, []
    previous = u_prev
    for k in range(N):
        u = u_seq[:, k]
        x = x + sample_time_s * ca.vertcat(x[3] * ca.cos(x[2]), x[3] * ca.sin(x[2]),
                                           x[3] / wheelbase_m * ca.tan(u[1]), u[0])
        error = x[0:2] - ref[:, k]
        rate = u - previous
        cost += (wy[0] * error[0] ** 2 + wy[1] * error[1] ** 2 + wu[0] * u[0] ** 2
                 + wu[1] * u[1] ** 2 + wdu[0] * rate[0] ** 2 + wdu[1] * rate[1] ** 2)
        previous = u
        for j in range(M):
            i = k * M + j
            constraints.append(Gx[i] * x[0] + Gy[i] * x[1] + S[i] - h[i])
    cost += w1 * ca.sum1(S) + w2 * ca.sumsqr(S)
    nlp = {"x": ca.vertcat(ca.vec(U), S), "p": p, "f": cost, "g": ca.vertcat(*constraints)}
    options = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
               "ipopt.max_iter": int(max_iter), "ipopt.tol": 1e-10,
               "ipopt.acceptable_tol": 1e-7}
    solver = ca.nlpsol("nmpc", "ipopt", nlp, options)
    a_lo, a_hi = structure.accel_bounds_mps2
    d_max = structure.steering_max_rad
    lbx = np.concatenate([np.tile([a_lo, -d_max], Nc), np.zeros(N * M)])
    ubx = np.concatenate([np.tile([a_hi, d_max], Nc), np.full(N * M, np.inf)])
    return NmpcProblem(solver, N, Nc, M, lbx, ubx, N * M)


class KinematicNmpc(KinematicTrack):
    """The kinematic NMPC: one CasADi NLP (from ``qp_cache``), warm starts, the fallback.

    Parameters
    ----------
    controller : KinematicMpcSettings
        Its settings (its kind's schema, as composed).
    vehicle : VehicleConfig
    sample_time_s : float
    qp_cache : QpCache, optional
        Built problems shared across runs of this process (a CasADi solver does not travel to
        worker processes: each worker builds its own, once).
    """

    def __init__(self, controller: KinematicMpcSettings,
                 vehicle: VehicleConfig, sample_time_s: float,
                 qp_cache: QpCache | None = None) -> None:
        controller = settings_of(controller, KinematicMpcSettings)
        self.cfg, self.vehicle, self.ts = controller, vehicle, float(sample_time_s)
        self.horizon = controller.horizon
        self.structure = KinematicQpStructure.of(controller, vehicle)
        self.blocking = blocking_matrix(controller.horizon, controller.control_horizon,
                                        controller.input_hold)
        cache = qp_cache if qp_cache is not None else QpCache()
        before_n, before_t = cache.compile_count, cache.compile_time_s
        key = ("kinematic", "nmpc", self.structure, self.ts, vehicle.wheelbase_m,
               controller.solver_max_iter)
        self.problem = cache.get(key, lambda: build_nmpc_problem(
            self.structure, self.ts, vehicle.wheelbase_m, controller.solver_max_iter))
        self.compile_count = cache.compile_count - before_n
        self.compile_time_s = cache.compile_time_s - before_t
        self.fallback = PlanFallback(controller.horizon)
        self.u_prev = np.zeros(2)
        self._moves: np.ndarray | None = None
        self._steps_ahead_s = np.arange(1, controller.horizon + 1) * self.ts
        self.records: list[tuple[Any, ...]] = []

    def parameters(self, x0: np.ndarray, u_prev: np.ndarray, reference: np.ndarray,
                   halfplanes: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
        """The NLP's parameter vector (layout of :func:`build_nmpc_problem`)."""
        Gx, Gy, h = halfplanes
        return np.concatenate([x0, u_prev, reference.ravel(order="F"), Gx.ravel(), Gy.ravel(),
                               h.ravel()])

    def solve(self, x0: np.ndarray, u_prev: np.ndarray, reference: np.ndarray,
              predicted_obstacles: np.ndarray, radii: np.ndarray,
              log: dict[str, Any] | None = None) -> ControlStep:
        """Solve one step (arguments as :meth:`KinematicLtvMpc.solve`)."""
        N, Nc, M = self.horizon, self.problem.control_horizon, self.problem.max_obstacles
        last = self.fallback.last_plan
        guess_plan = np.hstack([last[:, 1:], last[:, -1:]]) if last is not None \
            else np.zeros((2, N))
        status, iterations, elapsed, values = "not_solved", -1, 0.0, None
        halfplanes: tuple[Any, ...] | None = None
        if np.all(np.isfinite(x0)) and np.all(np.isfinite(u_prev)):
            states = self.rollout(x0, guess_plan)
            halfplanes = kinematic_halfplanes(states, reference, predicted_obstacles, radii,
                                              self.vehicle, self.cfg)
            moves = guess_plan[:, :Nc]
            start = np.concatenate([moves.ravel(order="F"), np.zeros(N * M)])
            start = np.clip(start, self.problem.lbx, self.problem.ubx)
            status, iterations, elapsed, values = ipopt_solve(
                self.problem.solver, x0=start,
                p=self.parameters(x0, u_prev, reference, halfplanes), lbx=self.problem.lbx,
                ubx=self.problem.ubx, lbg=0.0, ubg=np.inf)
        log = {**(log or {}), "ltv_passes": 0, "ltv_change": float("nan")}
        if status in ("optimal", "optimal_inaccurate") and values is not None \
                and halfplanes is not None and np.all(np.isfinite(values)):
            plan = values[:2 * Nc].reshape(2, Nc, order="F") @ self.blocking
            self.fallback.accept(plan)
            states = self.rollout(x0, plan)
            Gx, Gy, h = halfplanes
            needed = h - Gx * states[0, 1:][:, None] - Gy * states[1, 1:][:, None]
            return ControlStep(plan[:, 0].copy(), plan, states, status, iterations, elapsed,
                               "none", float(max(np.max(needed, initial=0.0), 0.0)), log)
        speed = x0[3] if np.isfinite(x0[3]) else 0.0
        a_lo, a_hi = self.cfg.accel_bounds_mps2
        return self.fallback.step(
            status, iterations, elapsed,
            lambda: np.array([float(np.clip(-speed / self.ts, a_lo, a_hi)), 0.0]), log)
