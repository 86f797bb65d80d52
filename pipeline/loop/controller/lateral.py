"""The lateral MPC (paper Section 3): a DPP QP compiled once per structure, solved by Clarabel.

The QP over ``N`` steps::

    min  sum_k q_y (y_k - y_ref,k)^2 + q_psi (epsi_k - psi_ref,k)^2 + q_r r_k^2 + q_d delta_k^2
         + r_u u_k^2 + w1 sum(s) + w2 sum(s^2)
    s.t. x_{k+1} = Ad x_k + Bd u_k + Ed d_k,  x_0 = measured state
         |u_k| <= delta_dot_max,  |delta_k| <= delta_max,
         u_k = U[min(k, Nc - 1)] (hold_last) or 0 for k >= Nc (zero_rate)
         G_kj y_k + s_kj >= h_kj,  s >= 0   (soft half-plane per obstacle slot j and step k)

The model matrices are parameters, so one compiled problem serves every speed (velocity
planning) and every scenario; unused obstacle slots get rows that cannot bind. A failed solve
never raises: the controller takes :class:`~pipeline.loop.controller.base.PlanFallback`.

``controller.formulation`` chooses how the same QP is stated. ``sparse`` keeps the states as
variables with the dynamics as equality constraints (151 variables at N = 10, three obstacle
slots). ``condensed`` (the default) eliminates them: ``X = free response + Gamma U`` with the
prediction matrices of the model's speed (:class:`CondensedPrediction`, cached per speed) and
the free response computed in numpy each step, so the QP carries only ``U`` and the slacks (33
variables); its parameters are the weighted prediction rows and the half-planes folded onto
``U``, so it stays DPP. Both give the same optimum (tests hold them to each other).
"""

from __future__ import annotations

from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from pipeline.loop.settings import ControllerConfig, ModelConfig, VehicleConfig
from pipeline.loop.controller.base import ControlStep, Observation, PlanFallback
from pipeline.loop.controller.qp import NON_FINITE_DATA, QpCache, QpSolution, compiled_backend
from pipeline.loop.controller.references import (collision_halfplanes, force_heading_reference,
                                            lateral_reference)
from pipeline.loop.model import LateralModel, LateralModelCache, vehicle_key


@dataclass(frozen=True)
class MpcInputs:
    """Per-step data of the lateral QP (everything that is a ``cp.Parameter``)."""

    x0: np.ndarray
    model: LateralModel
    y_ref_m: np.ndarray
    psi_ref_rad: np.ndarray
    constraint_gain: np.ndarray
    constraint_bound: np.ndarray
    disturbance_rad_s: np.ndarray


@dataclass(frozen=True)
class LateralQpStructure:
    """Everything that enters the lateral QP as a constant: the cache key of a compilation."""

    horizon: int
    control_horizon: int
    max_obstacles: int
    input_hold: str
    weights: tuple
    steering_rate_max_rad_s: float
    steering_max_rad: float
    formulation: str = "sparse"

    @classmethod
    def of(cls, controller: ControllerConfig, vehicle: VehicleConfig) -> "LateralQpStructure":
        c = controller
        return cls(c.horizon, c.control_horizon, c.max_obstacles, c.input_hold,
                   (c.q_lateral, c.q_heading, c.q_yaw_rate, c.q_steering, c.r_steering_rate,
                    c.slack_weight_linear, c.slack_weight_quadratic),
                   vehicle.steering_rate_max_rad_s, vehicle.steering_max_rad, c.formulation)


def blocking_matrix(horizon: int, control_horizon: int, input_hold: str) -> np.ndarray:
    """Matrix ``T`` (Nc x N) with ``u_seq = U @ T`` for the move-blocking rule."""
    T = np.zeros((control_horizon, horizon))
    for k in range(horizon):
        if k < control_horizon:
            T[k, k] = 1.0
        elif input_hold == "hold_last":
            T[control_horizon - 1, k] = 1.0
    return T


def build_lateral_problem(s: LateralQpStructure) -> tuple[cp.Problem, list, dict]:
    """The lateral QP in CVXPY: problem, parameters in ``theta`` order, variables to read."""
    N, Nc, M = s.horizon, s.control_horizon, s.max_obstacles
    q_y, q_psi, q_r, q_d, r_u, w1, w2 = s.weights
    blocking = blocking_matrix(N, Nc, s.input_hold)
    x0 = cp.Parameter(5, name="x0")
    Ad = cp.Parameter((5, 5), name="Ad")
    Bd = cp.Parameter((5, 1), name="Bd")
    disturbance = cp.Parameter((5, N), name="Ed_times_d")
    y_ref = cp.Parameter(N, name="y_ref")
    psi_ref = cp.Parameter(N, name="psi_ref")
    G = cp.Parameter((N, M), name="halfplane_gain")
    h = cp.Parameter((N, M), name="halfplane_bound")
    X = cp.Variable((5, N + 1), name="X")
    U = cp.Variable(Nc, name="U")
    S = cp.Variable((N, M), nonneg=True, name="slack")
    u_seq = U @ blocking
    cost = (q_y * cp.sum_squares(X[0, 1:] - y_ref) + q_psi * cp.sum_squares(X[2, 1:] - psi_ref)
            + q_r * cp.sum_squares(X[3, 1:]) + q_d * cp.sum_squares(X[4, 1:])
            + r_u * cp.sum_squares(u_seq) + w1 * cp.sum(S) + w2 * cp.sum_squares(S))
    lateral = cp.reshape(X[0, 1:], (N, 1), order="F") @ np.ones((1, M))
    constraints = [
        X[:, 0] == x0,
        X[:, 1:] == Ad @ X[:, :-1] + Bd @ cp.reshape(u_seq, (1, N), order="F") + disturbance,
        cp.abs(U) <= s.steering_rate_max_rad_s,
        cp.abs(X[4, 1:]) <= s.steering_max_rad,
        cp.multiply(G, lateral) + S >= h,
    ]
    problem = cp.Problem(cp.Minimize(cost), constraints)
    if not problem.is_dcp(dpp=True):
        raise RuntimeError("lateral MPC is not DPP; it would recompile every step")
    return problem, [x0, Ad, Bd, disturbance, y_ref, psi_ref, G, h], {"X": X, "U": U}


#: Rows of the state that the cost weighs (y, epsi, r, delta) and their weight's index.
COST_STATES = (0, 2, 3, 4)


@dataclass(frozen=True)
class CondensedPrediction:
    """Prediction over the horizon for one model: ``X_k = A^k x0 + sum A^(k-1-i) (B u_i +
    e_i)``, with the input sequence ``u = U T`` (move blocking).

    Attributes
    ----------
    gamma : ndarray, shape (N, 5, Nc)
        Response of each state at steps 1..N to the free moves ``U``.
    """

    model: LateralModel
    gamma: np.ndarray

    @classmethod
    def of(cls, model: LateralModel, blocking: np.ndarray) -> "CondensedPrediction":
        Ad, Bd = model.Ad, model.Bd[:, 0]
        nc, n = blocking.shape
        # response of x_k to a unit input at step i (k > i): A^(k-1-i) B
        impulse = np.zeros((n, 5))
        power = Bd.copy()
        for lag in range(n):
            impulse[lag] = power
            power = Ad @ power
        psi = np.zeros((n, 5, n))
        for k in range(1, n + 1):
            for i in range(k):
                psi[k - 1, :, i] = impulse[k - 1 - i]
        return cls(model, psi @ blocking.T)

    def free_response(self, x0: np.ndarray, disturbance: np.ndarray) -> np.ndarray:
        """States at steps 1..N with ``U = 0`` (shape (N, 5)); ``disturbance`` is (5, N)."""
        Ad = self.model.Ad
        out = np.empty((disturbance.shape[1], 5))
        x = x0
        for k in range(disturbance.shape[1]):
            x = Ad @ x + disturbance[:, k]
            out[k] = x
        return out


def build_condensed_lateral_problem(s: LateralQpStructure) -> tuple[cp.Problem, list, dict]:
    """The same lateral QP with the states eliminated (see the module docstring)."""
    N, Nc, M = s.horizon, s.control_horizon, s.max_obstacles
    q_y, q_psi, q_r, q_d, r_u, w1, w2 = s.weights
    blocking = blocking_matrix(N, Nc, s.input_hold)
    gamma_w = cp.Parameter((4 * N, Nc), name="weighted_gamma")
    free_w = cp.Parameter(4 * N, name="weighted_free_error")
    gamma_d = cp.Parameter((N, Nc), name="steering_gamma")
    free_d = cp.Parameter(N, name="steering_free")
    gamma_h = cp.Parameter((N * M, Nc), name="halfplane_gamma")
    bound_h = cp.Parameter(N * M, name="halfplane_free_bound")
    U = cp.Variable(Nc, name="U")
    S = cp.Variable(N * M, nonneg=True, name="slack")
    cost = (cp.sum_squares(gamma_w @ U + free_w) + r_u * cp.sum_squares(U @ blocking)
            + w1 * cp.sum(S) + w2 * cp.sum_squares(S))
    constraints = [cp.abs(U) <= s.steering_rate_max_rad_s,
                   cp.abs(gamma_d @ U + free_d) <= s.steering_max_rad,
                   gamma_h @ U + S >= bound_h]
    problem = cp.Problem(cp.Minimize(cost), constraints)
    if not problem.is_dcp(dpp=True):
        raise RuntimeError("condensed lateral MPC is not DPP; it would recompile every step")
    return problem, [gamma_w, free_w, gamma_d, free_d, gamma_h, bound_h], {"U": U}


@dataclass(frozen=True)
class CondensedData:
    """One step's condensed QP data (the parameters of
    :func:`build_condensed_lateral_problem`) and the free response they came from."""

    gamma_w: np.ndarray     # (4N, Nc) weighted responses of y, epsi, r, delta to U
    free_w: np.ndarray      # (4N,) weighted free errors
    gamma_d: np.ndarray     # (N, Nc) steering angle's response to U
    free_d: np.ndarray      # (N,) free steering angle
    gamma_h: np.ndarray     # (N M, Nc) half-plane rows folded onto U
    bound_h: np.ndarray     # (N M,) their bounds
    free: np.ndarray        # (N, 5) free response

    def theta(self) -> np.ndarray:
        """The parameter vector in the compiled problem's order (column-major)."""
        return np.concatenate([self.gamma_w.ravel(order="F"), self.free_w,
                               self.gamma_d.ravel(order="F"), self.free_d,
                               self.gamma_h.ravel(order="F"), self.bound_h])


def condensed_data(prediction: CondensedPrediction, inputs: "MpcInputs",
                   weights: tuple) -> CondensedData:
    """The condensed QP's data for one step."""
    q_y, q_psi, q_r, q_d = weights[:4]
    disturbance = inputs.model.Ed @ inputs.disturbance_rad_s[None, :]
    free = prediction.free_response(inputs.x0, disturbance)
    gamma = prediction.gamma
    root = np.sqrt(np.array([q_y, q_psi, q_r, q_d]))
    # rows ordered by cost term, then step: [y_1..y_N, epsi_1.., r_1.., delta_1..]
    gamma_w = (root[:, None, None] * gamma[:, COST_STATES, :].transpose(1, 0, 2)
               ).reshape(-1, gamma.shape[2])
    target = np.stack([inputs.y_ref_m, inputs.psi_ref_rad, np.zeros_like(inputs.y_ref_m),
                       np.zeros_like(inputs.y_ref_m)])
    free_w = (root[:, None] * (free[:, COST_STATES].T - target)).ravel()
    G, h = inputs.constraint_gain, inputs.constraint_bound  # (N, M)
    # G_kj (y_free,k + gamma_y,k U) + s_kj >= h_kj, rows k-major as S is flattened (C order)
    gamma_h = (G[:, :, None] * gamma[:, 0, None, :]).reshape(-1, gamma.shape[2])
    bound_h = (h - G * free[:, 0, None]).ravel()
    return CondensedData(gamma_w, free_w, gamma[:, 4, :], free[:, 4], gamma_h, bound_h, free)


class ClarabelCondensedQp:
    """Backend ``clarabel_dense``: the condensed QP's data built in numpy (``P = 2 (gamma_w'
    gamma_w + r_u T T')`` and the rows of :class:`DaqpCondensedQp`) and handed to a kept
    Clarabel solver, updated in place on a fixed sparsity pattern: the 33-variable QP itself,
    without the auxiliary variables CVXPY's canonicalization of ``sum_squares(Gamma U + F)``
    adds (the CVXPY statement stays the reference the tests compare with)."""

    def __init__(self, structure: LateralQpStructure, max_iter: int) -> None:
        import scipy.sparse as sparse

        self.daqp = DaqpCondensedQp(structure, max_iter)
        self.max_iter = int(max_iter)
        self._solver = None
        N, Nc, M = structure.horizon, structure.control_horizon, structure.max_obstacles
        n_u, n_s = Nc, N * M
        self.n_u, self.n_s, self.N, n = n_u, n_s, N, n_u + n_s
        # the pattern: dense blocks where data live, diagonals for the identities
        rows = 2 * n_u + n_s + 2 * N + n_s
        mask = np.zeros((rows, n), bool)
        mask[np.arange(n_u), np.arange(n_u)] = True
        mask[n_u + np.arange(n_u), np.arange(n_u)] = True
        mask[2 * n_u + np.arange(n_s), n_u + np.arange(n_s)] = True
        r = 2 * n_u + n_s
        mask[r:r + 2 * N, :n_u] = True
        mask[r + 2 * N:, :n_u] = True
        mask[r + 2 * N + np.arange(n_s), n_u + np.arange(n_s)] = True
        a_pattern = sparse.csc_matrix(mask.astype(float))
        a_pattern.sort_indices()
        cols = np.repeat(np.arange(n), np.diff(a_pattern.indptr))
        self.a_index = (a_pattern.indices, cols)
        self.a_structure = (a_pattern.indices.copy(), a_pattern.indptr.copy(), mask.shape)
        p_mask = np.zeros((n, n), bool)
        p_mask[:n_u, :n_u] = np.triu(np.ones((n_u, n_u), bool))
        p_mask[n_u + np.arange(n_s), n_u + np.arange(n_s)] = True
        p_pattern = sparse.csc_matrix(p_mask.astype(float))
        p_pattern.sort_indices()
        self.p_index = (p_pattern.indices, np.repeat(np.arange(n), np.diff(p_pattern.indptr)))
        self.p_structure = (p_pattern.indices.copy(), p_pattern.indptr.copy(), (n, n))

    def _data(self, data: CondensedData):
        """Dense ``P``, ``q``, ``A`` and ``b`` of ``A z + s = b, s >= 0``."""
        s = self.daqp.s
        n_u, n_s, N = self.n_u, self.n_s, self.N
        P, q = self.daqp.cost(data)
        A = np.zeros(self.a_structure[2])
        A[:n_u, :n_u], A[n_u:2 * n_u, :n_u] = np.eye(n_u), -np.eye(n_u)
        A[2 * n_u:2 * n_u + n_s, n_u:] = -np.eye(n_s)
        r = 2 * n_u + n_s
        A[r:r + N, :n_u], A[r + N:r + 2 * N, :n_u] = data.gamma_d, -data.gamma_d
        A[r + 2 * N:, :n_u], A[r + 2 * N:, n_u:] = -data.gamma_h, -np.eye(n_s)
        rate, dmax = s.steering_rate_max_rad_s, s.steering_max_rad
        b = np.concatenate([np.full(2 * n_u, rate), np.zeros(n_s), dmax - data.free_d,
                            dmax + data.free_d, -data.bound_h])
        return P[self.p_index], q, A[self.a_index], b

    def solve(self, data: CondensedData) -> QpSolution:
        import time

        import clarabel
        import scipy.sparse as sparse

        from pipeline.loop.controller.qp import CLARABEL_STATUS, SOLVER_ERRORS, clarabel_settings

        start = time.perf_counter()
        p_values, q, a_values, b = self._data(data)
        if not (np.isfinite(p_values).all() and np.isfinite(q).all()
                and np.isfinite(a_values).all() and np.isfinite(b).all()):
            return QpSolution(NON_FINITE_DATA, -1, time.perf_counter() - start, None)
        try:
            if self._solver is None:
                p_idx, p_ptr, p_shape = self.p_structure
                a_idx, a_ptr, a_shape = self.a_structure
                self._solver = clarabel.DefaultSolver(
                    sparse.csc_matrix((p_values, p_idx, p_ptr), shape=p_shape), q,
                    sparse.csc_matrix((a_values, a_idx, a_ptr), shape=a_shape), b,
                    [clarabel.NonnegativeConeT(a_shape[0])], clarabel_settings(self.max_iter))
            else:
                self._solver.update(P=p_values, q=q, A=a_values, b=b)
            solution = self._solver.solve()
        except SOLVER_ERRORS as exc:
            return QpSolution(f"error:{type(exc).__name__}", -1, time.perf_counter() - start,
                              None)
        status = CLARABEL_STATUS.get(str(solution.status).rsplit(".", 1)[-1], "solver_error")
        x = np.asarray(solution.x)
        values = {"U": x[:self.n_u], "slack": x[self.n_u:]} \
            if status in ("optimal", "optimal_inaccurate") else None
        return QpSolution(status, int(solution.iterations), time.perf_counter() - start, values)


class DaqpCondensedQp:
    """Backend ``daqp``: the condensed lateral QP with explicit slacks, solved by DAQP (a dual
    active-set solver for small dense QPs): the same problem as the Clarabel backends.

    Variables ``z = [U, S]``; cost ``|gamma_w U + free_w|^2 + r_u |U T|^2 + w1 sum S +
    w2 |S|^2`` as ``0.5 z' H z + f' z``; simple bounds ``|U| <= rate max``, ``S >= 0``; rows
    ``|gamma_d U + free_d| <= delta max`` and ``gamma_h U + S >= bound_h``.
    """

    #: DAQP exit flags mapped to the status words the log uses (CVXPY's)
    STATUS = {1: "optimal", 2: "optimal", -1: "infeasible", -2: "solver_error",
              -3: "unbounded", -4: "user_limit", -5: "solver_error", -6: "solver_error"}

    def __init__(self, structure: LateralQpStructure, max_iter: int) -> None:
        self.s = structure
        N, Nc, M = structure.horizon, structure.control_horizon, structure.max_obstacles
        self.n_u, self.n_s = Nc, N * M
        blocking = blocking_matrix(N, Nc, structure.input_hold)
        self.input_hessian = structure.weights[4] * blocking @ blocking.T
        self.max_iter = int(max_iter)

    def cost(self, data: CondensedData) -> tuple[np.ndarray, np.ndarray]:
        """``H`` and ``f`` of the cost ``0.5 z' H z + f' z`` over ``z = [U, S]`` (shared with
        :class:`ClarabelCondensedQp`, whose ``P`` is the same ``H``)."""
        n_u, n_s = self.n_u, self.n_s
        w1, w2 = self.s.weights[5], self.s.weights[6]
        H = np.zeros((n_u + n_s, n_u + n_s))
        H[:n_u, :n_u] = 2.0 * (data.gamma_w.T @ data.gamma_w + self.input_hessian)
        H[n_u:, n_u:] = 2.0 * w2 * np.eye(n_s)
        f = np.concatenate([2.0 * data.gamma_w.T @ data.free_w, np.full(n_s, w1)])
        return H, f

    def solve(self, data: CondensedData) -> QpSolution:
        import time

        import daqp

        start = time.perf_counter()
        n_u, n_s = self.n_u, self.n_s
        n = n_u + n_s
        H, f = self.cost(data)
        A = np.zeros((data.gamma_d.shape[0] + n_s, n))
        A[:data.gamma_d.shape[0], :n_u] = data.gamma_d
        A[data.gamma_d.shape[0]:, :n_u] = data.gamma_h
        A[data.gamma_d.shape[0]:, n_u:] = np.eye(n_s)
        rate, dmax = self.s.steering_rate_max_rad_s, self.s.steering_max_rad
        upper = np.concatenate([np.full(n_u, rate), np.full(n_s, 1e30), dmax - data.free_d,
                                np.full(n_s, 1e30)])
        lower = np.concatenate([np.full(n_u, -rate), np.zeros(n_s), -dmax - data.free_d,
                                data.bound_h])
        if not (np.isfinite(H).all() and np.isfinite(f).all() and np.isfinite(A).all()
                and np.isfinite(lower).all()):
            return QpSolution(NON_FINITE_DATA, -1, time.perf_counter() - start, None)
        x, _, exitflag, info = daqp.solve(H, f, A, upper, lower, np.zeros(upper.size, np.intc),
                                          iter_limit=self.max_iter)
        status = self.STATUS.get(int(exitflag), "solver_error")
        values = {"U": np.asarray(x[:n_u], float), "slack": np.asarray(x[n_u:], float)} \
            if status == "optimal" else None
        return QpSolution(status, int(info.get("iterations", -1)), time.perf_counter() - start,
                          values)


class LateralMpc:
    """The lateral MPC: one compiled QP (from ``qp_cache``), a kept solver, the fallback.

    Parameters
    ----------
    controller : ControllerConfig
    vehicle : VehicleConfig
    model : ModelConfig
        The lateral model's settings (B2 entry, speed grid).
    sample_time_s : float
    qp_cache : QpCache, optional
        Compiled problems shared across runs; a private one when omitted.

    Attributes
    ----------
    compile_count : int
        Compilations this controller caused (0 when the cache already held its structure).
    compile_time_s : float
    """

    def __init__(self, controller: ControllerConfig, vehicle: VehicleConfig,
                 model: ModelConfig | None = None, sample_time_s: float = 0.1,
                 qp_cache: QpCache | None = None) -> None:
        self.cfg, self.vehicle = controller, vehicle
        self.model_cfg = model if model is not None else ModelConfig()
        self.horizon = controller.horizon
        self.sample_time_s = float(sample_time_s)
        self.blocking = blocking_matrix(controller.horizon, controller.control_horizon,
                                        controller.input_hold)
        # the discretized models by speed, shared by every run handed the same cache (python-
        # control's c2d is paid once per speed, not once per family member)
        shared = qp_cache.memo(("lateral_models", vehicle_key(vehicle), self.sample_time_s,
                                self.model_cfg.b2_heading_entry, self.model_cfg.speed_grid_mps),
                               dict) if qp_cache is not None else {}
        self.models = LateralModelCache(vehicle, self.sample_time_s,
                                        self.model_cfg.b2_heading_entry,
                                        self.model_cfg.speed_grid_mps, shared)
        structure = LateralQpStructure.of(controller, vehicle)
        self.condensed = controller.formulation == "condensed"
        builder = build_condensed_lateral_problem if self.condensed else build_lateral_problem
        self.weights = structure.weights
        if controller.backend in ("daqp", "clarabel_dense"):
            # no compilation: the condensed data go to the solver as numpy matrices
            dense = DaqpCondensedQp if controller.backend == "daqp" else ClarabelCondensedQp
            self.qp, self.compile_count, self.compile_time_s = \
                dense(structure, controller.solver_max_iter), 0, 0.0
        else:
            self.qp, self.compile_count, self.compile_time_s = compiled_backend(
                qp_cache, "lateral", structure, lambda: builder(structure),
                controller.backend, controller.solver_max_iter)
        self._predictions: dict[int, CondensedPrediction] = {}
        self.fallback = PlanFallback(controller.horizon)
        self._steps_ahead_s = np.arange(1, controller.horizon + 1) * self.sample_time_s
        self._times_s = np.concatenate([[0.0], self._steps_ahead_s])

    @staticmethod
    def parameter_vector(inputs: MpcInputs) -> np.ndarray:
        """One step's parameter values stacked (column-major) in ``theta`` order."""
        disturbance = inputs.model.Ed @ inputs.disturbance_rad_s[None, :]
        return np.concatenate([
            inputs.x0, inputs.model.Ad.ravel(order="F"), inputs.model.Bd.ravel(order="F"),
            disturbance.ravel(order="F"), inputs.y_ref_m, inputs.psi_ref_rad,
            inputs.constraint_gain.ravel(order="F"), inputs.constraint_bound.ravel(order="F")])

    def prediction(self, model: LateralModel) -> CondensedPrediction:
        """The condensed prediction of ``model`` (built once per model, i.e. per speed)."""
        key = id(model)
        entry = self._predictions.get(key)
        if entry is None or entry.model is not model:
            entry = self._predictions[key] = CondensedPrediction.of(model, self.blocking)
        return entry

    def solve(self, inputs: MpcInputs, log: dict | None = None) -> ControlStep:
        """Solve the QP for one step's data, falling back safely on any failure."""
        solution = QpSolution("not_solved", -1, 0.0, None)
        free = None
        if np.all(np.isfinite(inputs.x0)):
            if self.condensed:
                data = condensed_data(self.prediction(inputs.model), inputs, self.weights)
                free = data.free
                solution = self.qp.solve(
                    data if isinstance(self.qp, (DaqpCondensedQp, ClarabelCondensedQp))
                    else data.theta())
            else:
                solution = self.qp.solve(self.parameter_vector(inputs))
        if solution.ok:
            U = np.asarray(solution.values["U"], dtype=float).reshape(-1)
            plan = U @ self.blocking
            if np.all(np.isfinite(plan)):
                plan = plan[None, :]
                self.fallback.accept(plan)
                if self.condensed:
                    # the eliminated states, for the log and the slack: X = free + Gamma U
                    predicted = free + self.prediction(inputs.model).gamma @ U
                    states = np.concatenate([inputs.x0[:, None], predicted.T], axis=1)
                else:
                    states = solution.values["X"]
                # slack needed by the optimal plan (what the QP's slack variable holds); rows
                # of idle slots and far obstacles are 0 y + s >= 0 and need none
                slack = 0.0
                if inputs.constraint_gain.any() or inputs.constraint_bound.any():
                    lateral = states[0, 1:][:, None]
                    slack = np.max(inputs.constraint_bound - inputs.constraint_gain * lateral,
                                   initial=0.0)
                return ControlStep(plan[:, 0].copy(), plan, states, solution.status,
                                   solution.iterations, solution.solve_time_s, "none",
                                   float(max(slack, 0.0)), log or {})
        delta = inputs.x0[4] if np.isfinite(inputs.x0[4]) else 0.0
        rate_max = self.vehicle.steering_rate_max_rad_s
        ts = inputs.model.sample_time_s
        return self.fallback.step(
            solution.status, solution.iterations, solution.solve_time_s,
            lambda: np.array([float(np.clip(-delta / ts, -rate_max, rate_max))]), log)

    def inputs_from(self, obs: Observation) -> tuple[MpcInputs, dict]:
        """The QP data of one observation: references from the APF path, half-planes, model."""
        ctrl, N = self.cfg, self.horizon
        model = self.models.at_speed(obs.speed_ref_mps)
        line_pos = obs.position_line_m
        stations = line_pos[0] + model.speed_mps * self._steps_ahead_s
        path_line = obs.frame.to_line(obs.rollout.path_m)
        y_ref, psi_ref = lateral_reference(path_line, stations, ctrl)
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
        log = {"y_ref_m": y_ref[0], "psi_ref_rad": psi_ref[0]}
        return MpcInputs(x0, model, y_ref, psi_ref, G, h, np.zeros(N)), log

    def step(self, obs: Observation) -> ControlStep:
        """One closed-loop step."""
        inputs, log = self.inputs_from(obs)
        return self.solve(inputs, log)
