"""The bench's yardstick: the lateral QP with the states as variables (the *sparse* statement,
the dynamics as equality constraints: 151 variables at N = 10 and three obstacle slots, against
the condensed statement's 33) on a kept Clarabel solver.

No controller solves it any more: ``controller.formulation=sparse`` was removed (issue 58, no
experiment used it). The bench's ratios are measured over it (``*_over_sparse_floor``: the
same QPs a run solved, restated with the states as variables), and the tests hold the
condensed QP to its optimum (``tests/loop/test_controller.py``).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from functools import lru_cache
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from pipeline.loop.controller.lateral_qp import LateralQpStructure, MpcInputs, blocking_matrix

if TYPE_CHECKING:
    import cvxpy as cp

    from pipeline.loop.controller.qp import AffineQpMap


def build_sparse_lateral_problem(s: LateralQpStructure) -> tuple[cp.Problem, list[Any], dict[str, Any]]:
    """The lateral QP in CVXPY with the states as variables: problem, parameters in ``theta``
    order (:func:`sparse_parameter_vector`), variables to read."""
    import cvxpy as cp

    N, Nc, M = s.horizon, s.control_horizon, s.max_obstacles
    w = s.weights
    q_y, q_psi, q_r, q_d, r_u = w.tracking
    w1, w2 = w.slack_linear, w.slack_quadratic
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


def sparse_parameter_vector(inputs: MpcInputs) -> np.ndarray:
    """One step's data as the sparse statement's parameter vector (``theta``: its parameters
    stacked column-major in :func:`build_sparse_lateral_problem`'s order)."""
    disturbance = inputs.model.Ed @ inputs.disturbance_rad_s[None, :]
    return np.concatenate([
        inputs.x0, inputs.model.Ad.ravel(order="F"), inputs.model.Bd.ravel(order="F"),
        disturbance.ravel(order="F"), inputs.y_ref_m, inputs.psi_ref_rad,
        inputs.yaw_rate_reference(), inputs.steering_reference(),
        inputs.constraint_gain.ravel(order="F"), inputs.constraint_bound.ravel(order="F")])


def sparse_map(controller: Any, vehicle: Any) -> AffineQpMap:
    """The sparse statement of a lateral MPC's settings, compiled once per structure in this
    process (the map a kept Clarabel solves through:
    :class:`~benchmarks.harness.inputs.KeptClarabelFloor`)."""
    return _compiled(LateralQpStructure.of(controller, vehicle))


@lru_cache(maxsize=16)
def _compiled(structure: LateralQpStructure) -> AffineQpMap:
    from pipeline.loop.controller.qp import compile_affine_map

    return compile_affine_map(*build_sparse_lateral_problem(structure))


class SparseStep(NamedTuple):
    """One sparse solve as the lateral MPC would apply it: the status, the planned steering
    rates over the horizon (rad/s) and the slack the plan needs (m)."""

    status: str
    planned_rates_rad_s: np.ndarray | None
    max_slack_m: float


class SparseLateralQp:
    """The sparse statement solved on a kept Clarabel (``clarabel_direct``'s solver): the
    tests' oracle of the condensed QP.

    Parameters
    ----------
    controller : MpcSettings
    vehicle : VehicleConfig
    max_iter : int
        Clarabel's iteration limit.
    """

    def __init__(self, controller: Any, vehicle: Any, max_iter: int = 200) -> None:
        from pipeline.loop.controller.qp import DirectQp

        self.qp = DirectQp(sparse_map(controller, vehicle), max_iter)
        self.blocking = blocking_matrix(controller.horizon, controller.control_horizon,
                                        controller.input_hold)

    def solve(self, inputs: MpcInputs) -> SparseStep:
        solution = self.qp.solve(sparse_parameter_vector(inputs))
        if not solution.ok:
            return SparseStep(solution.status, None, float("nan"))
        plan = solution.value("U").reshape(-1) @ self.blocking
        lateral = solution.value("X")[0, 1:][:, None]
        slack = (inputs.constraint_bound - inputs.constraint_gain * lateral).max()
        return SparseStep(solution.status, plan, float(max(slack, 0.0)))


@contextmanager
def recorded_inputs() -> Iterator[list[MpcInputs]]:
    """Every step's QP data (:class:`MpcInputs`) the lateral MPC condenses while the context is
    open, in order (the list is filled in)."""
    import pipeline.loop.controller.lateral as lateral

    original = lateral.condensed_data
    recorded: list[MpcInputs] = []

    def record(prediction: Any, inputs: MpcInputs, weights: Any) -> Any:
        recorded.append(inputs)
        return original(prediction, inputs, weights)

    lateral.condensed_data = record
    try:
        yield recorded
    finally:
        lateral.condensed_data = original


def recorded_sparse_qps(cfg: Any, scenario: Any) -> tuple[AffineQpMap, list[np.ndarray]]:
    """The QPs of a run of ``cfg`` (its own closed loop, on its own backend) restated with the
    states as variables: the compiled sparse map and each step's parameter vector."""
    from pipeline.loop.controller import QpCache
    from pipeline.loop.simulate import simulate

    with recorded_inputs() as inputs:
        simulate(cfg, scenario, QpCache())
    return sparse_map(cfg.controller, cfg.vehicle), [sparse_parameter_vector(i) for i in inputs]
