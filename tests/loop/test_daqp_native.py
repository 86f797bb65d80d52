"""DAQP called through its C interface (pipeline/loop/controller/daqp_native.py) and the lateral
QPs of many members condensed and solved in one compiled call (daqp_rows.py), against the
oracles they replace: ``daqp.Model`` (DAQP's own Python interface) on a whole closed loop, and
:meth:`LateralMpc.solve` of each member alone, step by step: set-up, warm-started updates, a
new Hessian, data that are not finite, a failed solve's fallback."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.loop.controller import QpCache, daqp_native
from pipeline.loop.controller.lateral import LateralMpc
from pipeline.loop.controller.lateral_qp import MpcInputs
from pipeline.loop.controller.lateral_rows import _by_move_count, _daqp_steps, _direct_steps
from pipeline.loop.scenario import build_scenario
from pipeline.loop.simulate import simulate


def _run(cfg):
    result = simulate(cfg, build_scenario(cfg.scenario), QpCache())
    clock = [c for c in result.trajectory.columns if c.endswith("solve_time_s")]
    return result.trajectory.drop(columns=clock)


def test_native_workspace_gives_daqp_models_run(make_config, monkeypatch):
    """A whole paper-scenario run (a hundred warm-started solves) on the native workspace is
    the run through ``daqp.Model``, bit for bit; and the native one is what ran."""
    cfg = make_config(["method=improved", "controller.backend=daqp"])
    mpc = LateralMpc(cfg.controller, cfg.vehicle, cfg.model, cfg.scenario.sample_time_s)
    assert mpc.qp.native is not None
    native = _run(cfg)
    monkeypatch.setattr(daqp_native, "native_daqp_functions", lambda: None)
    assert LateralMpc(cfg.controller, cfg.vehicle, cfg.model,
                      cfg.scenario.sample_time_s).qp.native is None
    model = _run(cfg)
    assert list(native.columns) == list(model.columns)
    assert [c for c in model.columns if not native[c].equals(model[c])] == []
    assert (native["qp_iterations"] > 0).any() if "qp_iterations" in native else True


def test_another_daqp_release_is_refused_and_a_wrong_layout_caught(monkeypatch):
    """The offsets are DAQP 0.11's: another release gets daqp.Model; a workspace whose
    dimensions do not read back as set up is a one-line error before any solve."""
    functions = daqp_native.native_daqp_functions()
    assert functions is not None
    workspace = daqp_native.NativeDaqp(3, 2, 50, functions)
    workspace.H[:] = np.eye(3)
    workspace.upper[:], workspace.lower[:] = 1.0, -1.0
    workspace.A[:] = [[1.0, 1.0, 0.0], [0.0, 1.0, 1.0]]
    workspace.f[:] = [1.0, -2.0, 0.5]
    assert workspace.setup() >= 0
    workspace.check_layout()
    assert workspace.solve()[0] == 1
    np.testing.assert_allclose(workspace.x, [-1.0, 1.0, -0.5], atol=1e-12)
    workspace.workspace[daqp_native.WORK_N] += 1
    with pytest.raises(RuntimeError, match="not laid out as DAQP 0.11.0's"):
        workspace.check_layout()
    workspace.workspace[daqp_native.WORK_N] -= 1
    # never copied: a copy's problem would point into this workspace's buffer (daqp.Model
    # refuses the same)
    import copy
    import pickle

    for duplicate in (copy.deepcopy, copy.copy, pickle.dumps):
        with pytest.raises(TypeError, match="cannot be copied"):
            duplicate(workspace)
    daqp_native.native_daqp_functions.cache_clear()
    monkeypatch.setattr(daqp_native.metadata, "version", lambda name: "0.12.0")
    try:
        assert daqp_native.native_daqp_functions() is None
    finally:
        monkeypatch.undo()
        daqp_native.native_daqp_functions.cache_clear()
    assert daqp_native.native_daqp_functions() is not None


def _inputs(mpc: LateralMpc, rng: np.random.Generator, speed: float,
            bad_bound: bool = False, used: int = 2) -> MpcInputs:
    """One step's data with half-planes in the first ``used`` slots (0-3)."""
    N, M = mpc.horizon, mpc.cfg.max_obstacles
    gain, bound = np.zeros((N, M)), np.zeros((N, M))
    if used >= 1:
        gain[:, 0], bound[:, 0] = 1.0, rng.uniform(-0.5, 1.2, N)   # y >= h: an obstacle
    if used >= 2:
        gain[4:, 1], bound[4:, 1] = -1.0, rng.uniform(-2.0, -0.5, N - 4)
    if used >= 3:  # the third slot alone on its last steps (the second left empty there)
        gain[7:, 2], bound[7:, 2] = 1.0, rng.uniform(-0.2, 0.4, N - 7)
    if bad_bound:
        bound[3, 0] = np.nan
    disturbance = rng.normal(0.0, 0.02, N) if rng.random() < 0.5 else np.zeros(N)
    return MpcInputs(rng.normal(0.0, [0.4, 0.1, 0.08, 0.05, 0.03]),
                     mpc.models.at_speed(speed), rng.normal(0.0, 0.3, N),
                     rng.normal(0.0, 0.05, N), gain, bound, disturbance,
                     rng.normal(0.0, 0.02, N) if rng.random() < 0.5 else None,
                     rng.normal(0.0, 0.01, N) if rng.random() < 0.5 else None)


def _same(a, b) -> list[str]:
    found = []
    for name in ("command", "planned", "predicted_states"):
        x, y = getattr(a, name), getattr(b, name)
        if (x is None) != (y is None) or (x is not None and not np.array_equal(
                np.asarray(x, float), np.asarray(y, float), equal_nan=True)):
            found.append(name)
    found += [name for name in ("status", "iterations", "fallback")
              if getattr(a, name) != getattr(b, name)]
    if not np.array_equal(a.max_slack_m, b.max_slack_m, equal_nan=True):
        found.append("max_slack_m")
    return found


def test_members_solved_in_one_call_are_each_solved_alone(make_config):
    """Four members' QPs through the compiled call, step after step (set-up, warm starts, a
    speed change, a NaN bound, a tight steering limit that fails, another move count), each
    equal to the same member's LateralMpc.solve alone: the same plan, states, status, iterations, slack and
    fallback, bit for bit."""
    from pipeline.loop.compiled import COMPILED_KERNELS

    cfgs = [make_config(["method=improved", "controller.backend=daqp"]),
            make_config(["method=baseline", "controller.backend=daqp",
                         "controller.q_lateral=3.0"]),
            make_config(["method=improved", "controller.backend=daqp",
                         "vehicle.steering_max_rad=0.001", "controller.solver_max_iter=2"]),
            # another move count in the same batch (a tune's trials): a call of its own
            make_config(["method=improved", "controller.backend=daqp",
                         "controller.control_horizon=5"])]

    def controllers():
        return [LateralMpc(c.controller, c.vehicle, c.model, c.scenario.sample_time_s,
                           QpCache(compiled_kernels=True), COMPILED_KERNELS) for c in cfgs]

    alone, together = controllers(), controllers()
    rng = np.random.default_rng(7)
    statuses = set()
    for step in range(12):
        speeds = [3.0 if step < 6 else 2.5, 3.0, 4.0, 3.5]
        inputs = [_inputs(mpc, rng, speed, bad_bound=(step == 4 and i == 1))
                  for i, (mpc, speed) in enumerate(zip(alone, speeds, strict=True))]
        expected = [mpc.solve(x, {}) for mpc, x in zip(alone, inputs, strict=True)]
        got = _by_move_count(_daqp_steps, together, inputs, [{} for _ in inputs],
                             COMPILED_KERNELS)
        assert [_same(e, g) for e, g in zip(expected, got, strict=True)] == [[]] * len(cfgs)
        statuses |= {(e.status, e.fallback) for e in expected}
    assert ("optimal", "none") in statuses
    assert ("non_finite_data", "shifted_plan") in statuses
    assert any(status not in ("optimal", "non_finite_data") for status, _ in statuses)


def test_clarabel_members_in_two_calls_are_each_solved_alone(make_config):
    """The ``clarabel_direct`` members' QP data in one compiled call, each member's kept
    Clarabel solver on the statement of the slots it uses, the read-out in another call: step
    after step (0 to 3 slots used, a speed change, a NaN bound, a tight steering limit that
    fails, another move count), each equal to the same member's LateralMpc.solve alone, bit for
    bit; and the statements solved are those of the slots used."""
    from pipeline.loop.compiled import COMPILED_KERNELS

    cfgs = [make_config(["method=improved"]),
            make_config(["method=baseline", "controller.q_lateral=3.0"]),
            make_config(["method=improved", "vehicle.steering_max_rad=0.001",
                         "controller.solver_max_iter=2"]),
            make_config(["method=improved", "controller.control_horizon=5"])]

    def controllers():
        return [LateralMpc(c.controller, c.vehicle, c.model, c.scenario.sample_time_s,
                           QpCache(compiled_kernels=True), COMPILED_KERNELS) for c in cfgs]

    alone, together = controllers(), controllers()
    sizes = []
    for mpc in together:
        for slots, qp in mpc.qp_by_slots.items():
            solve = qp.compiled.solve

            def counted(theta, solve=solve, slots=slots):
                sizes.append(slots)
                return solve(theta)

            qp.compiled.solve = counted
    rng = np.random.default_rng(11)
    statuses = set()
    for step in range(16):
        speeds = [3.0 if step < 8 else 2.5, 3.0, 4.0, 3.5]
        used = [(step + i) % 4 for i in range(len(cfgs))]
        inputs = [_inputs(mpc, rng, speed, bad_bound=(step == 5 and i == 1), used=used[i])
                  for i, (mpc, speed) in enumerate(zip(alone, speeds, strict=True))]
        expected = [mpc.solve(x, {}) for mpc, x in zip(alone, inputs, strict=True)]
        sizes.clear()
        got = _by_move_count(_direct_steps, together, inputs, [{} for _ in inputs],
                             COMPILED_KERNELS)
        assert [_same(e, g) for e, g in zip(expected, got, strict=True)] == [[]] * len(cfgs)
        assert sorted(sizes) == sorted(u for i, u in enumerate(used)
                                       if not (step == 5 and i == 1))
        statuses |= {(e.status, e.fallback) for e in expected}
    assert ("optimal", "none") in statuses
    assert ("non_finite_data", "shifted_plan") in statuses
    assert any(status not in ("optimal", "non_finite_data") for status, _ in statuses)
