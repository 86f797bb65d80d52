"""The lateral MPC's QP backends on the condensed statement (``controller.backend``):
``clarabel_direct`` and ``cvxpy`` through the compiled CVXPY statement
(:class:`CompiledCondensedQp`), ``clarabel_dense`` (:class:`ClarabelCondensedQp`: the QP's data
from numpy on a kept Clarabel) and ``daqp`` (:class:`DaqpCondensedQp`). Each takes one step's
:class:`~pipeline.loop.controller.lateral_qp.CondensedData` and returns a
:class:`~pipeline.loop.controller.qp.QpSolution` with the moves ``U``."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from pipeline.loop.controller.lateral_qp import CondensedData, LateralQpStructure
from pipeline.loop.controller.qp import NON_FINITE_DATA, CvxpyQp, DirectQp, QpSolution


class LateralQp(Protocol):
    """What the lateral MPC asks of its backend: one solve of a step's data (the condensed
    data, or the sparse statement's parameter vector)."""

    def solve(self, data: Any) -> QpSolution:
        ...


class CompiledCondensedQp:
    """Backends ``clarabel_direct`` and ``cvxpy`` on the condensed statement: one step's
    :class:`CondensedData` in, the moves ``U = R^-1 W`` out (the statement's own variable is
    ``W``, see :func:`build_condensed_lateral_problem`).

    Parameters
    ----------
    compiled : DirectQp or CvxpyQp
        The compiled statement (shared through the ``QpCache``).
    """

    def __init__(self, compiled: DirectQp | CvxpyQp) -> None:
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

        self.s, self.max_iter = structure, int(max_iter)
        self._solver: Any = None  # clarabel.DefaultSolver, made at the first solve
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
        self._p_values = np.full(p_idx.size, 2.0 * structure.weights.slack_quadratic)
        self._q = np.full(n_u + n_s, float(structure.weights.slack_linear))
        rate, dmax = structure.steering_rate_max_rad_s, structure.steering_max_rad
        self._b = np.zeros(rows)
        self._b[:2 * n_u] = rate
        self._dmax = dmax
        self._sparse = sparse

    def _data(self, data: CondensedData
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
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

        from pipeline.loop.controller.qp import (
            CLARABEL_STATUS,
            OPTIMAL_STATUSES,
            SOLVER_ERROR,
            clarabel_settings,
            solver_errors,
        )

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
        w1, w2 = structure.weights.slack_linear, structure.weights.slack_quadratic
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
        self._model: Any = None   # daqp.Model, set up on the first solve
        # the hessian_u array the workspace holds (one per speed)
        self._hessian_of: np.ndarray | None = None

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
