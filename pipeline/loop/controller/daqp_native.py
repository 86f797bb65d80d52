"""DAQP's C interface, called directly: one kept workspace per member, whose data live in one
buffer of the member's own, so that the lockstep engine can fill and solve the QPs of many
members in one compiled call (:mod:`pipeline.loop.controller.daqp_rows`) and a member stepped
alone can do the same from Python, on the same workspace.

The calls are those of ``daqp.Model`` (DAQP's Python interface): ``setup`` is
``allocate_daqp_settings`` then ``setup_daqp_main(qp, work, &time, 0)`` with the first step's
data, the iteration limit written into the workspace's settings after it; every later step is
``daqp_update_ldp(mask, work, qp)`` with the constraint states of the last solve
(``qp.sense = work.sense``) and ``daqp_solve(result, work)``. The same calls on the same data
give the same bits (tests: a sequence of QPs against ``daqp.Model``).

The C structures are DAQP 0.11's (``types.h``, ``api.h`` of that release, x86-64 and aarch64
alike: LP64): their offsets are constants here, and :func:`native_daqp_functions` refuses any
other DAQP release, in which case the backend uses ``daqp.Model`` as before. After each setup
the workspace's dimensions and problem pointer are read back and compared with ours, so a
layout that does not match is caught before any solve (a one-line ``RuntimeError``).
"""

from __future__ import annotations

import ctypes
import weakref
from functools import lru_cache
from importlib import metadata
from typing import Any, NamedTuple

import numpy as np

__all__ = ["DAQP_LAYOUT_VERSION", "DaqpFunctions", "NativeDaqp", "native_daqp_functions"]

#: The DAQP release whose C structures the offsets below are.
DAQP_LAYOUT_VERSION = "0.11.0"

# DAQPProblem: int n, m, ms; double *H, *f, *A, *bupper, *blower; int *sense, *break_points;
# int nh, problem_type (80 bytes)
PROBLEM_BYTES = 80
PROBLEM_N, PROBLEM_M, PROBLEM_MS = 0, 4, 8
PROBLEM_H, PROBLEM_F, PROBLEM_A, PROBLEM_UPPER, PROBLEM_LOWER = 16, 24, 32, 40, 48
PROBLEM_SENSE = 56
# DAQPResult: double *x, *lam; double fval, soft_slack; int exitflag, iter, nodes;
# double solve_time, setup_time (64 bytes)
RESULT_BYTES = 64
RESULT_X, RESULT_LAM, RESULT_EXITFLAG, RESULT_ITER = 0, 8, 32, 36
# DAQPWorkspace (328 bytes; a larger zeroed block is kept): the problem pointer, the
# dimensions, the constraint states and the settings
WORKSPACE_BYTES = 1024
WORK_QP, WORK_N, WORK_M, WORK_MS, WORK_SENSE, WORK_SETTINGS = 0, 8, 12, 16, 64, 224
# DAQPSettings: iter_limit after five doubles and an int
SETTINGS_ITER_LIMIT = 44
# daqp_update_ldp's mask: the data a step changes (constraint matrix, linear cost, bounds)
# and the constraint states of the last solve; the Hessian's bit when the model changed
UPDATE_RINV, UPDATE_M, UPDATE_V, UPDATE_D, UPDATE_SENSE = 1, 2, 4, 8, 16
UPDATE_STEP = UPDATE_M | UPDATE_V | UPDATE_D | UPDATE_SENSE
#: the compiled caller's exit flag for data that are not finite (not solved, the workspace
#: untouched) and for a setup that failed (DAQP's own flag is not kept)
NON_FINITE_FLAG, SETUP_FAILED_FLAG = -100, -101


class DaqpFunctions(NamedTuple):
    """The C functions' ctypes callables (``library``) and, for the compiled caller, their
    addresses (``arguments``: allocate_daqp_settings, setup_daqp_main, daqp_update_ldp,
    daqp_solve, free_daqp_workspace, free_daqp_ldp, then the address of ``setup_time``, a
    double where DAQP writes its setup time, never read)."""

    library: ctypes.CDLL
    arguments: np.ndarray
    setup_time: np.ndarray


@lru_cache(maxsize=1)
def native_daqp_functions() -> DaqpFunctions | None:
    """The installed DAQP's C functions, or None when its release is not
    :data:`DAQP_LAYOUT_VERSION` (whose structures this module knows) or its library does not
    export them."""
    try:
        if metadata.version("daqp") != DAQP_LAYOUT_VERSION:
            return None
        import daqp

        library = ctypes.CDLL(daqp.__file__)
        names = ("allocate_daqp_settings", "setup_daqp_main", "daqp_update_ldp", "daqp_solve",
                 "free_daqp_workspace", "free_daqp_ldp")
        handles = [getattr(library, name) for name in names]
    except (metadata.PackageNotFoundError, ImportError, OSError, AttributeError):
        return None
    pointer = ctypes.c_void_p
    handles[0].argtypes, handles[0].restype = [pointer], None
    handles[1].argtypes, handles[1].restype = [pointer, pointer, pointer, ctypes.c_int], \
        ctypes.c_int
    handles[2].argtypes, handles[2].restype = [ctypes.c_int, pointer, pointer], ctypes.c_int
    handles[3].argtypes, handles[3].restype = [pointer, pointer], None
    handles[4].argtypes, handles[4].restype = [pointer], None
    handles[5].argtypes, handles[5].restype = [pointer], None
    setup_time = np.zeros(1)
    arguments = np.array([ctypes.cast(h, ctypes.c_void_p).value or 0 for h in handles]
                         + [setup_time.ctypes.data], dtype=np.int64)
    return DaqpFunctions(library, arguments, setup_time)


def _free(functions: DaqpFunctions, workspace: np.ndarray, ready: np.ndarray) -> None:
    """Free what DAQP allocated in a workspace that was set up (its settings, LDP and
    iterates), as ``daqp.Model`` does when it is dropped."""
    if ready[0]:
        address = workspace.ctypes.data
        functions.library.free_daqp_workspace(address)
        functions.library.free_daqp_ldp(address)
    ready[0] = 0


class NativeDaqp:
    """One kept DAQP workspace for a QP of ``n`` variables, ``n`` simple bounds and ``rows``
    general rows, its data in one buffer of ours (``[H (n x n), f, A (rows x n), upper, lower,
    x, lam]``, C order) that the problem structure points into for the workspace's life.

    Parameters
    ----------
    n : int
        Variables (each with a simple bound).
    rows : int
        General constraint rows.
    iter_limit : int
        DAQP's ``iter_limit``.
    functions : DaqpFunctions
        :func:`native_daqp_functions`.
    """

    def __init__(self, n: int, rows: int, iter_limit: int, functions: DaqpFunctions) -> None:
        self.n, self.rows, self.m = n, rows, n + rows
        self.iter_limit = int(iter_limit)
        self.functions = functions
        m = self.m
        sizes = (n * n, n, rows * n, m, m, n, m)
        starts = np.concatenate([[0], np.cumsum(sizes)])
        #: where each part starts in :attr:`buffer`
        self.offsets = tuple(int(s) for s in starts[:-1])
        self.buffer = np.zeros(int(starts[-1]))
        H, f, A, upper, lower, x, lam = (self.buffer[a:a + s] for a, s in
                                         zip(self.offsets, sizes, strict=True))
        self.H, self.f, self.A = H.reshape(n, n), f, A.reshape(rows, n)
        self.upper, self.lower, self.x, self.lam = upper, lower, x, lam
        self.sense = np.zeros(m, dtype=np.intc)
        self.problem = np.zeros(PROBLEM_BYTES, dtype=np.uint8)
        self.result = np.zeros(RESULT_BYTES, dtype=np.uint8)
        self.workspace = np.zeros(WORKSPACE_BYTES, dtype=np.uint8)
        #: [1] once set up (DAQP's allocations are then freed with the workspace)
        self.ready = np.zeros(1, dtype=np.int64)
        ints, pointers = self.problem.view(np.int32), self.problem.view(np.int64)
        ints[PROBLEM_N // 4], ints[PROBLEM_M // 4], ints[PROBLEM_MS // 4] = n, m, n
        address = self.buffer.ctypes.data
        for field, part in zip((PROBLEM_H, PROBLEM_F, PROBLEM_A, PROBLEM_UPPER, PROBLEM_LOWER),
                               self.offsets[:5], strict=True):
            pointers[field // 8] = address + 8 * part
        pointers[PROBLEM_SENSE // 8] = self.sense.ctypes.data
        result = self.result.view(np.int64)
        result[RESULT_X // 8] = address + 8 * self.offsets[5]
        result[RESULT_LAM // 8] = address + 8 * self.offsets[6]
        #: the buffer's, problem's, result's and workspace's addresses (the compiled caller's
        #: arguments; the arrays never move)
        self.addresses = (address, self.problem.ctypes.data, self.result.ctypes.data,
                          self.workspace.ctypes.data)
        weakref.finalize(self, _free, functions, self.workspace, self.ready)

    def __reduce__(self) -> Any:
        """Not copied nor pickled (as ``daqp.Model`` is not): the problem structure holds this
        object's own addresses, which a copy would share."""
        raise TypeError("a kept DAQP workspace (NativeDaqp) cannot be copied or pickled")

    def setup(self) -> int:
        """``daqp.Model.setup`` on the data in the buffer: DAQP's default settings, the
        setup, then the iteration limit; DAQP's setup flag (negative: failed, not set up)."""
        library = self.functions.library
        _, problem, _, work = self.addresses
        if self.ready[0]:
            library.free_daqp_workspace(work)
            library.free_daqp_ldp(work)
            self.ready[0] = 0
        library.allocate_daqp_settings(work)
        flag = int(library.setup_daqp_main(problem, work, int(self.functions.arguments[6]), 0))
        if flag < 0:  # DAQP freed its settings on failure
            self.workspace[WORK_SETTINGS:WORK_SETTINGS + 8] = 0
            return flag
        self.ready[0] = 1
        self.check_layout()
        settings = int(self.workspace[WORK_SETTINGS:WORK_SETTINGS + 8].view(np.int64)[0])
        ctypes.c_int.from_address(settings + SETTINGS_ITER_LIMIT).value = self.iter_limit
        return flag

    def check_layout(self) -> None:
        """The workspace's problem pointer and dimensions as set up: a DAQP whose structures
        are not :data:`DAQP_LAYOUT_VERSION`'s fails here, before any solve."""
        ints = self.workspace[:WORK_MS + 4].view(np.int32)
        qp = int(self.workspace[WORK_QP:WORK_QP + 8].view(np.int64)[0])
        if qp != self.addresses[1] or (int(ints[WORK_N // 4]), int(ints[WORK_M // 4]),
                                              int(ints[WORK_MS // 4])) != (self.n, self.m,
                                                                          self.n):
            raise RuntimeError(f"DAQP's workspace is not laid out as DAQP "
                               f"{DAQP_LAYOUT_VERSION}'s (controller.backend=daqp)")

    def update(self, hessian: bool) -> int:
        """``daqp.Model.update`` of the constraint matrix, linear cost and bounds (and the
        Hessian when ``hessian``), the constraint states of the last solve kept."""
        self.problem.view(np.int64)[PROBLEM_SENSE // 8] = \
            self.workspace[WORK_SENSE:WORK_SENSE + 8].view(np.int64)[0]
        mask = UPDATE_STEP | (UPDATE_RINV if hessian else 0)
        _, problem, _, work = self.addresses
        return int(self.functions.library.daqp_update_ldp(mask, work, problem))

    def solve(self) -> tuple[int, int]:
        """``daqp.Model.solve``: DAQP's exit flag and iterations; the solution in :attr:`x`."""
        _, _, result, work = self.addresses
        self.functions.library.daqp_solve(result, work)
        flags = self.result.view(np.int32)
        return int(flags[RESULT_EXITFLAG // 4]), int(flags[RESULT_ITER // 4])
