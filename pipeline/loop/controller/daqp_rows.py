"""The lateral QPs of many members condensed and solved by DAQP in one compiled call: what the
lockstep engine (:mod:`pipeline.loop.engine`) runs each step for the members whose lateral MPC
has the ``daqp`` backend (:func:`daqp_condensed_rows`).

For each member it is, statement for statement, :func:`~pipeline.loop.controller.lateral_qp.
condensed_data`, :meth:`DaqpCondensedQp.solve <pipeline.loop.controller.lateral_backends.
DaqpCondensedQp.solve>` on the member's own kept workspace (:class:`~pipeline.loop.controller.
daqp_native.NativeDaqp`: the C calls of ``daqp.Model``) and the plan, predicted states and
slack of :meth:`LateralMpc.solve <pipeline.loop.controller.lateral.LateralMpc.solve>`: the same
products (numba's ``np.dot`` calls the same BLAS routines as numpy's ``@`` for these shapes and
orders) in the same order, so the same bits (the tests hold a member's run equal to its run
alone, and to ``daqp.Model``). The member's data are read where they live: its prediction's
packed maps (:attr:`CondensedPrediction.pack <pipeline.loop.controller.lateral_qp.
CondensedPrediction.pack>`) and its workspace's buffer, by address, so nothing is copied to
call it; DAQP's functions are called by address too, which keeps the kernel in numba's on-disk
cache (a ctypes function would make numba compile it in every process).

Imported only by :mod:`pipeline.loop.compiled` (it imports numba).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from llvmlite import ir
from numba import carray, farray, types
from numba.extending import intrinsic

from pipeline.loop.controller.daqp_native import (
    NON_FINITE_FLAG,
    PROBLEM_SENSE,
    RESULT_EXITFLAG,
    RESULT_ITER,
    SETTINGS_ITER_LIMIT,
    SETUP_FAILED_FLAG,
    UPDATE_RINV,
    UPDATE_STEP,
    WORK_SENSE,
    WORK_SETTINGS,
)

__all__ = ["condensed_free", "daqp_condensed_rows", "plan_readout", "slots_in_use"]


def _intrinsic(function: Callable[..., Any]) -> Any:
    """``numba.extending.intrinsic`` (typed for mypy)."""
    return intrinsic(function)


@_intrinsic
def _double_pointer(typingctx: Any, address: Any) -> Any:  # pragma: no cover (numba's)
    """An address (int64) as a pointer to doubles."""
    signature = types.CPointer(types.float64)(types.int64)

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        return builder.inttoptr(args[0], ir.DoubleType().as_pointer())

    return signature, codegen


def _loader(width: int) -> Any:
    """An intrinsic that reads the ``width``-bit integer (a C int, or a pointer as int64)
    stored at an address."""
    kind = types.int64 if width == 64 else types.int32

    def load(typingctx: Any, address: Any) -> Any:  # pragma: no cover (numba's)
        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            return builder.load(builder.inttoptr(args[0], ir.IntType(width).as_pointer()))

        return kind(types.int64), codegen

    return _intrinsic(load)


_load_int64, _load_int32 = _loader(64), _loader(32)


@_intrinsic
def _store(typingctx: Any, address: Any, value: Any) -> Any:  # pragma: no cover (numba's)
    """Store an integer (an int32 as a C int, an int64 as a pointer) at an address."""
    width = value.bitwidth

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        builder.store(args[1], builder.inttoptr(args[0], ir.IntType(width).as_pointer()))
        return context.get_dummy_value()

    return types.void(types.int64, value), codegen


def _pointer_call(builder: Any, function: Any, result: Any, arguments: list[Any]) -> Any:
    """Call the C function at address ``function`` with pointers and ints."""
    pointer = ir.IntType(8).as_pointer()
    kinds = [a.type if isinstance(a.type, ir.IntType) and a.type.width == 32 else pointer
             for a in arguments]
    values = [a if kind is a.type else builder.inttoptr(a, pointer)
              for a, kind in zip(arguments, kinds, strict=True)]
    callee = builder.inttoptr(function, ir.FunctionType(result, kinds).as_pointer())
    return builder.call(callee, values)


@_intrinsic
def _call_pointer(typingctx: Any, function: Any, first: Any) -> Any:  # pragma: no cover
    """``void f(void*)`` at an address."""
    signature = types.void(types.int64, types.int64)

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        _pointer_call(builder, args[0], ir.VoidType(), [args[1]])
        return context.get_dummy_value()

    return signature, codegen


@_intrinsic
def _call_pointers(typingctx: Any, function: Any, first: Any,
                   second: Any) -> Any:  # pragma: no cover
    """``void f(void*, void*)`` at an address (``daqp_solve``)."""
    signature = types.void(types.int64, types.int64, types.int64)

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        _pointer_call(builder, args[0], ir.VoidType(), [args[1], args[2]])
        return context.get_dummy_value()

    return signature, codegen


@_intrinsic
def _call_update(typingctx: Any, function: Any, mask: Any, work: Any,
                 qp: Any) -> Any:  # pragma: no cover
    """``int daqp_update_ldp(int mask, DAQPWorkspace*, DAQPProblem*)`` at an address."""
    signature = types.int32(types.int64, types.int32, types.int64, types.int64)

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        return _pointer_call(builder, args[0], ir.IntType(32), [args[1], args[2], args[3]])

    return signature, codegen


@_intrinsic
def _call_setup(typingctx: Any, function: Any, qp: Any, work: Any, time: Any,
                mask: Any) -> Any:  # pragma: no cover
    """``int setup_daqp_main(DAQPProblem*, DAQPWorkspace*, double* time, int mask)``."""
    signature = types.int32(types.int64, types.int64, types.int64, types.int64, types.int32)

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        return _pointer_call(builder, args[0], ir.IntType(32), [args[1], args[2], args[3],
                                                                 args[4]])

    return signature, codegen


def daqp_condensed_rows(functions: np.ndarray, workspaces: np.ndarray, packs: np.ndarray,  # noqa: C901
                        offsets: np.ndarray, n_u: int, horizon: int, slots: int,
                        blockings: np.ndarray, x0s: np.ndarray, disturbances: np.ndarray,
                        disturbed: np.ndarray, y_refs: np.ndarray, psi_refs: np.ndarray,
                        r_refs: np.ndarray, has_r: np.ndarray, delta_refs: np.ndarray,
                        has_delta: np.ndarray, gains: np.ndarray, bounds: np.ndarray,
                        steering_max: np.ndarray, hessian_new: np.ndarray,
                        iter_limits: np.ndarray) -> tuple[np.ndarray, ...]:  # pragma: no cover (numba's)
    """Condense, solve and read out the lateral QPs of ``n`` members (compiled only).

    Parameters
    ----------
    functions : int64 array (7,)
        :class:`~pipeline.loop.controller.daqp_native.DaqpFunctions`' addresses and that of a
        double for DAQP's setup time.
    workspaces : int64 array (n, M + 1, 5)
        Each member's :attr:`NativeDaqp.addresses` and whether it is set up (0: set it up on
        this step's data), by the statement's obstacle slots (``LateralMpc.qp_by_slots``):
        each member solves the statement of the slots its half-planes use
        (:func:`~pipeline.loop.controller.lateral_qp.slots_used`, as ``LateralMpc.qp_for``).
    packs : int64 array (n,)
        The address of each member's prediction pack
        (:func:`~pipeline.loop.controller.lateral_qp.pack_offsets`).
    offsets : int64 array
        :func:`~pipeline.loop.controller.lateral_qp.pack_offsets`.
    n_u, horizon, slots : int
        Moves ``Nc``, horizon ``N``, obstacle slots ``M`` of the data (all members alike).
    blockings : (n, Nc, N)
    x0s : (n, 5)
    disturbances, disturbed : (n, N), bool (n,)
        ``r_d`` and whether any entry is non-zero.
    y_refs, psi_refs, r_refs, delta_refs : (n, N); has_r, has_delta : bool (n,)
    gains, bounds : (n, N, M)
        The half-planes ``G``, ``h``.
    steering_max : (n,)
    hessian_new : bool (n, M + 1)
        The member's Hessian is not the one the workspace of that many slots holds.
    iter_limits : int64 (n,)

    Returns
    -------
    exitflags, iterations : int64 (n,)
        DAQP's (:data:`~pipeline.loop.controller.daqp_native.NON_FINITE_FLAG`: data not
        finite, not solved; ``SETUP_FAILED_FLAG``: the setup failed).
    moves : (n, Nc)
    plans : (n, N)
        ``U @ blocking``.
    states : (n, 5, N + 1)
        The measured state and ``free + gamma U``.
    slacks : (n,)
        The slack the plan needs (0 where no half-plane binds).
    plan_finite : bool (n,)
    used : int64 (n,)
        The slots of the statement each member solved.
    """
    n = x0s.shape[0]
    N, nc, M = horizon, n_u, slots
    used = np.zeros(n, dtype=np.int64)
    exitflags = np.zeros(n, dtype=np.int64)
    iterations = np.full(n, -1, dtype=np.int64)
    moves = np.zeros((n, nc))
    plans = np.zeros((n, N))
    states = np.zeros((n, 5, N + 1))
    slacks = np.zeros(n)
    plan_finite = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        base_pack = packs[i]
        gamma = carray(_double_pointer(base_pack + 8 * offsets[5]), (N, 5, nc))
        gradient_map = farray(_double_pointer(base_pack + 8 * offsets[6]), (nc, 4 * N))
        hessian_u = carray(_double_pointer(base_pack + 8 * offsets[7]), (nc, nc))
        x0 = x0s[i]
        # condensed_data: the free response, the weighted errors, the half-planes on U
        free, free_w = condensed_free(base_pack, offsets, x0, disturbances[i], disturbed[i],
                                      y_refs[i], psi_refs[i], r_refs[i], has_r[i],
                                      delta_refs[i], has_delta[i], N)
        gradient = np.dot(gradient_map, free_w)
        # LateralMpc.qp_for: the statement of the slots used
        S = slots_in_use(gains[i], bounds[i], N, M)
        used[i] = S
        space = workspaces[i, S]
        nv = nc + N * S
        rows = N + N * S
        m = nv + rows
        # DaqpCondensedQp.solve: the data in the member's buffer
        address = space[0]
        buffer = carray(_double_pointer(address), (nv * nv + nv + rows * nv + 3 * m + nv,))
        H = buffer[:nv * nv].reshape((nv, nv))
        f = buffer[nv * nv:nv * nv + nv]
        a0 = nv * nv + nv
        A = buffer[a0:a0 + rows * nv].reshape((rows, nv))
        upper = buffer[a0 + rows * nv:a0 + rows * nv + m]
        lower = buffer[a0 + rows * nv + m:a0 + rows * nv + 2 * m]
        finite = True
        for r in range(nc):
            for c in range(nc):
                H[r, c] = hessian_u[r, c]
                finite = finite and np.isfinite(hessian_u[r, c])
        for r in range(nc):
            f[r] = gradient[r]
        dmax = steering_max[i]
        base = nv
        for k in range(N):
            for c in range(nc):
                A[k, c] = gamma[k, 4, c]
            upper[base + k] = dmax - free[5 * k + 4]
            lower[base + k] = -dmax - free[5 * k + 4]
        for k in range(N):
            y_free = free[5 * k]
            for j in range(S):
                g = gains[i, k, j]
                for c in range(nc):
                    A[N + k * S + j, c] = g * gamma[k, 0, c]
                lower[base + N + k * S + j] = bounds[i, k, j] - g * y_free
        for r in range(nv):
            finite = finite and np.isfinite(f[r])
        for r in range(rows):
            for c in range(nv):
                finite = finite and np.isfinite(A[r, c])
        for r in range(m):
            finite = finite and np.isfinite(lower[r])
        if not finite:
            exitflags[i] = NON_FINITE_FLAG
            continue
        problem, result, work = space[1], space[2], space[3]
        if space[4] == 0:
            # daqp.Model.setup: default settings, the setup, then the iteration limit
            _call_pointer(functions[0], work)
            flag = _call_setup(functions[1], problem, work, functions[6], np.int32(0))
            if flag < 0:
                _store(work + WORK_SETTINGS, np.int64(0))
                exitflags[i] = SETUP_FAILED_FLAG
                continue
            space[4] = 1
            _store(_load_int64(work + WORK_SETTINGS) + SETTINGS_ITER_LIMIT,
                   np.int32(iter_limits[i]))
        else:
            # daqp.Model.update: the constraint states of the last solve kept
            _store(problem + PROBLEM_SENSE, _load_int64(work + WORK_SENSE))
            mask = UPDATE_STEP | (UPDATE_RINV if hessian_new[i, S] else 0)
            _call_update(functions[2], np.int32(mask), work, problem)
        _call_pointers(functions[3], result, work)
        exitflag = _load_int32(result + RESULT_EXITFLAG)
        exitflags[i] = exitflag
        iterations[i] = _load_int32(result + RESULT_ITER)
        if exitflag != 1 and exitflag != 2:
            continue
        x = buffer[a0 + rows * nv + 2 * m:a0 + rows * nv + 2 * m + nv]
        U = x[:nc].copy()
        moves[i] = U
        plan_finite[i], slacks[i] = plan_readout(U, blockings[i], x0, free, gamma, gains[i],
                                                 bounds[i], N, M, plans[i], states[i])
    return exitflags, iterations, moves, plans, states, slacks, plan_finite, used


def slots_in_use(gains: np.ndarray, bounds: np.ndarray, horizon: int,
                 slots: int) -> int:  # pragma: no cover (numba's)
    """:func:`~pipeline.loop.controller.lateral_qp.slots_used` of one member's half-planes
    ``gains``, ``bounds`` (N, M): one past the last slot with a row that is not ``0 y + s >=
    0`` (NaN is not 0). A helper the compiled callers share."""
    used = 0
    for j in range(slots):
        for k in range(horizon):
            if gains[k, j] != 0.0 or bounds[k, j] != 0.0:
                used = j + 1
                break
    return used


def condensed_free(pack: int, offsets: np.ndarray, x0: np.ndarray, disturbance: np.ndarray,
                   disturbed: bool, y_ref: np.ndarray, psi_ref: np.ndarray, r_ref: np.ndarray,
                   has_r: bool, delta_ref: np.ndarray, has_delta: bool,
                   horizon: int) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover (numba's)
    """:func:`~pipeline.loop.controller.lateral_qp.condensed_data`'s free response (5N,) and
    weighted free errors (4N,), statement for statement, from the maps of the prediction pack
    at address ``pack`` (layout ``offsets``; a helper the compiled callers share)."""
    N = horizon
    free_map = farray(_double_pointer(pack + 8 * offsets[0]), (5 * N, 5))
    disturbance_map = farray(_double_pointer(pack + 8 * offsets[1]), (5 * N, N))
    cost_root = carray(_double_pointer(pack + 8 * offsets[2]), (4 * N,))
    cost_index = carray(_double_pointer(pack + 8 * offsets[3]), (4 * N,))
    root = carray(_double_pointer(pack + 8 * offsets[4]), (4,))
    if disturbed:
        free = np.dot(free_map, x0) + np.dot(disturbance_map, disturbance)
    else:
        free = np.dot(free_map, x0)
    free_w = np.empty(4 * N)
    for r in range(4 * N):
        free_w[r] = cost_root[r] * free[int(cost_index[r])]
    for k in range(N):
        free_w[k] -= root[0] * y_ref[k]
    for k in range(N):
        free_w[N + k] -= root[1] * psi_ref[k]
    if has_r:
        for k in range(N):
            free_w[2 * N + k] -= root[2] * r_ref[k]
    if has_delta:
        for k in range(N):
            free_w[3 * N + k] -= root[3] * delta_ref[k]
    return free, free_w


def plan_readout(U: np.ndarray, blocking: np.ndarray, x0: np.ndarray, free: np.ndarray,
                 gamma: np.ndarray, gains: np.ndarray, bounds: np.ndarray, horizon: int,
                 slots: int, plan: np.ndarray,
                 states: np.ndarray) -> tuple[bool, float]:  # pragma: no cover (numba's)
    """:meth:`LateralMpc.solve <pipeline.loop.controller.lateral.LateralMpc.solve>` after the
    QP: the plan ``U @ blocking`` into ``plan`` (N,), the measured state and ``free + gamma U``
    into ``states`` (5, N + 1); returns whether the plan is finite and the slack it needs (0
    where no half-plane binds). A helper the compiled callers share."""
    N, M = horizon, slots
    plan[:] = np.dot(blocking.T, U)
    total = 0.0
    for k in range(N):
        total += plan[k]
    states[:, 0] = x0
    for k in range(N):
        predicted = free[5 * k:5 * k + 5] + np.dot(gamma[k], U)
        states[:, k + 1] = predicted
    binding = False
    for k in range(N):
        for j in range(M):
            if gains[k, j] != 0.0 or bounds[k, j] != 0.0:
                binding = True
    slack = 0.0
    if binding:  # numpy's max of the rows: NaN if any is
        slack = -np.inf
        for k in range(N):
            for j in range(M):
                value = bounds[k, j] - gains[k, j] * states[0, k + 1]
                if np.isnan(value) or np.isnan(slack):
                    slack = np.nan
                elif value > slack:
                    slack = value
    return np.isfinite(total), 0.0 if slack < 0.0 else slack
