"""Lateral MPC against independent formulations: a closed-form condensed QP (numpy), SciPy's
SLSQP on the same condensed problem and the QP with the states as variables (the bench's sparse
floor, ``benchmarks/harness/sparse_floor.py``); DPP, recompilation and fallbacks."""

from __future__ import annotations

import cvxpy as cp
import numpy as np
import pytest
from builders import make_inputs
from scipy.optimize import minimize

from pipeline.loop.controller import LateralMpc, QpCache, blocking_matrix, collision_halfplanes
from pipeline.loop.controller.lateral_qp import LateralQpStructure, build_condensed_lateral_problem
from pipeline.loop.model import build_lateral_model


def condensed(model, cfg, x0, y_ref, psi_ref):
    """Prediction X = Phi x0 + Gamma u and the quadratic cost in U (independent of cvxpy)."""
    N, Nc = cfg.horizon, cfg.control_horizon
    Phi = np.vstack([np.linalg.matrix_power(model.Ad, k) for k in range(1, N + 1)])
    Gamma = np.zeros((5 * N, N))
    for k in range(1, N + 1):
        for i in range(k):
            Gamma[5 * (k - 1):5 * k, i] = (np.linalg.matrix_power(model.Ad, k - 1 - i)
                                           @ model.Bd).ravel()
    T = blocking_matrix(N, Nc, cfg.input_hold)
    Q = np.kron(np.eye(N), np.diag([cfg.q_lateral, 0.0, cfg.q_heading, cfg.q_yaw_rate,
                                    cfg.q_steering]))
    x_ref = np.zeros(5 * N)
    x_ref[0::5], x_ref[2::5] = y_ref, psi_ref
    M = Gamma @ T.T
    H = M.T @ Q @ M + cfg.r_steering_rate * T @ T.T
    g = M.T @ Q @ (Phi @ x0 - x_ref)
    return H, g, Phi, M, T


@pytest.fixture()
def setup(make_config):
    cfg = make_config()
    model = build_lateral_model(cfg.vehicle, 3.0, 0.1)
    return cfg, model


def test_problem_is_dpp(setup):
    cfg, _ = setup
    problem, _, _ = build_condensed_lateral_problem(
        LateralQpStructure.of(cfg.controller, cfg.vehicle))
    assert problem.is_dcp(dpp=True)


@pytest.mark.parametrize("input_hold", ["hold_last", "zero_rate"])
def test_first_input_matches_closed_form_condensed_qp(make_config, input_hold):
    cfg = make_config([f"controller.input_hold={input_hold}"])
    model = build_lateral_model(cfg.vehicle, 3.0, 0.1)
    ctrl = cfg.controller
    x0 = np.array([0.05, 0.02, -0.01, 0.01, 0.02])
    y_ref = np.linspace(0.0, 0.15, ctrl.horizon)
    psi_ref = np.full(ctrl.horizon, 0.03)
    H, g, Phi, M, T = condensed(model, ctrl, x0, y_ref, psi_ref)
    U_star = np.linalg.solve(H, -g)
    states = Phi @ x0 + M @ U_star
    # the oracle is the unconstrained optimum: check that no bound is active there
    assert np.max(np.abs(U_star)) < cfg.vehicle.steering_rate_max_rad_s
    assert np.max(np.abs(states[4::5])) < cfg.vehicle.steering_max_rad
    step = LateralMpc(ctrl, cfg.vehicle).solve(make_inputs(model, ctrl, x0, y_ref, psi_ref))
    assert step.fallback == "none"
    assert step.steering_rate_rad_s == pytest.approx(U_star[0], abs=1e-4)
    np.testing.assert_allclose(step.planned_rates_rad_s, T.T @ U_star, atol=1e-4)


def test_first_input_matches_scipy_slsqp_with_active_bounds(setup):
    cfg, model = setup
    ctrl, veh = cfg.controller, cfg.vehicle
    x0 = np.array([0.0, 0.0, 0.0, 0.0, 0.1])
    y_ref = np.full(ctrl.horizon, 2.0)  # far reference: rate and angle bounds become active
    psi_ref = np.full(ctrl.horizon, 0.4)
    H, g, Phi, M, T = condensed(model, ctrl, x0, y_ref, psi_ref)
    delta_rows = M[4::5]
    delta_free = (Phi @ x0)[4::5]
    cons = [{"type": "ineq", "fun": lambda U: veh.steering_max_rad - (delta_free + delta_rows @ U),
             "jac": lambda U: -delta_rows},
            {"type": "ineq", "fun": lambda U: veh.steering_max_rad + (delta_free + delta_rows @ U),
             "jac": lambda U: delta_rows}]
    res = minimize(lambda U: 0.5 * U @ H @ U + g @ U, np.zeros(ctrl.control_horizon),
                   jac=lambda U: H @ U + g, method="SLSQP", constraints=cons,
                   bounds=[(-veh.steering_rate_max_rad_s, veh.steering_rate_max_rad_s)]
                   * ctrl.control_horizon, options={"ftol": 1e-12, "maxiter": 500})
    assert res.success
    step = LateralMpc(ctrl, veh).solve(make_inputs(model, ctrl, x0, y_ref, psi_ref))
    assert step.steering_rate_rad_s == pytest.approx(res.x[0], abs=1e-4)
    states = step.predicted_states
    # constraints hold at the solution (Clarabel's tolerance)
    assert np.max(np.abs(states[4, 1:])) <= veh.steering_max_rad + 1e-6
    assert np.max(np.abs(step.planned_rates_rad_s)) <= veh.steering_rate_max_rad_s + 1e-6
    assert np.max(np.abs(states[4, 1:])) == pytest.approx(veh.steering_max_rad, abs=1e-5)


def test_halfplane_constraint_holds_without_slack_when_reachable(setup):
    cfg, model = setup
    ctrl, veh = cfg.controller, cfg.vehicle
    N = ctrl.horizon
    stations = 0.3 * np.arange(1, N + 1)
    obstacles = np.tile(np.array([[2.9, 1.3]]), (N, 1, 1))  # static, ahead and to the left
    y_ref = np.zeros(N)
    G, h = collision_halfplanes(stations, y_ref, np.zeros(2), obstacles, np.array([0.2]), veh,
                                ctrl)
    step = LateralMpc(ctrl, veh).solve(make_inputs(model, ctrl, np.zeros(5), y_ref, np.zeros(N),
                                                  G, h))
    y = step.predicted_states[0, 1:]
    # every half-plane is satisfied by the predicted lateral positions, slack ~ 0
    assert np.all(G[:, 0] * y >= h[:, 0] - 1e-5)
    assert step.max_slack_m < 1e-5
    assert np.any(h[:, 0] > 0)  # the constraint was really binding somewhere
    assert y[-1] < -0.09  # pushed to the right: the last plane asks y <= -0.097 m


def test_parameter_changes_do_not_recompile(setup):
    cfg, model = setup
    ctrl = cfg.controller
    mpc = LateralMpc(ctrl, cfg.vehicle)
    rng = np.random.default_rng(0)
    for speed in (2.0, 3.0, 5.0):
        m = build_lateral_model(cfg.vehicle, speed, 0.1)
        for _ in range(3):
            step = mpc.solve(make_inputs(m, ctrl, rng.normal(0, 0.05, 5),
                                        rng.normal(0, 0.3, ctrl.horizon),
                                        rng.normal(0, 0.05, ctrl.horizon)))
            assert step.fallback == "none"
    # one statement per number of obstacle slots (0 to max_obstacles), all made at
    # construction; none since
    assert mpc.compile_count == ctrl.max_obstacles + 1 == len(mpc.qp_by_slots)


@pytest.mark.parametrize("backend", ["cvxpy", "clarabel_direct"])
def test_one_compilation_serves_every_controller_of_a_structure(make_config, backend):
    """A shared QpCache compiles a structure once; a new structure compiles again."""
    cfg = make_config([f"controller.backend={backend}"])
    cache = QpCache()
    first = LateralMpc(cfg.controller, cfg.vehicle, qp_cache=cache)
    second = LateralMpc(cfg.controller, cfg.vehicle, qp_cache=cache)
    statements = cfg.controller.max_obstacles + 1  # one per number of obstacle slots
    assert (first.compile_count, second.compile_count, cache.compile_count) \
        == (statements, 0, statements)
    first_qp, second_qp = first.qp.compiled, second.qp.compiled  # the condensed statement
    assert first_qp is second_qp or first_qp.map is second_qp.map
    other = make_config([f"controller.backend={backend}", "controller.horizon=12"])
    assert LateralMpc(other.controller, other.vehicle, qp_cache=cache).compile_count \
        == statements
    # the affine map travels to worker processes, CVXPY problems do not
    import pickle

    copied = pickle.loads(pickle.dumps(cache))
    assert len(copied.entries) == (2 * statements if backend == "clarabel_direct" else 0)


def test_code_error_inside_the_qp_is_raised_not_recorded_as_fallback(setup):
    """A parameter vector of the wrong shape is a bug: it raises, it is not a solver failure."""
    cfg, model = setup
    mpc = LateralMpc(cfg.controller, cfg.vehicle)
    with pytest.raises(ValueError, match="parameter vector"):
        mpc.qp.compiled.solve(np.zeros(3))


def test_infeasible_qp_falls_back_to_safe_input_then_shifted_plan(setup):
    cfg, model = setup
    ctrl, veh = cfg.controller, cfg.vehicle
    N = ctrl.horizon
    mpc = LateralMpc(ctrl, veh)
    bad = np.array([0.0, 0.0, 0.0, 0.0, 2.0])  # steering far beyond its bound: infeasible
    first = mpc.solve(make_inputs(model, ctrl, bad, np.zeros(N), np.zeros(N)))
    assert first.fallback == "safe_input"
    assert first.status in ("infeasible", "infeasible_inaccurate")
    assert abs(first.steering_rate_rad_s) == pytest.approx(veh.steering_rate_max_rad_s)
    ok = mpc.solve(make_inputs(model, ctrl, np.zeros(5), np.full(N, 0.3), np.zeros(N)))
    assert ok.fallback == "none"
    second = mpc.solve(make_inputs(model, ctrl, bad, np.zeros(N), np.zeros(N)))
    assert second.fallback == "shifted_plan"
    assert second.steering_rate_rad_s == pytest.approx(ok.planned_rates_rad_s[1])
    nan_state = mpc.solve(make_inputs(model, ctrl, np.full(5, np.nan), np.zeros(N), np.zeros(N)))
    assert nan_state.status == "not_solved" and nan_state.fallback == "shifted_plan"


@pytest.mark.parametrize("backend", ["cvxpy", "clarabel_direct"])
def test_solver_exception_is_a_fallback_not_a_crash(make_config, monkeypatch, backend):
    cfg = make_config([f"controller.backend={backend}"])
    model = build_lateral_model(cfg.vehicle, 3.0, 0.1)
    ctrl = cfg.controller
    mpc = LateralMpc(ctrl, cfg.vehicle)

    def boom(*args, **kwargs):
        raise cp.error.SolverError("injected")

    for qp in mpc.qp_by_slots.values():  # whichever statement the step solves
        if backend == "cvxpy":
            monkeypatch.setattr(qp.compiled.problem, "solve", boom)
        else:
            monkeypatch.setattr(qp.compiled, "_solver", type("Boom", (), {"solve": boom,
                                                                        "update": boom})())
    step = mpc.solve(make_inputs(model, ctrl, np.zeros(5), np.zeros(ctrl.horizon),
                                np.zeros(ctrl.horizon)))
    assert step.status == "error:SolverError" and step.fallback == "safe_input"
    assert step.steering_rate_rad_s == 0.0


def test_backends_agree_in_closed_loop_and_never_recompile(make_config, tmp_path):
    """The clarabel_direct backend solves the same QP as CVXPY: the closed loops coincide."""
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate

    results = {}
    for backend in ("cvxpy", "clarabel_direct"):
        cfg = make_config(["method=improved", f"controller.backend={backend}"])
        results[backend] = simulate(cfg, build_scenario(cfg.scenario))
        assert results[backend].compile_count == cfg.controller.max_obstacles + 1
    a, b = results["cvxpy"].trajectory, results["clarabel_direct"].trajectory
    assert len(a) == len(b)
    for column in ("X_m", "Y_m", "delta_rad", "steering_rate_rad_s"):
        np.testing.assert_allclose(a[column].fillna(0), b[column].fillna(0), atol=1e-7)


def _capture_condensed_data(monkeypatch) -> list:
    """Every step's condensed QP data of the closed loops that follow (a list filled in)."""
    import pipeline.loop.controller.lateral as lateral

    captured = []
    original = lateral.condensed_data

    def capture(*args, **kwargs):
        captured.append(original(*args, **kwargs))
        return captured[-1]

    monkeypatch.setattr(lateral, "condensed_data", capture)
    return captured


@pytest.mark.parametrize("overrides, member", [
    (["method=improved"], None), (["method=baseline"], None),
    (["method=improved", "scenario=family", "scenario.family.size=12"], 0),
    (["method=baseline", "scenario=family", "scenario.family.size=12"], 5),
    (["method=improved", "scenario=family", "scenario.family.size=12",
      "controller.frame=fixed"], 0),
    (["method=baseline", "scenario=family", "scenario.family.size=12",
      "controller.frame=fixed"], 4)])
def test_condensed_qp_equals_the_sparse_qp(make_config, overrides, member):
    """On every QP of a closed loop (the paper scenario; family members where the half-plane
    slacks bind: in the path frame member 0 of improved, 5 of baseline, slack up to 1.4 m; in
    the fixed frame 0 and 4) the condensed statement (``W = R U``) and the same QP with the
    states as variables (the oracle: the dynamics as equality constraints, nothing eliminated)
    reach the same moves to Clarabel's tolerance (1e-5 rad/s and relative; 1e-4 for the later moves where a
    slack exceeds 1 m: the objective is then dominated by the slack's penalty and Clarabel's
    tolerance is relative to it), on identical data: in the path frame with the previewed
    curvature as disturbance and the yaw-rate and steering references. (Compared per QP: closed
    loops part where the plant's steering bound switches, a 1e-6 difference decides whether a
    step saturates.)"""
    import dataclasses

    from benchmarks.harness.sparse_floor import SparseLateralQp, recorded_inputs
    from pipeline.loop.scenario import build_scenario, family_members
    from pipeline.loop.simulate import simulate

    cfg = make_config(overrides)
    if member is not None:
        cfg = dataclasses.replace(cfg, scenario=family_members(
            cfg.scenario, cfg.vehicle.footprint_radius_m)[member])
    with recorded_inputs() as captured_inputs:
        trajectory = simulate(cfg, build_scenario(cfg.scenario)).trajectory
    if member is not None:
        assert np.nanmax(trajectory["max_slack_m"].to_numpy(float)) > 0.05  # slacks bind
    if cfg.controller.frame == "path":  # the path frame's data reach the QP
        assert any(np.count_nonzero(i.disturbance_rad_s) for i in captured_inputs)
        assert any(np.count_nonzero(i.delta_ref_rad) for i in captured_inputs)
    condensed = LateralMpc(cfg.controller, cfg.vehicle)
    sparse = SparseLateralQp(cfg.controller, cfg.vehicle)
    assert len(captured_inputs) > 50
    for inputs in captured_inputs:
        a = condensed.solve(inputs)
        b = sparse.solve(inputs)
        assert a.status == b.status == "optimal" and a.fallback == "none"
        tolerance = 1e-4 if a.max_slack_m > 1.0 else 1e-5
        # relative too: a move near its 1 rad/s bound is met to Clarabel's relative tolerance
        # (the condensed step solves the statement of the slots it uses: 1.01e-5 at 0.98 rad/s
        # in the fixed frame's member 0)
        np.testing.assert_allclose(a.planned_rates_rad_s, b.planned_rates_rad_s,
                                   rtol=tolerance, atol=tolerance)
        assert abs(a.max_slack_m - b.max_slack_m) < 1e-5


def test_condensed_prediction_matches_the_recurrence():
    """Gamma U + free response equals stepping x_{k+1} = A x_k + B u_k + e_k (oracle: the
    recurrence itself, u from the move-blocking rule)."""
    from pipeline.loop.controller.lateral_qp import CondensedPrediction, blocking_matrix
    from pipeline.loop.model import build_lateral_model
    from pipeline.loop.settings import VehicleConfig

    vehicle = VehicleConfig(name="car", source="test")
    model = build_lateral_model(vehicle, 3.0, 0.1, -1.0)
    T = blocking_matrix(10, 3, "hold_last")
    prediction = CondensedPrediction.of(model, T)
    rng = np.random.default_rng(0)
    x0, U, e = rng.normal(size=5), rng.normal(size=3), rng.normal(size=(5, 10))
    x, expected = x0.copy(), []
    for k, u in enumerate(U @ T):
        x = model.Ad @ x + model.Bd[:, 0] * u + e[:, k]
        expected.append(x)
    got = prediction.free_response(x0, e) + prediction.gamma @ U
    assert np.allclose(got, np.array(expected), atol=1e-12)


@pytest.mark.parametrize("overrides, member", [
    (["method=improved"], None), (["method=baseline"], None),
    (["method=improved", "scenario=family", "scenario.family.size=12"], 0),
    (["method=baseline", "scenario=family", "scenario.family.size=12"], 5),
    (["method=baseline", "scenario=family", "scenario.family.size=12",
      "controller.frame=fixed"], 4)])
def test_daqp_backend_solves_the_same_qps_as_clarabel(make_config, overrides, member,
                                                      monkeypatch):
    """controller.backend=daqp solves the same condensed QP (explicit slacks) with DAQP. On
    every QP of a closed loop (the paper scenario; family members where the half-plane slacks
    bind) both solvers reach the same optimum: cost within 1e-6 relative, u0 within 1e-5 rad/s
    (Clarabel's interior-point tolerance; the closed loops themselves drift apart where the
    steering bound switches, so they are compared per QP, on identical data)."""
    import dataclasses

    import pipeline.loop.controller.lateral_backends as backends
    import pipeline.loop.controller.lateral_qp as lateral_qp
    from pipeline.loop.controller.qp import DirectQp, compile_affine_map
    from pipeline.loop.scenario import build_scenario, family_members
    from pipeline.loop.simulate import simulate

    cfg = make_config(overrides)
    if member is not None:
        cfg = dataclasses.replace(cfg, scenario=family_members(
            cfg.scenario, cfg.vehicle.footprint_radius_m)[member])
    captured = _capture_condensed_data(monkeypatch)
    trajectory = simulate(cfg, build_scenario(cfg.scenario)).trajectory
    if member is not None:
        assert np.nanmax(trajectory["max_slack_m"].to_numpy(float)) > 0.05  # slacks bind
    s = lateral_qp.LateralQpStructure.of(cfg.controller, cfg.vehicle)
    clarabel = backends.CompiledCondensedQp(
        DirectQp(compile_affine_map(*lateral_qp.build_condensed_lateral_problem(s)), 200))
    daqp = backends.DaqpCondensedQp(s, 200)
    T = blocking_matrix(s.horizon, s.control_horizon, s.input_hold)

    def cost(data, U):
        slack = np.maximum(0.0, data.bound_h - data.gamma_h @ U)
        return (np.sum((data.gamma_w @ U + data.free_w) ** 2) + s.weights[4]
                * np.sum((U @ T) ** 2) + s.weights[5] * slack.sum()
                + s.weights[6] * np.sum(slack ** 2))

    assert len(captured) > 50
    for data in captured:
        a, b = clarabel.solve(data), daqp.solve(data)
        assert a.status == b.status == "optimal"
        assert abs(a.values["U"][0] - b.values["U"][0]) < 1e-5
        assert cost(data, b.values["U"]) <= cost(data, a.values["U"]) * (1 + 1e-6) + 1e-9
        assert cost(data, a.values["U"]) <= cost(data, b.values["U"]) * (1 + 1e-6) + 1e-9


def test_daqp_solves_the_statement_of_the_slots_a_step_uses(make_config, monkeypatch):
    """DAQP, as Clarabel, solves the statement of the fewest obstacle slots that holds a
    step's half-planes (``LateralMpc.qp_for``: most steps of a family member use none and
    solve the 3-variable QP): on every QP of a member whose slacks bind, the statement of the
    slots used gives the full statement's moves (1e-9 rad/s: the same optimum, DAQP's
    rounding), steps of every size occur, and the closed loop (alone and stepped in a group)
    set up the workspace of the statement without slots."""
    import dataclasses

    import pipeline.loop.controller.lateral_backends as backends
    import pipeline.loop.controller.lateral_qp as lateral_qp
    from pipeline.loop.controller import QpCache
    from pipeline.loop.controller.lateral import LateralMpc
    from pipeline.loop.engine import MemberLoop, step_members
    from pipeline.loop.scenario import build_scenario, family_members
    from pipeline.loop.simulate import run_kernels, simulate

    cfg = make_config(["method=improved", "scenario=family", "scenario.family.size=12",
                       "controller.backend=daqp"])
    cfg = dataclasses.replace(cfg, scenario=family_members(
        cfg.scenario, cfg.vehicle.footprint_radius_m)[0])
    captured = _capture_condensed_data(monkeypatch)
    simulate(cfg, build_scenario(cfg.scenario))
    s = lateral_qp.LateralQpStructure.of(cfg.controller, cfg.vehicle)
    N, M, nc = s.horizon, s.max_obstacles, s.control_horizon
    full = backends.DaqpCondensedQp(s, 200)
    sized = {k: backends.DaqpCondensedQp(dataclasses.replace(s, max_obstacles=k), 200)
             for k in range(M + 1)}
    assert [sized[k].native.n for k in range(M + 1)] == [nc + N * k for k in range(M + 1)]
    seen = set()
    for data in captured:
        k = lateral_qp.slots_used(data.gamma_h.reshape(N, M, nc).any(axis=2),
                                  data.bound_h.reshape(N, M))
        seen.add(k)
        a, b = full.solve(data), sized[k].solve(data)
        assert a.status == b.status == "optimal"
        np.testing.assert_allclose(b.values["U"], a.values["U"], rtol=0, atol=1e-9)
    assert 0 in seen and max(seen) >= 1
    # the closed loop's own statements: each member alone (CPython's kernels: qp_for), in the
    # engine's batched DAQP call (a speed rule keeps members out of the groups) and in a group
    for compiled, overrides in ((False, []), (True, ["planner.velocity_planning=true"]),
                                (True, [])):
        member_cfg = make_config(["method=improved", "controller.backend=daqp", *overrides])
        cache = QpCache(compiled_kernels=compiled)
        members = [MemberLoop(member_cfg, build_scenario(member_cfg.scenario), cache,
                              run_kernels(cache), False) for _ in range(2)]
        step_members(members)
        for member in members:
            mpc = member.controller
            assert isinstance(mpc, LateralMpc)
            ready = [int(mpc.qp_by_slots[k].native.ready[0]) for k in range(M + 1)]
            # the statement without slots and one with the obstacle's
            assert ready[0] == 1 and any(ready[1:]), (compiled, overrides, ready)


def test_daqp_iteration_limit_and_bad_data_take_the_fallback(make_config):
    """A DAQP solve stopped by its iteration limit is 'user_limit' and non-finite data never
    reach it: both take the shifted-plan / safe-input fallback, as with Clarabel."""
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate

    cfg = make_config(["method=improved", "controller.backend=daqp",
                       "controller.solver_max_iter=1"])
    trajectory = simulate(cfg, build_scenario(cfg.scenario)).trajectory
    limited = trajectory["solver_status"] == "user_limit"
    assert limited.any()
    assert set(trajectory.loc[limited, "fallback"]) <= {"shifted_plan", "safe_input"}
    # every step applied a finite input (the last row logs the end, without one)
    assert np.isfinite(trajectory["steering_rate_rad_s"].to_numpy(float)[:-1]).all()


def test_daqp_needs_the_lateral_mpc(make_config):
    from pipeline.errors import ConfigError

    with pytest.raises(ConfigError, match="daqp only with controller.kind=mpc"):
        make_config(["controller=kinematic", "controller.backend=daqp"])


@pytest.mark.parametrize("key, value, allowed", [
    ("controller.backend", "clarabel_dense", "one of cvxpy, clarabel_direct, daqp, nmpc"),
    ("controller.formulation", "sparse", "one of condensed")])
def test_a_removed_choice_is_refused_naming_the_key_and_what_is_allowed(make_config, key, value,
                                                                       allowed):
    """``clarabel_dense`` and ``sparse`` were removed (issue 58: no experiment used them): a
    configuration that still names one is refused in one line with the key, the values allowed
    now, and that it was removed."""
    from pipeline.errors import ConfigError

    with pytest.raises(ConfigError) as refused:
        make_config([f"{key}={value}"])
    message = str(refused.value)
    assert "\n" not in message and refused.value.key == key
    assert f"{key}='{value}' is invalid; allowed: {allowed} ({value} was removed: no " \
           "experiment used it" in message


def test_kept_daqp_workspace_follows_speed_changes(make_config, monkeypatch):
    """The kept DAQP workspace receives the Hessian only when the model's speed changes it;
    with velocity planning on, the speed changes during the run, and every QP's u0 equals a
    fresh ``daqp.solve`` of the same data (the oracle: no kept state)."""
    import daqp

    import pipeline.loop.controller.lateral_backends as backends
    import pipeline.loop.controller.lateral_qp as lateral_qp
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate

    # the stopping-distance rule slows the vehicle on the paper scenario (the default rule
    # keeps the nominal speed there: nothing is predicted in the way)
    cfg = make_config(["method=improved", "controller.backend=daqp",
                       "planner.velocity_planning=true",
                       "planner.velocity_rule=stopping_distance"])
    captured = _capture_condensed_data(monkeypatch)
    trajectory = simulate(cfg, build_scenario(cfg.scenario)).trajectory
    assert trajectory["speed_ref_mps"].nunique() > 2  # the model changed during the run
    assert len({id(d.hessian_u) for d in captured}) > 2
    s = lateral_qp.LateralQpStructure.of(cfg.controller, cfg.vehicle)
    kept = backends.DaqpCondensedQp(s, 200)
    fresh = backends.DaqpCondensedQp(s, 200)
    for data in captured:
        got = kept.solve(data)
        H, f = fresh.cost(data)
        A = fresh._A.copy()
        A[:s.horizon, :fresh.n_u], A[s.horizon:, :fresh.n_u] = data.gamma_d, data.gamma_h
        upper, lower = fresh._upper.copy(), fresh._lower.copy()
        base = fresh.n_u + fresh.n_s
        upper[base:base + s.horizon] = s.steering_max_rad - data.free_d
        lower[base:base + s.horizon] = -s.steering_max_rad - data.free_d
        lower[base + s.horizon:] = data.bound_h
        x, _, flag, _ = daqp.solve(H.copy(), f.copy(), A, upper, lower,
                                   np.zeros(upper.size, np.intc))
        assert flag == 1 and got.status == "optimal"
        assert abs(got.values["U"][0] - x[0]) < 1e-9


def test_status_words_are_cvxpys_and_the_loop_imports_neither_cvxpy_nor_python_control():
    """The QP plumbing spells CVXPY's status words out (so a worker that runs shipped maps never
    imports CVXPY); they are CVXPY's own. And importing the run entry point imports neither
    CVXPY nor python-control (each costs start-up to every process; they load where used)."""
    import subprocess
    import sys

    import pipeline.loop.controller.qp as qp

    assert qp.OPTIMAL_STATUSES == (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)
    assert qp.SOLVER_ERROR == cp.SOLVER_ERROR
    assert set(qp.CLARABEL_STATUS.values()) == {cp.OPTIMAL, cp.OPTIMAL_INACCURATE, cp.INFEASIBLE,
                                                cp.INFEASIBLE_INACCURATE, cp.UNBOUNDED,
                                                cp.UNBOUNDED_INACCURATE, cp.USER_LIMIT}
    assert cp.error.SolverError in qp.solver_errors()
    code = ("import sys, pipeline.run; "
            "print(sorted(m for m in ('cvxpy', 'control') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_each_controller_kind_has_its_own_schema(make_config):
    """Each kind is composed into its own schema (no flat union, no copy): the built-in
    controller holds the composed settings themselves; choices are words equal to their enums;
    a key of another kind is refused at composition, and so is a kind that is not its
    schema's (naming the file of the other kind); the weights read by name."""
    from hydra.errors import ConfigCompositionException

    from pipeline.errors import ConfigError
    from pipeline.loop.controller import make_controller
    from pipeline.loop.controller_settings import (
        Frame,
        KinematicMpcSettings,
        KinematicWeights,
        LateralWeights,
        MpcSettings,
        PurePursuitSettings,
        ReferenceAlignment,
    )

    kinds = {"method=improved": MpcSettings, "method=apf_pursuit": PurePursuitSettings,
             "experiment=kinematic": KinematicMpcSettings}
    for override, kind in kinds.items():
        cfg = make_config([override])
        assert type(cfg.controller) is kind and cfg.controller.kind == kind.kind_word
        assert make_controller(cfg, 0.1).cfg is cfg.controller
    assert not hasattr(make_config(["method=apf_pursuit"]).controller, "q_lateral")
    assert not hasattr(make_config(["experiment=kinematic"]).controller, "frame")
    assert not hasattr(make_config([]).controller, "accel_bounds_mps2")
    cfg = make_config(["method=improved", "controller.frame=fixed", "controller.q_heading=7"])
    assert cfg.controller.frame == Frame.FIXED and cfg.controller.frame == "fixed"
    assert LateralMpc(cfg.controller, cfg.vehicle).cfg is cfg.controller
    assert cfg.controller.weights == LateralWeights(10.0, 7.0, 0.1, 0.5, 1.0, 1.0e4, 1.0e3)
    kinematic = make_config(["experiment=kinematic", "controller.reference_alignment=path_speed",
                             "controller.input_weights=[0.2,0.3]"]).controller
    assert kinematic.reference_alignment == ReferenceAlignment.PATH_SPEED
    assert list(kinematic.accel_bounds_mps2) == [-3.0, 3.0]
    assert kinematic.weights == KinematicWeights(1.0, 1.0, 0.2, 0.3, 0.01, 0.01, 1.0e4, 1.0e3)
    with pytest.raises(ConfigError, match="one of path, fixed"):
        make_config(["controller.frame=curved"])
    for override in (["method=apf_pursuit", "controller.q_lateral=3"],
                     ["experiment=kinematic", "controller.frame=fixed"],
                     ["controller.lookahead_min_m=1"]):
        with pytest.raises(ConfigCompositionException, match="Could not override"):
            make_config(override)
    with pytest.raises(ConfigError, match="controller=pure_pursuit") as refused:
        make_config(["controller.kind=pure_pursuit"])
    assert refused.value.key == "controller.kind"
    with pytest.raises(ConfigError, match="for this controller"):
        LateralMpc(make_config(["experiment=kinematic"]).controller,
                   make_config([]).vehicle)


def test_slots_used_is_one_past_the_last_slot_with_a_row():
    """Closed forms: no row, a row in the first slot, a bound alone in the last of three."""
    from pipeline.loop.controller.lateral_qp import slots_used

    G, h = np.zeros((10, 3)), np.zeros((10, 3))
    assert slots_used(G, h) == 0
    G[4, 0] = 1.0
    assert slots_used(G, h) == 1
    h[9, 2] = 0.5  # a slot whose gain is 0 but whose bound is not still binds the plan
    assert slots_used(G, h) == 3
    # the kinematic MPC's rows (Gx, Gy, h): a slot used by its second gain alone counts
    gy = np.zeros((10, 3))
    gy[0, 1] = -1.0
    assert slots_used(np.zeros((10, 3)), gy, np.zeros((10, 3))) == 2


@pytest.mark.parametrize("backend", ["clarabel_direct", "cvxpy"])
def test_a_step_solves_the_smallest_statement_that_holds_its_halfplanes(setup, make_config,
                                                                       backend):
    """A step with no half-plane solves the statement without slots, one whose only obstacle
    sits in the second slot the two-slot statement; each gives the full statement's moves on
    the same data (oracle: the three-slot statement solved directly) to Clarabel's tolerance,
    and the full statement is not the one called."""
    from pipeline.loop.controller.lateral_qp import condensed_data

    _, model = setup
    cfg = make_config([f"controller.backend={backend}"])
    ctrl, N = cfg.controller, cfg.controller.horizon
    mpc = LateralMpc(ctrl, cfg.vehicle)
    assert sorted(mpc.qp_by_slots) == list(range(ctrl.max_obstacles + 1))
    free = make_inputs(model, ctrl, np.array([0.1, 0.0, 0.02, 0.0, 0.0]), np.full(N, 0.4),
                       np.zeros(N))
    G, h = np.zeros((N, ctrl.max_obstacles)), np.zeros((N, ctrl.max_obstacles))
    G[:, 1], h[:, 1] = 1.0, np.linspace(0.2, 0.8, N)  # y_k >= h_k: binds beyond the reference
    walled = make_inputs(model, ctrl, np.array([0.1, 0.0, 0.02, 0.0, 0.0]), np.full(N, 0.4),
                         np.zeros(N), G, h)
    calls = []
    for slots, qp in mpc.qp_by_slots.items():
        original = qp.solve
        qp.solve = lambda data, slots=slots, original=original: (calls.append(slots),
                                                                 original(data))[1]
    for inputs, slots in ((free, 0), (walled, 2)):
        calls.clear()
        step = mpc.solve(inputs)
        assert calls == [slots] and step.fallback == "none"
        data = condensed_data(mpc.prediction(inputs.model), inputs, mpc.weights)
        full = mpc.qp_by_slots[ctrl.max_obstacles].compiled.solve(data.theta())
        full_moves = data.chol_inv @ np.asarray(full.values["W"], float).reshape(-1)
        np.testing.assert_allclose(step.planned_rates_rad_s[:ctrl.control_horizon],
                                   full_moves, atol=1e-6)
    # the wall binds: the plan needs no slack yet lies above the reference's 0.4 m at the end
    assert step.predicted_states[0, -1] > 0.75
