"""The lockstep engine against the per-member loop it replaced (tests/loop/oracle_loop.py):
members stepped together give each member's run alone, bit for bit, on every backend and
track; a member that ends early leaves the batch without touching the others' numbers; a
plug-in steps in the same batch as the built-ins; the batched plant is the plant row by row;
a family chunk through the engine writes what one member at a time wrote."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pipeline.loop.controller import QpCache
from pipeline.loop.engine import MemberLoop, simulate_members, step_members
from pipeline.loop.scenario import build_scenario, family_members
from tests.loop.oracle_loop import oracle_simulate

ROOT = Path(__file__).resolve().parents[2]


def _members(make_config, overrides, size):
    cfg = make_config([*overrides, "scenario=family", f"scenario.family.size={size}"])
    members = family_members(cfg.scenario, cfg.vehicle.footprint_radius_m)
    return [(replace(cfg, scenario=member), build_scenario(member)) for member in members]


def _differences(engine, oracle, atol: float = 0.0) -> list[str]:
    """What differs between two runs (empty: the same run): bit for bit, or within ``atol`` in
    every number (the cvxpy backend, whose compiled problems are shared by all members: its
    solves differ from one order of calls to another by solver noise, about 1e-22 on values
    that are 0, up to 3e-11 rad/s in a steering rate since each step solves the statement of
    the obstacle slots it uses)."""
    found = []
    if (engine.termination, engine.goal_reached) != (oracle.termination, oracle.goal_reached):
        found.append(f"ending {engine.termination} vs {oracle.termination}")
    # wall-clock columns (the CBF filter's solve time) are not part of the run
    clock = [name for name in oracle.trajectory.columns if name.endswith("solve_time_s")]
    ours, theirs = engine.trajectory.drop(columns=clock), oracle.trajectory.drop(columns=clock)
    if list(ours.columns) != list(theirs.columns) or len(ours) != len(theirs):
        return [*found, "columns or rows"]
    for name in theirs.columns:
        a, b = ours[name], theirs[name]
        same = np.allclose(a, b, rtol=0.0, atol=atol, equal_nan=True) \
            if b.dtype.kind == "f" and atol > 0.0 else a.equals(b)
        if not same:
            found.append(name)
    if engine.horizon.keys() != oracle.horizon.keys():
        return [*found, "horizon keys"]
    found += [f"horizon {name}" for name, values in oracle.horizon.items()
              if not np.allclose(engine.horizon[name], values, rtol=0.0, atol=atol,
                                 equal_nan=True)]
    return found


COMPILED_CASES = [
    ["method=improved", "controller.backend=daqp"],
    ["method=improved"],                                   # clarabel_direct
    ["method=baseline", "controller.backend=cvxpy"],
    ["method=improved", "controller.frame=fixed"],
    ["method=improved", "controller.path_reference=pursuit"],
    ["method=mpc_dcbf"],
    ["method=cbf_filter"],
    ["method=apf_pursuit"],
]
#: CPython's kernels (a single run's): every member steps alone in the engine's step
PYTHON_CASES = [["method=improved", "controller.backend=daqp"], ["method=cbf_filter"]]


@pytest.mark.parametrize(("overrides", "compiled"),
                         [(case, True) for case in COMPILED_CASES]
                         + [(case, False) for case in PYTHON_CASES])
def test_members_stepped_together_are_each_member_alone(make_config, overrides, compiled):
    """Four members of a family stepped in one batch (each with its own controller, solver
    workspace and fallback) against each run alone through the oracle loop: the same
    trajectories, horizons and terminations, bit for bit (members leaving the batch early:
    test_a_member_that_ends_early_leaves_the_others_untouched)."""
    runs = _members(make_config, overrides, 4)
    cache = QpCache(compiled_kernels=compiled)
    together = simulate_members(runs, cache)
    for (cfg, scenario), engine in zip(runs, together, strict=True):
        oracle = oracle_simulate(cfg, scenario, QpCache(compiled_kernels=compiled))
        atol = 1e-9 if getattr(cfg.controller, "backend", "") == "cvxpy" else 0.0
        assert _differences(engine, oracle, atol) == []


def test_kinematic_members_stepped_together_are_each_alone(make_config):
    runs = _members(make_config, ["method=improved", "controller=kinematic",
                                  "scenario.n_steps=60"], 3)
    together = simulate_members(runs, QpCache(compiled_kernels=True))
    for (cfg, scenario), engine in zip(runs, together, strict=True):
        alone = oracle_simulate(cfg, scenario, QpCache(compiled_kernels=True))
        assert _differences(engine, alone) == []


def test_members_of_different_settings_in_one_batch(make_config):
    """A tune's batch: members of several trials (other weights, another method, another
    backend) stepped together, each the run of its own settings."""
    runs = (_members(make_config, ["method=improved", "controller.backend=daqp"], 2)
            + _members(make_config, ["method=baseline", "controller.q_lateral=3.0"], 2)
            + _members(make_config, ["method=improved", "vehicle.steering_rate_max_rad_s=0.3"],
                       2))
    together = simulate_members(runs, QpCache(compiled_kernels=True))
    for (cfg, scenario), engine in zip(runs, together, strict=True):
        alone = oracle_simulate(cfg, scenario, QpCache(compiled_kernels=True))
        assert _differences(engine, alone) == []


def test_a_member_that_ends_early_leaves_the_others_untouched(make_config):
    """One member whose run ends at its fifth step (n_steps=4) in a batch with two full ones:
    the two are the same bits as without it, and it is its own run alone."""
    runs = _members(make_config, ["method=improved", "controller.backend=daqp"], 3)
    short_cfg = replace(runs[1][0], scenario=replace(runs[1][0].scenario, n_steps=4))
    short = (short_cfg, build_scenario(short_cfg.scenario))
    cache = QpCache(compiled_kernels=True)
    with_short = simulate_members([runs[0], short, runs[2]], cache)
    without = simulate_members([runs[0], runs[2]], QpCache(compiled_kernels=True))
    assert len(with_short[1].trajectory) == 5 and with_short[1].termination == "max_steps"
    assert len(with_short[0].trajectory) > 5
    assert _differences(with_short[0], with_short[2])  # two members differ: it can fail
    assert _differences(with_short[0], without[0]) == []
    assert _differences(with_short[2], without[1]) == []
    alone = oracle_simulate(*short, QpCache(compiled_kernels=True))
    assert _differences(with_short[1], alone) == []


def test_a_plugin_steps_in_the_batch_as_alone(make_config, monkeypatch):
    """A planner of one's own (``planner._target_``: the README's example, behind the plug-in
    checks) and a controller of one's own (the CBF filter is one, by ``controller._target_``)
    beside built-in members in one batch: each run is its run alone."""
    monkeypatch.syspath_prepend(str(ROOT / "examples" / "my_planner"))
    runs = (_members(make_config, ["method=improved", "planner._target_=my_planner.SideStepPlanner",
                                   "+planner.params={reach_m: 8.0, offset_m: 2.0}"], 2)
            + _members(make_config, ["method=cbf_filter"], 2)
            + _members(make_config, ["method=improved", "controller.backend=daqp"], 2))
    assert runs[0][0].planner._target_ and runs[2][0].controller._target_
    together = simulate_members(runs, QpCache(compiled_kernels=True))
    for (cfg, scenario), engine in zip(runs, together, strict=True):
        alone = oracle_simulate(cfg, scenario, QpCache(compiled_kernels=True))
        assert _differences(engine, alone) == []


def test_batched_plant_is_the_plant_row_by_row(make_config):
    """:func:`single_track_rk4_rows` (one compiled call) against the compiled and the CPython
    single-row step, bit for bit, each row with its own constants, rate, target, period and
    substeps."""
    from pipeline.loop.compiled import COMPILED_KERNELS
    from pipeline.loop.model import single_track_constants
    from pipeline.loop.python_kernels import PYTHON_KERNELS

    rng = np.random.default_rng(3)
    vehicles = [make_config().vehicle,
                make_config(["vehicle.mass_kg=2100", "vehicle.kinematic_below_mps=2.0"]).vehicle]
    n = 40
    states = np.column_stack([rng.normal(0, 20, n), rng.normal(0, 3, n), rng.normal(0, .5, n),
                              rng.uniform(0.0, 25.0, n), rng.normal(0, .8, n),
                              rng.normal(0, .5, n), rng.normal(0, .3, n)])
    constants = np.array([single_track_constants(vehicles[i % 2]) for i in range(n)])
    rates, targets = rng.normal(0, .4, n), rng.uniform(0, 25, n)
    periods = np.where(np.arange(n) % 3 == 0, 0.05, 0.1)
    substeps = rng.integers(1, 8, n)
    batch = COMPILED_KERNELS.plant_rk4_rows(states, constants, rates, targets, periods, substeps)
    python = PYTHON_KERNELS.plant_rk4_rows(states, constants, rates, targets, periods, substeps)
    for i in range(n):
        one = COMPILED_KERNELS.plant_rk4(states[i], constants[i], float(rates[i]),
                                         float(targets[i]), float(periods[i]), int(substeps[i]))
        plain = PYTHON_KERNELS.plant_rk4(states[i].tolist(), constants[i].tolist(),
                                         float(rates[i]), float(targets[i]), float(periods[i]),
                                         int(substeps[i]))
        assert np.array_equal(batch[i], one) and np.array_equal(python[i], plain)
        assert np.array_equal(one, plain)


def test_engine_steps_every_member_once_per_step(make_config):
    """The lockstep: at step k every member still running is observed and controlled once,
    a member that has ended is never called again, and the plants of the compiled members
    are stepped in one call per step (members outside the engine's groups, whose own loops
    it steps: velocity planning on)."""
    runs = _members(make_config, ["method=improved", "controller.backend=daqp",
                                  "planner.velocity_planning=true"], 4)
    cache = QpCache(compiled_kernels=True)
    from pipeline.loop.engine import run_kernels

    kernels = run_kernels(cache)
    calls = {"rows": []}

    def rows(states, *args):
        calls["rows"].append(states.shape[0])
        return kernels.plant_rk4_rows(states, *args)

    members = [MemberLoop(cfg, scenario, cache, kernels._replace(plant_rk4_rows=rows))
               for cfg, scenario in runs]
    results = step_members(members)
    lengths = [len(r.trajectory) for r in results]
    # rows stepped at step k: the members whose log goes past row k
    expected = [sum(length > k + 1 for length in lengths) for k in range(max(lengths) - 1)]
    assert calls["rows"] == [e for e in expected if e]


def test_default_lateral_mpcs_share_one_path_frame_call_per_step(make_config):
    """The members whose controller is the default statement have their path frames computed
    in one compiled call per step (and their plans' poses in another, their DAQP QPs in a
    third), the others (the fixed frame here) step alone: every member's run is still its run
    alone. (Members outside the engine's groups, pipeline/loop/lateral_group.py, whose own
    loops it steps: velocity planning on.)"""
    runs = _members(make_config, ["method=improved", "controller.backend=daqp",
                                  "planner.velocity_planning=true"], 3) \
        + _members(make_config, ["method=baseline", "controller.frame=fixed"], 2)
    cache = QpCache(compiled_kernels=True)
    from pipeline.loop.engine import run_kernels

    kernels = run_kernels(cache)
    rows = []

    def path_frame_rows(targets, *args):
        rows.append(targets.shape[0])
        return kernels.path_frame_rows(targets, *args)

    solved = []

    def daqp_rows(functions, workspaces, *args):
        solved.append(workspaces.shape[0])
        return kernels.daqp_rows(functions, workspaces, *args)

    counted = kernels._replace(path_frame_rows=path_frame_rows, daqp_rows=daqp_rows)
    together = simulate_members(runs, cache, counted)
    lengths = [len(result.trajectory) for result in together[:3]]
    # one call per step while two or more default members run (a lone one steps alone); their
    # DAQP QPs in one call of the compiled caller on the same steps
    assert rows and set(rows) <= {2, 3}
    assert solved == rows
    assert len(rows) == sum(sum(length > k + 1 for length in lengths) >= 2
                            for k in range(max(lengths)))
    for (cfg, scenario), engine in zip(runs, together, strict=True):
        alone = oracle_simulate(cfg, scenario, QpCache(compiled_kernels=True))
        assert _differences(engine, alone) == []



def test_clarabel_members_get_their_qp_data_in_one_call_per_step(make_config):
    """The default backend's members (clarabel_direct) have their QP data made in one compiled
    call per step and read out in another, a member of one move steps alone: every run is
    still its run alone. (Members outside the engine's groups, whose own loops it steps:
    velocity planning on.)"""
    runs = _members(make_config, ["method=improved", "planner.velocity_planning=true"], 3) \
        + _members(make_config, ["method=improved", "controller.control_horizon=1"], 1)
    cache = QpCache(compiled_kernels=True)
    from pipeline.loop.engine import run_kernels

    kernels = run_kernels(cache)
    made, read = [], []

    def direct_theta_rows(packs, *args):
        made.append(packs.shape[0])
        return kernels.direct_theta_rows(packs, *args)

    def direct_readout_rows(packs, *args):
        read.append(packs.shape[0])
        return kernels.direct_readout_rows(packs, *args)

    counted = kernels._replace(direct_theta_rows=direct_theta_rows,
                               direct_readout_rows=direct_readout_rows)
    together = simulate_members(runs, cache, counted)
    lengths = [len(result.trajectory) for result in together]
    # on each step where two or more of the four step together: one call with those of the
    # three of three moves still running; the one-move member is never in it
    active = [[length > k + 1 for length in lengths] for k in range(max(lengths))]
    expected = [sum(now[:3]) for now in active if sum(now) >= 2 and any(now[:3])]
    assert made == read == expected and max(made) == 3
    for (cfg, scenario), engine in zip(runs, together, strict=True):
        alone = oracle_simulate(cfg, scenario, QpCache(compiled_kernels=True))
        assert _differences(engine, alone) == []

def test_path_frame_rows_are_each_members_path_frame(make_config):
    """The CPython statement of the batched path frame against the compiled one and against
    each member's own path-frame step (already held equal to the loop): one batch step of
    three members with different obstacles, speeds and last plans."""
    from pipeline.loop.compiled import COMPILED_KERNELS
    from pipeline.loop.python_kernels import PYTHON_KERNELS

    rng = np.random.default_rng(5)
    n, N, M = 3, 10, 3
    targets = np.cumsum(rng.uniform(0.1, 0.4, (n, N, 2)), axis=1)
    n_obs = np.array([0, 2, 4])
    starts = np.concatenate([[0], np.cumsum(N * n_obs)])
    obstacles = rng.uniform(0.0, 6.0, (starts[-1], 2))
    radii = rng.uniform(0.3, 0.8, int(n_obs.sum()))
    plans_xy, plans_course = np.zeros((n, N + 1, 2)), np.zeros((n, N + 1))
    plans_xy[1] = targets[1, 0] + np.cumsum(np.full((N + 1, 2), [0.3, 0.0]), axis=0)
    plan_lengths = np.array([0, N + 1, 0])
    args = (targets, np.tile([1.0, 0.0], (n, 1)), np.array([True, True, False]),
            np.full(n, 0.2), np.array([0.3, 0.25, 0.5]), np.array([12, 14, 11]),
            targets[:, 0].copy(), np.array([3.0, 2.5, 5.0]), np.array([3.0, 3.0, 1.0]),
            np.full(n, 0.1), np.array([0.1, 0.1, 0.12]), N, np.full(n, 0.5), np.full(n, 2.0),
            np.array([2.0, 6.0, 2.5]),  # braking limits (the third member brakes at its own)
            plans_xy, plans_course, plan_lengths, obstacles, starts, radii, M,
            np.full(n, 0.9), np.full(n, 0.2), np.full(n, 12.0), np.array([True, True, True]))
    fast = COMPILED_KERNELS.path_frame_rows(*args)
    plain = PYTHON_KERNELS.path_frame_rows(*args)
    for ours, theirs in zip(fast, plain, strict=True):
        assert np.array_equal(ours, theirs, equal_nan=True)
    for i in range(n):
        m = int(args[5][i])
        p, hd, cv, bd = COMPILED_KERNELS.rollout_path(targets[i], 1.0, 0.0, bool(args[2][i]),
                                                      0.2, float(args[4][i]), m)
        assert np.array_equal(fast[0][i, :m + 1], p) and np.array_equal(fast[3][i, :m], bd)
        s0, d0, h0, st, rd, vx, s_o, d_o = COMPILED_KERNELS.frame_step(
            p, hd, cv, float(args[4][i]), m, *targets[i, 0], float(args[7][i]),
            float(args[8][i]), 0.1, float(args[10][i]), N, 0.5, 2.0, float(args[14][i]), 0.2,
            plans_xy[i, :plan_lengths[i]], plans_course[i, :plan_lengths[i]],
            obstacles[starts[i]:starts[i + 1]])
        assert np.array_equal(fast[4][i], [s0, d0, h0]) and np.array_equal(fast[5][i], st)
        assert np.array_equal(fast[8][starts[i]:starts[i + 1]], s_o)
        G, h = COMPILED_KERNELS.halfplanes(st[1:], np.zeros(N), s0, d0, s_o, d_o,
                                           int(n_obs[i]),
                                           radii[starts[i] // N:starts[i] // N + n_obs[i]],
                                           M, 0.9, 0.2, 12.0, True)
        assert np.array_equal(fast[10][i], G) and np.array_equal(fast[11][i], h)
    assert np.count_nonzero(fast[10])  # some half-planes bind
