"""Controller stage: the lateral MPC (CVXPY, solved by Clarabel) and its APF-derived inputs.

The QP over ``N`` steps, built once per run with ``cp.Parameter``s (DPP)::

    min  sum_k q_y (y_k - y_ref,k)^2 + q_psi (epsi_k - psi_ref,k)^2 + q_r r_k^2 + q_d delta_k^2
         + r_u u_k^2 + w1 sum(s) + w2 sum(s^2)
    s.t. x_{k+1} = Ad x_k + Bd u_k + Ed d_k,  x_0 = measured state
         |u_k| <= delta_dot_max,  |delta_k| <= delta_max,
         u_k = U[min(k, Nc - 1)] (hold_last) or 0 for k >= Nc (zero_rate)
         G_kj y_k + s_kj >= h_kj,  s >= 0   (soft half-plane per obstacle j and step k)

A failed solve never raises: the controller falls back to the shifted previous plan, then to a
bounded input that brings the steering back to zero, and says which in the result.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from pipeline.config import ControllerConfig, VehicleConfig
from pipeline.model import LateralModel

OPTIMAL_STATUSES = (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)


@dataclass(frozen=True)
class MpcInputs:
    """Per-step data of the QP (everything that is a ``cp.Parameter``)."""

    x0: np.ndarray
    model: LateralModel
    y_ref_m: np.ndarray
    psi_ref_rad: np.ndarray
    constraint_gain: np.ndarray
    constraint_bound: np.ndarray
    disturbance_rad_s: np.ndarray


@dataclass(frozen=True)
class MpcStep:
    """Result of one controller step.

    Attributes
    ----------
    steering_rate_rad_s : float
        Input applied now.
    planned_rates_rad_s : ndarray, shape (N,)
        Input sequence of the plan that was applied (after fallback, if any).
    predicted_states : ndarray, shape (5, N + 1) or None
    status : str
        Solver status, or ``"not_solved"`` when the state was not finite.
    iterations : int
    solve_time_s : float
        Wall time of ``problem.solve`` (s).
    fallback : str
        ``"none"``, ``"shifted_plan"`` or ``"safe_input"``.
    max_slack_m : float
    """

    steering_rate_rad_s: float
    planned_rates_rad_s: np.ndarray
    predicted_states: np.ndarray | None
    status: str
    iterations: int
    solve_time_s: float
    fallback: str
    max_slack_m: float


class CompiledQp:
    """A CVXPY problem solved repeatedly by Clarabel, counting its compilations.

    Subclasses set ``self.problem`` and ``self.cfg`` (a :class:`ControllerConfig`).
    """

    problem: cp.Problem
    cfg: ControllerConfig
    compile_count: int = 0
    compile_time_s: float = 0.0
    _compiled_program: object = None

    def _solve_raw(self) -> tuple[str, int, float]:
        """Solve once; return status, Clarabel's iteration count and the wall time (s)."""
        start = time.perf_counter()
        with warnings.catch_warnings():
            # "solution may be inaccurate": the status says so and is logged per step
            warnings.simplefilter("ignore", UserWarning)
            self.problem.solve(solver=cp.CLARABEL, max_iter=self.cfg.solver_max_iter)
        elapsed = time.perf_counter() - start
        # DPP: CVXPY keeps the parameter-to-data map after the first solve; a new one means
        # the problem was compiled again
        program = getattr(self.problem._cache, "param_prog", None)
        if program is not self._compiled_program:
            self.compile_count += 1
            self.compile_time_s = float(getattr(self.problem, "compilation_time", 0.0) or 0.0)
            self._compiled_program = program
        stats = self.problem.solver_stats
        iterations = int(stats.num_iters) if stats is not None and stats.num_iters is not None else -1
        return str(self.problem.status), iterations, elapsed


class ClarabelDirect:
    """Backend ``clarabel_direct``: CVXPY's canonicalization once, then Clarabel directly.

    At the first call the problem is compiled by CVXPY (``get_problem_data``) and its
    parameter-to-data map is read off once: the QP data ``(q, A, b)`` is affine in the stacked
    parameter vector ``theta``, so applying the map (``apply_parameters``, zeros kept so the
    sparsity never changes) at ``theta = 0`` and at each unit vector gives the exact affine map.
    Every step then costs three small matrix-vector products and an in-place update of the kept
    Clarabel solver (``q``, ``A`` values, ``b``); the primal solution is read back through
    CVXPY's variable offsets. Same QP, same solver, without CVXPY's per-call overhead.
    """

    STATUS = {"Solved": cp.OPTIMAL, "AlmostSolved": cp.OPTIMAL_INACCURATE,
              "PrimalInfeasible": cp.INFEASIBLE, "AlmostPrimalInfeasible": cp.INFEASIBLE_INACCURATE,
              "DualInfeasible": cp.UNBOUNDED, "AlmostDualInfeasible": cp.UNBOUNDED_INACCURATE,
              "MaxIterations": cp.USER_LIMIT, "MaxTime": cp.USER_LIMIT}

    def __init__(self) -> None:
        self.maps = None
        self.solver = None

    @staticmethod
    def _data(param_prog) -> tuple:
        import scipy.sparse as sp

        P, q, _, A, b = param_prog.apply_parameters(keep_zeros=True, quad_obj=True)
        A = sp.csc_matrix(-A)
        A.sort_indices()
        return sp.triu(P).tocsc(), np.asarray(q, float), A, np.asarray(b, float)

    def _compile(self, owner) -> None:
        import clarabel
        import scipy.sparse as sp
        from cvxpy.reductions.solvers.conic_solvers.clarabel_conif import dims_to_solver_cones

        start = time.perf_counter()
        data, _, inverse = owner.problem.get_problem_data(cp.CLARABEL)
        param_prog = data["param_prob"]
        stuffing = next(inv for inv in inverse if getattr(inv, "var_offsets", None)
                        and owner.X.id in inv.var_offsets and owner.U.id in inv.var_offsets
                        and len(inv.var_offsets) > 3)
        params = owner.parameter_list()
        sizes = [p.size for p in params]
        saved = [p.value for p in params]

        def assign(theta: np.ndarray) -> None:
            for param, chunk in zip(params, np.split(theta, np.cumsum(sizes)[:-1])):
                param.value = chunk.reshape(param.shape, order="F")

        n_theta = int(sum(sizes))
        assign(np.zeros(n_theta))
        P, q0, A0, b0 = self._data(param_prog)
        Tq = np.zeros((q0.size, n_theta))
        TA = np.zeros((A0.data.size, n_theta))
        Tb = np.zeros((b0.size, n_theta))
        for i in range(n_theta):
            unit = np.zeros(n_theta)
            unit[i] = 1.0
            assign(unit)
            _, q, A, b = self._data(param_prog)
            if not (np.array_equal(A.indices, A0.indices) and np.array_equal(A.indptr, A0.indptr)):
                raise RuntimeError("sparsity of A changed with the parameters")
            Tq[:, i], TA[:, i], Tb[:, i] = q - q0, A.data - A0.data, b - b0
        for param, value in zip(params, saved):
            param.value = value
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        settings.presolve_enable = False  # keeps in-place data updates allowed
        settings.max_iter = owner.cfg.solver_max_iter
        # the maps are mostly zeros (each entry depends on a few parameters): keep them sparse
        self.maps = {"P": P, "A": A0, "q0": q0, "a0": A0.data.copy(), "b0": b0,
                     "Tq": sp.csr_matrix(Tq), "TA": sp.csr_matrix(TA), "Tb": sp.csr_matrix(Tb), "cones": dims_to_solver_cones(data["dims"]),
                     "settings": settings, "offsets": stuffing.var_offsets}
        owner.compile_count += 1
        owner.compile_time_s = time.perf_counter() - start

    def solve(self, owner, theta: np.ndarray) -> tuple[str, int, float, np.ndarray, np.ndarray]:
        """Status, iterations, wall time (s) of map + solve, X (5 x N+1) and U (Nc,)."""
        import clarabel
        import scipy.sparse as sp

        if self.maps is None:
            self._compile(owner)
        m = self.maps
        start = time.perf_counter()
        q = m["q0"] + m["Tq"] @ theta
        A = sp.csc_matrix((m["a0"] + m["TA"] @ theta, m["A"].indices, m["A"].indptr),
                          shape=m["A"].shape)
        b = m["b0"] + m["Tb"] @ theta
        if self.solver is None:
            self.solver = clarabel.DefaultSolver(m["P"], q, A, b, m["cones"], m["settings"])
        else:
            self.solver.update(q=q, A=A, b=b)
        solution = self.solver.solve()
        elapsed = time.perf_counter() - start
        status = self.STATUS.get(str(solution.status).split(".")[-1], cp.SOLVER_ERROR)
        x = np.asarray(solution.x)
        ox, ou = m["offsets"][owner.X.id], m["offsets"][owner.U.id]
        states = x[ox:ox + owner.X.size].reshape(owner.X.shape, order="F")
        return status, int(solution.iterations), elapsed, states, x[ou:ou + owner.U.size]


def blocking_matrix(horizon: int, control_horizon: int, input_hold: str) -> np.ndarray:
    """Matrix ``T`` (Nc x N) with ``u_seq = U @ T`` for the move-blocking rule."""
    T = np.zeros((control_horizon, horizon))
    for k in range(horizon):
        if k < control_horizon:
            T[k, k] = 1.0
        elif input_hold == "hold_last":
            T[control_horizon - 1, k] = 1.0
    return T


class LateralMpc(CompiledQp):
    """The lateral MPC problem, compiled once and re-solved with new parameter values.

    Parameters
    ----------
    controller : ControllerConfig
    vehicle : VehicleConfig
    """

    def __init__(self, controller: ControllerConfig, vehicle: VehicleConfig) -> None:
        self.cfg = controller
        self.vehicle = vehicle
        N, Nc, M = controller.horizon, controller.control_horizon, controller.max_obstacles
        self.horizon = N
        self.blocking = blocking_matrix(N, Nc, controller.input_hold)
        self.x0 = cp.Parameter(5, name="x0")
        self.Ad = cp.Parameter((5, 5), name="Ad")
        self.Bd = cp.Parameter((5, 1), name="Bd")
        self.disturbance = cp.Parameter((5, N), name="Ed_times_d")
        self.y_ref = cp.Parameter(N, name="y_ref")
        self.psi_ref = cp.Parameter(N, name="psi_ref")
        self.G = cp.Parameter((N, M), name="halfplane_gain")
        self.h = cp.Parameter((N, M), name="halfplane_bound")
        self.X = cp.Variable((5, N + 1), name="X")
        self.U = cp.Variable(Nc, name="U")
        self.S = cp.Variable((N, M), nonneg=True, name="slack")
        u_seq = self.U @ self.blocking
        self.u_seq = u_seq
        c = controller
        cost = (c.q_lateral * cp.sum_squares(self.X[0, 1:] - self.y_ref)
                + c.q_heading * cp.sum_squares(self.X[2, 1:] - self.psi_ref)
                + c.q_yaw_rate * cp.sum_squares(self.X[3, 1:])
                + c.q_steering * cp.sum_squares(self.X[4, 1:])
                + c.r_steering_rate * cp.sum_squares(u_seq)
                + c.slack_weight_linear * cp.sum(self.S)
                + c.slack_weight_quadratic * cp.sum_squares(self.S))
        lateral = cp.reshape(self.X[0, 1:], (N, 1), order="F") @ np.ones((1, M))
        constraints = [
            self.X[:, 0] == self.x0,
            self.X[:, 1:] == self.Ad @ self.X[:, :-1]
            + self.Bd @ cp.reshape(u_seq, (1, N), order="F") + self.disturbance,
            cp.abs(self.U) <= vehicle.steering_rate_max_rad_s,
            cp.abs(self.X[4, 1:]) <= vehicle.steering_max_rad,
            cp.multiply(self.G, lateral) + self.S >= self.h,
        ]
        self.problem = cp.Problem(cp.Minimize(cost), constraints)
        if not self.problem.is_dcp(dpp=True):
            raise RuntimeError("lateral MPC is not DPP; it would recompile every step")
        self._direct = ClarabelDirect()
        self._last_plan: np.ndarray | None = None
        self._plan_age = 0

    def parameter_list(self) -> list:
        """The parameters in the order of :meth:`parameter_vector`."""
        return [self.x0, self.Ad, self.Bd, self.disturbance, self.y_ref, self.psi_ref, self.G,
                self.h]

    @staticmethod
    def parameter_vector(inputs: MpcInputs) -> np.ndarray:
        """One step's parameter values stacked (column-major), for the direct backend."""
        disturbance = inputs.model.Ed @ inputs.disturbance_rad_s[None, :]
        parts = (inputs.x0, inputs.model.Ad, inputs.model.Bd, disturbance, inputs.y_ref_m,
                 inputs.psi_ref_rad, inputs.constraint_gain, inputs.constraint_bound)
        return np.concatenate([np.asarray(v, float).ravel(order="F") for v in parts])

    def set_parameters(self, inputs: MpcInputs) -> None:
        """Write one step's data into the parameters (no recompilation)."""
        self.x0.value = inputs.x0
        self.Ad.value = inputs.model.Ad
        self.Bd.value = inputs.model.Bd
        self.disturbance.value = inputs.model.Ed @ inputs.disturbance_rad_s[None, :]
        self.y_ref.value = inputs.y_ref_m
        self.psi_ref.value = inputs.psi_ref_rad
        self.G.value = inputs.constraint_gain
        self.h.value = inputs.constraint_bound

    def step(self, inputs: MpcInputs) -> MpcStep:
        """Solve for the current step, falling back safely on any failure."""
        status, iterations, elapsed = "not_solved", -1, 0.0
        if np.all(np.isfinite(inputs.x0)):
            try:
                if self.cfg.backend == "clarabel_direct":
                    if self._direct.maps is None:
                        self.set_parameters(inputs)  # the first call compiles
                    status, iterations, elapsed, states, u_blocked = self._direct.solve(
                        self, self.parameter_vector(inputs))
                else:
                    self.set_parameters(inputs)
                    status, iterations, elapsed = self._solve_raw()
                    states = self.X.value
                    u_blocked = self.U.value
            except (cp.error.SolverError, ValueError, ArithmeticError) as exc:
                status, states, u_blocked = f"error:{type(exc).__name__}", None, None
            if status in OPTIMAL_STATUSES and u_blocked is not None:
                plan = np.asarray(u_blocked, dtype=float).reshape(-1) @ self.blocking
                if np.all(np.isfinite(plan)):
                    self._last_plan, self._plan_age = plan, 0
                    states = np.asarray(states, dtype=float)
                    # slack needed by the optimal plan (what the QP's slack variable holds)
                    lateral = states[0, 1:][:, None]
                    slack = np.max(inputs.constraint_bound - inputs.constraint_gain * lateral,
                                   initial=0.0)
                    return MpcStep(float(plan[0]), plan, states, status, iterations, elapsed,
                                   "none", float(max(slack, 0.0)))
        return self._fallback(inputs, status, iterations, elapsed)

    def _fallback(self, inputs: MpcInputs, status: str, iterations: int,
                  elapsed: float) -> MpcStep:
        if self._last_plan is not None and self._plan_age + 1 < self.horizon:
            self._plan_age += 1
            shifted = np.concatenate([self._last_plan[self._plan_age:],
                                      np.repeat(self._last_plan[-1], self._plan_age)])
            return MpcStep(float(shifted[0]), shifted, None, status, iterations, elapsed,
                           "shifted_plan", float("nan"))
        delta = inputs.x0[4] if np.isfinite(inputs.x0[4]) else 0.0
        rate_max = self.vehicle.steering_rate_max_rad_s
        safe = float(np.clip(-delta / inputs.model.sample_time_s, -rate_max, rate_max))
        return MpcStep(safe, np.full(self.horizon, safe), None, status, iterations, elapsed,
                       "safe_input", float("nan"))


def lateral_reference(path_line_m: np.ndarray, stations_m: np.ndarray,
                      controller: ControllerConfig) -> tuple[np.ndarray, np.ndarray]:
    """Lateral and heading references at the MPC's predicted stations.

    The APF path (line frame) is made monotone in x (points that do not advance are dropped),
    interpolated at ``stations_m``, and beyond its end either extended along its last segment
    (slope saturated at ``heading_ref_max_rad``) or held. The heading reference is the
    saturated slope of that curve.

    Returns
    -------
    y_ref_m, psi_ref_rad : ndarray, shape (len(stations_m),)
    """
    xs, ys = [path_line_m[0, 0]], [path_line_m[0, 1]]
    for x, y in path_line_m[1:]:
        if x > xs[-1] + 1e-9:
            xs.append(x)
            ys.append(y)
    xs_a, ys_a = np.asarray(xs), np.asarray(ys)
    max_slope = np.tan(controller.heading_ref_max_rad)
    if xs_a.size < 2:
        # the rollout does not advance: hold its last lateral position
        y_end = path_line_m[-1, 1]
        return np.full(stations_m.shape, y_end), np.zeros(stations_m.shape)
    seg_slopes = np.clip(np.diff(ys_a) / np.diff(xs_a), -max_slope, max_slope)
    end_slope = seg_slopes[-1] if controller.path_beyond_end == "extend" else 0.0
    y_ref = np.interp(stations_m, xs_a, ys_a)
    beyond = stations_m > xs_a[-1]
    y_ref[beyond] = ys_a[-1] + end_slope * (stations_m[beyond] - xs_a[-1])
    idx = np.clip(np.searchsorted(xs_a, stations_m, side="right") - 1, 0, seg_slopes.size - 1)
    slope = np.where(beyond, end_slope, seg_slopes[idx])
    return y_ref, np.arctan(slope)


def force_heading_reference(total_force_line: np.ndarray, heading_line_rad: float,
                            n_steps: int, sample_time_s: float,
                            controller: ControllerConfig) -> np.ndarray:
    """Heading reference of Section 3.1: ramp toward ``psi_apf = atan2(F_y, F_x)`` at the
    saturated rate ``omega_ref = sat((psi_apf - theta)/Ts)``."""
    psi_apf = np.arctan2(total_force_line[1], total_force_line[0])
    error = np.arctan2(np.sin(psi_apf - heading_line_rad), np.cos(psi_apf - heading_line_rad))
    omega_ref = np.clip(error / sample_time_s, -controller.yaw_rate_ref_max_rad_s,
                        controller.yaw_rate_ref_max_rad_s)
    k = np.arange(1, n_steps + 1)
    ramp = np.clip(omega_ref * k * sample_time_s, -abs(error), abs(error))
    return np.clip(heading_line_rad + ramp, -controller.heading_ref_max_rad,
                   controller.heading_ref_max_rad)


def collision_halfplanes(stations_m: np.ndarray, y_ref_m: np.ndarray, vehicle_line_m: np.ndarray,
                         predicted_obstacles_line_m: np.ndarray, radii_m: np.ndarray,
                         vehicle: VehicleConfig, controller: ControllerConfig
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Soft half-plane data ``G y_k + s >= h`` for each horizon step and obstacle.

    With ``R = r_o + r_v + margin`` and the APF reference point ``q_k = (station_k, y_ref_k)``:

    * ``halfplane_normal = lateral_side`` (default): at station ``x_k`` the keep-out disk covers
      ``|y - o_y| < w_k = sqrt(R^2 - (x_k - o_x)^2)``; the APF chooses the side
      ``sigma = sign(y_ref_k - o_y)`` and the plane is ``sigma (y_k - o_y) >= w_k`` (exact for the
      disk at that station; empty where ``|x_k - o_x| >= R``).
    * ``halfplane_normal = radial``: ``n . (p_k - o_k) >= R`` with ``n`` the unit vector from the
      predicted obstacle to ``q_k`` (the tangent plane of the disk facing the reference point).

    Obstacles farther than ``constraint_activation_m`` from the vehicle get empty rows.

    Parameters
    ----------
    predicted_obstacles_line_m : ndarray, shape (N, n, 2)
        Obstacle centres at the horizon's steps, line frame.

    Returns
    -------
    G, h : ndarray, shape (N, max_obstacles)
    """
    N, M = stations_m.shape[0], controller.max_obstacles
    G, h = np.zeros((N, M)), np.zeros((N, M))
    n_obs = predicted_obstacles_line_m.shape[1] if predicted_obstacles_line_m.ndim == 3 else 0
    for j in range(min(n_obs, M)):
        current = predicted_obstacles_line_m[0, j]
        if np.linalg.norm(current - vehicle_line_m) > controller.constraint_activation_m:
            continue
        obstacle = predicted_obstacles_line_m[:, j, :]
        reach = radii_m[j] + vehicle.footprint_radius_m + controller.safety_margin_m
        fallback_side = np.sign(vehicle_line_m[1] - current[1]) or 1.0
        if controller.halfplane_normal == "lateral_side":
            dx = stations_m - obstacle[:, 0]
            inside = np.abs(dx) < reach
            half_width = np.sqrt(np.maximum(reach**2 - dx**2, 0.0))
            side = np.sign(y_ref_m - obstacle[:, 1])
            side = np.where(side == 0.0, fallback_side, side)
            G[:, j] = np.where(inside, side, 0.0)
            h[:, j] = np.where(inside, side * obstacle[:, 1] + half_width, 0.0)
            continue
        ref = np.stack([stations_m, y_ref_m], axis=1)
        normal = ref - obstacle
        dist = np.linalg.norm(normal, axis=1)
        normal = np.where(dist[:, None] > 1e-6, normal / np.maximum(dist, 1e-6)[:, None],
                          np.array([0.0, fallback_side])[None, :])
        G[:, j] = normal[:, 1]
        h[:, j] = reach - normal[:, 0] * (stations_m - obstacle[:, 0]) + normal[:, 1] * obstacle[:, 1]
    return G, h


def pure_pursuit_steering_rate(path_line_m: np.ndarray, position_line_m: np.ndarray,
                               heading_line_rad: float, steering_rad: float, speed_mps: float,
                               vehicle: VehicleConfig, controller: ControllerConfig,
                               sample_time_s: float) -> float:
    """Peer without MPC: pure pursuit of the APF path, steering rate toward the pursuit angle.

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


@dataclass(frozen=True)
class KinematicStep:
    """Result of one step of the kinematic LTV-MPC.

    Attributes
    ----------
    control_input : ndarray, shape (2,)
        ``[a (m/s^2), delta (rad)]`` applied now.
    planned_inputs : ndarray, shape (2, N)
    predicted_states : ndarray, shape (4, N + 1) or None
    status : str
    iterations : int
        Clarabel iterations summed over the linearization passes.
    solve_time_s : float
    fallback : str
    max_slack_m : float
    ltv_passes : int
        Linearization passes done this step.
    ltv_change : float
        Max-norm change of the input plan in the last pass (convergence indicator).
    """

    control_input: np.ndarray
    planned_inputs: np.ndarray
    predicted_states: np.ndarray | None
    status: str
    iterations: int
    solve_time_s: float
    fallback: str
    max_slack_m: float
    ltv_passes: int
    ltv_change: float


class KinematicLtvMpc(CompiledQp):
    """Appendix A's ``nlmpc`` as a linear-time-varying QP (CVXPY + Clarabel, DPP).

    Each step linearizes the Euler-discretized kinematic bicycle about a trajectory rolled out
    from the measured state with the previous plan (shifted), solves the QP, and optionally
    repeats the linearization about the new plan (``ltv_iterations`` passes). Cost as MATLAB
    writes it, weights squared: ``sum |w_y (y_k - y_ref,k)|^2 + |w_u u_k|^2 + |w_du (u_k -
    u_{k-1})|^2``; inputs held after ``Nc``; soft half-plane per obstacle and step with normal
    from the predicted obstacle toward the APF reference point.

    Parameters
    ----------
    controller : ControllerConfig
    vehicle : VehicleConfig
    sample_time_s : float
    """

    def __init__(self, controller: ControllerConfig, vehicle: VehicleConfig,
                 sample_time_s: float) -> None:
        self.cfg, self.vehicle, self.ts = controller, vehicle, float(sample_time_s)
        N, Nc, M = controller.horizon, controller.control_horizon, controller.max_obstacles
        self.horizon = N
        self.blocking = blocking_matrix(N, Nc, controller.input_hold)
        self.A = [cp.Parameter((4, 4), name=f"A{k}") for k in range(N)]
        self.B = [cp.Parameter((4, 2), name=f"B{k}") for k in range(N)]
        self.c = cp.Parameter((4, N), name="c")
        self.x0 = cp.Parameter(4, name="x0")
        self.ref = cp.Parameter((2, N), name="y_ref")
        self.u_prev = cp.Parameter(2, name="u_prev")
        self.Gx = cp.Parameter((N, M), name="halfplane_nx")
        self.Gy = cp.Parameter((N, M), name="halfplane_ny")
        self.h = cp.Parameter((N, M), name="halfplane_bound")
        self.X = cp.Variable((4, N + 1), name="X")
        self.U = cp.Variable((2, Nc), name="U")
        self.S = cp.Variable((N, M), nonneg=True, name="slack")
        u_seq = self.U @ self.blocking
        self.u_seq = u_seq
        wy = np.asarray(controller.output_weights, float)[:, None]
        wu = np.asarray(controller.input_weights, float)[:, None]
        wdu = np.asarray(controller.input_rate_weights, float)[:, None]
        rates = cp.hstack([cp.reshape(u_seq[:, 0] - self.u_prev, (2, 1), order="F"),
                           u_seq[:, 1:] - u_seq[:, :-1]])
        ones = np.ones((1, M))
        px = cp.reshape(self.X[0, 1:], (N, 1), order="F") @ ones
        py = cp.reshape(self.X[1, 1:], (N, 1), order="F") @ ones
        cost = (cp.sum_squares(cp.multiply(wy, self.X[0:2, 1:] - self.ref))
                + cp.sum_squares(cp.multiply(wu, u_seq))
                + cp.sum_squares(cp.multiply(wdu, rates))
                + controller.slack_weight_linear * cp.sum(self.S)
                + controller.slack_weight_quadratic * cp.sum_squares(self.S))
        a_lo, a_hi = controller.accel_bounds_mps2
        constraints = [self.X[:, 0] == self.x0,
                       self.U[0, :] >= a_lo, self.U[0, :] <= a_hi,
                       cp.abs(self.U[1, :]) <= vehicle.steering_max_rad,
                       cp.multiply(self.Gx, px) + cp.multiply(self.Gy, py) + self.S >= self.h]
        constraints += [self.X[:, k + 1] == self.A[k] @ self.X[:, k] + self.B[k] @ u_seq[:, k]
                        + self.c[:, k] for k in range(N)]
        self.problem = cp.Problem(cp.Minimize(cost), constraints)
        if not self.problem.is_dcp(dpp=True):
            raise RuntimeError("kinematic LTV-MPC is not DPP; it would recompile every step")
        self._last_plan: np.ndarray | None = None
        self._plan_age = 0

    def rollout(self, x0: np.ndarray, plan: np.ndarray) -> np.ndarray:
        """States of the Euler model from ``x0`` under ``plan`` (2 x N), shape (4, N + 1)."""
        from pipeline.model import kinematic_euler_step

        states = np.zeros((4, self.horizon + 1))
        states[:, 0] = x0
        for k in range(self.horizon):
            states[:, k + 1] = kinematic_euler_step(states[:, k], plan[:, k],
                                                    self.vehicle.wheelbase_m, self.ts)
        return states

    def _linearize(self, x0: np.ndarray, plan: np.ndarray) -> np.ndarray:
        from pipeline.model import kinematic_jacobians

        states = self.rollout(x0, plan)
        offsets = np.zeros((4, self.horizon))
        for k in range(self.horizon):
            A, B, c = kinematic_jacobians(states[:, k], plan[:, k], self.vehicle.wheelbase_m,
                                          self.ts)
            self.A[k].value, self.B[k].value = A, B
            offsets[:, k] = c
        self.c.value = offsets
        return states

    def _halfplanes(self, states: np.ndarray, reference: np.ndarray,
                    predicted_obstacles: np.ndarray, radii: np.ndarray) -> None:
        N, M = self.horizon, self.cfg.max_obstacles
        Gx, Gy, h = np.zeros((N, M)), np.zeros((N, M)), np.zeros((N, M))
        n_obs = predicted_obstacles.shape[1] if predicted_obstacles.ndim == 3 else 0
        for j in range(min(n_obs, M)):
            obstacle = predicted_obstacles[:, j, :]
            if np.linalg.norm(obstacle[0] - states[:2, 0]) > self.cfg.constraint_activation_m:
                continue
            normal = reference.T - obstacle
            dist = np.linalg.norm(normal, axis=1)
            backup = states[:2, 1:].T - obstacle
            backup_dist = np.linalg.norm(backup, axis=1)
            normal = np.where(dist[:, None] > 1e-6, normal / np.maximum(dist, 1e-6)[:, None],
                              np.where(backup_dist[:, None] > 1e-6,
                                       backup / np.maximum(backup_dist, 1e-6)[:, None],
                                       np.array([0.0, 1.0])[None, :]))
            reach = radii[j] + self.vehicle.footprint_radius_m + self.cfg.safety_margin_m
            Gx[:, j], Gy[:, j] = normal[:, 0], normal[:, 1]
            h[:, j] = np.sum(normal * obstacle, axis=1) + reach
        self.Gx.value, self.Gy.value, self.h.value = Gx, Gy, h

    def step(self, x0: np.ndarray, u_prev: np.ndarray, reference: np.ndarray,
             predicted_obstacles: np.ndarray, radii: np.ndarray,
             passes: int | None = None) -> KinematicStep:
        """Solve one step.

        Parameters
        ----------
        x0 : ndarray, shape (4,)
        u_prev : ndarray, shape (2,)
            Input applied at the previous step (for the rate penalty).
        reference : ndarray, shape (2, N)
            Reference position for predicted steps 1..N.
        predicted_obstacles : ndarray, shape (N, n, 2)
        radii : ndarray, shape (n,)
        passes : int, optional
            Linearization passes (default ``ltv_iterations``).
        """
        N = self.horizon
        passes = self.cfg.ltv_iterations if passes is None else passes
        if self._last_plan is not None:
            plan = np.hstack([self._last_plan[:, 1:], self._last_plan[:, -1:]])
        else:
            plan = np.zeros((2, N))
        status, total_iters, total_time, change = "not_solved", 0, 0.0, float("nan")
        states = None
        done = 0
        if np.all(np.isfinite(x0)) and np.all(np.isfinite(u_prev)):
            self.x0.value, self.u_prev.value, self.ref.value = x0, u_prev, reference
            for _ in range(max(passes, 1)):
                states = self._linearize(x0, plan)
                self._halfplanes(states, reference, predicted_obstacles, radii)
                try:
                    status, iters, elapsed = self._solve_raw()
                except (cp.error.SolverError, ValueError, ArithmeticError) as exc:
                    status, iters, elapsed = f"error:{type(exc).__name__}", -1, 0.0
                total_iters += max(iters, 0)
                total_time += elapsed
                done += 1
                if status not in OPTIMAL_STATUSES or self.U.value is None:
                    break
                new_plan = np.asarray(self.u_seq.value, dtype=float)
                if not np.all(np.isfinite(new_plan)):
                    status = "non_finite_solution"
                    break
                change = float(np.max(np.abs(new_plan - plan)))
                plan = new_plan
            if status in OPTIMAL_STATUSES and np.all(np.isfinite(plan)):
                self._last_plan, self._plan_age = plan, 0
                return KinematicStep(plan[:, 0].copy(), plan, np.asarray(self.X.value), status,
                                     total_iters, total_time, "none",
                                     float(np.max(self.S.value, initial=0.0)), done, change)
        # fallback: shifted previous plan, then a bounded safe input (straight wheels, braking)
        if self._last_plan is not None and self._plan_age + 1 < N:
            self._plan_age += 1
            shifted = np.hstack([self._last_plan[:, self._plan_age:],
                                 np.repeat(self._last_plan[:, -1:], self._plan_age, axis=1)])
            return KinematicStep(shifted[:, 0].copy(), shifted, None, status, total_iters,
                                 total_time, "shifted_plan", float("nan"), done, change)
        speed = x0[3] if np.isfinite(x0[3]) else 0.0
        a_lo, a_hi = self.cfg.accel_bounds_mps2
        safe = np.array([float(np.clip(-speed / self.ts, a_lo, a_hi)), 0.0])
        return KinematicStep(safe, np.repeat(safe[:, None], N, axis=1), None, status,
                             total_iters, total_time, "safe_input", float("nan"), done, change)
