"""The lateral QPs of many members on the ``clarabel_direct`` backend, their data and read-out
in two compiled calls: what the lockstep engine (:mod:`pipeline.loop.engine`) runs each step
around each member's own kept Clarabel solver (:func:`direct_theta_rows`,
:func:`direct_readout_rows`).

For each member :func:`direct_theta_rows` is, statement for statement,
:func:`~pipeline.loop.controller.lateral_qp.condensed_data`,
:func:`~pipeline.loop.controller.lateral_qp.slots_used` and :meth:`CondensedData.theta
<pipeline.loop.controller.lateral_qp.CondensedData.theta>` of the statement of the slots it
uses: the parameter vector of the compiled CVXPY statement, which each member's solver then
takes as :meth:`DirectQp.solve <pipeline.loop.controller.qp.DirectQp.solve>` does (in Python:
Clarabel's update and solve). :func:`direct_readout_rows` is the rest of :meth:`LateralMpc.solve
<pipeline.loop.controller.lateral.LateralMpc.solve>`: the moves ``U = R^-1 W``, the plan, the
predicted states and the slack. The products are numba's ``np.dot`` on the same layouts as
numpy's ``@`` (the same BLAS routines for these shapes, with at least two moves: the engine
steps a member of one move alone), in the same order, so the same bits (the tests hold a
member's run in a batch equal to its run alone).

Imported only by :mod:`pipeline.loop.compiled` (it imports numba).
"""

from __future__ import annotations

import numpy as np
from numba import carray, farray

from pipeline.loop.controller.daqp_rows import (
    _double_pointer,
    condensed_free,
    plan_readout,
    slots_in_use,
)
from pipeline.loop.controller.lateral_qp import direct_theta_size

__all__ = ["direct_readout_rows", "direct_theta_rows"]


def direct_theta_rows(packs: np.ndarray, offsets: np.ndarray, direct_packs: np.ndarray,  # noqa: C901
                      direct_offsets: np.ndarray, n_u: int, horizon: int, slots: int,
                      x0s: np.ndarray, disturbances: np.ndarray, disturbed: np.ndarray,
                      y_refs: np.ndarray, psi_refs: np.ndarray, r_refs: np.ndarray,
                      has_r: np.ndarray, delta_refs: np.ndarray, has_delta: np.ndarray,
                      gains: np.ndarray, bounds: np.ndarray
                      ) -> tuple[np.ndarray, ...]:  # pragma: no cover (numba's)
    """Each member's parameter vector for the statement of the obstacle slots it uses.

    Parameters
    ----------
    packs, offsets : int64 arrays
        As :func:`~pipeline.loop.controller.daqp_rows.daqp_condensed_rows` takes them.
    direct_packs, direct_offsets : int64 arrays
        The address of each member's :attr:`CondensedPrediction.direct_pack
        <pipeline.loop.controller.lateral_qp.CondensedPrediction.direct_pack>` and
        :func:`~pipeline.loop.controller.lateral_qp.direct_pack_offsets`.
    n_u, horizon, slots : int
        Moves ``Nc``, horizon ``N``, obstacle slots ``M`` (all members alike).
    x0s, disturbances, disturbed, y_refs, psi_refs, r_refs, has_r, delta_refs, has_delta,
    gains, bounds
        As :func:`~pipeline.loop.controller.daqp_rows.daqp_condensed_rows` takes them.

    Returns
    -------
    thetas : (n, :func:`~pipeline.loop.controller.lateral_qp.direct_theta_size` of ``M``)
        Each member's vector in its first ``direct_theta_size(N, Nc, used)`` entries.
    used : int64 (n,)
        The slots each member's half-planes use (:func:`~pipeline.loop.controller.
        lateral_qp.slots_used`).
    frees : (n, 5N)
        The free responses (for :func:`direct_readout_rows`).
    finite : bool (n,)
        Whether the vector is finite (else the member's solve reports non-finite data).
    """
    n = x0s.shape[0]
    N, nc, M = horizon, n_u, slots
    thetas = np.zeros((n, direct_theta_size(N, nc, M)))
    used = np.zeros(n, dtype=np.int64)
    frees = np.zeros((n, 5 * N))
    finite = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        base_pack = packs[i]
        gamma = carray(_double_pointer(base_pack + 8 * offsets[5]), (N, 5, nc))
        direct = direct_packs[i]
        chol_rhs_map = farray(_double_pointer(direct + 8 * direct_offsets[0]), (nc, 4 * N))
        chol_inv = farray(_double_pointer(direct + 8 * direct_offsets[1]), (nc, nc))
        steering_flat = carray(_double_pointer(direct + 8 * direct_offsets[2]), (N * nc,))
        free, free_w = condensed_free(base_pack, offsets, x0s[i], disturbances[i],
                                      disturbed[i], y_refs[i], psi_refs[i], r_refs[i], has_r[i],
                                      delta_refs[i], has_delta[i], N)
        frees[i] = free
        s = slots_in_use(gains[i], bounds[i], N, M)  # slots_used
        used[i] = s
        # CondensedData.theta(s): [R^-1 (F), r, gamma_d R^-1 (F), free_d, gamma_h R^-1 (F),
        # bound_h], the half-plane rows k-major over the first s slots
        theta = thetas[i]
        p = 0
        for c in range(nc):
            for r in range(nc):
                theta[p] = chol_inv[r, c]
                p += 1
        chol_rhs = np.dot(chol_rhs_map, free_w)
        for r in range(nc):
            theta[p] = chol_rhs[r]
            p += 1
        for r in range(N * nc):
            theta[p] = steering_flat[r]
            p += 1
        for k in range(N):
            theta[p] = free[5 * k + 4]
            p += 1
        if s > 0:
            gamma_h = np.empty((N * s, nc))
            for k in range(N):
                for j in range(s):
                    for c in range(nc):
                        gamma_h[k * s + j, c] = gains[i, k, j] * gamma[k, 0, c]
            folded = np.dot(gamma_h, chol_inv)
            for c in range(nc):
                for r in range(N * s):
                    theta[p] = folded[r, c]
                    p += 1
            for k in range(N):
                for j in range(s):
                    theta[p] = bounds[i, k, j] - gains[i, k, j] * free[5 * k]
                    p += 1
        ok = True
        for r in range(p):
            ok = ok and np.isfinite(theta[r])
        finite[i] = ok
    return thetas, used, frees, finite


def direct_readout_rows(packs: np.ndarray, offsets: np.ndarray, direct_packs: np.ndarray,
                        direct_offsets: np.ndarray, n_u: int, horizon: int, slots: int,
                        Ws: np.ndarray, blockings: np.ndarray, x0s: np.ndarray,
                        frees: np.ndarray, gains: np.ndarray, bounds: np.ndarray
                        ) -> tuple[np.ndarray, ...]:  # pragma: no cover (numba's)
    """The moves, plans, predicted states and slacks of solved members (``Ws``: each one's
    ``W``, (n, Nc)); the other arguments as :func:`direct_theta_rows` and
    :func:`~pipeline.loop.controller.daqp_rows.daqp_condensed_rows` take them.

    Returns
    -------
    moves : (n, Nc)
        ``U = R^-1 W``.
    plans, states, slacks, plan_finite
        As :func:`~pipeline.loop.controller.daqp_rows.daqp_condensed_rows` returns them.
    """
    n = Ws.shape[0]
    N, nc, M = horizon, n_u, slots
    moves = np.zeros((n, nc))
    plans = np.zeros((n, N))
    states = np.zeros((n, 5, N + 1))
    slacks = np.zeros(n)
    plan_finite = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        gamma = carray(_double_pointer(packs[i] + 8 * offsets[5]), (N, 5, nc))
        chol_inv = farray(_double_pointer(direct_packs[i] + 8 * direct_offsets[1]), (nc, nc))
        U = np.dot(chol_inv, Ws[i])
        moves[i] = U
        plan_finite[i], slacks[i] = plan_readout(U, blockings[i], x0s[i], frees[i], gamma,
                                                 gains[i], bounds[i], N, M, plans[i],
                                                 states[i])
    return moves, plans, states, slacks, plan_finite
