"""The lateral MPC's QP backends on the condensed statement (``controller.backend``):
``clarabel_direct`` and ``cvxpy`` through the compiled CVXPY statement
(:class:`CompiledCondensedQp`) and ``daqp`` (:class:`DaqpCondensedQp`). Each takes one step's
:class:`~pipeline.loop.controller.lateral_qp.CondensedData` and returns a
:class:`~pipeline.loop.controller.qp.QpSolution` with the moves ``U``."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from pipeline.loop.controller.lateral_qp import CondensedData, LateralQpStructure
from pipeline.loop.controller.qp import NON_FINITE_DATA, CvxpyQp, DirectQp, QpSolution


class LateralQp(Protocol):
    """What the lateral MPC asks of its backend: one solve of a step's condensed data."""

    def solve(self, data: CondensedData) -> QpSolution:
        ...


class CompiledCondensedQp:
    """Backends ``clarabel_direct`` and ``cvxpy`` on the condensed statement: one step's
    :class:`CondensedData` in, the moves ``U = R^-1 W`` out (the statement's own variable is
    ``W``, see :func:`build_condensed_lateral_problem`).

    Parameters
    ----------
    compiled : DirectQp or CvxpyQp
        The compiled statement (shared through the ``QpCache``).
    slots : int, optional
        The statement's obstacle slots when it has fewer than the data (the first ``slots``
        are handed to it, :meth:`CondensedData.theta`); all of them by default.
    """

    def __init__(self, compiled: DirectQp | CvxpyQp, slots: int | None = None) -> None:
        self.compiled = compiled
        self.slots = slots

    def solve(self, data: CondensedData) -> QpSolution:
        solution = self.compiled.solve(data.theta(self.slots))
        if solution.values is None:
            return solution
        W = np.asarray(solution.values["W"], float).reshape(-1)
        return QpSolution(solution.status, solution.iterations, solution.solve_time_s,
                          {"U": data.chol_inv @ W, "W": W})


class DaqpCondensedQp:
    """Backend ``daqp``: the condensed lateral QP with explicit slacks, solved by DAQP (a dual
    active-set solver for small dense QPs): the same problem as the Clarabel backends.

    Variables ``z = [U, S]``; cost ``|gamma_w U + free_w|^2 + r_u |U T|^2 + w1 sum S +
    w2 |S|^2`` as ``0.5 z' H z + f' z``; simple bounds ``|U| <= rate max``, ``S >= 0``; rows
    ``|gamma_d U + free_d| <= delta max`` and ``gamma_h U + S >= bound_h``.

    The workspace is kept from step to step (:class:`~pipeline.loop.controller.daqp_native.
    NativeDaqp`, DAQP's C interface: the lockstep engine solves the QPs of many members in one
    compiled call on these same workspaces, :mod:`~pipeline.loop.controller.daqp_rows`);
    ``daqp.Model`` where the installed DAQP is not the release whose structures we know.

    Parameters
    ----------
    structure : LateralQpStructure
        The statement: its ``max_obstacles`` slots (``S`` has ``N`` of them per slot); data of
        more slots are handed its first ones (:meth:`CondensedData.halfplane_rows`: the others
        must be empty rows), as the Clarabel statements by slots take them.
    max_iter : int
        DAQP's iteration limit.
    """

    #: DAQP exit flags mapped to the status words the log uses (CVXPY's)
    STATUS = {1: "optimal", 2: "optimal", -1: "infeasible", -2: "solver_error",
              -3: "unbounded", -4: "user_limit", -5: "solver_error", -6: "solver_error"}

    def __init__(self, structure: LateralQpStructure, max_iter: int) -> None:
        from pipeline.loop.controller.daqp_native import NativeDaqp, native_daqp_functions

        self.s = structure
        N, Nc, M = structure.horizon, structure.control_horizon, structure.max_obstacles
        self.n_u, self.n_s, self.N = Nc, N * M, N
        n = Nc + N * M
        self.max_iter = int(max_iter)
        functions = native_daqp_functions()
        #: the kept workspace and its data (None: daqp.Model's, set up on the first solve)
        self.native = NativeDaqp(n, N + N * M, self.max_iter, functions) \
            if functions is not None else None
        if self.native is not None:
            self._H, self._f, self._A = self.native.H, self.native.f, self.native.A
            self._upper, self._lower = self.native.upper, self.native.lower
        else:
            self._H, self._f, self._A = np.zeros((n, n)), np.zeros(n), np.zeros((N + N * M, n))
            self._upper, self._lower = np.zeros(n + N + N * M), np.zeros(n + N + N * M)
        w1, w2 = structure.weights.slack_linear, structure.weights.slack_quadratic
        self._H[:] = 2.0 * w2 * np.eye(n)
        self._f[:] = float(w1)
        self._A[N:, Nc:] = np.eye(N * M)
        rate, dmax = structure.steering_rate_max_rad_s, structure.steering_max_rad
        self._dmax = dmax
        self._upper[:] = np.concatenate([np.full(Nc, rate), np.full(N * M, 1e30), np.zeros(N),
                                         np.full(N * M, 1e30)])
        self._lower[:] = np.concatenate([np.full(Nc, -rate), np.zeros(N * M), np.zeros(N),
                                         np.zeros(N * M)])
        self._sense = np.zeros(self._upper.size, np.intc)
        self._model: Any = None   # daqp.Model, set up on the first solve (no native DAQP)
        # the hessian_u array the workspace holds (one per speed)
        self._hessian_of: np.ndarray | None = None

    def holds_hessian(self, hessian_u: np.ndarray) -> bool:
        """Whether the workspace holds ``hessian_u`` (the same model's: no update of it)."""
        return hessian_u is self._hessian_of

    def solved_with(self, hessian_u: np.ndarray | None) -> None:
        """Note the Hessian a solve left in the workspace (None: its setup failed)."""
        self._hessian_of = hessian_u

    def cost(self, data: CondensedData) -> tuple[np.ndarray, np.ndarray]:
        """``H`` and ``f`` of the cost ``0.5 z' H z + f' z`` over ``z = [U, S]``."""
        n_u = self.n_u
        H, f = self._H, self._f
        H[:n_u, :n_u] = data.hessian_u
        f[:n_u] = data.gradient_u
        return H, f

    def solve(self, data: CondensedData) -> QpSolution:
        import time

        start = time.perf_counter()
        n_u, n_s, N = self.n_u, self.n_s, self.N
        H, f = self.cost(data)
        A = self._A
        A[:N, :n_u] = data.gamma_d
        gamma_h, bound_h = data.halfplane_rows(self.s.max_obstacles)
        A[N:, :n_u] = gamma_h
        upper, lower = self._upper, self._lower
        base = n_u + n_s
        # the steering bound at the model's speed where it is tighter than the statement's
        # (controller.steering_friction_share)
        bound = data.prediction.steering_bound_rad
        dmax = self._dmax if bound is None else (
            bound if data.steering_bounds_rad is None else data.steering_bounds_rad)
        upper[base:base + N] = dmax - data.free_d
        lower[base:base + N] = -dmax - data.free_d
        lower[base + N:] = bound_h
        if not (np.isfinite(data.hessian_u).all() and np.isfinite(f).all()
                and np.isfinite(A).all() and np.isfinite(lower).all()):
            return QpSolution(NON_FINITE_DATA, -1, time.perf_counter() - start, None)
        # a kept workspace: the Hessian is sent again only when the model's speed changed it;
        # the rest every step (the same optimum as daqp.solve, ~3x cheaper)
        hessian = data.hessian_u is not self._hessian_of
        self._hessian_of = data.hessian_u
        if self.native is not None:
            exitflag, iterations = self._native_solve(hessian)
            x = self.native.x
        else:
            x, exitflag, iterations = self._model_solve(H, f, A, upper, lower, hessian)
        status = self.STATUS.get(int(exitflag), "solver_error")
        values = {"U": np.array(x[:n_u], float), "slack": np.array(x[n_u:], float)} \
            if status == "optimal" else None
        return QpSolution(status, iterations, time.perf_counter() - start, values)

    def _native_solve(self, hessian: bool) -> tuple[int, int]:
        """Set up (first solve) or update the kept workspace, and solve."""
        native = self.native
        assert native is not None
        if not native.ready[0]:
            flag = native.setup()
            if flag < 0:
                self._hessian_of = None
                return -2, -1
        else:
            native.update(hessian)
        return native.solve()

    def _model_solve(self, H: np.ndarray, f: np.ndarray, A: np.ndarray, upper: np.ndarray,
                     lower: np.ndarray, hessian: bool) -> tuple[np.ndarray, int, int]:
        """The same through ``daqp.Model`` (a DAQP release whose structures we do not know)."""
        import daqp

        if self._model is None:
            self._model = daqp.Model()
            self._model.setup(H, f, A, upper, lower, self._sense)
            self._model.settings = {"iter_limit": self.max_iter}
        elif not hessian:
            self._model.update(f=f, A=A, bupper=upper, blower=lower)
        else:
            self._model.update(H=H, f=f, A=A, bupper=upper, blower=lower)
        x, _, exitflag, info = self._model.solve()
        return np.asarray(x, float), int(exitflag), int(info.get("iterations", -1))
