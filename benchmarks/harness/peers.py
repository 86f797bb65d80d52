"""The peers on the same QP (CVXPY rebuilt every step, python-control) and the kinematic
LTV-QP step."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from benchmarks.harness.inputs import compose_config, step_inputs


def bench_peers(n_steps: int) -> list[dict]:
    """Rebuild-every-step CVXPY and python-control's optimizer on the same (obstacle-free) QP."""
    import warnings

    import control
    import control.optimal as opt
    from scipy.optimize import OptimizeWarning

    from pipeline.loop.controller import LateralMpc

    # python-control passes the unbounded rows of its state range to SciPy, which says so
    warnings.simplefilter("ignore", OptimizeWarning)
    rows = []
    for N in (10, 20):
        cfg = compose_config(["method=improved", f"controller.horizon={N}",
                              f"controller.control_horizon={N}"])
        ctrl, veh = cfg.controller, cfg.vehicle
        kept = LateralMpc(ctrl, veh)
        steps = step_inputs(cfg, 1, n_steps, seed=1)
        model = steps[0][0].model
        sys_d = control.ss(model.Ad, model.Bd, np.eye(5), np.zeros((5, 1)), dt=0.1)
        Q = np.diag([ctrl.q_lateral, 0.0, ctrl.q_heading, ctrl.q_yaw_rate, ctrl.q_steering])
        R = np.array([[ctrl.r_steering_rate]])
        lower = [-np.inf] * 4 + [-veh.steering_max_rad]
        upper = [np.inf] * 4 + [veh.steering_max_rad]
        constraints = [opt.input_range_constraint(sys_d, [-veh.steering_rate_max_rad_s],
                                                  [veh.steering_rate_max_rad_s]),
                       opt.state_range_constraint(sys_d, lower, upper)]
        for k, (inputs, *_) in enumerate(steps):
            # constant references so that python-control's quadratic_cost states the same QP
            y_ref, psi_ref = float(inputs.y_ref_m[-1]), float(inputs.psi_ref_rad[-1])
            flat = replace(inputs, y_ref_m=np.full(N, y_ref), psi_ref_rad=np.full(N, psi_ref),
                           constraint_gain=np.zeros_like(inputs.constraint_gain),
                           constraint_bound=np.zeros_like(inputs.constraint_bound))
            t0 = time.perf_counter()
            u_kept = kept.solve(flat).steering_rate_rad_s
            t1 = time.perf_counter()
            # PythonRobotics style: a new CVXPY problem every step, solved through CVXPY
            rebuilt = LateralMpc(replace(ctrl, backend="cvxpy"), veh).solve(flat).steering_rate_rad_s
            t2 = time.perf_counter()
            x_ref = np.array([y_ref, 0.0, psi_ref, 0.0, 0.0])
            result = opt.solve_ocp(sys_d, np.arange(N + 1) * 0.1, flat.x0,
                                   opt.quadratic_cost(sys_d, Q, R, x0=x_ref), constraints,
                                   print_summary=False)
            t3 = time.perf_counter()
            rows.append({"section": "peers", "N": N, "step": k, "kept_cvxpy_s": t1 - t0,
                         "rebuild_cvxpy_s": t2 - t1, "python_control_s": t3 - t2,
                         "u0_kept": u_kept, "u0_rebuild": rebuilt,
                         "u0_python_control": float(np.asarray(result.inputs).ravel()[0]),
                         "python_control_success": bool(result.success)})
    return rows


def bench_kinematic(n_steps: int) -> list[dict]:
    """The kinematic LTV-QP step along a straight drive with a swaying reference."""
    from pipeline.loop.controller import KinematicLtvMpc

    cfg = compose_config(["controller=kinematic"])
    mpc = KinematicLtvMpc(cfg.controller, cfg.vehicle, 0.1)
    rows = []
    state = np.array([0.0, 0.0, 0.0, 2.0])
    empty = np.zeros((cfg.controller.horizon, 0, 2))
    for k in range(n_steps):
        reference = np.vstack([state[0] + 0.3 * np.arange(1, 11), 0.2 * np.sin(0.1 * k)
                               * np.ones(10)])
        t0 = time.perf_counter()
        step = mpc.solve(state, np.zeros(2), reference, empty, np.zeros(0))
        rows.append({"section": "kinematic", "N": 10, "step": k,
                     "kinematic_step_s": time.perf_counter() - t0,
                     "kinematic_compiles": mpc.compile_count, "status": step.status})
        state = state + np.array([0.3, 0.0, 0.0, 0.0])
    return rows
