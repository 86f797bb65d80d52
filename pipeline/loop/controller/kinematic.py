"""Appendix A's ``nlmpc`` as a linear-time-varying QP (CVXPY + Clarabel, DPP), compiled once.

Each step linearizes the Euler-discretized kinematic bicycle about a trajectory rolled out from
the measured state with the previous plan (shifted), solves the QP, and optionally repeats the
linearization about the new plan (``ltv_iterations`` passes). Cost as MATLAB writes it, weights
squared: ``sum |w_y (y_k - y_ref,k)|^2 + |w_u u_k|^2 + |w_du (u_k - u_{k-1})|^2``; inputs held
after ``Nc``; soft half-plane per obstacle slot and step
(:func:`~pipeline.loop.controller.references.kinematic_halfplanes`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline.loop.controller.base import ControlStep, Observation, PlanFallback
from pipeline.loop.controller.lateral_qp import blocking_matrix, slots_used
from pipeline.loop.controller.qp import QpCache, QpSolution, compiled_backend
from pipeline.loop.controller.references import kinematic_halfplanes
from pipeline.loop.controller_settings import KinematicMpcSettings, settings_of
from pipeline.loop.planner import path_at_arc_length
from pipeline.loop.settings import VehicleConfig

if TYPE_CHECKING:
    import cvxpy as cp


#: The smaller QPs a kinematic MPC with more obstacle slots than these also keeps: a step
#: solves the smallest that holds the slots its half-planes use.
SLOT_BUCKETS = (4, 8, 16, 32)


@dataclass(frozen=True)
class KinematicQpStructure:
    """Everything that enters the kinematic LTV-QP as a constant (the cache key)."""

    horizon: int
    control_horizon: int
    max_obstacles: int
    input_hold: str
    output_weights: tuple[Any, ...]
    input_weights: tuple[Any, ...]
    input_rate_weights: tuple[Any, ...]
    slack_weights: tuple[Any, ...]
    accel_bounds_mps2: tuple[Any, ...]
    steering_max_rad: float
    #: whether the predicted speed has rows ``low <= v_k <= high`` (their values are
    #: parameters: :meth:`KinematicLtvMpc.speed_rows`)
    speed_bounded: bool = False

    @classmethod
    def of(cls, c: KinematicMpcSettings,
           vehicle: VehicleConfig) -> KinematicQpStructure:
        return cls(c.horizon, c.control_horizon, c.max_obstacles, c.input_hold,
                   tuple(c.output_weights), tuple(c.input_weights), tuple(c.input_rate_weights),
                   (c.slack_weight_linear, c.slack_weight_quadratic),
                   tuple(c.accel_bounds_mps2), vehicle.steering_max_rad,
                   c.speed_bounds_mps is not None)


def build_kinematic_problem(s: KinematicQpStructure) -> tuple[cp.Problem, list[Any], dict[str, Any]]:
    """The LTV-QP in CVXPY: problem, parameters in ``theta`` order, variables to read."""
    import cvxpy as cp

    N, Nc, M = s.horizon, s.control_horizon, s.max_obstacles
    blocking = blocking_matrix(N, Nc, s.input_hold)
    A = [cp.Parameter((4, 4), name=f"A{k}") for k in range(N)]
    B = [cp.Parameter((4, 2), name=f"B{k}") for k in range(N)]
    c = cp.Parameter((4, N), name="c")
    x0 = cp.Parameter(4, name="x0")
    ref = cp.Parameter((2, N), name="y_ref")
    u_prev = cp.Parameter(2, name="u_prev")
    Gx = cp.Parameter((N, M), name="halfplane_nx")
    Gy = cp.Parameter((N, M), name="halfplane_ny")
    h = cp.Parameter((N, M), name="halfplane_bound")
    X = cp.Variable((4, N + 1), name="X")
    U = cp.Variable((2, Nc), name="U")
    S = cp.Variable((N, M), nonneg=True, name="slack")
    u_seq = U @ blocking
    wy = np.asarray(s.output_weights, float)[:, None]
    wu = np.asarray(s.input_weights, float)[:, None]
    wdu = np.asarray(s.input_rate_weights, float)[:, None]
    slack_linear, slack_quadratic = s.slack_weights  # the soft rows' (w1, w2)
    rates = cp.hstack([cp.reshape(u_seq[:, 0] - u_prev, (2, 1), order="F"),
                       u_seq[:, 1:] - u_seq[:, :-1]])
    ones = np.ones((1, M))
    px = cp.reshape(X[0, 1:], (N, 1), order="F") @ ones
    py = cp.reshape(X[1, 1:], (N, 1), order="F") @ ones
    cost = (cp.sum_squares(cp.multiply(wy, X[0:2, 1:] - ref))
            + cp.sum_squares(cp.multiply(wu, u_seq))
            + cp.sum_squares(cp.multiply(wdu, rates))
            + slack_linear * cp.sum(S) + slack_quadratic * cp.sum_squares(S))
    a_lo, a_hi = s.accel_bounds_mps2
    constraints = [X[:, 0] == x0,
                   U[0, :] >= a_lo, U[0, :] <= a_hi,
                   cp.abs(U[1, :]) <= s.steering_max_rad,
                   cp.multiply(Gx, px) + cp.multiply(Gy, py) + S >= h]
    constraints += [X[:, k + 1] == A[k] @ X[:, k] + B[k] @ u_seq[:, k] + c[:, k]
                    for k in range(N)]
    parameters = [x0, u_prev, ref, c, *A, *B, Gx, Gy, h]
    if s.speed_bounded:
        speed_low, speed_high = cp.Parameter(name="speed_low"), cp.Parameter(name="speed_high")
        constraints += [X[3, 1:] >= speed_low, X[3, 1:] <= speed_high]
        parameters += [speed_low, speed_high]
    problem = cp.Problem(cp.Minimize(cost), constraints)
    if not problem.is_dcp(dpp=True):
        raise RuntimeError("kinematic LTV-MPC is not DPP; it would recompile every step")
    return problem, parameters, {"X": X, "U": U}


def kinematic_theta(x0: np.ndarray, u_prev: np.ndarray, reference: np.ndarray,
                    offsets: np.ndarray, As: np.ndarray, Bs: np.ndarray, Gx: np.ndarray,
                    Gy: np.ndarray, h: np.ndarray,
                    speed_rows: tuple[float, float] | None = None) -> np.ndarray:
    """The LTV-QP's parameters stacked as ``theta`` (the order of
    :func:`build_kinematic_problem`'s list, each column-major); ``speed_rows`` the speed
    rows' bounds where the problem has them."""
    blocks = [x0, u_prev, reference.ravel(order="F"), offsets.ravel(order="F")] \
        + [A.ravel(order="F") for A in As] + [B.ravel(order="F") for B in Bs] \
        + [Gx.ravel(order="F"), Gy.ravel(order="F"), h.ravel(order="F")]
    if speed_rows is not None:
        blocks.append(np.asarray(speed_rows, dtype=float))
    return np.concatenate(blocks)


class KinematicTrack:
    """What both kinematic-track controllers share: the Euler rollout of a plan and the
    closed-loop step (the APF's time-indexed path as ``y_ref``, as ``nlmpcmove`` receives it;
    constant-velocity obstacle predictions). Subclasses set ``cfg``, ``vehicle``, ``ts``,
    ``horizon``, ``u_prev``, ``_steps_ahead_s``, ``records`` (an empty list: each step's state
    and plan, for :meth:`model_check`) and provide ``solve``."""

    cfg: KinematicMpcSettings
    vehicle: VehicleConfig
    ts: float
    horizon: int
    u_prev: np.ndarray
    _steps_ahead_s: np.ndarray
    records: list[tuple[Any, ...]]

    def solve(self, x0: np.ndarray, u_prev: np.ndarray, reference: np.ndarray,
              predicted_obstacles: np.ndarray, radii: np.ndarray, *,
              log: dict[str, Any] | None = None) -> ControlStep:
        """The subclass's solve (see :class:`KinematicLtvMpc`)."""
        raise NotImplementedError

    def rollout(self, x0: np.ndarray, plan: np.ndarray) -> np.ndarray:
        """States of the Euler model from ``x0`` under ``plan`` (2 x N), shape (4, N + 1)."""
        states = np.zeros((4, self.horizon + 1))
        states[:, 0] = x0
        # kinematic_euler_step written out on scalars (the same operations in the same order,
        # numpy's trig: bit for bit its result, without two arrays per step)
        dt_s, L = self.ts, self.vehicle.wheelbase_m
        X, Y, theta, v = states[:, 0].tolist()
        N = self.horizon
        for k, (accel, delta) in enumerate(zip(plan[0, :N].tolist(), plan[1, :N].tolist(), strict=True)):
            X, Y, theta, v = (X + dt_s * (v * np.cos(theta)), Y + dt_s * (v * np.sin(theta)),
                              theta + dt_s * (v / L * np.tan(delta)), v + dt_s * accel)
            states[:, k + 1] = (X, Y, theta, v)
        return states

    def reference(self, obs: Observation) -> np.ndarray:
        """The position reference for predicted steps 1..N, shape (2, N), by
        ``controller.reference_alignment``: ``literal`` (row k of the APF path for step k, as
        ``nlmpcmove`` receives it), ``shifted`` (row k + 1), or ``path_speed`` (Section 3.1's
        velocity planning: the point at arc length ``V_r Ts k`` along the APF path, continued
        along its last segment beyond its end)."""
        N = self.horizon
        path = obs.rollout.path_m
        if self.cfg.reference_alignment == "path_speed":
            return path_at_arc_length(path, obs.speed_ref_mps * self._steps_ahead_s).T
        rows = np.arange(N) if self.cfg.reference_alignment == "literal" \
            else np.minimum(np.arange(1, N + 1), N - 1)
        return path[rows].T

    def step(self, obs: Observation) -> ControlStep:
        """One closed-loop step."""
        reference = self.reference(obs)
        predicted = obs.obstacles.predicted_positions(self._steps_ahead_s)
        ref_line = obs.frame.to_line(reference[:, 0])
        u_prev = self.u_prev
        step = self.solve(obs.plant_state, u_prev, reference, predicted, obs.obstacles.radii_m,
                          log={"y_ref_m": ref_line[1], "psi_ref_rad": np.nan})
        step.log["steering_rate_rad_s"] = (step.command[1] - u_prev[1]) / self.ts
        step.log["accel_mps2"] = step.command[0]
        self.u_prev = step.command
        self.records.append((np.asarray(obs.plant_state, float).copy(),
                        step.predicted_states if step.fallback == "none" else None))
        return step

    def model_check(self, log: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """How well each step's prediction held, one value per row of the run's log: the
        Euler model replayed from the step's state with the inputs then applied (``accel_mps2``,
        ``delta_rad``), and the plan's own states, against the plant's position 0.5 s and 1 s
        later (the columns of :func:`~pipeline.loop.controller.prediction_check.prediction_check`; the
        kinematic model has no small-angle assumption, so no heading error)."""
        from pipeline.loop.controller.prediction_check import MODEL_CHECK_COLUMNS
        from pipeline.loop.model import kinematic_euler_step

        xy = np.column_stack([log["X_m"], log["Y_m"]])
        inputs = np.column_stack([log["accel_mps2"], log["delta_rad"]])
        rows = xy.shape[0]
        out = {name: np.full(rows, np.nan) for name in MODEL_CHECK_COLUMNS}
        one, half = int(round(1.0 / self.ts)), int(round(0.5 / self.ts))
        L = self.vehicle.wheelbase_m
        for k, (x0, plan) in enumerate(self.records[:rows]):
            steps = min(rows - 1, k + one) - k
            x = x0
            for j in range(1, steps + 1):
                x = kinematic_euler_step(x, inputs[k + j - 1], L, self.ts)
                if j in (half, one):
                    suffix = "05s" if j == half else "1s"
                    out[f"model_error_{suffix}_m"][k] = float(np.hypot(*(x[:2] - xy[k + j])))
                    if plan is not None and j < plan.shape[1]:
                        out[f"plan_error_{suffix}_m"][k] = float(np.hypot(
                            *(plan[:2, j] - xy[k + j])))
        return out

    def horizon_view(self, rows: int) -> dict[str, np.ndarray]:
        """Each step's plan and half-planes in the global frame, one row per log row (the
        report's scenario explorer; :func:`~pipeline.loop.horizon.kinematic_horizon_view`)."""
        from pipeline.loop.horizon import kinematic_horizon_view

        return kinematic_horizon_view(self.records, getattr(self, "halfplanes", {}), rows,
                                      self.horizon, self.cfg.max_obstacles, self.ts)


class KinematicLtvMpc(KinematicTrack):
    """The kinematic LTV-MPC: one compiled QP, a kept solver, linearization passes, fallback.

    Parameters
    ----------
    controller : KinematicMpcSettings
        Its settings (its kind's schema, as composed).
    vehicle : VehicleConfig
    sample_time_s : float
    qp_cache : QpCache, optional
    """

    def __init__(self, controller: KinematicMpcSettings,
                 vehicle: VehicleConfig, sample_time_s: float,
                 qp_cache: QpCache | None = None) -> None:
        controller = settings_of(controller, KinematicMpcSettings)
        self.cfg, self.vehicle, self.ts = controller, vehicle, float(sample_time_s)
        self.horizon = controller.horizon
        self.blocking = blocking_matrix(controller.horizon, controller.control_horizon,
                                        controller.input_hold)
        structure = KinematicQpStructure.of(controller, vehicle)
        self.qp, self.compile_count, self.compile_time_s = compiled_backend(
            qp_cache, "kinematic", structure, lambda: build_kinematic_problem(structure),
            controller.backend, controller.solver_max_iter, controller.solver_refinement)
        # the QP by its number of obstacle slots: a step whose half-planes fill fewer slots
        # solves the smallest that holds them (empty slots are rows 0 + s >= 0: leaving them
        # out changes no solution; among walkers, 50 slots are mostly empty)
        self._structure, self._qp_cache = structure, qp_cache
        self._by_slots = {structure.max_obstacles: self.qp}
        self._slot_sizes = tuple(sorted({b for b in SLOT_BUCKETS if b < structure.max_obstacles}
                                        | {structure.max_obstacles}))
        if qp_cache is not None:
            # every size compiled here, into the shared cache (a family's parent): its workers
            # get them with it and compile nothing (compiled on first use, each chunk of a
            # family among walkers compiled them again: 54 compilations for 200 members)
            for slots in self._slot_sizes:
                self._qp_of_size(slots)
        self.fallback = PlanFallback(controller.horizon)
        self.u_prev = np.zeros(2)
        self._steps_ahead_s = np.arange(1, controller.horizon + 1) * self.ts
        self.records = []
        #: each solved step's half-planes by step index (:meth:`horizon_view`)
        self.halfplanes: dict[int, tuple[Any, ...]] = {}

    def _linearize(self, x0: np.ndarray, plan: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                     np.ndarray, np.ndarray]:
        """:func:`kinematic_jacobians` at every step of the rollout, shapes (N, 4, 4), (N, 4, 2)
        and (4, N), entry for entry the same expressions on the horizon's vectors (the tests
        hold them to the function). The offset's Euler step is the rollout's next state (the
        same call on the same numbers), and ``A x``, ``B u`` stay one product per step."""
        states = self.rollout(x0, plan)
        N, dt_s, L = self.horizon, self.ts, self.vehicle.wheelbase_m
        theta, v, delta = states[2, :N], states[3, :N], plan[1]
        sin_t, cos_t = np.sin(theta), np.cos(theta)
        As = np.zeros((N, 4, 4))
        As[:, (0, 1, 2, 3), (0, 1, 2, 3)] = 1.0
        As[:, 0, 2] = -dt_s * v * sin_t
        As[:, 0, 3] = dt_s * cos_t
        As[:, 1, 2] = dt_s * v * cos_t
        As[:, 1, 3] = dt_s * sin_t
        As[:, 2, 3] = dt_s * np.tan(delta) / L
        Bs = np.zeros((N, 4, 2))
        # the square as the scalar expression takes it (C's pow(), which differs from numpy's
        # x * x in the last bit now and then)
        cos_squared = np.array([c ** 2 for c in np.cos(delta).tolist()])
        Bs[:, 2, 1] = dt_s * v / (L * cos_squared)
        Bs[:, 3, 0] = dt_s
        offsets = np.zeros((4, N))
        for k in range(N):
            offsets[:, k] = states[:, k + 1] - As[k] @ states[:, k] - Bs[k] @ plan[:, k]
        return states, As, Bs, offsets

    def speed_rows(self, speed_mps: float) -> tuple[float, float] | None:
        """The predicted speed's bounds this step, or None without ``speed_bounds_mps``:
        ``[min(low, v0), max(high, v0)]``, so that a measured speed outside the bounds (a
        fallback's step, the solver's tolerance) never makes the rows infeasible: holding the
        speed (zero acceleration, inside ``accel_bounds_mps2``) always meets them, and the
        Euler model's speed row is the plant's own (``v' = a``), so from inside the bounds the
        plant stays inside."""
        bounds = self.cfg.speed_bounds_mps
        if bounds is None:
            return None
        low, high = (float(b) for b in bounds)
        return min(low, speed_mps), max(high, speed_mps)

    def _qp_for(self, Gx: np.ndarray, Gy: np.ndarray, h: np.ndarray) -> tuple[Any, int]:
        """The QP with the fewest slots (of :data:`SLOT_BUCKETS` and ``max_obstacles``) that
        holds every slot these half-planes use, and that number (every size compiled once,
        through the shared cache: at construction when there is one, else on first use)."""
        need = max(slots_used(Gx, Gy, h), 1)
        slots = next(b for b in self._slot_sizes if b >= need)
        return self._qp_of_size(slots), slots

    def _qp_of_size(self, slots: int) -> Any:
        """This controller's QP of ``slots`` obstacle slots (its kept solver made at its first
        solve), the compiled statement taken from the shared cache or compiled into it."""
        qp = self._by_slots.get(slots)
        if qp is None:
            structure = dataclasses.replace(self._structure, max_obstacles=slots)
            qp, count, seconds = compiled_backend(
                self._qp_cache, "kinematic", structure,
                lambda: build_kinematic_problem(structure), self.cfg.backend,
                self.cfg.solver_max_iter, self.cfg.solver_refinement)
            self.compile_count += count
            self.compile_time_s += seconds
            self._by_slots[slots] = qp
        return qp

    def _accepted(self, plan: np.ndarray, solution: QpSolution, halfplanes: tuple[Any, ...],
                  status: str,
                  total_iters: int, total_time: float, log: dict[str, Any]) -> ControlStep:
        """The step of a solved plan (kept for the fallback), with the slack it needs."""
        Gx, Gy, h = halfplanes
        self.halfplanes[len(self.records)] = halfplanes  # this step's, for horizon_view
        self.fallback.accept(plan)
        states = solution.value("X")
        # slack needed by the optimal plan (what the QP's slack variable holds)
        needed = h - Gx * states[0, 1:][:, None] - Gy * states[1, 1:][:, None]
        return ControlStep(plan[:, 0].copy(), plan, states, status, total_iters,
                           total_time, "none", float(max(np.max(needed, initial=0.0), 0.0)),
                           log)

    def solve(self, x0: np.ndarray, u_prev: np.ndarray, reference: np.ndarray,
              predicted_obstacles: np.ndarray, radii: np.ndarray,
              passes: int | None = None, log: dict[str, Any] | None = None) -> ControlStep:
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
        last = self.fallback.last_plan
        plan = np.hstack([last[:, 1:], last[:, -1:]]) if last is not None else np.zeros((2, N))
        status, total_iters, total_time, change = "not_solved", 0, 0.0, float("nan")
        done = 0
        solution = None
        if np.all(np.isfinite(x0)) and np.all(np.isfinite(u_prev)):
            for _ in range(max(passes, 1)):
                states, As, Bs, offsets = self._linearize(x0, plan)
                Gx, Gy, h = kinematic_halfplanes(states, reference, predicted_obstacles, radii,
                                                 self.vehicle, self.cfg)
                qp, slots = self._qp_for(Gx, Gy, h)
                solution = qp.solve(kinematic_theta(x0, u_prev, reference, offsets, As, Bs,
                                                    Gx[:, :slots], Gy[:, :slots], h[:, :slots],
                                                    self.speed_rows(float(x0[3]))))
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
        log = {**(log or {}), "ltv_passes": done, "ltv_change": change}
        if solution is not None and solution.ok and status == solution.status \
                and np.all(np.isfinite(plan)):
            return self._accepted(plan, solution, (Gx, Gy, h), status, total_iters, total_time,
                                  log)
        speed = x0[3] if np.isfinite(x0[3]) else 0.0
        a_lo, a_hi = self.cfg.accel_bounds_mps2
        return self.fallback.step(
            status, total_iters, total_time,
            lambda: np.array([float(np.clip(-speed / self.ts, a_lo, a_hi)), 0.0]), log)
