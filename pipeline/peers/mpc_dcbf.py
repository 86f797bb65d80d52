"""MPC with discrete-time control barrier functions (MPC-DCBF), on both tracks.

Zeng, Zhang and Sreenath, "Safety-critical model predictive control with discrete-time control
barrier function", ACC 2021: the MPC's collision constraints are the DCBF conditions

    h_j(x_{k+1}) >= (1 - gamma) h_j(x_k),   k = 0 .. N-1, every obstacle slot j,

with ``h_j(p) = |p - o_j(t_k)| - R_j`` (``R_j`` = obstacle radius + ``vehicle.footprint_radius_m``
+ ``controller.safety_margin_m``; ``o_j(t_k)`` the obstacle moved with its velocity, constant
velocity, visible obstacles only), in place of the built-in MPCs' half-planes. The reference is
the goal line (planner ``straight_to_goal``): no APF.

Linearization (the problem stays a QP, compiled once). ``h_j`` is replaced at every step ``k``
by its tangent at a linearization point ``pbar_k``: ``h_j(p) ~ n_kj . (p - o_j(t_k)) - R_j`` with
``n_kj`` the unit vector from ``o_j(t_k)`` to ``pbar_k``. ``h_j`` is convex in ``p``, so the
tangent never exceeds it: a plan meeting ``tangent >= c`` has ``h_j >= c``. ``h_j(x_0)`` is the
exact (measured) value. The linearization points:

* lateral track (:class:`LateralMpcDcbf`, ``controller.frame=fixed``): the station (along the
  goal line) is not a decision variable, it advances at the planned speed,
  ``s_k = s_0 + V_r k Ts``; the lateral coordinate is ``ybar_k``, the previous plan's prediction
  shifted by one step (the reference ``y_ref`` at the first step and after a fallback), so the
  rows are linear in the predicted lateral positions ``y_k`` (two per row: ``k`` and ``k+1``);
* kinematic track (:class:`KinematicMpcDcbf`): ``pbar_k`` is the LTV linearization's own
  trajectory (the measured state rolled out with the previous plan, shifted), both coordinates.

Side rule. Where the linearization point sits on the obstacle's line (dead ahead) the tangent's
lateral part vanishes and steering cannot raise ``h``. So each obstacle gets one side ``sigma_j``
per step (in the start-goal line's frame): the side the linearization trajectory is on where it
comes closest to the obstacle; if it is dead ahead there (within 1e-6 m), the side the vehicle is
on now; on a tie, the left (``+1``). The linearization point's lateral offset from the obstacle
is then taken as ``sigma_j max(sigma_j (ybar_k - o_y), rho R_j)`` (``rho`` =
``params.min_lateral_offset_ratio``): at least a share of the keep-out radius on the chosen side,
so the gradient always has a lateral part and one side is kept along the horizon (any tangent
point keeps the rows conservative, see above). The rule lives in :mod:`pipeline.peers.side_rule`
(:func:`~pipeline.peers.side_rule.sided_normals`), shared with the CBF-QP filter
(:mod:`pipeline.peers.cbf_filter`).

Slack. Each row ``(k, j)`` has a slack ``s_kj >= 0`` weighted ``controller.slack_weight_linear
sum(s) + controller.slack_weight_quadratic sum(s^2)`` (the built-in MPCs' weights), so the QP is
always feasible; ``ControlStep.max_slack_m`` is the largest slack the optimal plan needs (0: every
linearized DCBF row holds).

Fallback. When the solve fails (solver status not optimal, non-finite data or solution), the
controller takes :class:`~pipeline.loop.controller.base.PlanFallback`: the previous plan shifted
by one step while it lasts, then a bounded safe input (lateral: the steering rate that returns
the wheel to straight; kinematic: brake to rest, wheel straight), as the built-in MPCs do.

Obstacle slots. The ``controller.max_obstacles`` visible obstacles nearest the vehicle within
``controller.constraint_activation_m`` get rows (none when ``controller.collision_constraints``
is false); other slots get rows ``0 + s >= 0`` that cannot bind.

The lateral rows ride on the condensed lateral QP
(:func:`~pipeline.loop.controller.lateral_qp.build_condensed_lateral_problem`), whose obstacle
rows are generic parameters ``gamma_h U + s >= bound_h`` (one row per step and slot): the DCBF
rows are written in that form, so the compiled problem (the QP cache's ``lateral`` entry, the
built-in's, compiled once per structure) and every condensed backend are reused.
The kinematic rows involve two steps' positions, so :func:`build_kinematic_dcbf_problem` states
its own LTV-QP (compiled once per structure through the QP cache).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from math import isfinite
from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline.errors import ConfigError
from pipeline.loop.controller.base import ControlStep, Observation, PlanFallback
from pipeline.loop.controller.kinematic import KinematicLtvMpc, KinematicQpStructure
from pipeline.loop.controller.lateral import LateralMpc
from pipeline.loop.controller.lateral_qp import blocking_matrix, condensed_data
from pipeline.loop.controller.qp import QpCache, QpSolution, compiled_backend
from pipeline.loop.controller.references import constrains
from pipeline.loop.controller_settings import KinematicMpcSettings, MpcSettings, settings_of
from pipeline.loop.scenario import ObstacleSnapshot
from pipeline.loop.settings import VehicleConfig
from pipeline.peers.side_rule import sided_normals

if TYPE_CHECKING:
    import cvxpy as cp

__all__ = ["DcbfParams", "KinematicMpcDcbf", "LateralMpcDcbf", "barrier_m", "nearest_slots",
           "build_kinematic_dcbf_problem"]


@dataclass(frozen=True)
class DcbfParams:
    """The method's own settings (``controller.params``).

    Attributes
    ----------
    gamma : float
        DCBF decay rate in ``(0, 1]``: ``h`` may shrink by at most the share ``gamma`` of itself
        per step. 1 only keeps ``h >= 0`` at each next step; smaller values make the controller
        turn away earlier.
    min_lateral_offset_ratio : float
        ``rho`` in ``(0, 1]``: least lateral offset of a linearization point from the obstacle,
        as a share of the keep-out radius (side rule).
    """

    gamma: float = 0.2
    min_lateral_offset_ratio: float = 0.5

    #: Allowed range of each key: (low, high, low inclusive).
    RANGES = {"gamma": (0.0, 1.0, False), "min_lateral_offset_ratio": (0.0, 1.0, False)}

    @classmethod
    def of(cls, params: Mapping[str, Any] | None) -> DcbfParams:
        """Read and check ``controller.params``; a :class:`~pipeline.errors.ConfigError` (a
        ``ValueError``, one line) names ``controller.params.<key>`` and its range."""
        params = dict(params or {})
        for key in params:
            if key not in cls.RANGES:
                raise ConfigError(f"controller.params.{key}", params[key],
                                  f"one of the keys {sorted(cls.RANGES)}")
        values: dict[str, float] = {}
        for key, (low, high, closed) in cls.RANGES.items():
            value = params.get(key, getattr(cls, key))
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) \
                and isfinite(value) and (low <= value if closed else low < value) \
                and value <= high
            if not ok:
                bracket = "[" if closed else "("
                raise ConfigError(f"controller.params.{key}", value,
                                  f"a number in {bracket}{low:g}, {high:g}]")
            values[key] = float(value)
        return cls(**values)


def _params_of(controller: Any) -> DcbfParams:
    """:class:`DcbfParams` of a controller's settings (defaults for settings without params)."""
    return DcbfParams.of(getattr(controller, "params", None))


def barrier_m(points_m: np.ndarray, centres_m: np.ndarray, reach_m: np.ndarray) -> np.ndarray:
    """The exact barrier ``h = |p - o| - R``.

    Parameters
    ----------
    points_m : ndarray, shape (K, 2)
        Vehicle positions.
    centres_m : ndarray, shape (K, n, 2)
        Obstacle centres at the same instants.
    reach_m : ndarray, shape (n,)
        Keep-out radii ``R``.

    Returns
    -------
    ndarray, shape (K, n)
    """
    return np.linalg.norm(points_m[:, None, :] - centres_m, axis=2) - reach_m[None, :]


def nearest_slots(snapshot: ObstacleSnapshot, position_m: np.ndarray,
                  controller: MpcSettings | KinematicMpcSettings) -> np.ndarray:
    """Indices of the obstacles that get DCBF rows: within ``constraint_activation_m`` (and
    collision constraints on, :func:`~pipeline.loop.controller.references.constrains`),
    nearest first, at most ``max_obstacles``."""
    n = snapshot.radii_m.shape[0]
    if not n:
        return np.zeros(0, dtype=int)
    distance = np.linalg.norm(snapshot.positions_m - position_m[None, :], axis=1)
    order = np.argsort(distance, kind="stable")
    keep = [int(j) for j in order if constrains(float(distance[j]), controller)]
    return np.array(keep[:controller.max_obstacles], dtype=int)


class LateralMpcDcbf(LateralMpc):
    """MPC-DCBF on the lateral track: the lateral MPC (its model bank, fixed frame, condensed
    QP, backends, fallback and prediction record) with linearized DCBF rows in place of the
    half-planes (module docstring).

    Parameters
    ----------
    controller : MpcSettings
        ``kind=mpc``, ``frame=fixed``, a QP backend (not nmpc);
        ``params``: :class:`DcbfParams`.
    vehicle : VehicleConfig
    sample_time_s : float
    qp_cache : QpCache, optional

    Notes
    -----
    The loop hands a ``_target_`` controller no model settings: the lateral model is built with
    :class:`~pipeline.loop.settings.ModelConfig`'s defaults (those of ``conf/config.yaml``).
    """

    def __init__(self, controller: MpcSettings, vehicle: VehicleConfig,
                 sample_time_s: float = 0.1, qp_cache: QpCache | None = None) -> None:
        kind = getattr(controller, "kind", "mpc")
        if kind != "mpc":
            raise ConfigError("controller.kind", str(kind),
                              "mpc (LateralMpcDcbf drives the single-track plant)")
        settings = settings_of(controller, MpcSettings)
        if settings.frame != "fixed":
            raise ConfigError("controller.frame", str(settings.frame),
                              "fixed (the DCBF rows are stated about the goal line)")
        if settings.backend == "nmpc":
            raise ConfigError("controller.backend", "nmpc",
                              "clarabel_direct, cvxpy or daqp (a QP)")
        self.params = _params_of(controller)
        self.dcbf_cfg = settings
        # the frame's half-planes are not used: it is handed settings without them
        super().__init__(replace(settings, collision_constraints=False), vehicle, None,
                         sample_time_s, qp_cache)
        N = settings.horizon
        self._times_s = np.arange(N + 1) * self.sample_time_s
        self._last_lateral_m: np.ndarray | None = None   # the last plan's y_1..y_N

    def dcbf_rows(self, obs: Observation, stations_m: np.ndarray, y_ref_m: np.ndarray,
                  free: np.ndarray, gamma: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, float]:
        """The linearized DCBF rows on the moves ``U``: ``rows U + s >= bound``.

        Parameters
        ----------
        obs : Observation
        stations_m : ndarray, shape (N + 1,)
            ``s_0 .. s_N`` along the goal line.
        y_ref_m : ndarray, shape (N,)
            Linearization fallback (first step, after a fallback).
        free : ndarray, shape (N, 5)
            Free response (``U = 0``) at steps 1..N.
        gamma : ndarray, shape (N, 5, Nc)
            Response of the states at steps 1..N to ``U``.

        Returns
        -------
        rows : ndarray, shape (N M, Nc)
            Row ``k M + j``: step ``k`` (``h(x_{k+1}) >= (1 - gamma) h(x_k)``), slot ``j``.
        bound : ndarray, shape (N M,)
        min_h_m : float
            The smallest exact ``h(x_0)`` over the constrained obstacles (NaN when none).
        """
        ctrl, N, M = self.dcbf_cfg, self.horizon, self.dcbf_cfg.max_obstacles
        nc = gamma.shape[2]
        rows, bound = np.zeros((N, M, nc)), np.zeros((N, M))
        position = obs.plant_state[:2]
        slots = nearest_slots(obs.obstacles, position, ctrl)
        if not slots.size:
            return rows.reshape(N * M, nc), bound.ravel(), float("nan")
        visible = obs.obstacles
        centres = obs.frame.to_line(visible.predicted_positions(self._times_s)[:, slots, :])
        reach = visible.radii_m[slots] + self.vehicle.footprint_radius_m + ctrl.safety_margin_m
        lateral = self._last_lateral_m if self._last_lateral_m is not None else y_ref_m
        points = np.column_stack([stations_m, np.concatenate([[obs.position_line_m[1]],
                                                              lateral])])
        h0 = barrier_m(obs.position_line_m[None, :], centres[:1], reach)[0]
        normals = sided_normals(points, centres, reach, self.params.min_lateral_offset_ratio)
        decay = 1.0 - self.params.gamma
        n_x, n_y = normals[..., 0], normals[..., 1]
        # tangent of h at step k: n_x (s_k - o_x) + n_y (y_k - o_y) - R = c_k + n_y y_k
        c = n_x * (stations_m[:, None] - centres[..., 0]) - n_y * centres[..., 1] - reach
        # h(x_{k+1}) - (1 - gamma) h(x_k) = a1 y_{k+1} + a0 y_k + const   (y_0, h(x_0) measured)
        a1, a0 = n_y[1:], -decay * n_y[:-1]
        a0[0] = 0.0
        const = c[1:] - decay * c[:-1]
        const[0] = c[1, :] - decay * h0
        n = slots.size
        y = free[:, 0]
        y_prev = np.concatenate([[0.0], y[:-1]])
        g_prev = np.concatenate([np.zeros((1, nc)), gamma[:-1, 0, :]])
        rows[:, :n, :] = a1[:, :, None] * gamma[:, None, 0, :] + a0[:, :, None] * g_prev[:, None, :]
        bound[:, :n] = -(const + a1 * y[:, None] + a0 * y_prev[:, None])
        return rows.reshape(N * M, nc), bound.ravel(), float(h0.min())

    def step(self, obs: Observation) -> ControlStep:
        """One closed-loop step: the fixed frame's data, the DCBF rows, one QP solve (or the
        fallback); the prediction kept for :meth:`model_check`."""
        inputs, log = self.frame.inputs(obs)
        solution = QpSolution("not_solved", -1, 0.0, None)
        min_h = float("nan")
        data = None
        if isfinite(sum(inputs.x0.tolist())):
            prediction = self.prediction(inputs.model)
            data = condensed_data(prediction, inputs, self.weights)
            stations = obs.position_line_m[0] + inputs.model.speed_mps * self._times_s
            rows, bound, min_h = self.dcbf_rows(obs, stations, inputs.y_ref_m, data.free,
                                                prediction.gamma)
            data = replace(data, gamma_h=rows, bound_h=bound)
            solution = self.qp.solve(data)
        log = {**log, "cbf_min_h_m": min_h}
        step: ControlStep | None = None
        if solution.ok and data is not None:
            U = solution.value("U").reshape(-1)
            plan = U @ self.blocking
            if isfinite(sum(plan.tolist())):
                predicted = data.free + data.prediction.gamma @ U
                states = np.concatenate([inputs.x0[:, None], predicted.T], axis=1)
                slack = float(np.max(data.bound_h - data.gamma_h @ U, initial=0.0))
                self.fallback.accept(plan[None, :])
                self._last_lateral_m = np.concatenate([states[0, 2:], states[0, -1:]])
                step = ControlStep(plan[:1].copy(), plan[None, :], states, solution.status,
                                   solution.iterations, solution.solve_time_s, "none",
                                   max(slack, 0.0), log)
        if step is None:
            self._last_lateral_m = None
            delta = inputs.x0[4] if np.isfinite(inputs.x0[4]) else 0.0
            rate_max, ts = self.vehicle.steering_rate_max_rad_s, self.sample_time_s
            step = self.fallback.step(
                solution.status, solution.iterations, solution.solve_time_s,
                lambda: np.array([float(np.clip(-delta / ts, -rate_max, rate_max))]), log)
        self.frame.after_step(step)
        self.keep_record(inputs, step.predicted_states[0] if step.predicted_states is not None
                         and step.fallback == "none" else None)
        return step


@dataclass(frozen=True)
class KinematicDcbfStructure:
    """Everything that enters the kinematic MPC-DCBF QP as a constant (the cache key): the
    LTV-QP's constants (:class:`~pipeline.loop.controller.kinematic.KinematicQpStructure`)."""

    base: KinematicQpStructure


def build_kinematic_dcbf_problem(s: KinematicDcbfStructure
                                 ) -> tuple[cp.Problem, list[Any], dict[str, Any]]:
    """The kinematic LTV-QP with linearized DCBF rows, in CVXPY (DPP).

    The cost, dynamics and input bounds of
    :func:`~pipeline.loop.controller.kinematic.build_kinematic_problem`; the collision rows,
    per step ``k = 0..N-1`` and slot ``j``::

        a1x x_{k+1} + a1y y_{k+1} + a0x x_k + a0y y_k + s_kj >= b_kj,   s >= 0

    (``a1 = n_{k+1}``, ``a0 = -(1 - gamma) n_k``, zero at ``k = 0`` where ``h(x_0)`` is folded
    into ``b``).

    Returns
    -------
    problem, parameters in ``theta`` order, variables to read (``X``, ``U``)
    """
    import cvxpy as cp

    b = s.base
    N, Nc, M = b.horizon, b.control_horizon, b.max_obstacles
    blocking = blocking_matrix(N, Nc, b.input_hold)
    A = [cp.Parameter((4, 4), name=f"A{k}") for k in range(N)]
    B = [cp.Parameter((4, 2), name=f"B{k}") for k in range(N)]
    c = cp.Parameter((4, N), name="c")
    x0 = cp.Parameter(4, name="x0")
    ref = cp.Parameter((2, N), name="y_ref")
    u_prev = cp.Parameter(2, name="u_prev")
    a1x = cp.Parameter((N, M), name="dcbf_next_x")
    a1y = cp.Parameter((N, M), name="dcbf_next_y")
    a0x = cp.Parameter((N, M), name="dcbf_now_x")
    a0y = cp.Parameter((N, M), name="dcbf_now_y")
    bound = cp.Parameter((N, M), name="dcbf_bound")
    X = cp.Variable((4, N + 1), name="X")
    U = cp.Variable((2, Nc), name="U")
    S = cp.Variable((N, M), nonneg=True, name="slack")
    u_seq = U @ blocking
    wy = np.asarray(b.output_weights, float)[:, None]
    wu = np.asarray(b.input_weights, float)[:, None]
    wdu = np.asarray(b.input_rate_weights, float)[:, None]
    slack_linear, slack_quadratic = b.slack_weights  # the soft rows' (w1, w2)
    rates = cp.hstack([cp.reshape(u_seq[:, 0] - u_prev, (2, 1), order="F"),
                       u_seq[:, 1:] - u_seq[:, :-1]])
    ones = np.ones((1, M))

    def columns(row: Any) -> Any:
        return cp.reshape(row, (N, 1), order="F") @ ones

    cost = (cp.sum_squares(cp.multiply(wy, X[0:2, 1:] - ref))
            + cp.sum_squares(cp.multiply(wu, u_seq))
            + cp.sum_squares(cp.multiply(wdu, rates))
            + slack_linear * cp.sum(S) + slack_quadratic * cp.sum_squares(S))
    a_lo, a_hi = b.accel_bounds_mps2
    constraints = [X[:, 0] == x0,
                   U[0, :] >= a_lo, U[0, :] <= a_hi,
                   cp.abs(U[1, :]) <= b.steering_max_rad,
                   cp.multiply(a1x, columns(X[0, 1:])) + cp.multiply(a1y, columns(X[1, 1:]))
                   + cp.multiply(a0x, columns(X[0, :-1])) + cp.multiply(a0y, columns(X[1, :-1]))
                   + S >= bound]
    constraints += [X[:, k + 1] == A[k] @ X[:, k] + B[k] @ u_seq[:, k] + c[:, k]
                    for k in range(N)]
    problem = cp.Problem(cp.Minimize(cost), constraints)
    if not problem.is_dcp(dpp=True):
        raise RuntimeError("kinematic MPC-DCBF is not DPP; it would recompile every step")
    return problem, [x0, u_prev, ref, c, *A, *B, a1x, a1y, a0x, a0y, bound], \
        {"X": X, "U": U}


class KinematicMpcDcbf(KinematicLtvMpc):
    """MPC-DCBF on the Appendix-A kinematic track: the kinematic LTV-MPC (its Euler model
    linearized about the shifted previous plan, ``ltv_iterations`` passes, references, fallback)
    with linearized DCBF rows in ``(x, y)`` in place of its half-planes (module docstring).

    Parameters
    ----------
    controller : KinematicMpcSettings
        ``kind=kinematic_mpc``, backend ``clarabel_direct`` or ``cvxpy``; ``params``:
        :class:`DcbfParams`.
    vehicle : VehicleConfig
    sample_time_s : float
    qp_cache : QpCache, optional
    """

    def __init__(self, controller: KinematicMpcSettings,
                 vehicle: VehicleConfig, sample_time_s: float,
                 qp_cache: QpCache | None = None) -> None:
        kind = getattr(controller, "kind", "kinematic_mpc")
        if kind != "kinematic_mpc":
            raise ConfigError("controller.kind", str(kind),
                              "kinematic_mpc (KinematicMpcDcbf drives the kinematic plant)")
        settings = settings_of(controller, KinematicMpcSettings)
        if settings.backend not in ("clarabel_direct", "cvxpy"):
            raise ConfigError("controller.backend", str(settings.backend),
                              "clarabel_direct or cvxpy")
        self.params = _params_of(controller)
        self.cfg, self.vehicle, self.ts = settings, vehicle, float(sample_time_s)
        self.horizon = settings.horizon
        self.blocking = blocking_matrix(settings.horizon, settings.control_horizon,
                                        settings.input_hold)
        structure = KinematicDcbfStructure(KinematicQpStructure.of(settings, vehicle))
        self.qp, self.compile_count, self.compile_time_s = compiled_backend(
            qp_cache, "kinematic_dcbf", structure,
            lambda: build_kinematic_dcbf_problem(structure), settings.backend,
            settings.solver_max_iter)
        self.fallback = PlanFallback(settings.horizon)
        self.u_prev = np.zeros(2)
        self._steps_ahead_s = np.arange(1, settings.horizon + 1) * self.ts
        self._times_s = np.arange(settings.horizon + 1) * self.ts
        self.records = []
        self._observation: Observation | None = None   # the step's (for solve)

    def dcbf_rows(self, states: np.ndarray, obs: Observation
                  ) -> tuple[tuple[np.ndarray, ...], float]:
        """The linearized DCBF rows about the linearization trajectory ``states``.

        Parameters
        ----------
        states : ndarray, shape (4, N + 1)
            The rollout the dynamics are linearized about (column 0: the measured state).
        obs : Observation

        Returns
        -------
        (a1x, a1y, a0x, a0y, bound) : ndarrays, shape (N, M)
            The rows of :func:`build_kinematic_dcbf_problem`.
        min_h_m : float
            The smallest exact ``h(x_0)`` over the constrained obstacles (NaN when none).
        """
        N, M = self.horizon, self.cfg.max_obstacles
        out = tuple(np.zeros((N, M)) for _ in range(5))
        position = states[:2, 0]
        slots = nearest_slots(obs.obstacles, position, self.cfg)
        if not slots.size:
            return out, float("nan")
        a1x, a1y, a0x, a0y, bound = out
        visible = obs.obstacles
        centres = visible.predicted_positions(self._times_s)[:, slots, :]     # global
        reach = visible.radii_m[slots] + self.vehicle.footprint_radius_m \
            + self.cfg.safety_margin_m
        h0 = barrier_m(position[None, :], centres[:1], reach)[0]
        normals = sided_normals(states[:2].T, centres, reach,
                                self.params.min_lateral_offset_ratio, obs.frame)
        decay = 1.0 - self.params.gamma
        n = slots.size
        # tangent at step k: n_k . p_k - (n_k . o_k + R)
        offset = np.sum(normals * centres, axis=2) + reach[None, :]
        a1x[:, :n], a1y[:, :n] = normals[1:, :, 0], normals[1:, :, 1]
        a0x[:, :n], a0y[:, :n] = -decay * normals[:-1, :, 0], -decay * normals[:-1, :, 1]
        a0x[0, :n] = a0y[0, :n] = 0.0
        bound[:, :n] = offset[1:] - decay * offset[:-1]
        bound[0, :n] = offset[1] + decay * h0
        return out, float(h0.min())

    def step(self, obs: Observation) -> ControlStep:
        """One closed-loop step (the reference and logs of the built-in kinematic MPC)."""
        self._observation = obs
        return super().step(obs)

    def solve(self, x0: np.ndarray, u_prev: np.ndarray, reference: np.ndarray,
              predicted_obstacles: np.ndarray, radii: np.ndarray,
              passes: int | None = None, log: dict[str, Any] | None = None) -> ControlStep:
        """Solve one step: ``ltv_iterations`` passes, each linearizing the model and the DCBF
        rows about the latest plan's rollout (the obstacles are read from the step's
        observation, ``predicted_obstacles`` and ``radii`` being its predictions)."""
        obs = self._observation
        if obs is None:
            raise RuntimeError("KinematicMpcDcbf.solve is called through step(observation)")
        N = self.horizon
        passes = self.cfg.ltv_iterations if passes is None else passes
        last = self.fallback.last_plan
        plan = np.hstack([last[:, 1:], last[:, -1:]]) if last is not None else np.zeros((2, N))
        status, total_iters, total_time, change = "not_solved", 0, 0.0, float("nan")
        done, min_h = 0, float("nan")
        solution: QpSolution | None = None
        rows: tuple[np.ndarray, ...] = ()
        if np.all(np.isfinite(x0)) and np.all(np.isfinite(u_prev)):
            for _ in range(max(passes, 1)):
                states, As, Bs, offsets = self._linearize(x0, plan)
                rows, min_h = self.dcbf_rows(states, obs)
                # build_kinematic_dcbf_problem's parameters in order, each column-major
                theta = np.concatenate(
                    [x0, u_prev, reference.ravel(order="F"), offsets.ravel(order="F")]
                    + [A.ravel(order="F") for A in As] + [B.ravel(order="F") for B in Bs]
                    + [row.ravel(order="F") for row in rows])
                solution = self.qp.solve(theta)
                status = solution.status
                total_iters += max(solution.iterations, 0)
                total_time += solution.solve_time_s
                done += 1
                if not solution.ok:
                    break
                new_plan = solution.value("U") @ self.blocking
                if not np.all(np.isfinite(new_plan)):
                    status = "non_finite_solution"
                    break
                change = float(np.max(np.abs(new_plan - plan)))
                plan = new_plan
        log = {**(log or {}), "ltv_passes": done, "ltv_change": change, "cbf_min_h_m": min_h}
        if solution is not None and solution.ok and status == solution.status:
            a1x, a1y, a0x, a0y, bound = rows
            self.fallback.accept(plan)
            X = solution.value("X")
            needed = bound - (a1x * X[0, 1:, None] + a1y * X[1, 1:, None]
                              + a0x * X[0, :-1, None] + a0y * X[1, :-1, None])
            return ControlStep(plan[:, 0].copy(), plan, X, status, total_iters, total_time,
                               "none", float(max(np.max(needed, initial=0.0), 0.0)), log)
        speed = x0[3] if np.isfinite(x0[3]) else 0.0
        a_lo, a_hi = self.cfg.accel_bounds_mps2
        return self.fallback.step(
            status, total_iters, total_time,
            lambda: np.array([float(np.clip(-speed / self.ts, a_lo, a_hi)), 0.0]), log)
