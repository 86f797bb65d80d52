"""The fast paths against their references: the scalar APF rollout against the vectorized
``apf_step``, the scalar RK4 plants against the numpy derivatives and SciPy's ``solve_ivp`` (and
a circle in closed form), the affine parameter-to-data map against CVXPY's own
``apply_parameters`` and against the CVXPY backend, and one compilation per family."""

from __future__ import annotations

import json

import cvxpy as cp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pipeline.loop.controller import KinematicLtvMpc, LateralMpc, QpCache
from pipeline.loop.controller.lateral_qp import LateralQpStructure, build_condensed_lateral_problem
from pipeline.loop.controller.qp import compile_affine_map
from pipeline.loop.model import (
    kinematic_derivative,
    kinematic_plant_step,
    plant_derivative,
    step_plant,
)
from pipeline.loop.planner import apf_rollout, apf_step
from pipeline.loop.scenario import ObstacleSnapshot


def reference_rollout(position, goal, snap, params, horizon, ts, velocity):
    """The rollout written with the vectorized ``apf_step`` (the statement of the equations)."""
    path = [np.asarray(position, float)]
    for t in range(horizon - 1):
        obs = snap.positions_m + (t * ts * snap.velocities_mps
                                  if params.obstacle_prediction == "constant_velocity" else 0.0)
        closing = None
        if velocity is not None and obs.shape[0]:
            los = obs - path[-1]
            dist = np.maximum(np.linalg.norm(los, axis=1), 1e-12)
            closing = np.sum((velocity - snap.velocities_mps) * los, axis=1) / dist
        path.append(apf_step(path[-1], goal, obs, params, closing)[0])
    return np.array(path)


@pytest.mark.parametrize("planner", ["baseline", "improved", "velocity_aware"])
@pytest.mark.parametrize("obstacles", [[], [[12.0, 1.0]], [[12.0, 1.0], [13.0, -1.0], [10.0, 0.3]]])
def test_scalar_rollout_equals_vectorized_apf_step(make_config, planner, obstacles):
    params = make_config([f"planner={planner}"]).planner
    positions = np.array(obstacles, float).reshape(-1, 2)
    n = positions.shape[0]
    snap = ObstacleSnapshot(positions, np.tile([[0.1, -0.4]], (n, 1)), np.full(n, 0.5),
                            np.ones(n, bool))
    start, goal, velocity = np.array([10.0, 0.3]), np.array([30.0, 0.0]), np.array([3.0, 0.1])
    fast = apf_rollout(start, goal, snap, params, 10, 0.1, velocity)
    slow = reference_rollout(start, goal, snap, params, 10, 0.1, velocity)
    np.testing.assert_allclose(fast.path_m, slow, rtol=0, atol=1e-12)
    assert fast.path_m.shape == (10, 2) and fast.step_cap_active.shape == (9,)


def rk4_reference(derivative, state, dt, substeps):
    h = dt / substeps
    x = np.asarray(state, float)
    for _ in range(substeps):
        k1 = derivative(x)
        k2 = derivative(x + 0.5 * h * k1)
        k3 = derivative(x + 0.5 * h * k2)
        k4 = derivative(x + h * k3)
        x = x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


@pytest.mark.parametrize("rate", [0.0, 0.3, -1.0])
def test_scalar_single_track_step_equals_numpy_rk4_and_solve_ivp(make_config, rate):
    vehicle = make_config().vehicle
    state = np.array([5.0, 0.1, 0.05, 2.8, 0.05, 0.1, 0.05])
    fast = step_plant(state, rate, 3.0, vehicle, 0.1, 10)
    slow = rk4_reference(lambda x: plant_derivative(x, rate, 3.0, vehicle), state, 0.1, 10)
    np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-13)
    exact = solve_ivp(lambda _, x: plant_derivative(x, rate, 3.0, vehicle), (0.0, 0.1), state,
                      rtol=1e-11, atol=1e-12).y[:, -1]
    # RK4's truncation error at h = 0.01 s on the stiff tyre modes, and its fourth order
    error_10 = np.max(np.abs(fast - exact))
    error_20 = np.max(np.abs(step_plant(state, rate, 3.0, vehicle, 0.1, 20) - exact))
    assert error_10 < 1e-5 and error_20 < error_10 / 10.0


def test_kinematic_plant_follows_the_closed_form_circle():
    """Constant speed and steering: a circle of radius L / tan(delta), exactly."""
    L, v, delta, T = 2.5, 2.0, 0.2, 0.1
    state = np.array([0.0, 0.0, 0.3, v])
    for _ in range(30):
        state = kinematic_plant_step(state, np.array([0.0, delta]), L, T, 5)
    omega = v * np.tan(delta) / L
    radius = L / np.tan(delta)
    theta = 0.3 + omega * 3.0
    expected = np.array([radius * (np.sin(theta) - np.sin(0.3)),
                         -radius * (np.cos(theta) - np.cos(0.3)), theta, v])
    np.testing.assert_allclose(state, expected, atol=1e-9)
    ref = rk4_reference(lambda x: kinematic_derivative(x, np.array([0.5, 0.1]), L),
                        np.array([1.0, 2.0, 0.1, 1.0]), 0.1, 7)
    np.testing.assert_allclose(kinematic_plant_step(np.array([1.0, 2.0, 0.1, 1.0]),
                                                    np.array([0.5, 0.1]), L, 0.1, 7), ref,
                               atol=1e-14)


@pytest.mark.parametrize("overrides", [[], ["controller.horizon=5", "controller.max_obstacles=2",
                                            "controller.input_hold=zero_rate"]])
def test_affine_map_equals_cvxpy_apply_parameters(make_config, overrides):
    cfg = make_config(overrides)
    problem, params, variables = build_condensed_lateral_problem(
        LateralQpStructure.of(cfg.controller, cfg.vehicle))
    qp_map = compile_affine_map(problem, params, variables)
    prog = problem.get_problem_data(cp.CLARABEL)[0]["param_prob"]
    rng = np.random.default_rng(3)
    for _ in range(3):
        values = {p.id: rng.standard_normal(p.shape) for p in params}
        theta = np.concatenate([values[p.id].ravel(order="F") for p in params])
        P, q, _, A, b = prog.apply_parameters(values, keep_zeros=True, quad_obj=True)
        q_map, a_map, b_map = qp_map.data(theta)
        np.testing.assert_allclose(q_map, q, atol=1e-12)
        np.testing.assert_allclose(b_map, b, atol=1e-12)
        np.testing.assert_allclose(qp_map.matrix_A(a_map).toarray(), -A.toarray(), atol=1e-12)


def test_kinematic_backends_agree(make_config):
    cfg = make_config(["controller=kinematic"])
    x0, u_prev = np.array([0.0, 0.0, 0.1, 2.0]), np.array([0.5, 0.05])
    k = np.arange(1, cfg.controller.horizon + 1)
    reference = np.vstack([0.3 * k, 0.02 * k**2])
    obstacles = np.tile(np.array([[[2.0, 0.6]]]), (cfg.controller.horizon, 1, 1))
    steps = {}
    for backend in ("cvxpy", "clarabel_direct"):
        ctrl = make_config(["controller=kinematic", f"controller.backend={backend}"]).controller
        steps[backend] = KinematicLtvMpc(ctrl, cfg.vehicle, 0.1).solve(
            x0, u_prev, reference, obstacles, np.array([0.4]), passes=3)
    np.testing.assert_allclose(steps["cvxpy"].planned, steps["clarabel_direct"].planned,
                               atol=1e-7)
    assert steps["cvxpy"].max_slack_m == pytest.approx(steps["clarabel_direct"].max_slack_m,
                                                       abs=1e-7)


def test_a_kinematic_family_among_walkers_compiles_every_slot_size_once_in_the_parent(
        make_config, tmp_path):
    """The kinematic MPC with 50 slots solves the smallest of 4, 8, 16, 32 and 50 that holds
    the slots a step uses: all five statements compiled in the family's parent, none in its
    workers (each chunk compiled them again before: 54 compilations for 200 members)."""
    from pipeline.loop.controller import KinematicLtvMpc
    from pipeline.studies.experiment import run_family

    cfg = make_config(["experiment=pedestrians", "planner=improved", "scenario.family.size=6",
                       "scenario.family.n_jobs=2", "scenario.n_steps=60"])
    cache = QpCache()
    table = run_family(cfg, tmp_path / "fam", progress=False, qp_cache=cache)
    timing = json.loads((tmp_path / "fam" / "timing.json").read_text())
    assert timing["compiles"] == cache.compile_count == 5
    assert table["compile_count"].sum() == 0
    assert KinematicLtvMpc(cfg.controller, cfg.vehicle, 0.1, qp_cache=cache).compile_count == 0


def test_unused_obstacle_slots_do_not_change_the_solution(make_config):
    """One compiled problem serves 1-3 obstacles: a run with one obstacle on a 3-slot problem
    equals the same run on a 1-slot problem."""
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate

    runs = {}
    for slots in (1, 3):
        cfg = make_config(["method=improved", f"controller.max_obstacles={slots}"])
        runs[slots] = simulate(cfg, build_scenario(cfg.scenario)).trajectory
    # equal to the interior-point tolerance (the idle slots change Clarabel's iterates only)
    np.testing.assert_allclose(runs[1]["steering_rate_rad_s"].fillna(0),
                               runs[3]["steering_rate_rad_s"].fillna(0), rtol=0, atol=1e-6)
    np.testing.assert_allclose(runs[1]["Y_m"], runs[3]["Y_m"], rtol=0, atol=1e-6)


def test_family_compiles_once_on_two_workers(make_config, tmp_path):
    from pipeline.studies.experiment import run_family

    cfg = make_config(["method=improved", "scenario=family", "scenario.family.size=6",
                       "scenario.family.n_jobs=2"])
    cache = QpCache()
    table = run_family(cfg, tmp_path / "fam", progress=False, qp_cache=cache)
    # compilations depend on the process: in the family's timing.json, not family.json
    timing = json.loads((tmp_path / "fam" / "timing.json").read_text())
    # one statement per number of obstacle slots (0 to max_obstacles), all in the parent
    statements = cfg.controller.max_obstacles + 1
    assert timing["compiles"] == statements and cache.compile_count == statements
    assert "compiles" not in json.loads((tmp_path / "fam" / "family.json").read_text())
    assert table["compile_count"].sum() == 0  # every member reused the parent's compilation
    # the same structure in this process again: nothing to compile
    assert LateralMpc(cfg.controller, cfg.vehicle, qp_cache=cache).compile_count == 0


def test_a_family_chunk_freezes_what_outlives_it_and_still_collects_its_own_cycles(
        make_config, tmp_path):
    """A worker's chunk moves what is alive when it starts (imports, kernels) out of the
    collector's scans, so loky's gc.collect() after each task stays cheap; cycles made by the
    chunk's own runs are still found by that collection."""
    import dataclasses
    import gc
    import weakref

    from pipeline.loop.scenario import family_members
    from pipeline.studies.experiment import _run_chunk

    cfg = make_config(["method=improved", "scenario=family", "scenario.family.size=1"])

    member = dataclasses.replace(cfg, scenario=family_members(cfg.scenario, 0.5)[0])
    gc.unfreeze()
    try:
        rows = _run_chunk([(0, member, tmp_path / "m0")], QpCache())
        assert gc.get_freeze_count() > 1000 and rows[0][0] == 0
        class Node:
            pass

        node = Node()
        node.self = node  # a cycle made after the freeze: only the collector frees it
        probe = weakref.ref(node)
        del node
        gc.collect()
        assert probe() is None
    finally:
        gc.unfreeze()


@pytest.mark.parametrize("frame", ["fixed", "path"])
def test_a_family_discretizes_each_model_once(tmp_path, make_config, monkeypatch, frame):
    """python-control's c2d runs once per (vehicle, speed, sample time) for a whole family, not
    once per member: 6 members at one speed build the nominal model and the controller's model
    once each (12 calls before the models were shared through the QpCache). In the path
    frame the controller's model follows the predicted speed (3.0-3.2 m/s on the speed grid
    here: the plant's forward speed grows in turns), each speed built once."""
    import pipeline.loop.model as model_module
    import pipeline.studies.experiment as experiment_module
    from pipeline.studies.experiment import run_family

    calls = []
    original = model_module.build_lateral_model

    def counting(*args, **kwargs):
        calls.append(args[1])
        return original(*args, **kwargs)

    monkeypatch.setattr(model_module, "build_lateral_model", counting)
    monkeypatch.setattr(experiment_module, "build_lateral_model", counting)
    run_family(make_config(["method=improved", "scenario=family", "scenario.family.size=6",
                            "scenario.family.n_jobs=1", f"controller.frame={frame}"]),
               tmp_path / "family", progress=False)
    assert calls.count(3.0) == 2  # the nominal model (model.json) and the controller's
    assert len(calls) == len(set(calls)) + 1
    assert len(calls) == 2 if frame == "fixed" else len(calls) > 2


def test_trajectory_csv_writer_matches_pandas(make_config):
    """The store's CSV writer gives pandas' ``to_csv(float_format="%.10g")`` byte for byte (the
    oracle: pandas itself) on a real trajectory, on missing values of every kind, and falls back
    to pandas where a cell needs quoting."""
    import pandas as pd

    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate
    from pipeline.store.files import csv_text

    def pandas_csv(frame):
        return frame.to_csv(index=False, float_format="%.10g", lineterminator="\n")

    cfg = make_config(["method=improved"])
    trajectory = simulate(cfg, build_scenario(cfg.scenario)).trajectory
    assert csv_text(trajectory) == pandas_csv(trajectory)
    odd = pd.DataFrame({"x": [1.0, np.nan, -0.0, 1e-12, np.inf, 123456789012.5],
                        "flag": [True, False, True, False, True, False],
                        "n": np.arange(6), "word": ["a", None, np.nan, "optimal", True, "b"]})
    assert csv_text(odd) == pandas_csv(odd)
    quoted = odd.assign(word=["a,b", 'say "x"', "", "c", "d", "e"])
    assert csv_text(quoted) == pandas_csv(quoted)


def test_closed_loop_runs_blas_on_one_thread(make_config, monkeypatch):
    """simulate limits BLAS to one thread for the loop (OpenBLAS's idle threads spin and double
    a run's CPU time); checked from inside a step with threadpoolctl's own report."""
    from threadpoolctl import threadpool_info

    import pipeline.loop.planner as planner_module
    import pipeline.loop.simulate as simulate_module
    from pipeline.loop.scenario import build_scenario

    seen = []
    original = planner_module._rollout  # what every APF rollout of a step goes through

    def spy(*args, **kwargs):
        seen.extend(pool["num_threads"] for pool in threadpool_info()
                    if pool["user_api"] == "blas")
        return original(*args, **kwargs)

    monkeypatch.setattr(planner_module, "_rollout", spy)
    cfg = make_config(["method=improved", "scenario.n_steps=5"])
    simulate_module.simulate(cfg, build_scenario(cfg.scenario))
    assert seen and set(seen) == {1}


def _lateral_reference_numpy(path_line_m, stations_m, controller):
    """The vectorized statement of :func:`lateral_reference` (np.interp, np.searchsorted): the
    oracle of its plain-float version."""
    from math import tan

    # the points that advance in x by more than 1e-9 m past the last one kept
    xs, ys = [path_line_m[0, 0]], [path_line_m[0, 1]]
    for x, y in path_line_m[1:].tolist():
        if x > xs[-1] + 1e-9:
            xs.append(x)
            ys.append(y)
    if len(xs) < 2:
        return np.full(stations_m.shape, path_line_m[-1, 1]), np.zeros(stations_m.shape)
    xs_a, ys_a = np.array(xs), np.array(ys)
    max_slope = tan(controller.heading_ref_max_rad)
    seg_slopes = np.clip((ys_a[1:] - ys_a[:-1]) / (xs_a[1:] - xs_a[:-1]), -max_slope, max_slope)
    end_slope = seg_slopes[-1] if controller.path_beyond_end == "extend" else 0.0
    y_ref = np.interp(stations_m, xs_a, ys_a)
    beyond = stations_m > xs[-1]
    y_ref[beyond] = ys[-1] + end_slope * (stations_m[beyond] - xs[-1])
    idx = np.clip(np.searchsorted(xs_a, stations_m, side="right") - 1, 0, seg_slopes.size - 1)
    return y_ref, np.arctan(np.where(beyond, end_slope, seg_slopes[idx]))


@pytest.mark.parametrize("beyond", ["extend", "hold"])
def test_plain_float_lateral_reference_equals_np_interp(make_config, beyond):
    """Random APF paths (some points not advancing, steep segments past the heading bound) and
    stations before the path, on its knots, between them and past its end: the plain-float
    reference equals the np.interp statement exactly."""
    import dataclasses

    from pipeline.loop.controller import lateral_reference

    ctrl = dataclasses.replace(make_config().controller, path_beyond_end=beyond)
    rng = np.random.default_rng(3)
    for trial in range(300):
        n = int(rng.integers(1, 12))
        steps = rng.choice([0.0, 0.05, 0.3], size=n) * rng.uniform(0.5, 1.5, n)
        path = np.column_stack([rng.uniform(-1, 1) + np.cumsum(steps),
                                rng.normal(0, 1.5, n) if trial % 3 else np.full(n, 0.2)])
        stations = np.sort(np.concatenate([rng.uniform(path[0, 0] - 0.5, path[-1, 0] + 1.0, 8),
                                           path[rng.integers(0, n, 2), 0]]))
        got = lateral_reference(path, stations, ctrl)
        want = _lateral_reference_numpy(path, stations, ctrl)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])


def test_the_kept_blas_limit_covers_every_blas_the_loop_has_loaded():
    """simulate() keeps threadpoolctl's controller for the process (a library scan per run cost
    ~2 ms), also across caches unpickled in a worker (each task's cache arrives with an empty
    process-local part: the scan was rebuilt for every task); once a run has loaded what the loop needs (scipy.linalg's BLAS among them, imported
    only when a prediction is first built), the next run's limit covers every BLAS library
    loaded in the process, as a fresh scan would. In a fresh interpreter, where nothing else
    has loaded those libraries first."""
    import subprocess
    import sys

    code = """
from threadpoolctl import threadpool_info
from hydra import compose, initialize_config_dir
from pipeline.config import CONF_DIR, register_configs, to_experiment_config
from pipeline.loop.controller import QpCache
from pipeline.loop.scenario import build_scenario
from pipeline.loop.simulate import simulate
register_configs()
with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
    cfg = to_experiment_config(compose(config_name="config", overrides=["method=improved",
                                                                        "controller.backend=daqp"]))
import pickle
import sys
from pipeline.loop import engine
cache = QpCache()
for _ in range(3):  # the first run imports what builds a prediction: a new scan after it
    simulate(cfg, build_scenario(cfg.scenario), cache)
    cache = pickle.loads(pickle.dumps(cache))  # as a worker's next task receives it
info = engine._threadpool_controller.cache_info()
kept = {c.filepath for c in engine._threadpool_controller(len(sys.modules)).lib_controllers}
blas = {i["filepath"] for i in threadpool_info() if i["user_api"] == "blas"}
print(len(blas), info.hits, sorted(blas - kept))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert int(out[0]) >= 2 and int(out[1]) >= 1 and out[2:] == ["[]"]


def test_line_frame_at_heading_zero_gives_the_rotations_values():
    """The heading-0 shortcut of ``to_line`` and ``vectors_to_line`` against the rotation
    written out (cos 0 = 1, sin 0 = 0), and a turned frame still rotated."""
    from pipeline.loop.scenario import LineFrame

    rng = np.random.default_rng(5)
    points = rng.normal(0.0, 20.0, (10, 3, 2))
    origin = np.array([1.5, -2.0])
    frame = LineFrame(origin, 0.0)
    d = points - origin
    rotated = np.stack([1.0 * d[..., 0] + 0.0 * d[..., 1], -0.0 * d[..., 0] + 1.0 * d[..., 1]],
                       axis=-1)
    assert np.array_equal(frame.to_line(points), rotated)
    assert np.array_equal(frame.vectors_to_line(points[0]), points[0])
    turned = LineFrame(origin, 0.3)
    c, s = np.cos(0.3), np.sin(0.3)
    np.testing.assert_array_equal(turned.to_line(points)[..., 1],
                                  -s * d[..., 0] + c * d[..., 1])
    back = turned.to_global(turned.to_line(points))
    np.testing.assert_allclose(back, points, atol=1e-12)


def test_config_yaml_from_kept_sections_is_the_whole_dump(make_config):
    """Family members share every section but the scenario: the YAML put together from the
    sections kept in the memo is the dump of the whole configuration, byte for byte (a member
    of a different family, a kinematic run and a changed section included)."""
    import dataclasses

    from pipeline.loop.scenario import family_members
    from pipeline.studies.experiment import config_yaml

    memo: dict = {}
    seen = 0
    for overrides in (["method=baseline", "scenario=family", "scenario.family.size=5"],
                      ["method=improved", "scenario=family", "scenario.family.size=3",
                       "controller.backend=daqp"], ["experiment=kinematic"]):
        cfg = make_config(overrides)
        configs = [cfg]
        if cfg.scenario.family is not None:
            configs += [dataclasses.replace(cfg, scenario=m) for m in
                        family_members(cfg.scenario, cfg.vehicle.footprint_radius_m)]
        configs.append(dataclasses.replace(cfg, planner=dataclasses.replace(cfg.planner,
                                                                           beta=0.123)))
        for c in configs:
            whole = config_yaml(c)
            assert config_yaml(c, memo) == whole and config_yaml(c, memo) == whole
            seen += 1
    assert seen == 14 and "beta: 0.123" in whole


def test_a_workers_next_cache_finds_the_models_its_last_task_built(make_config):
    """A worker's tasks each receive the QP cache anew (unpickled): the tables of values that
    are pure functions of their key (the lateral models by speed, their condensed predictions)
    are the process's, so the next task's cache holds the same model objects the last task
    built, and a member run on it gives the same log bit for bit as on a fresh cache. A cache
    made here (not unpickled) keeps its own tables."""
    import pickle

    from pipeline.loop.controller import QpCache
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate

    cfg = make_config(["method=improved", "controller.backend=daqp",
                       "scenario.speed_mps=7.25"])  # a speed no other test's tables hold
    parent = QpCache()
    parent.memo(("a pure table", 1), dict)  # the parent's tables travel empty
    first, second = (pickle.loads(pickle.dumps(parent)) for _ in range(2))
    run_first = simulate(cfg, build_scenario(cfg.scenario), first)
    models = {k: v for k, v in first.memos.items() if k[0] == "lateral_models"}
    assert models and all(v for v in models.values())
    run_second = simulate(cfg, build_scenario(cfg.scenario), second)
    for key, table in models.items():
        assert second.memos[key] is table  # the same table, the same model objects
    first.memos[("a pure table", 1)]["x"] = 1
    assert second.memos[("a pure table", 1)] == {"x": 1}
    alone = simulate(cfg, build_scenario(cfg.scenario), QpCache())
    for run in (run_first, run_second):
        for name in ("X_m", "Y_m", "steering_rate_rad_s", "solver_iterations"):
            np.testing.assert_array_equal(run.trajectory[name].to_numpy(),
                                          alone.trajectory[name].to_numpy())
    own = QpCache()
    assert own.memo(("a pure table", 1), dict) == {}  # not the process's
