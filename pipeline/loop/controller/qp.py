"""QP plumbing shared by every MPC: a DPP problem compiled once, solved many times.

CVXPY canonicalizes a DPP problem into a parametrized cone program whose data
``(q, A, b)`` is an affine function of the stacked parameter vector ``theta``; CVXPY keeps that
function as sparse tensors (``ParamConeProg.q``, ``.A``, ``.P``). :func:`compile_affine_map`
reads those tensors once, in the parameter order the caller chooses, and keeps the result as a
picklable :class:`AffineQpMap` (numpy and scipy arrays only), so a compiled problem can be
handed to worker processes. Two backends solve it:

* :class:`DirectQp` (``clarabel_direct``, the default): three matrix-vector products, then an
  in-place data update of a kept Clarabel solver (``update(q=..., A=values, b=...)``) and
  ``solve``. Same QP, same solver, without CVXPY's per-call overhead.
* :class:`CvxpyQp` (``cvxpy``): parameter values set and ``problem.solve(solver=CLARABEL)``;
  the reference the direct backend is tested against.

Both return a :class:`QpSolution`. A :class:`QpCache` holds compiled problems keyed by their
structure (what enters the problem as a constant), so every run and every family member that
shares a structure reuses one compilation; it is an explicit object handed to the loop, never
module state.
"""

from __future__ import annotations

import functools
import time
import warnings
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp

if TYPE_CHECKING:
    import cvxpy as cp

# CVXPY's status words, spelled out: a process that only runs compiled maps (a family's worker)
# never imports CVXPY (a second of start-up); tests/loop/test_controller.py holds them to CVXPY's
OPTIMAL, OPTIMAL_INACCURATE = "optimal", "optimal_inaccurate"
SOLVER_ERROR = "solver_error"
OPTIMAL_STATUSES = (OPTIMAL, OPTIMAL_INACCURATE)

#: Clarabel's status names mapped to CVXPY's status strings (the log uses CVXPY's words).
CLARABEL_STATUS = {"Solved": OPTIMAL, "AlmostSolved": OPTIMAL_INACCURATE,
                   "PrimalInfeasible": "infeasible",
                   "AlmostPrimalInfeasible": "infeasible_inaccurate",
                   "DualInfeasible": "unbounded", "AlmostDualInfeasible": "unbounded_inaccurate",
                   "MaxIterations": "user_limit", "MaxTime": "user_limit"}


def solver_errors() -> tuple[type[BaseException], ...]:
    """Exceptions a solver may raise on numerical trouble; anything else (a shape error, a
    bug) is a code error and propagates instead of being recorded as a solver fallback. A
    function, called in ``except`` clauses (evaluated only when something was raised), so
    CVXPY is imported only then."""
    from cvxpy.error import SolverError

    return (SolverError, ArithmeticError)


#: Status of a step whose QP data were not finite (never handed to the solver).
NON_FINITE_DATA = "non_finite_data"


@dataclass(frozen=True)
class QpSolution:
    """One solve.

    Attributes
    ----------
    status : str
        CVXPY status word (``optimal``, ``infeasible``, ...) or ``error:<Exception>``.
    iterations : int
        Clarabel's iteration count (-1 when unknown).
    solve_time_s : float
        Wall time of the data update and the solve (s).
    values : dict
        Primal value of each named variable (None when the solve failed).
    """

    status: str
    iterations: int
    solve_time_s: float
    values: dict[str, Any] | None

    @property
    def ok(self) -> bool:
        return self.status in OPTIMAL_STATUSES and self.values is not None

    def value(self, name: str) -> np.ndarray:
        """A variable's value as a float array (a solve that has values: :attr:`ok`)."""
        if self.values is None:
            raise ValueError(f"no values: the solve ended {self.status}")
        return np.asarray(self.values[name], dtype=float)


@dataclass
class AffineQpMap:
    """QP data as an affine function of ``theta`` (Clarabel's form ``A x + s = b``, ``s in K``).

    ``q = q0 + Tq theta``, ``A.data = a0 + TA theta`` on the fixed sparsity ``(A_indices,
    A_indptr, A_shape)``, ``b = b0 + Tb theta``; ``P`` is constant (upper triangle).
    ``maps`` stacks ``[Tq; TA; Tb]`` so one product gives all three.
    """

    P: sp.csc_matrix
    offset: np.ndarray
    maps: sp.csr_matrix
    n_q: int
    n_a: int
    A_indices: np.ndarray
    A_indptr: np.ndarray
    A_shape: tuple[Any, ...]
    cone_dims: dict[str, Any]
    variables: dict[str, Any]            # name -> (offset, shape)
    n_theta: int
    compile_time_s: float

    def __post_init__(self) -> None:
        # the map's entries as (row, column, value) in CSR's stored order, for data()
        self.map_rows = np.repeat(np.arange(self.maps.shape[0]), np.diff(self.maps.indptr))
        self.map_columns = np.asarray(self.maps.indices, dtype=np.intp)
        self.map_values = np.asarray(self.maps.data, dtype=float)

    def data(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``q``, the values of ``A`` and ``b`` at ``theta``.

        ``maps @ theta`` as a gather, a product and a ``bincount`` over the map's few hundred
        entries: each row's products summed in the stored order, as scipy's CSR product sums
        them (the same numbers), without its per-call dispatch (half the time)."""
        products = self.map_values * theta[self.map_columns]
        flat = self.offset + np.bincount(self.map_rows, weights=products,
                                         minlength=self.offset.size)
        return flat[:self.n_q], flat[self.n_q:self.n_q + self.n_a], flat[self.n_q + self.n_a:]

    def matrix_A(self, values: np.ndarray) -> sp.csc_matrix:
        return sp.csc_matrix((values, self.A_indices, self.A_indptr), shape=self.A_shape)

    def cones(self) -> list[Any]:
        import clarabel

        cones = []
        if self.cone_dims["zero"]:
            cones.append(clarabel.ZeroConeT(self.cone_dims["zero"]))
        if self.cone_dims["nonneg"]:
            cones.append(clarabel.NonnegativeConeT(self.cone_dims["nonneg"]))
        cones.extend(clarabel.SecondOrderConeT(d) for d in self.cone_dims["soc"])
        return cones

    def unpack(self, x: np.ndarray) -> dict[str, Any]:
        """Named variable values from Clarabel's primal vector."""
        out = {}
        for name, (off, shape) in self.variables.items():
            size = shape[0] * shape[1] if len(shape) == 2 else (shape[0] if shape else 1)
            out[name] = x[off:off + size].reshape(shape, order="F")
        return out


def _column_ranges(param_prog: Any, parameters: list[Any]) -> np.ndarray:
    """CVXPY's columns of each parameter entry, in the caller's order (column-major)."""
    cols = [param_prog.param_id_to_col[p.id] + np.arange(p.size) for p in parameters]
    return np.concatenate(cols) if cols else np.zeros(0, dtype=int)


def compile_affine_map(problem: cp.Problem, parameters: list[Any], variables: dict[str, Any],
                       check: bool = True) -> AffineQpMap:
    """Canonicalize ``problem`` once and read its parameter-to-data map off CVXPY's tensors.

    Parameters
    ----------
    problem : cvxpy.Problem
        A DPP problem with a constant quadratic objective.
    parameters : list of cvxpy.Parameter
        Every parameter of the problem, in the order ``theta`` stacks them (each column-major).
    variables : dict
        Name -> ``cvxpy.Variable`` to read back after a solve.
    check : bool
        Compare the map once with CVXPY's own ``apply_parameters`` at the parameters' current
        values (random values where a parameter has none); a mismatch raises ``RuntimeError``.

    Returns
    -------
    AffineQpMap
    """
    import cvxpy as cp

    start = time.perf_counter()
    data, chain, inverse = problem.get_problem_data(cp.CLARABEL)
    prog = data["param_prob"]
    columns, const_col = _parameter_columns(prog, parameters)
    n = prog.x.size
    maps, offset, n_a, m, indices, indptr = _constraint_map(prog, n, columns, const_col)
    P = _constant_quadratic(prog, n, columns, const_col)
    dims = data["dims"]
    qp_map = AffineQpMap(
        P=P, offset=offset, maps=maps, n_q=n, n_a=n_a,
        A_indices=np.asarray(indices[:n_a], dtype=np.int64),
        A_indptr=np.asarray(indptr, dtype=np.int64)[:n + 1].copy(), A_shape=(m, n),
        cone_dims={"zero": int(dims.zero), "nonneg": int(dims.nonneg),
                   "soc": [int(d) for d in dims.soc]},
        variables=_variable_offsets(chain, inverse, variables),
        n_theta=int(columns.size), compile_time_s=0.0)
    if int(dims.exp) or list(dims.psd) or list(dims.p3d) or list(dims.pnd):
        raise RuntimeError("the direct backend handles zero, nonnegative and SOC cones only")
    if check:
        _check_map(qp_map, prog, parameters)
    qp_map.compile_time_s = time.perf_counter() - start
    return qp_map


def _parameter_columns(prog: Any, parameters: list[Any]) -> tuple[np.ndarray, int]:
    """The tensors' columns of ``parameters`` (in the caller's order) and of the constant;
    ``RuntimeError`` for variable bounds or a parameter list that is not the problem's."""
    from cvxpy.lin_ops.lin_op import CONSTANT_ID

    if getattr(prog, "lb_tensor", None) is not None or getattr(prog, "ub_tensor", None) is not None:
        raise RuntimeError("variable bounds are not supported by the direct backend")
    known = {p.id for p in parameters}
    if known != {pid for pid in prog.param_id_to_col if pid != CONSTANT_ID}:
        raise RuntimeError("the parameter list does not match the problem's parameters")
    return _column_ranges(prog, parameters), prog.param_id_to_col[CONSTANT_ID]


def _constraint_map(prog: Any, n: int, columns: np.ndarray, const_col: int
                    ) -> tuple[sp.csr_matrix, np.ndarray, int, int, np.ndarray, np.ndarray]:
    """``q``, ``A``'s nonzero values and ``b`` as one affine map of ``theta`` (``maps`` and
    ``offset``), with ``A``'s sparsity (``m`` rows, ``n_a`` entries, ``indices``, ``indptr``)."""
    from cvxpy.cvxcore.python.canonInterface import reduce_problem_data_tensor

    # constraints: flat (m x (n + 1)) data, column-major, rows that can ever be nonzero
    reduced, indices, indptr, shape = reduce_problem_data_tensor(sp.csc_matrix(prog.A), n)
    reduced = sp.csr_matrix(reduced)
    m = shape[0]
    n_a = int(indptr[n])
    A_rows = reduced[:n_a]
    b_rows = reduced[n_a:]
    b_index = np.asarray(indices[n_a:], dtype=np.int64)
    scatter_b = sp.csr_matrix((np.ones(b_index.size), (b_index, np.arange(b_index.size))),
                              shape=(m, b_index.size))
    q_tensor = sp.csr_matrix(prog.q)[:n]
    # Clarabel wants A x + s = b with s in K; CVXPY's cone program is A x + b in K
    stacked = sp.vstack([q_tensor, -A_rows, scatter_b @ b_rows]).tocsc()
    maps = sp.csr_matrix(stacked[:, columns])
    offset = np.asarray(stacked[:, [const_col]].todense()).ravel()
    return maps, offset, n_a, m, indices, indptr


def _constant_quadratic(prog: Any, n: int, columns: np.ndarray, const_col: int
                        ) -> sp.csc_matrix:
    """The objective's ``P`` (upper triangle); ``RuntimeError`` where it depends on
    ``theta``."""
    P_tensor = sp.csc_matrix(prog.P)
    if P_tensor.nnz and np.any(np.abs(P_tensor[:, columns]).sum() > 0):
        raise RuntimeError("the direct backend needs a constant quadratic objective")
    P_full = np.asarray(P_tensor[:, [const_col]].todense()).reshape((n, n), order="F")
    return sp.triu(sp.csc_matrix(P_full)).tocsc()


def _variable_offsets(chain: Any, inverse: Any, variables: dict[str, Any]
                      ) -> dict[str, tuple[int, tuple[int, ...]]]:
    """Each variable's offset in the solver's vector and its shape: those of the
    matrix-stuffing step."""
    from cvxpy.reductions.dcp2cone.cone_matrix_stuffing import ConeMatrixStuffing

    stuffing = next(inv for reduction, inv in zip(chain.reductions, inverse, strict=False)
                    if isinstance(reduction, ConeMatrixStuffing))
    return {name: (int(stuffing.var_offsets[v.id]), tuple(v.shape))
            for name, v in variables.items()}


def _check_map(qp_map: AffineQpMap, prog: Any, parameters: list[Any]) -> None:
    """The map against CVXPY's ``apply_parameters`` at one point (a guard against a change of
    CVXPY's internal layout)."""
    rng = np.random.default_rng(0)
    values = {p.id: (np.asarray(p.value, float) if p.value is not None
                     else rng.standard_normal(p.shape)) for p in parameters}
    theta = np.concatenate([np.asarray(values[p.id]).ravel(order="F") for p in parameters]) \
        if parameters else np.zeros(0)
    P, q, _, A, b = prog.apply_parameters(values, keep_zeros=True, quad_obj=True)
    q_map, a_map, b_map = qp_map.data(theta)
    A_map = qp_map.matrix_A(a_map)
    def largest(values: Any) -> float:
        values = np.asarray(values.todense() if sp.issparse(values) else values)
        return float(np.max(np.abs(values))) if values.size else 0.0

    A_cvx = sp.csc_matrix(A)
    scale = 1.0 + max(largest(q), largest(A_cvx), largest(b))
    error = max(largest(q_map - q), largest(A_map + A_cvx), largest(b_map - b),
                largest(qp_map.P - sp.triu(sp.csc_matrix(P))))
    if error > 1e-9 * scale:
        raise RuntimeError(f"parameter-to-data map disagrees with CVXPY's ({error:.3g})")


def clarabel_settings(max_iter: int, refinement: bool = True) -> Any:
    """Clarabel's settings for a kept solver: quiet, presolve off (it would forbid in-place data
    updates), the iteration limit, and its iterative refinement of each KKT solve on
    (Clarabel's default) or off (``controller.solver_refinement``)."""
    import clarabel

    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.presolve_enable = False
    settings.max_iter = int(max_iter)
    settings.iterative_refinement_enable = bool(refinement)
    return settings


class DirectQp:
    """Backend ``clarabel_direct``: a kept Clarabel solver fed by an :class:`AffineQpMap`.

    Parameters
    ----------
    qp_map : AffineQpMap
    max_iter : int
        Clarabel's iteration limit.
    refinement : bool
        Clarabel's iterative refinement (:func:`clarabel_settings`).
    """

    def __init__(self, qp_map: AffineQpMap, max_iter: int, refinement: bool = True) -> None:
        self.map = qp_map
        self.max_iter = int(max_iter)
        self.refinement = bool(refinement)
        self._solver: Any = None  # clarabel.DefaultSolver, made at the first solve

    def solve(self, theta: np.ndarray) -> QpSolution:
        """Solve at ``theta``; never raises on solver trouble (the status says it)."""
        import clarabel

        m = self.map
        start = time.perf_counter()
        if theta.shape != (m.n_theta,):
            raise ValueError(f"QP parameter vector has shape {theta.shape}, the compiled "
                             f"problem takes ({m.n_theta},)")
        if not np.isfinite(theta).all():  # finite parameters give finite data (a linear map)
            return QpSolution(NON_FINITE_DATA, -1, time.perf_counter() - start, None)
        q, a, b = m.data(theta)
        try:
            if self._solver is None:
                self._solver = clarabel.DefaultSolver(m.P, q, m.matrix_A(a), b, m.cones(),
                                                      clarabel_settings(self.max_iter,
                                                                        self.refinement))
            else:
                self._solver.update(q=q, A=a, b=b)
            solution = self._solver.solve()
        except solver_errors() as exc:
            return QpSolution(f"error:{type(exc).__name__}", -1, time.perf_counter() - start,
                              None)
        elapsed = time.perf_counter() - start
        status = CLARABEL_STATUS.get(str(solution.status).rsplit(".", 1)[-1], SOLVER_ERROR)
        values = m.unpack(np.asarray(solution.x)) if status in OPTIMAL_STATUSES else None
        return QpSolution(status, int(solution.iterations), elapsed, values)


class CvxpyQp:
    """Backend ``cvxpy``: parameters set, ``problem.solve(solver=CLARABEL)``.

    Parameters
    ----------
    problem : cvxpy.Problem
    parameters : list of cvxpy.Parameter
        In ``theta``'s order.
    variables : dict
        Name -> ``cvxpy.Variable``.
    max_iter : int
    refinement : bool
        Clarabel's iterative refinement (:func:`clarabel_settings`).
    """

    def __init__(self, problem: cp.Problem, parameters: list[Any], variables: dict[str, Any],
                 max_iter: int, refinement: bool = True) -> None:
        self.problem = problem
        self.parameters = parameters
        self.variables = variables
        self.max_iter = int(max_iter)
        self.refinement = bool(refinement)
        self.sizes = np.cumsum([p.size for p in parameters])[:-1]
        self.compile_count = 0
        self._program = None

    def solve(self, theta: np.ndarray) -> QpSolution:
        import cvxpy as cp

        if not np.all(np.isfinite(theta)):
            return QpSolution(NON_FINITE_DATA, -1, 0.0, None)
        for param, chunk in zip(self.parameters, np.split(theta, self.sizes), strict=True):
            param.value = chunk.reshape(param.shape, order="F")
        start = time.perf_counter()
        try:
            with warnings.catch_warnings():
                # "solution may be inaccurate": the status says so and is logged per step
                warnings.simplefilter("ignore", UserWarning)
                self.problem.solve(solver=cp.CLARABEL, max_iter=self.max_iter,
                                   iterative_refinement_enable=self.refinement)
        except solver_errors() as exc:
            return QpSolution(f"error:{type(exc).__name__}", -1, time.perf_counter() - start,
                              None)
        elapsed = time.perf_counter() - start
        # DPP: CVXPY keeps the parameter-to-data map after the first solve; a new one means
        # the problem was compiled again
        program = getattr(self.problem._cache, "param_prog", None)
        if program is not self._program:
            self.compile_count += 1
            self._program = program
        stats = self.problem.solver_stats
        iterations = int(stats.num_iters) if stats is not None and stats.num_iters is not None \
            else -1
        status = str(self.problem.status)
        values = None
        if status in OPTIMAL_STATUSES:
            values = {name: np.asarray(v.value, float) if v.value is not None else None
                      for name, v in self.variables.items()}
            if any(v is None for v in values.values()):
                values = None
        return QpSolution(status, iterations, elapsed, values)


@dataclass
class QpCache:
    """Compiled problems keyed by structure, shared by every run handed this object.

    ``get(key, build)`` returns the cached entry or calls ``build()`` once. Entries that hold
    CVXPY problems are dropped when the cache is pickled (for worker processes); affine maps,
    being plain arrays, travel.

    Attributes
    ----------
    compile_count : int
        Number of ``build()`` calls (compilations) through this cache.
    compile_time_s : float
        Their total wall time (s).
    """

    entries: dict[Hashable, Any] = field(default_factory=dict)
    compile_count: int = 0
    compile_time_s: float = 0.0
    #: values worth keeping that are no compilation (discretized models by speed): shipped to
    #: workers with the cache, never counted as compilations
    memos: dict[Hashable, Any] = field(default_factory=dict)

    #: objects bound to this process (e.g. the members' YAML by section): never pickled
    process_local: dict[str, Any] = field(default_factory=dict)
    #: run the single-track plant and the APF rollout as compiled kernels
    #: (:mod:`pipeline.loop.compiled`, the same bits as their Python statements); set by runners
    #: of many runs, where numba's import and cache load pay back
    #: (:data:`pipeline.studies.experiment.COMPILED_KERNELS_MIN_MEMBERS`), and shipped to
    #: their workers
    compiled_kernels: bool = False
    #: members the family runner has planned through this cache (what ``compiled_kernels``
    #: is decided on)
    members_planned: int = 0

    def memo(self, key: Hashable, build: Callable[[], Any]) -> Any:
        """The value stored under ``key``, built once (not counted as a compilation). In a
        cache a worker received (unpickled), a value not shipped with it is this process's
        (:func:`_process_memo`): a worker's tasks each receive the cache anew, and the values
        kept here are pure functions of their key (the models by speed, their condensed
        predictions), so its next task finds what its last one built (a task of 8 DAQP
        members spent about 12 % of its closed loops building them again)."""
        if key not in self.memos:
            self.memos[key] = _process_memo(key, build) if self.__dict__.get("_unpickled") \
                else build()
        return self.memos[key]

    def get(self, key: Hashable, build: Callable[[], Any]) -> Any:
        if key not in self.entries:
            start = time.perf_counter()
            self.entries[key] = build()
            self.compile_count += 1
            self.compile_time_s += time.perf_counter() - start
        return self.entries[key]

    def __getstate__(self) -> dict[str, Any]:
        portable = {k: v for k, v in self.entries.items() if isinstance(v, AffineQpMap)}
        return {"entries": portable, "compile_count": 0, "compile_time_s": 0.0,
                "memos": dict(self.memos), "process_local": {},
                "compiled_kernels": self.compiled_kernels,
                "members_planned": self.members_planned}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self.__dict__["_unpickled"] = True
        # the tables shipped with the cache (the parent's, often still empty) become this
        # process's (memo), their entries added where the process has none yet
        memos = {}
        for key, value in self.memos.items():
            if isinstance(value, dict):
                table = _process_memo(key, dict)
                for name, entry in value.items():
                    table.setdefault(name, entry)
                memos[key] = table
            else:
                memos[key] = _process_memo(key, functools.partial(_same, value))
        self.memos = memos


@functools.lru_cache(maxsize=128)
def _process_memo_value(key: Hashable) -> list[Any]:
    """A holder of this process's value of memo ``key`` (empty until built): the tables of the
    caches its worker tasks receive (:meth:`QpCache.memo`), at most 128 keys (a tune's trials
    of other tracking weights each have their own predictions)."""
    return []


def _same(value: Any) -> Any:
    return value


def _process_memo(key: Hashable, build: Callable[[], Any]) -> Any:
    """This process's value of memo ``key``, built once."""
    holder = _process_memo_value(key)
    if not holder:
        holder.append(build())
    return holder[0]


def compiled_backend(cache: QpCache | None, name: str, structure: Hashable,
                     build: Callable[[], tuple[Any, list[Any], dict[str, Any]]], backend: str,
                     max_iter: int, refinement: bool = True
                     ) -> tuple[DirectQp | CvxpyQp, int, float]:
    """The solver object of one controller, its problem taken from ``cache``.

    Parameters
    ----------
    cache : QpCache or None
        Shared compilations (a private cache when None).
    name : str
        Family of problems (``lateral``, ``kinematic``), part of the cache key.
    structure : hashable
        What enters the problem as a constant.
    build : callable
        Returns ``(problem, parameters, variables)``.
    backend : str
        ``clarabel_direct`` or ``cvxpy``.
    max_iter : int
    refinement : bool
        Clarabel's iterative refinement (:func:`clarabel_settings`).

    Returns
    -------
    qp : DirectQp or CvxpyQp
    compile_count, compile_time_s
        Compilations this call caused (0 when the cache held the structure) and their time.
    """
    cache = cache if cache is not None else QpCache()
    before_n, before_t = cache.compile_count, cache.compile_time_s
    if backend == "clarabel_direct":
        qp_map = cache.get((name, "map", structure), lambda: compile_affine_map(*build()))
        qp = DirectQp(qp_map, max_iter, refinement)
    else:
        # one CVXPY problem per statement and solver settings (a problem solves with its own)
        qp = cache.get((name, "cvxpy", structure, int(max_iter), bool(refinement)),
                       lambda: CvxpyQp(*build(), max_iter=max_iter, refinement=refinement))
    return qp, cache.compile_count - before_n, cache.compile_time_s - before_t
