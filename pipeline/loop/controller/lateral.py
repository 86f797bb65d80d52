"""The lateral MPC (paper Section 3): a DPP QP compiled once per structure, solved by Clarabel.

The QP over ``N`` steps::

    min  sum_k q_y (y_k - y_ref,k)^2 + q_psi (epsi_k - psi_ref,k)^2 + q_r (r_k - r_ref,k)^2
         + q_d (delta_k - delta_ref,k)^2 + r_u u_k^2 + w1 sum(s) + w2 sum(s^2)
    s.t. x_{k+1} = Ad x_k + Bd u_k + Ed d_k,  x_0 = measured state
         |u_k| <= delta_dot_max,  |delta_k| <= delta_max,
         u_k = U[min(k, Nc - 1)] (hold_last) or 0 for k >= Nc (zero_rate)
         G_kj y_k + s_kj >= h_kj,  s >= 0   (soft half-plane per obstacle slot j and step k)

The model matrices are parameters, so one compiled problem serves every speed (velocity
planning) and every scenario; unused obstacle slots get rows that cannot bind.

``controller.frame`` says what the state is measured against. ``path`` (the default): the
offset and heading error from a drivable path built from the APF rollout each step
(:mod:`~pipeline.loop.controller.path`), the path's curvature previewed as the disturbance
``r_d`` and the references the model's equilibrium on it (``r_ref = r_d``, the steering and
sideslip that hold it); ``fixed``: the position and heading against the start-goal line, the
references interpolated on the rollout, ``r_d = 0`` (the earlier reading). Both are the same QP
with other data. A failed solve
never raises: the controller takes :class:`~pipeline.loop.controller.base.PlanFallback`.

``controller.formulation`` chooses how the same QP is stated. ``sparse`` keeps the states as
variables with the dynamics as equality constraints (151 variables at N = 10, three obstacle
slots). ``condensed`` (the default) eliminates them: ``X = free response + Gamma U`` with the
prediction matrices of the model's speed (:class:`CondensedPrediction`, cached per speed) and
the free response computed in numpy each step, so the QP carries only ``U`` and the slacks (33
variables); its parameters are the weighted prediction rows and the half-planes folded onto
``U``, so it stays DPP. Both give the same optimum (tests hold them to each other).

The condensed statement is written in the coordinates ``W = R U`` of the cost's Cholesky factor
``R`` (``R' R`` = half the Hessian in ``U``): the tracking cost is then ``|W|^2 + 2 r' W``, a
constant quadratic, and every bound is a plain pair of inequalities, so CVXPY's canonical
problem is the 33-variable, 86-row QP itself (no auxiliary variables, no equality rows) and the
kept Clarabel solver sees exactly what :class:`ClarabelCondensedQp` hands it. ``U = R^-1 W`` is
read back (:class:`CompiledCondensedQp`).
"""

from __future__ import annotations

from dataclasses import dataclass
from math import atan2, isfinite, pi
from typing import TYPE_CHECKING

import numpy as np

from pipeline.loop.settings import ControllerConfig, ModelConfig, VehicleConfig
from pipeline.loop.controller.base import ControlStep, Observation, PlanFallback
from pipeline.loop.controller.path import (PredictionRecord, ReferencePath, chase_path_arrays,
                                           frame_step_arrays, heading_ramp_path,
                                           plan_poses_arrays,
                                           prediction_check, steady_state_gains)
from pipeline.loop.controller.qp import NON_FINITE_DATA, QpCache, QpSolution, compiled_backend
from pipeline.loop.controller.references import (collision_halfplanes, force_heading_reference,
                                            lateral_reference)
from pipeline.loop.model import LateralModel, LateralModelCache, model_speed_mps, vehicle_key

if TYPE_CHECKING:
    import cvxpy as cp


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
    r_ref_rad_s: np.ndarray | None = None
    delta_ref_rad: np.ndarray | None = None

    def yaw_rate_reference(self) -> np.ndarray:
        """``r_ref`` over the horizon (zeros when not set)."""
        return self.r_ref_rad_s if self.r_ref_rad_s is not None \
            else np.zeros(self.y_ref_m.shape[0])

    def steering_reference(self) -> np.ndarray:
        """``delta_ref`` over the horizon (zeros when not set)."""
        return self.delta_ref_rad if self.delta_ref_rad is not None \
            else np.zeros(self.y_ref_m.shape[0])


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
    import cvxpy as cp

    N, Nc, M = s.horizon, s.control_horizon, s.max_obstacles
    q_y, q_psi, q_r, q_d, r_u, w1, w2 = s.weights
    blocking = blocking_matrix(N, Nc, s.input_hold)
    x0 = cp.Parameter(5, name="x0")
    Ad = cp.Parameter((5, 5), name="Ad")
    Bd = cp.Parameter((5, 1), name="Bd")
    disturbance = cp.Parameter((5, N), name="Ed_times_d")
    y_ref = cp.Parameter(N, name="y_ref")
    psi_ref = cp.Parameter(N, name="psi_ref")
    r_ref = cp.Parameter(N, name="r_ref")
    delta_ref = cp.Parameter(N, name="delta_ref")
    G = cp.Parameter((N, M), name="halfplane_gain")
    h = cp.Parameter((N, M), name="halfplane_bound")
    X = cp.Variable((5, N + 1), name="X")
    U = cp.Variable(Nc, name="U")
    S = cp.Variable((N, M), nonneg=True, name="slack")
    u_seq = U @ blocking
    cost = (q_y * cp.sum_squares(X[0, 1:] - y_ref) + q_psi * cp.sum_squares(X[2, 1:] - psi_ref)
            + q_r * cp.sum_squares(X[3, 1:] - r_ref) + q_d * cp.sum_squares(X[4, 1:] - delta_ref)
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
    return problem, [x0, Ad, Bd, disturbance, y_ref, psi_ref, r_ref, delta_ref, G, h], \
        {"X": X, "U": U}


#: Rows of the state that the cost weighs (y, epsi, r, delta) and their weight's index.
COST_STATES = (0, 2, 3, 4)


@dataclass(frozen=True)
class CondensedPrediction:
    """Prediction over the horizon for one model, as stacked maps (built once per model, i.e.
    per speed): ``X_k = A^k x0 + sum A^(k-1-i) (B u_i + e_i)`` with the input sequence
    ``u = U T`` (move blocking).

    Everything of the condensed QP that depends on the model alone is here, so one step's data
    are a few matrix-vector products (:func:`condensed_data`).

    Attributes
    ----------
    gamma : ndarray, shape (N, 5, Nc)
        Response of each state at steps 1..N to the free moves ``U``.
    free_map : ndarray, shape (5 N, 5)
        ``A^k`` stacked (step-major): the free response is ``free_map @ x0`` without disturbance.
    gamma_w : ndarray, shape (4 N, Nc)
        The weighted cost rows (``sqrt(q)`` times y, epsi, r, delta; ordered by term, then
        step).
    hessian_u : ndarray, shape (Nc, Nc)
        ``2 (gamma_w' gamma_w + r_u T T')``, the cost's Hessian in ``U``.
    chol : ndarray, shape (Nc, Nc)
        Upper-triangular ``R`` with ``R' R = hessian_u / 2`` (the cost as ``|R U + r|^2``).
    chol_rhs_map : ndarray, shape (Nc, 4 N)
        ``R^-T gamma_w'``: ``r = chol_rhs_map @ free_w``.
    chol_inv : ndarray, shape (Nc, Nc)
        ``R^-1``: the moves of the condensed statement's coordinates, ``U = R^-1 W``.
    cost_index, cost_root : ndarray, shape (4 N,)
        Where each weighted cost row's state sits in the flat free response (``5 k + state``)
        and its weight's square root: ``free_w = cost_root * free.ravel()[cost_index] - target``.
    steering_gamma_w : ndarray, shape (N, Nc)
        The steering angle's response in the statement's coordinates, ``gamma_d R^-1``.
    chol_inv_flat, steering_gamma_w_flat : ndarray
        The two, column-major and flat (parameters of the CVXPY statement).
    disturbance_map : ndarray, shape (5 N, N)
        Response of the states at steps 1..N (step-major) to the disturbances ``r_d`` at steps
        0..N-1: the free response is ``free_map @ x0 + disturbance_map @ r_d``.
    gradient_map : ndarray, shape (Nc, 4 N)
        ``2 gamma_w'``: the cost's gradient in ``U`` is ``gradient_map @ free_w``.
    """

    model: LateralModel
    gamma: np.ndarray
    free_map: np.ndarray
    gamma_w: np.ndarray
    root_weights: np.ndarray
    hessian_u: np.ndarray
    chol: np.ndarray
    chol_rhs_map: np.ndarray
    gradient_map: np.ndarray
    chol_inv: np.ndarray
    cost_index: np.ndarray
    cost_root: np.ndarray
    steering_gamma_w: np.ndarray
    chol_inv_flat: np.ndarray
    steering_gamma_w_flat: np.ndarray
    disturbance_map: np.ndarray

    @classmethod
    def of(cls, model: LateralModel, blocking: np.ndarray,
           weights: tuple = (1.0, 1.0, 1.0, 1.0, 0.0)) -> "CondensedPrediction":
        """Build the maps of ``model``; ``weights`` starts ``(q_y, q_psi, q_r, q_d, r_u)``."""
        from scipy.linalg import cholesky, solve_triangular

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
        gamma = psi @ blocking.T
        # the same for the disturbance: response of x_k to a unit r_d at step i, A^(k-1-i) E
        disturbance_map = np.zeros((n, 5, n))
        power = model.Ed[:, 0].copy()
        for lag in range(n):
            for k in range(lag + 1, n + 1):
                disturbance_map[k - 1, :, k - 1 - lag] = power
            power = Ad @ power
        powers = np.zeros((n, 5, 5))
        power = np.eye(5)
        for k in range(n):
            power = Ad @ power
            powers[k] = power
        root = np.sqrt(np.asarray(weights[:4], float))
        # rows ordered by cost term, then step: [y_1..y_N, epsi_1.., r_1.., delta_1..]
        gamma_w = (root[:, None, None] * gamma[:, COST_STATES, :].transpose(1, 0, 2)
                   ).reshape(-1, nc)
        half_hessian = gamma_w.T @ gamma_w + float(weights[4]) * blocking @ blocking.T
        chol = cholesky(half_hessian, lower=False)
        chol_rhs_map = solve_triangular(chol, gamma_w.T, trans="T", lower=False)
        # Fortran order: OpenBLAS multithreads a row-major gemv even this small, and its idle
        # threads then spin on the other core (measured: 2x the CPU time of the product)
        fortran = np.asfortranarray
        chol_inv = solve_triangular(chol, np.eye(nc), lower=False)
        # rows ordered by cost term, then step, as gamma_w: state COST_STATES[t] at step k
        cost_index = (5 * np.arange(n)[None, :] + np.array(COST_STATES)[:, None]).ravel()
        cost_root = np.repeat(root, n)
        steering_gamma_w = gamma[:, 4, :] @ chol_inv
        return cls(model, gamma, fortran(powers.reshape(-1, 5)), fortran(gamma_w),
                   root, 2.0 * half_hessian, chol, fortran(chol_rhs_map),
                   fortran(2.0 * gamma_w.T), chol_inv, cost_index, cost_root,
                   steering_gamma_w, chol_inv.ravel(order="F"),
                   steering_gamma_w.ravel(order="F"),
                   fortran(disturbance_map.reshape(-1, n)))

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
    """The same lateral QP with the states eliminated, in the coordinates ``W = R U``.

    The tracking cost ``|gamma_w U + free_w|^2 + r_u |U T|^2`` equals ``|R U + r|^2`` up to a
    constant (``R`` its Cholesky factor), i.e. ``|W|^2 + 2 r' W``: a constant quadratic, so
    CVXPY adds no auxiliary variable for it. The bounds are stated as pairs of inequalities
    (``cp.abs`` would add one variable per bounded entry). Every matrix that multiplies ``W``
    is one parameter computed in numpy (``R^-1``, ``gamma_d R^-1``, ``gamma_h R^-1``), which
    keeps the problem DPP. Canonicalized, it is the 33-variable, 86-row QP itself.
    """
    import cvxpy as cp

    N, Nc, M = s.horizon, s.control_horizon, s.max_obstacles
    w1, w2 = s.weights[5], s.weights[6]
    chol_inv = cp.Parameter((Nc, Nc), name="cost_cholesky_inverse")
    chol_rhs = cp.Parameter(Nc, name="cost_cholesky_rhs")
    gamma_d = cp.Parameter((N, Nc), name="steering_gamma_w")
    free_d = cp.Parameter(N, name="steering_free")
    gamma_h = cp.Parameter((N * M, Nc), name="halfplane_gamma_w")
    bound_h = cp.Parameter(N * M, name="halfplane_free_bound")
    W = cp.Variable(Nc, name="W")
    S = cp.Variable(N * M, name="slack")
    rate, steering = s.steering_rate_max_rad_s, s.steering_max_rad
    cost = cp.sum_squares(W) + 2 * chol_rhs @ W + w1 * cp.sum(S) + w2 * cp.sum_squares(S)
    moves = chol_inv @ W
    steering_angle = gamma_d @ W
    constraints = [moves <= rate, -moves <= rate,
                   steering_angle <= steering - free_d, -steering_angle <= steering + free_d,
                   gamma_h @ W + S >= bound_h, S >= 0]
    problem = cp.Problem(cp.Minimize(cost), constraints)
    if not problem.is_dcp(dpp=True):
        raise RuntimeError("condensed lateral MPC is not DPP; it would recompile every step")
    return problem, [chol_inv, chol_rhs, gamma_d, free_d, gamma_h, bound_h], {"W": W}


@dataclass(frozen=True)
class CondensedData:
    """One step's condensed QP data: the free response and what depends on it, with the
    prediction of the step's model for everything that does not. The cost's gradient in ``U``
    (the numpy backends) and its Cholesky right-hand side (the CVXPY statement) are computed
    when a backend first asks, so each step computes only the one its backend uses."""

    prediction: CondensedPrediction
    free_w: np.ndarray      # (4N,) weighted free errors
    gamma_d: np.ndarray     # (N, Nc) steering angle's response to U
    free_d: np.ndarray      # (N,) free steering angle
    gamma_h: np.ndarray     # (N M, Nc) half-plane rows folded onto U
    bound_h: np.ndarray     # (N M,) their bounds
    free: np.ndarray        # (N, 5) free response

    @property
    def gamma_w(self) -> np.ndarray:
        """(4N, Nc) weighted responses of y, epsi, r, delta to U."""
        return self.prediction.gamma_w

    @property
    def hessian_u(self) -> np.ndarray:
        """(Nc, Nc) ``2 (gamma_w' gamma_w + r_u T T')``."""
        return self.prediction.hessian_u

    @property
    def chol_inv(self) -> np.ndarray:
        """(Nc, Nc) ``R^-1``: ``U = R^-1 W``."""
        return self.prediction.chol_inv

    @property
    def gradient_u(self) -> np.ndarray:
        """(Nc,) ``2 gamma_w' free_w`` (computed on each access: a backend asks once)."""
        return self.prediction.gradient_map @ self.free_w

    @property
    def chol_rhs(self) -> np.ndarray:
        """(Nc,) ``r = R^-T gamma_w' free_w`` (computed on each access: a backend asks once)."""
        return self.prediction.chol_rhs_map @ self.free_w

    def theta(self) -> np.ndarray:
        """The parameter vector of :func:`build_condensed_lateral_problem` (its order, column-
        major): the rows that multiply ``U`` taken to ``W = R U``."""
        prediction = self.prediction
        return np.concatenate([prediction.chol_inv_flat, self.chol_rhs,
                               prediction.steering_gamma_w_flat, self.free_d,
                               (self.gamma_h @ prediction.chol_inv).ravel(order="F"),
                               self.bound_h])


def condensed_data(prediction: CondensedPrediction, inputs: "MpcInputs",
                   weights: tuple) -> CondensedData:
    """The condensed QP's data for one step: one product for the free response, one gather
    for the weighted errors, the half-planes folded onto ``U`` (``weights`` must be those
    ``prediction`` was built with)."""
    n = inputs.y_ref_m.shape[0]
    if np.count_nonzero(inputs.disturbance_rad_s):
        free = (prediction.free_map @ inputs.x0
                + prediction.disturbance_map @ inputs.disturbance_rad_s).reshape(n, 5)
    else:
        free = (prediction.free_map @ inputs.x0).reshape(n, 5)
    root = prediction.root_weights
    # the weighted free errors, rows by cost term then step: one gather, one product, and the
    # two reference terms (the same operations on each entry as a stacked target)
    free_w = prediction.cost_root * free.ravel()[prediction.cost_index]
    free_w[:n] -= root[0] * inputs.y_ref_m
    free_w[n:2 * n] -= root[1] * inputs.psi_ref_rad
    if inputs.r_ref_rad_s is not None:
        free_w[2 * n:3 * n] -= root[2] * inputs.r_ref_rad_s
    if inputs.delta_ref_rad is not None:
        free_w[3 * n:] -= root[3] * inputs.delta_ref_rad
    gamma = prediction.gamma
    G, h = inputs.constraint_gain, inputs.constraint_bound  # (N, M)
    # G_kj (y_free,k + gamma_y,k U) + s_kj >= h_kj, rows k-major as S is flattened (C order)
    gamma_h = (G[:, :, None] * gamma[:, 0, None, :]).reshape(-1, gamma.shape[2])
    bound_h = (h - G * free[:, 0, None]).ravel()
    return CondensedData(prediction, free_w, gamma[:, 4, :], free[:, 4], gamma_h, bound_h, free)


class CompiledCondensedQp:
    """Backends ``clarabel_direct`` and ``cvxpy`` on the condensed statement: one step's
    :class:`CondensedData` in, the moves ``U = R^-1 W`` out (the statement's own variable is
    ``W``, see :func:`build_condensed_lateral_problem`).

    Parameters
    ----------
    compiled : DirectQp or CvxpyQp
        The compiled statement (shared through the ``QpCache``).
    """

    def __init__(self, compiled) -> None:
        self.compiled = compiled

    def solve(self, data: CondensedData) -> QpSolution:
        solution = self.compiled.solve(data.theta())
        if solution.values is None:
            return solution
        W = np.asarray(solution.values["W"], float).reshape(-1)
        return QpSolution(solution.status, solution.iterations, solution.solve_time_s,
                          {"U": data.chol_inv @ W, "W": W})


class ClarabelCondensedQp:
    """Backend ``clarabel_dense``: the condensed QP's data built in numpy and handed to a kept
    Clarabel solver, updated in place on a fixed sparsity pattern: the 33-variable QP itself,
    without the auxiliary variables of CVXPY's canonicalization (the CVXPY statement stays the
    reference the tests compare with).

    Variables ``z = [U, S]``; ``A z + s = b, s >= 0`` with rows ``U <= rate``, ``-U <= rate``,
    ``-S <= 0``, ``gamma_d U <= dmax - free_d``, ``-gamma_d U <= dmax + free_d``,
    ``-gamma_h U - S <= -bound_h``. Only the ``U`` columns change from step to step: their
    values are one stacked array, column after column (CSC order).
    """

    def __init__(self, structure: LateralQpStructure, max_iter: int) -> None:
        import scipy.sparse as sparse

        self.s, self.max_iter, self._solver = structure, int(max_iter), None
        N, Nc, M = structure.horizon, structure.control_horizon, structure.max_obstacles
        n_u, n_s = Nc, N * M
        self.n_u, self.n_s, self.N = n_u, n_s, N
        rows = 2 * n_u + n_s + 2 * N + n_s
        r = 2 * n_u + n_s
        # U columns: the two rate rows, then every steering and half-plane row
        u_rows = [np.concatenate([[j, n_u + j], np.arange(r, rows)]) for j in range(n_u)]
        s_rows = [np.array([2 * n_u + i, r + 2 * N + i]) for i in range(n_s)]
        indices = np.concatenate(u_rows + s_rows)
        indptr = np.concatenate([[0], np.cumsum([a.size for a in u_rows + s_rows])])
        self.a_structure = (indices, indptr, (rows, n_u + n_s))
        self._a_values = np.full(indices.size, -1.0)  # slack columns: -1, -1
        self._u_block = np.empty((n_u, 2 + 2 * N + n_s))
        self._u_block[:, 0], self._u_block[:, 1] = 1.0, -1.0
        self._u_size = self._u_block.size
        upper = np.triu_indices(n_u)
        order = np.lexsort((upper[0], upper[1]))
        self._p_upper = (upper[0][order], upper[1][order])
        p_idx = np.concatenate([self._p_upper[0], n_u + np.arange(n_s)])
        p_ptr = np.concatenate([[0], np.cumsum(np.arange(1, n_u + 1)), n_u * (n_u + 1) // 2
                                + np.arange(1, n_s + 1)])
        self.p_structure = (p_idx, p_ptr, (n_u + n_s, n_u + n_s))
        self._p_values = np.full(p_idx.size, 2.0 * structure.weights[6])
        self._q = np.full(n_u + n_s, float(structure.weights[5]))
        rate, dmax = structure.steering_rate_max_rad_s, structure.steering_max_rad
        self._b = np.zeros(rows)
        self._b[:2 * n_u] = rate
        self._dmax = dmax
        self._sparse = sparse

    def _data(self, data: CondensedData):
        """Values of ``P`` (upper triangle) and ``A`` on their fixed patterns, ``q`` and ``b``."""
        n_u, N, r = self.n_u, self.N, 2 * self.n_u + self.n_s
        p_values = self._p_values
        p_values[:n_u * (n_u + 1) // 2] = data.hessian_u[self._p_upper]
        q = self._q
        q[:n_u] = data.gradient_u
        block = self._u_block
        block[:, 2:2 + N] = data.gamma_d.T
        block[:, 2 + N:2 + 2 * N] = -data.gamma_d.T
        block[:, 2 + 2 * N:] = -data.gamma_h.T
        a_values = self._a_values
        a_values[:self._u_size] = block.ravel()
        b = self._b
        b[r:r + N] = self._dmax - data.free_d
        b[r + N:r + 2 * N] = self._dmax + data.free_d
        b[r + 2 * N:] = -data.bound_h
        return p_values, q, a_values, b

    def solve(self, data: CondensedData) -> QpSolution:
        import time

        import clarabel

        from pipeline.loop.controller.qp import (CLARABEL_STATUS, OPTIMAL_STATUSES, SOLVER_ERROR,
                                                 clarabel_settings, solver_errors)

        start = time.perf_counter()
        p_values, q, a_values, b = self._data(data)
        if not (np.isfinite(p_values).all() and np.isfinite(q).all()
                and np.isfinite(a_values).all() and np.isfinite(b).all()):
            return QpSolution(NON_FINITE_DATA, -1, time.perf_counter() - start, None)
        try:
            if self._solver is None:
                csc = self._sparse.csc_matrix
                p_idx, p_ptr, p_shape = self.p_structure
                a_idx, a_ptr, a_shape = self.a_structure
                self._solver = clarabel.DefaultSolver(
                    csc((p_values, p_idx, p_ptr), shape=p_shape), q,
                    csc((a_values, a_idx, a_ptr), shape=a_shape), b,
                    [clarabel.NonnegativeConeT(a_shape[0])], clarabel_settings(self.max_iter))
            else:
                self._solver.update(P=p_values, q=q, A=a_values, b=b)
            solution = self._solver.solve()
        except solver_errors() as exc:
            return QpSolution(f"error:{type(exc).__name__}", -1, time.perf_counter() - start,
                              None)
        status = CLARABEL_STATUS.get(str(solution.status).rsplit(".", 1)[-1], SOLVER_ERROR)
        x = np.asarray(solution.x)
        values = {"U": x[:self.n_u], "slack": x[self.n_u:]} \
            if status in OPTIMAL_STATUSES else None
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
        self.n_u, self.n_s, self.N = Nc, N * M, N
        n = Nc + N * M
        self.max_iter = int(max_iter)
        w1, w2 = structure.weights[5], structure.weights[6]
        self._H = 2.0 * w2 * np.eye(n)
        self._f = np.full(n, float(w1))
        self._A = np.zeros((N + N * M, n))
        self._A[N:, Nc:] = np.eye(N * M)
        rate, dmax = structure.steering_rate_max_rad_s, structure.steering_max_rad
        self._dmax = dmax
        self._upper = np.concatenate([np.full(Nc, rate), np.full(N * M, 1e30), np.zeros(N),
                                      np.full(N * M, 1e30)])
        self._lower = np.concatenate([np.full(Nc, -rate), np.zeros(N * M), np.zeros(N),
                                      np.zeros(N * M)])
        self._sense = np.zeros(self._upper.size, np.intc)
        self._model = None        # daqp.Model, set up on the first solve
        self._hessian_of = None   # the hessian_u array the workspace holds (one per speed)

    def cost(self, data: CondensedData) -> tuple[np.ndarray, np.ndarray]:
        """``H`` and ``f`` of the cost ``0.5 z' H z + f' z`` over ``z = [U, S]`` (the same ``H``
        as :class:`ClarabelCondensedQp`'s ``P``)."""
        n_u = self.n_u
        H, f = self._H, self._f
        H[:n_u, :n_u] = data.hessian_u
        f[:n_u] = data.gradient_u
        return H, f

    def solve(self, data: CondensedData) -> QpSolution:
        import time

        import daqp

        start = time.perf_counter()
        n_u, n_s, N = self.n_u, self.n_s, self.N
        H, f = self.cost(data)
        A = self._A
        A[:N, :n_u] = data.gamma_d
        A[N:, :n_u] = data.gamma_h
        upper, lower = self._upper, self._lower
        base = n_u + n_s
        upper[base:base + N] = self._dmax - data.free_d
        lower[base:base + N] = -self._dmax - data.free_d
        lower[base + N:] = data.bound_h
        if not (np.isfinite(data.hessian_u).all() and np.isfinite(f).all()
                and np.isfinite(A).all() and np.isfinite(lower).all()):
            return QpSolution(NON_FINITE_DATA, -1, time.perf_counter() - start, None)
        # a kept workspace (daqp.Model): the Hessian is sent again only when the model's speed
        # changed it; the rest every step (the same optimum as daqp.solve, ~3x cheaper)
        if self._model is None:
            self._model = daqp.Model()
            self._model.setup(H, f, A, upper, lower, self._sense)
            self._model.settings = {"iter_limit": self.max_iter}
        elif data.hessian_u is self._hessian_of:
            self._model.update(f=f, A=A, bupper=upper, blower=lower)
        else:
            self._model.update(H=H, f=f, A=A, bupper=upper, blower=lower)
        self._hessian_of = data.hessian_u
        x, _, exitflag, info = self._model.solve()
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
        # models with a stretched prediction step (controller.horizon_reach_m), by step
        self._qp_cache = qp_cache
        self._stretched: dict[float, LateralModelCache] = {}
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
            if self.condensed:
                self.qp = CompiledCondensedQp(self.qp)
        # condensed predictions by model speed, shared like the models (built once per speed)
        key = ("lateral_predictions", vehicle_key(vehicle), self.sample_time_s,
               self.model_cfg.b2_heading_entry, self.model_cfg.speed_grid_mps,
               controller.horizon, controller.control_horizon, controller.input_hold,
               self.weights[:5])
        self._predictions: dict[float, CondensedPrediction] = \
            qp_cache.memo(key, dict) if qp_cache is not None else {}
        self.fallback = PlanFallback(controller.horizon)
        # the references by the compiled kernel (the same bits) in long studies
        self.compiled_kernels = qp_cache is not None and qp_cache.compiled_kernels
        self._steps_ahead_s = np.arange(1, controller.horizon + 1) * self.sample_time_s
        self._times_s = np.concatenate([[0.0], self._steps_ahead_s])
        self._gains: dict[float, tuple] = {}   # steady-state gains by model speed
        self._frame_record: tuple = ()         # the last step's frame, for its record
        self._plan_poses: tuple | None = None  # the last plan's global poses (path frame)
        self._speeds = np.zeros(0)             # the last path step's predicted speeds
        self._step_times: dict[float, np.ndarray] = {}  # prediction times by step
        self._no_points, self._no_values = np.zeros((0, 2)), np.zeros(0)
        self.records: list[PredictionRecord] = []

    @staticmethod
    def parameter_vector(inputs: MpcInputs) -> np.ndarray:
        """One step's parameter values stacked (column-major) in ``theta`` order."""
        disturbance = inputs.model.Ed @ inputs.disturbance_rad_s[None, :]
        return np.concatenate([
            inputs.x0, inputs.model.Ad.ravel(order="F"), inputs.model.Bd.ravel(order="F"),
            disturbance.ravel(order="F"), inputs.y_ref_m, inputs.psi_ref_rad,
            inputs.yaw_rate_reference(), inputs.steering_reference(),
            inputs.constraint_gain.ravel(order="F"), inputs.constraint_bound.ravel(order="F")])

    def model_at(self, speed_mps: float, step_s: float) -> LateralModel:
        """The model at ``speed_mps`` discretized with the prediction step ``step_s`` (the
        sample time, or longer where ``controller.horizon_reach_m`` stretches it)."""
        if step_s == self.sample_time_s:
            return self.models.at_speed(speed_mps)
        cache = self._stretched.get(step_s)
        if cache is None:
            cfg = self.model_cfg
            shared = self._qp_cache.memo(("lateral_models", vehicle_key(self.vehicle), step_s,
                                          cfg.b2_heading_entry, cfg.speed_grid_mps), dict) \
                if self._qp_cache is not None else {}
            cache = self._stretched[step_s] = LateralModelCache(
                self.vehicle, step_s, cfg.b2_heading_entry, cfg.speed_grid_mps, shared)
        return cache.at_speed(speed_mps)

    def prediction_step(self, speed_mps: float, speed_ref_mps: float) -> float:
        """The prediction step (s): the sample time, stretched where the horizon would cover
        less than ``controller.horizon_reach_m`` at the slower of the measured and the planned
        speed (on the model's speed grid), so that the half-planes see as far ahead in space
        at low speed as at the nominal one."""
        reach = self.cfg.horizon_reach_m
        if reach is None:
            return self.sample_time_s
        vehicle, cfg = self.vehicle, self.model_cfg
        slow = model_speed_mps(min(speed_mps, speed_ref_mps), vehicle.min_model_speed_mps,
                               cfg.speed_grid_mps)
        step = reach / (self.horizon * slow)
        return self.sample_time_s if step <= self.sample_time_s else round(step, 6)

    def prediction(self, model: LateralModel) -> CondensedPrediction:
        """The condensed prediction of ``model`` (built once per model: speed and step)."""
        key = (model.speed_mps, model.sample_time_s)
        entry = self._predictions.get(key)
        if entry is None or entry.model is not model:
            entry = self._predictions[key] = CondensedPrediction.of(model, self.blocking,
                                                                   self.weights[:5])
        return entry

    def solve(self, inputs: MpcInputs, log: dict | None = None) -> ControlStep:
        """Solve the QP for one step's data, falling back safely on any failure."""
        solution = QpSolution("not_solved", -1, 0.0, None)
        free = prediction = None
        if isfinite(sum(inputs.x0.tolist())):  # inf or nan anywhere makes the sum non-finite
            if self.condensed:
                prediction = self.prediction(inputs.model)
                data = condensed_data(prediction, inputs, self.weights)
                free = data.free
                solution = self.qp.solve(data)
            else:
                solution = self.qp.solve(self.parameter_vector(inputs))
        if solution.ok:
            U = np.asarray(solution.values["U"], dtype=float).reshape(-1)
            plan = U @ self.blocking
            if isfinite(sum(plan.tolist())):
                plan = plan[None, :]
                self.fallback.accept(plan)
                if self.condensed:
                    # the eliminated states, for the log and the slack: X = free + Gamma U
                    predicted = free + prediction.gamma @ U
                    states = np.concatenate([inputs.x0[:, None], predicted.T], axis=1)
                else:
                    states = solution.values["X"]
                # slack needed by the optimal plan (what the QP's slack variable holds); rows
                # of idle slots and far obstacles are 0 y + s >= 0 and need none
                slack = 0.0
                if np.count_nonzero(inputs.constraint_gain) \
                        or np.count_nonzero(inputs.constraint_bound):
                    lateral = states[0, 1:][:, None]
                    slack = (inputs.constraint_bound - inputs.constraint_gain * lateral).max()
                return ControlStep(plan[:, 0].copy(), plan, states, solution.status,
                                   solution.iterations, solution.solve_time_s, "none",
                                   float(max(slack, 0.0)), log or {})
        delta = inputs.x0[4] if np.isfinite(inputs.x0[4]) else 0.0
        rate_max = self.vehicle.steering_rate_max_rad_s
        ts = self.sample_time_s
        return self.fallback.step(
            solution.status, solution.iterations, solution.solve_time_s,
            lambda: np.array([float(np.clip(-delta / ts, -rate_max, rate_max))]), log)

    def inputs_from(self, obs: Observation) -> tuple[MpcInputs, dict]:
        """The QP data of one observation in the configured frame (``controller.frame``)."""
        if self.cfg.frame == "path":
            return self.path_inputs(obs)
        return self.fixed_inputs(obs)

    def fixed_inputs(self, obs: Observation) -> tuple[MpcInputs, dict]:
        """The QP data against the start-goal line: references interpolated on the APF path,
        half-planes about them, no disturbance."""
        ctrl, N = self.cfg, self.horizon
        model = self.models.at_speed(obs.speed_ref_mps)
        line_pos = obs.position_line_m
        stations = line_pos[0] + model.speed_mps * self._steps_ahead_s
        path_line = obs.frame.to_line(obs.rollout.path_m)
        y_ref, psi_ref = lateral_reference(path_line, stations, ctrl, self.compiled_kernels)
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
               "path_clipped": bool(abs(np.tan(psi_ref[0])) >= np.tan(ctrl.heading_ref_max_rad)
                                    - 1e-12) if ctrl.heading_reference == "path_slope"
               else False}
        self._frame_record = ("fixed", obs.frame.to_global(np.array([line_pos[0], 0.0])),
                              obs.frame.heading_rad, model.speed_mps * self._times_s,
                              self.sample_time_s)
        return MpcInputs(x0, model, y_ref, psi_ref, G, h, np.zeros(N)), log

    def path_inputs(self, obs: Observation) -> tuple[MpcInputs, dict]:
        """The QP data in path coordinates about the drivable path from the vehicle's pose
        towards the APF rollout (:meth:`reference_path`; :meth:`path_frame_inputs`)."""
        N, vehicle = self.horizon, self.vehicle
        speed = max(float(obs.plant_state[3]), vehicle.min_model_speed_mps)
        dt = self.prediction_step(speed, float(obs.speed_ref_mps))
        reach = max(speed, float(obs.speed_ref_mps)) + vehicle.accel_max_mps2 * dt
        path = self.reference_path(obs, speed * dt, int(np.ceil(N * reach / speed)) + 1)
        return self.path_frame_inputs(obs, path, dt)

    def path_frame_inputs(self, obs: Observation, path: ReferencePath, dt: float
                          ) -> tuple[MpcInputs, dict]:
        """The QP data about ``path`` with prediction step ``dt``: the state as errors from it
        (the vehicle projected on it), its curvature previewed as ``r_d`` at the stations the
        predicted speed reaches (:func:`~pipeline.loop.controller.path.frame_step_arrays`),
        the model's equilibrium on it as the references, and each predicted obstacle projected
        to ``(s, d)`` for half-planes in ``e_y``. On a path built from the vehicle's pose
        along its velocity (its course) ``s0 = e_y = 0`` and the heading error is minus the
        sideslip (what it is in a steady turn on the path)."""
        ctrl, N, vehicle = self.cfg, self.horizon, self.vehicle
        st = obs.plant_state
        speed = max(float(st[3]), vehicle.min_model_speed_mps)
        gains = self._steady_state(self.models.at_speed(speed))
        visible = obs.obstacles
        n_obs = visible.radii_m.shape[0]
        times = self._step_times.get(dt)
        if times is None:
            times = self._step_times[dt] = dt * np.arange(1, N + 1)
        obstacles = visible.predicted_positions(times).reshape(-1, 2) if n_obs \
            else self._no_points
        plan_xy, plan_course = self._plan_poses if self._plan_poses is not None \
            else (self._no_points, self._no_values)
        settings = (path.ds_m, path.n_intervals, float(st[0]), float(st[1]), speed,
                    float(obs.speed_ref_mps), float(gains[1]), dt, N,
                    vehicle.speed_time_constant_s, vehicle.accel_max_mps2)
        if self.compiled_kernels:
            from pipeline.loop.compiled import frame_step_kernel

            s0, d0, heading0, stations, r_d, vx, s_o, d_o = frame_step_kernel(
                path.points_m, path.headings_rad, path.curvature_1_per_m, *settings,
                np.ascontiguousarray(plan_xy), np.ascontiguousarray(plan_course),
                np.ascontiguousarray(obstacles))
        else:
            s0, d0, heading0, stations, r_d, vx, s_o, d_o = frame_step_arrays(
                path.points_m.tolist(), path.headings_rad.tolist(),
                path.curvature_1_per_m.tolist(), *settings, plan_xy.tolist(),
                plan_course.tolist(), obstacles.tolist())
        self._speeds = vx
        model = self.model_at(sum(vx.tolist()) / vx.shape[0], dt)
        heading_error = (float(st[2]) - heading0 + pi) % (2.0 * pi) - pi
        x0 = np.array([d0, st[4], heading_error, st[5], st[6]])
        if ctrl.path_state_reference == "steady_state":
            gains = self._steady_state(model)
            refs = gains[:, None] * r_d[None, :]  # the state that holds r_d, at steps 1..N
            psi_ref, r_ref, delta_ref = refs[2], refs[3], refs[4]
        else:
            psi_ref = r_ref = delta_ref = np.zeros(N)
        projected = np.empty((N, n_obs, 2))
        projected[:, :, 0], projected[:, :, 1] = s_o.reshape(N, n_obs), d_o.reshape(N, n_obs)
        G, h = collision_halfplanes(stations[1:], np.zeros(N), np.array([s0, d0]), projected,
                                    visible.radii_m, vehicle, ctrl)
        first = obs.frame.to_line(path.points_m[1]) if N else obs.position_line_m
        log = {"y_ref_m": first[1], "psi_ref_rad": path.headings_rad[1] - obs.frame.heading_rad,
               "path_clipped": bool(np.count_nonzero(
                   path.clipped[:int(np.ceil(stations[-1] / path.ds_m - 1e-9))])),
               "path_curvature_1_per_m": path.curvature_1_per_m[0], "r_d_rad_s": r_d[0]}
        self._frame_record = ("path", path, stations, dt)
        return MpcInputs(x0, model, np.zeros(N), psi_ref, G, h, r_d, r_ref, delta_ref), log

    def reference_path(self, obs: Observation, ds_m: float, n_intervals: int
                       ) -> ReferencePath:
        """The drivable path of one observation: ``n_intervals`` arcs of ``ds_m``."""
        ctrl, vehicle = self.cfg, self.vehicle
        kappa_max = ctrl.path_curvature_max_1_per_m if ctrl.path_curvature_max_1_per_m \
            is not None else np.tan(vehicle.steering_max_rad) / vehicle.wheelbase_m
        rollout = obs.rollout.path_m
        line = obs.frame.heading_rad
        st = obs.plant_state
        course = float(st[2]) + atan2(float(st[4]), max(float(st[3]), 0.1))
        if ctrl.heading_reference == "apf_force":
            # Section 3.1's psi_apf / omega_ref as the path's heading (the reading's path)
            rollout_forces = obs.rollout
            force = rollout_forces.attraction[0] + rollout_forces.repulsion[0] \
                if rollout_forces.attraction.shape[0] else np.array([np.cos(line),
                                                                   np.sin(line)])
            limits = (line - ctrl.heading_ref_max_rad, line + ctrl.heading_ref_max_rad)
            arrays = heading_ramp_path(float(st[0]), float(st[1]), course,
                                       float(np.arctan2(force[1], force[0])),
                                       ctrl.yaw_rate_ref_max_rad_s, limits, float(kappa_max),
                                       float(ds_m), self.sample_time_s, int(n_intervals))
            return ReferencePath(*arrays, float(ds_m))
        args = (float(st[0]), float(st[1]), course)
        cos_line, sin_line = obs.frame.cos_sin
        settings = (float(cos_line), float(sin_line), ctrl.path_beyond_end == "extend",
                    float(ctrl.path_lookahead_m), float(kappa_max), float(ds_m),
                    int(n_intervals))
        if self.compiled_kernels:
            from pipeline.loop.compiled import chase_path_kernel

            arrays = chase_path_kernel(*args, np.ascontiguousarray(rollout, dtype=float),
                                       *settings)
        else:
            arrays = chase_path_arrays(*args, rollout.tolist(), *settings)
        return ReferencePath(*arrays, float(ds_m))

    def _steady_state(self, model: LateralModel) -> np.ndarray:
        """:func:`~pipeline.loop.controller.path.steady_state_gains` of ``model`` (of its
        continuous matrices: one per speed)."""
        gains = self._gains.get(model.speed_mps)
        if gains is None:
            gains = self._gains[model.speed_mps] = steady_state_gains(model)
        return gains

    def step(self, obs: Observation) -> ControlStep:
        """One closed-loop step (its prediction kept for :meth:`model_check`)."""
        inputs, log = self.inputs_from(obs)
        step = self.solve(inputs, log)
        plan = step.predicted_states[0] if step.predicted_states is not None \
            and step.fallback == "none" else None
        self._plan_poses = None
        if plan is not None and self._frame_record[0] == "path":
            # the plan's poses (global), for the next step's stations
            _, path, stations, _ = self._frame_record
            states = step.predicted_states
            arrays = (path.points_m, path.headings_rad, path.curvature_1_per_m)
            rows = (stations, states[0], states[2], states[1], self._speeds)
            if self.compiled_kernels:
                from pipeline.loop.compiled import plan_poses_kernel

                self._plan_poses = plan_poses_kernel(
                    *arrays, path.ds_m, path.n_intervals,
                    *(np.ascontiguousarray(r) for r in rows))
            else:
                self._plan_poses = plan_poses_arrays(
                    *(a.tolist() for a in arrays), path.ds_m, path.n_intervals,
                    *(r.tolist() for r in rows))
        model = inputs.model if inputs.model.sample_time_s == self.sample_time_s \
            else self.models.at_speed(inputs.model.speed_mps)  # the replay's, at the log's rate
        self.records.append(PredictionRecord(self._frame_record, inputs.x0, model,
                                             inputs.disturbance_rad_s, plan))
        return step

    def model_check(self, log: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """How well each step's prediction held (:func:`prediction_check`), one value per row
        of the run's log (``log``: its columns)."""
        plant = np.column_stack([log[name] for name in ("X_m", "Y_m", "psi_rad", "delta_rad")])
        kernel = None
        if self.compiled_kernels:
            from pipeline.loop.compiled import check_record_kernel as kernel
        return prediction_check(self.records, log["time_s"], plant, self.sample_time_s, kernel)
