"""The lateral MPC's QP (paper Section 3), stated once per structure: the data one step hands
it (:class:`MpcInputs`), the condensed statement (states eliminated) and the condensed data of
one step (:func:`condensed_data`).

The QP over ``N`` steps::

    min  sum_k q_y (y_k - y_ref,k)^2 + q_psi (epsi_k - psi_ref,k)^2 + q_r (r_k - r_ref,k)^2
         + q_d (delta_k - delta_ref,k)^2 + r_u u_k^2 + w1 sum(s) + w2 sum(s^2)
    s.t. x_{k+1} = Ad x_k + Bd u_k + Ed d_k,  x_0 = measured state
         |u_k| <= delta_dot_max,  |delta_k| <= delta_max,
         u_k = U[min(k, Nc - 1)] (hold_last) or 0 for k >= Nc (zero_rate)
         G_kj y_k + s_kj >= h_kj,  s >= 0   (soft half-plane per obstacle slot j and step k)

The model matrices are parameters, so one compiled problem serves every speed (velocity
planning) and every scenario; unused obstacle slots get rows that cannot bind. A step solves
the statement of the fewest slots that holds its half-planes (:func:`slots_used`; the
controller keeps one per count, :attr:`LateralMpc.qp_by_slots
<pipeline.loop.controller.lateral.LateralMpc.qp_by_slots>`): with no obstacle within reach,
the 3-variable QP of the moves alone.

The QP is stated condensed (``controller.formulation=condensed``, its one value): the states
are eliminated, ``X = free response + Gamma U`` with the prediction matrices of the model's
speed (:class:`CondensedPrediction`, cached per speed) and the free response computed in numpy
each step, so the QP carries only ``U`` and the slacks (33 variables at N = 10, three obstacle
slots); its parameters are the weighted prediction rows and the half-planes folded onto ``U``,
so it stays DPP. The same QP with the states as variables (151 variables) is no controller's
any more (no experiment used it, issue 58): it is the benchmark's floor and the tests' oracle
(``benchmarks/harness/sparse_floor.py``), which hold the two to the same optimum.

The condensed statement is written in the coordinates ``W = R U`` of the cost's Cholesky factor
``R`` (``R' R`` = half the Hessian in ``U``): the tracking cost is then ``|W|^2 + 2 r' W``, a
constant quadratic, and every bound is a plain pair of inequalities, so CVXPY's canonical
problem is the 33-variable, 86-row QP itself (no auxiliary variables, no equality rows), the
one :class:`~pipeline.loop.controller.lateral_backends.DaqpCondensedQp` hands DAQP.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache, cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline.loop.controller_settings import LateralWeights, MpcSettings
from pipeline.loop.model import LateralModel
from pipeline.loop.settings import VehicleConfig

if TYPE_CHECKING:
    import cvxpy as cp


@dataclass(frozen=True)
class MpcInputs:
    """Per-step data of the lateral QP (everything that changes from step to step)."""

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


@cache
def pack_offsets(horizon: int, control_horizon: int) -> tuple[int, ...]:
    """Where each map starts in a prediction's pack, and the pack's length: ``free_map``
    (5N x 5, F), ``disturbance_map`` (5N x N, F), ``cost_root`` (4N), ``cost_index`` (4N),
    ``root_weights`` (4), ``gamma`` (N x 5 x Nc, C), ``gradient_map`` (Nc x 4N, F),
    ``hessian_u`` (Nc x Nc, C)."""
    N, nc = horizon, control_horizon
    sizes = (25 * N, 5 * N * N, 4 * N, 4 * N, 4, 5 * N * nc, 4 * N * nc, nc * nc)
    return tuple(int(v) for v in np.concatenate([[0], np.cumsum(sizes)]))


def direct_pack_offsets(horizon: int, control_horizon: int) -> tuple[int, ...]:
    """Where each map starts in a prediction's :attr:`CondensedPrediction.direct_pack`, and
    its length: ``chol_rhs_map`` (Nc x 4N, F), ``chol_inv`` (Nc x Nc, F),
    ``steering_gamma_w_flat`` (N Nc)."""
    N, nc = horizon, control_horizon
    sizes = (4 * N * nc, nc * nc, N * nc)
    return tuple(int(v) for v in np.concatenate([[0], np.cumsum(sizes)]))


def direct_theta_size(horizon: int, control_horizon: int, slots: int) -> int:
    """The length of the compiled statement's parameter vector with ``slots`` obstacle slots
    (:func:`build_condensed_lateral_problem`, :meth:`CondensedData.theta`)."""
    N, nc = horizon, control_horizon
    return nc * nc + nc + N * nc + N + slots * (N * nc + N)


#: The tracking weights of an unweighted prediction (all states at 1, no rate cost).
UNIT_TRACKING = (1.0, 1.0, 1.0, 1.0, 0.0)


@dataclass(frozen=True)
class LateralQpStructure:
    """Everything that enters the lateral QP as a constant: the cache key of a compilation."""

    horizon: int
    control_horizon: int
    max_obstacles: int
    input_hold: str
    weights: LateralWeights
    steering_rate_max_rad_s: float
    steering_max_rad: float

    @classmethod
    def of(cls, controller: MpcSettings,
           vehicle: VehicleConfig) -> LateralQpStructure:
        c = controller
        # the road's edges (controller.road_edge_weight) take two slots beyond the obstacles'
        return cls(c.horizon, c.control_horizon, c.max_obstacles + getattr(c, "road_slots", 0),
                   c.input_hold,
                   c.weights, vehicle.steering_rate_max_rad_s, vehicle.steering_max_rad)


def blocking_matrix(horizon: int, control_horizon: int, input_hold: str) -> np.ndarray:
    """Matrix ``T`` (Nc x N) with ``u_seq = U @ T`` for the move-blocking rule."""
    T = np.zeros((control_horizon, horizon))
    for k in range(horizon):
        if k < control_horizon:
            T[k, k] = 1.0
        elif input_hold == "hold_last":
            T[control_horizon - 1, k] = 1.0
    return T


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
    steering_bound_rad : float or None
        The steering bound at this model's speed where it is tighter than the statement's
        (``controller.steering_friction_share``, :func:`friction_steering_bound_rad`); None:
        the statement's ``vehicle.steering_max_rad``.
    steering_scale : float
        The statement's bound over ``steering_bound_rad`` (1 without one): the compiled
        statement states ``|delta_k| <= bound`` as its own rows with the steering angle's
        response and free value multiplied by this (:meth:`CondensedData.theta`).
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
    steering_bound_rad: float | None = None
    steering_scale: float = 1.0

    @classmethod
    def of(cls, model: LateralModel, blocking: np.ndarray,
           tracking: tuple[float, ...] = UNIT_TRACKING, steering_max_rad: float | None = None,
           steering_bound_rad: float | None = None) -> CondensedPrediction:
        """Build the maps of ``model``; ``tracking``: :attr:`LateralWeights.tracking`
        ``(q_y, q_psi, q_r, q_d, r_u)``; ``steering_bound_rad``: a steering bound at this
        speed below the statement's ``steering_max_rad`` (None, or not below it: the
        statement's)."""
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
        q_y, q_psi, q_r, q_d, r_u = tracking
        root = np.sqrt(np.array([q_y, q_psi, q_r, q_d], float))
        # rows ordered by cost term, then step: [y_1..y_N, epsi_1.., r_1.., delta_1..]
        gamma_w = (root[:, None, None] * gamma[:, COST_STATES, :].transpose(1, 0, 2)
                   ).reshape(-1, nc)
        half_hessian = gamma_w.T @ gamma_w + float(r_u) * blocking @ blocking.T
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
        scale = 1.0
        if steering_bound_rad is not None and steering_max_rad is not None \
                and steering_bound_rad < steering_max_rad:
            scale = float(steering_max_rad) / float(steering_bound_rad)
        else:
            steering_bound_rad = None
        return cls(model, gamma, fortran(powers.reshape(-1, 5)), fortran(gamma_w),
                   root, 2.0 * half_hessian, chol, fortran(chol_rhs_map),
                   fortran(2.0 * gamma_w.T), chol_inv, cost_index, cost_root,
                   steering_gamma_w, chol_inv.ravel(order="F"),
                   (steering_gamma_w * scale if scale != 1.0 else steering_gamma_w
                    ).ravel(order="F"),
                   fortran(disturbance_map.reshape(-1, n)),
                   None if steering_bound_rad is None else float(steering_bound_rad), scale)

    @cached_property
    def pack(self) -> np.ndarray:
        """The maps the compiled DAQP caller reads, in one contiguous array (its layout:
        :func:`pack_offsets`; each matrix in the order it has here, so a view of the pack is
        the same matrix to BLAS)."""
        return np.concatenate([self.free_map.ravel(order="F"),
                               self.disturbance_map.ravel(order="F"), self.cost_root,
                               self.cost_index.astype(float), self.root_weights,
                               np.ascontiguousarray(self.gamma).ravel(),
                               self.gradient_map.ravel(order="F"),
                               np.ascontiguousarray(self.hessian_u).ravel()])

    @cached_property
    def direct_pack(self) -> np.ndarray:
        """The maps the compiled statement of the CVXPY parameters reads beside :attr:`pack`
        (:mod:`~pipeline.loop.controller.direct_rows`; layout :func:`direct_pack_offsets`, each
        matrix in the order it has here)."""
        return np.concatenate([self.chol_rhs_map.ravel(order="F"),
                               self.chol_inv.ravel(order="F"), self.steering_gamma_w_flat])

    def free_response(self, x0: np.ndarray, disturbance: np.ndarray) -> np.ndarray:
        """States at steps 1..N with ``U = 0`` (shape (N, 5)); ``disturbance`` is (5, N)."""
        Ad = self.model.Ad
        out = np.empty((disturbance.shape[1], 5))
        x = x0
        for k in range(disturbance.shape[1]):
            x = Ad @ x + disturbance[:, k]
            out[k] = x
        return out


def build_condensed_lateral_problem(s: LateralQpStructure) -> tuple[cp.Problem, list[Any], dict[str, Any]]:
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
    w1, w2 = s.weights.slack_linear, s.weights.slack_quadratic
    chol_inv = cp.Parameter((Nc, Nc), name="cost_cholesky_inverse")
    chol_rhs = cp.Parameter(Nc, name="cost_cholesky_rhs")
    gamma_d = cp.Parameter((N, Nc), name="steering_gamma_w")
    free_d = cp.Parameter(N, name="steering_free")
    W = cp.Variable(Nc, name="W")
    rate, steering = s.steering_rate_max_rad_s, s.steering_max_rad
    cost = cp.sum_squares(W) + 2 * chol_rhs @ W
    moves = chol_inv @ W
    steering_angle = gamma_d @ W
    constraints = [moves <= rate, -moves <= rate,
                   steering_angle <= steering - free_d, -steering_angle <= steering + free_d]
    parameters = [chol_inv, chol_rhs, gamma_d, free_d]
    if M:  # no slot, no half-plane (the statement of a step whose half-planes are all empty)
        gamma_h = cp.Parameter((N * M, Nc), name="halfplane_gamma_w")
        bound_h = cp.Parameter(N * M, name="halfplane_free_bound")
        S = cp.Variable(N * M, name="slack")
        cost = cost + w1 * cp.sum(S) + w2 * cp.sum_squares(S)
        constraints += [gamma_h @ W + S >= bound_h, S >= 0]
        parameters += [gamma_h, bound_h]
    problem = cp.Problem(cp.Minimize(cost), constraints)
    if not problem.is_dcp(dpp=True):
        raise RuntimeError("condensed lateral MPC is not DPP; it would recompile every step")
    return problem, parameters, {"W": W}


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
    #: each step's steering bound where the prediction's friction bound
    #: (:attr:`CondensedPrediction.steering_bound_rad`) is relaxed, the steering now beyond it
    #: (:func:`steering_bounds_from`); None: the prediction's bound at every step
    steering_bounds_rad: np.ndarray | None = None

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

    def halfplane_rows(self, slots: int) -> tuple[np.ndarray, np.ndarray]:
        """``gamma_h`` and ``bound_h`` of the first ``slots`` obstacle slots (rows k-major:
        step k's slots j < slots), for a statement of fewer slots than these data (the rest
        must be empty rows, :func:`slots_used`); the arrays themselves when all of them."""
        n = self.free_d.shape[0]
        all_slots = self.bound_h.shape[0] // n if n else 0
        if slots >= all_slots:
            return self.gamma_h, self.bound_h
        moves = self.gamma_h.shape[1]
        gamma_h = self.gamma_h.reshape(n, all_slots, moves)[:, :slots].reshape(n * slots, moves)
        return gamma_h, self.bound_h.reshape(n, all_slots)[:, :slots].ravel()

    def theta(self, slots: int | None = None) -> np.ndarray:
        """The parameter vector of :func:`build_condensed_lateral_problem` (its order, column-
        major): the rows that multiply ``U`` taken to ``W = R U``; ``slots``: the statement's
        number of obstacle slots, the first ``slots`` of these data's (all by default; the
        rest must be empty rows, :func:`slots_used`)."""
        prediction = self.prediction
        # a bound tighter than the statement's: both steering rows multiplied by the scale
        # (c |gamma_d W + free_d| <= delta_max is |gamma_d W + free_d| <= delta_max / c; the
        # flat response is stored scaled), each row by its own where the bounds differ by step
        steering_flat, free_d = prediction.steering_gamma_w_flat, self.free_d
        if self.steering_bounds_rad is not None and prediction.steering_bound_rad is not None:
            scales = prediction.steering_bound_rad * prediction.steering_scale \
                / self.steering_bounds_rad
            steering_flat = (prediction.steering_gamma_w * scales[:, None]).ravel(order="F")
            free_d = self.free_d * scales
        elif prediction.steering_scale != 1.0:
            free_d = self.free_d * prediction.steering_scale
        head = [prediction.chol_inv_flat, self.chol_rhs, steering_flat, free_d]
        if slots == 0:
            return np.concatenate(head)
        gamma_h, bound_h = (self.gamma_h, self.bound_h) if slots is None \
            else self.halfplane_rows(slots)
        return np.concatenate([*head, (gamma_h @ prediction.chol_inv).ravel(order="F"),
                               bound_h])


def friction_steering_bound_rad(vehicle: VehicleConfig, share: float | None,
                                speed_mps: float) -> float:
    """The lateral MPC's steering bound at ``speed_mps`` (``controller.steering_friction_share``):
    ``min(steering_max, atan(share mu g L / v^2))``, the steering at which a kinematic
    single-track's lateral acceleration ``v^2 tan(delta) / L`` reaches ``share`` times the
    tyres' friction ``mu g`` (``vehicle.tire_friction``); ``vehicle.steering_max_rad`` when
    ``share`` is None."""
    from math import atan

    from pipeline.loop.model import GRAVITY_MPS2

    steering_max = float(vehicle.steering_max_rad)
    if share is None:
        return steering_max
    speed = max(abs(float(speed_mps)), 1e-6)
    return min(steering_max, atan(float(share) * float(vehicle.tire_friction) * GRAVITY_MPS2
                                  * float(vehicle.wheelbase_m) / speed ** 2))


def steering_bounds_from(bound_rad: float, steering_now_rad: float, rate_max_rad_s: float,
                         step_s: float, horizon: int) -> np.ndarray | None:
    """Each predicted step's steering bound when the steering now is beyond ``bound_rad``
    (the friction bound fell with a rising speed, or the step's model speed rose): the
    steering may come down at the actuator's rate, ``max(bound, |delta_0| - k rate dt)`` at
    step ``k = 1..N``, so the QP keeps a plan (the rows at ``bound`` would ask for more than
    the rate allows). None where the first step can be within the bound (``|delta_0| - rate
    dt <= bound``: the bound at every step, the same statement bit for bit)."""
    excess = abs(float(steering_now_rad))
    per_step = float(rate_max_rad_s) * float(step_s)
    if not excess - per_step > bound_rad:  # NaN too: the solve then reports non-finite data
        return None
    steps = np.arange(1, horizon + 1)
    return np.maximum(bound_rad, excess - steps * per_step)


def slots_used(*halfplane_rows: np.ndarray) -> int:
    """How many of a step's obstacle slots its half-planes use, given their gains and bounds
    (each shape (N, slots): the lateral MPC's ``G, h``, the kinematic MPC's ``Gx, Gy, h``): one
    past the last slot with a row that is not ``0 + s >= 0`` (0 when every row is empty).
    Slots beyond it can be left out of the QP: an empty row's slack is 0 at the optimum (its
    cost rises with it), so the smaller statement has the same solution (to the solver's
    tolerance)."""
    nonzero = np.zeros(halfplane_rows[0].shape, dtype=bool)
    for rows in halfplane_rows:
        nonzero |= rows != 0.0
    used = np.flatnonzero(np.any(nonzero, axis=0))
    return int(used[-1]) + 1 if used.size else 0


def condensed_data(prediction: CondensedPrediction, inputs: MpcInputs,
                   weights: LateralWeights) -> CondensedData:
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
