"""The engine's compiled path (pipeline/loop/lateral_group.py, pipeline/loop/group_rows.py)
against the per-member loop it replaced (tests/loop/oracle_loop.py): the members of the
default statement stepped as one group of arrays give each member's run alone, bit for bit
(trajectories, model checks, horizon records, terminations), on both backends, for members
that end early or at their first step, for members of different settings in one group, and
through the fallbacks; the path is taken (a switch that is not ignored), and a member it does
not state steps through its own loop."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pipeline.loop.controller import QpCache
from pipeline.loop.engine import MemberLoop, simulate_members
from pipeline.loop.lateral_group import group_key
from pipeline.loop.scenario import build_scenario, family_members
from pipeline.loop.simulate import run_kernels
from tests.loop.oracle_loop import oracle_simulate
from tests.loop.test_engine import _differences


def _members(make_config, overrides, size, first=0):
    cfg = make_config([*overrides, "scenario=family", f"scenario.family.size={first + size}"])
    members = family_members(cfg.scenario, cfg.vehicle.footprint_radius_m)[first:]
    return [(replace(cfg, scenario=member), build_scenario(member)) for member in members]


def _counted(cache):
    """The compiled kernels with the group's first call counted (members handed to it)."""
    kernels = run_kernels(cache)
    calls: list[int] = []

    def observe_plan_rows(k, members, *args):
        calls.append(members.shape[0])
        return kernels.observe_plan_rows(k, members, *args)

    return kernels._replace(observe_plan_rows=observe_plan_rows), calls


def _assert_each_alone(runs, together, record_horizon=True):
    for (cfg, scenario), engine in zip(runs, together, strict=True):
        oracle = oracle_simulate(cfg, scenario, QpCache(compiled_kernels=True),
                                 record_horizon=record_horizon)
        assert _differences(engine, oracle) == []
        assert engine.solve_times_s.shape == oracle.solve_times_s.shape


@pytest.mark.parametrize("backend", ["daqp", "clarabel_direct"])
def test_fifty_family_members_in_a_group_are_each_member_alone(make_config, backend):
    """50 family members of improved (and 8 of baseline) in groups of 8 (a worker's tasks),
    with horizon records, against each run alone through the oracle loop: the same bits."""
    for method, size in (("improved", 50), ("baseline", 8)):
        runs = _members(make_config, [f"method={method}", f"controller.backend={backend}"],
                        size)
        cache = QpCache(compiled_kernels=True)
        kernels, calls = _counted(cache)
        together = []
        for first in range(0, size, 8):
            together += simulate_members(runs[first:first + 8], cache, kernels)
        assert calls and max(calls) == 8  # the group's path was taken, 8 at a time
        _assert_each_alone(runs, together)


def test_a_group_without_horizon_records_is_the_same_run(make_config):
    """A tune's training members (no horizon record): each its run alone."""
    runs = _members(make_config, ["method=baseline_matched", "controller.backend=daqp"], 4)
    cache = QpCache(compiled_kernels=True)
    kernels, calls = _counted(cache)
    together = simulate_members(runs, cache, kernels, record_horizon=False)
    assert calls and all(result.horizon == {} for result in together)
    _assert_each_alone(runs, together, record_horizon=False)


def test_members_of_different_settings_in_one_group(make_config):
    """A tune's batch: trials of other weights, APFs and vehicles stepped in one group (one
    key: horizon, slots, moves), each the run of its own settings; another move count is
    another group."""
    runs = (_members(make_config, ["method=improved", "controller.backend=daqp"], 2)
            + _members(make_config, ["method=baseline", "controller.backend=daqp",
                                     "controller.q_lateral=3.0"], 2)
            + _members(make_config, ["method=improved", "controller.backend=daqp",
                                     "vehicle.steering_rate_max_rad_s=0.3",
                                     "controller.horizon_reach_m=12.0"], 2)
            + _members(make_config, ["method=improved", "controller.backend=daqp",
                                     "controller.control_horizon=5"], 2))
    cache = QpCache(compiled_kernels=True)
    members = [MemberLoop(cfg, scenario, cache, run_kernels(cache)) for cfg, scenario in runs]
    keys = [group_key(member) for member in members]
    assert len(set(keys[:6])) == 1 and keys[6] == keys[7] != keys[0]
    kernels, calls = _counted(cache)
    together = simulate_members(runs, cache, kernels)
    assert calls[0] == 6 and 2 in calls
    _assert_each_alone(runs, together)


def test_members_that_end_early_or_at_once_leave_the_others_untouched(make_config):
    """In one group: a member whose run ends at its fifth step (n_steps=4), one whose state is
    not finite at its first (it ends there: a log of one row, no step's columns), and two full
    ones: the full ones are the bits they are without the others, every one its run alone."""
    runs = _members(make_config, ["method=improved", "controller.backend=daqp"], 4)
    short_cfg = replace(runs[1][0], scenario=replace(runs[1][0].scenario, n_steps=4))
    short = (short_cfg, build_scenario(short_cfg.scenario))
    broken = (runs[2][0], replace(runs[2][1], start_m=np.array([np.nan, 0.0])))
    cache = QpCache(compiled_kernels=True)
    kernels, calls = _counted(cache)
    mixed = simulate_members([runs[0], short, broken, runs[3]], cache, kernels)
    without = simulate_members([runs[0], runs[3]], QpCache(compiled_kernels=True))
    assert calls[0] == 4
    assert len(mixed[1].trajectory) == 5 and mixed[1].termination == "max_steps"
    assert len(mixed[2].trajectory) == 1 and mixed[2].termination == "non_finite_state"
    assert "steering_rate_rad_s" not in mixed[2].trajectory.columns
    assert _differences(mixed[0], mixed[3])  # two members differ: the check can fail
    assert _differences(mixed[0], without[0]) == [] and _differences(mixed[3], without[1]) == []
    _assert_each_alone([runs[0], short, broken, runs[3]], mixed)


@pytest.mark.parametrize("overrides", [
    ["controller.backend=daqp", "controller.solver_max_iter=2"],
    ["controller.backend=clarabel_direct", "controller.solver_max_iter=6"],
])
def test_the_fallbacks_of_a_group_are_each_members_own(make_config, overrides):
    """QPs cut short by an iteration limit (user_limit): the plan shifted while it lasts,
    then the steering eased at its rate, each member's own, as alone."""
    runs = _members(make_config, ["method=improved", *overrides], 3)
    cache = QpCache(compiled_kernels=True)
    kernels, calls = _counted(cache)
    together = simulate_members(runs, cache, kernels)
    assert calls
    fallbacks = set().union(*(set(r.trajectory["fallback"].dropna()) for r in together))
    assert {"shifted_plan", "none", "safe_input"} <= fallbacks
    _assert_each_alone(runs, together)


@pytest.mark.parametrize(("overrides", "grouped"), [
    (["method=improved", "controller.backend=daqp"], True),
    (["method=baseline"], True),                                  # clarabel_direct
    (["method=improved", "controller.backend=daqp", "planner.velocity_planning=true"],
     False),                                                     # a speed rule
    (["method=improved", "controller.backend=cvxpy"], False),
    (["method=improved", "controller.frame=fixed"], False),
    (["method=improved", "controller.path_reference=pursuit"], False),
    (["method=improved", "controller.control_horizon=1"], False),
    (["method=improved", "controller=kinematic"], False),
    (["method=apf_pursuit"], False),
    (["method=mpc_dcbf"], False),
    (["method=improved", "scenario.obstacle_anchor=vehicle"], False),
])
def test_which_members_join_a_group(make_config, overrides, grouped):
    """The members of the default statement join a group; any other stage (a speed rule, the
    cvxpy backend, another frame or path, one move, the kinematic track, the peers, obstacles
    anchored to the vehicle) steps through its own loop."""
    (cfg, scenario), = _members(make_config, overrides, 1)
    cache = QpCache(compiled_kernels=True)
    member = MemberLoop(cfg, scenario, cache, run_kernels(cache))
    assert (group_key(member) is not None) is grouped
    assert group_key(MemberLoop(cfg, scenario, QpCache(), run_kernels(QpCache()))) is None


def test_a_group_of_odd_members_is_each_member_alone(make_config):
    """In one group: a member without obstacles, one of another sample time (and so another
    number of steps), one without a horizon reach (the prediction step is the sample time),
    beside a default one: each its run alone."""
    runs = _members(make_config, ["method=improved", "controller.backend=daqp"], 2)
    cfg, scenario = runs[1]
    empty = (cfg, replace(scenario, obstacle_start_m=np.zeros((0, 2)),
                          obstacle_velocity_mps=np.zeros((0, 2)),
                          obstacle_radius_m=np.zeros(0), obstacle_appear_s=np.zeros(0)))
    finer = _members(make_config, ["method=improved", "controller.backend=daqp",
                                   "scenario.sample_time_s=0.05", "scenario.n_steps=240"], 1,
                     first=2)
    unreached = _members(make_config, ["method=improved", "controller.backend=daqp",
                                       "controller.horizon_reach_m=null"], 1, first=3)
    odd = [runs[0], empty, *finer, *unreached]
    cache = QpCache(compiled_kernels=True)
    kernels, calls = _counted(cache)
    together = simulate_members(odd, cache, kernels)
    assert calls[0] == 4
    assert not any(c.startswith("obs") for c in together[1].trajectory.columns)
    assert len(together[2].trajectory) > len(together[0].trajectory)
    _assert_each_alone(odd, together)


def test_a_long_step_budget_costs_the_rows_run(make_config):
    """A group of members allowed 20,000 steps that end after a few dozen: the group's arrays
    grow with the rows run (twice, at most), not with the budget; each run is its run alone."""
    from pipeline.loop.lateral_group import ROWS_AT_FIRST, LateralGroup

    runs = _members(make_config, ["method=improved", "controller.backend=daqp",
                                  "scenario.n_steps=20000"], 2)
    cache = QpCache(compiled_kernels=True)
    members = [MemberLoop(cfg, scenario, cache, run_kernels(cache)) for cfg, scenario in runs]
    group = LateralGroup(members)
    group.run()
    assert group.capacity == ROWS_AT_FIRST and group.log.shape[1] == ROWS_AT_FIRST
    results = [member.result() for member in members]
    assert all(len(r.trajectory) < ROWS_AT_FIRST for r in results)
    _assert_each_alone(runs, results)


def test_rows_beyond_the_first_arrays_are_each_member_alone(make_config, monkeypatch):
    """The group's arrays grown while members run (room for 8 rows at first): each run is its
    run alone."""
    import pipeline.loop.lateral_group as lateral_group

    monkeypatch.setattr(lateral_group, "ROWS_AT_FIRST", 8)
    runs = _members(make_config, ["method=improved", "controller.backend=daqp"], 3)
    cache = QpCache(compiled_kernels=True)
    kernels, calls = _counted(cache)
    together = simulate_members(runs, cache, kernels)
    assert calls and all(len(r.trajectory) > 32 for r in together)
    _assert_each_alone(runs, together)


def test_an_obstacle_that_is_not_a_number_fails_as_alone(make_config):
    """A scenario whose obstacle velocity is not a number (a source of one's own may hand
    one): the group stops on the error the member's own loop raises (the model of a speed
    that is not a number), not on a run driven by its fallbacks."""
    (cfg, scenario), = _members(make_config, ["method=improved", "controller.backend=daqp"], 1)
    velocities = scenario.obstacle_velocity_mps.copy()
    velocities[0] = np.nan
    broken = replace(scenario, obstacle_velocity_mps=velocities)
    with pytest.raises(ValueError) as alone:
        oracle_simulate(cfg, broken, QpCache(compiled_kernels=True))
    cache = QpCache(compiled_kernels=True)
    kernels, calls = _counted(cache)
    with pytest.raises(ValueError) as grouped:
        simulate_members([(cfg, broken)], cache, kernels)
    assert calls and str(grouped.value) == str(alone.value)


def test_a_speed_off_the_grids_keys_is_read_as_alone(make_config):
    """A member started at 1e25 m/s (its model speeds beyond the grid's integer keys: the
    driver reads them with the frame's own functions) beside a default one: each its run
    alone."""
    runs = _members(make_config, ["method=improved", "controller.backend=daqp"], 2)
    cfg, scenario = runs[1]
    fast = (cfg, replace(scenario, initial_speed_mps=1e25))
    cache = QpCache(compiled_kernels=True)
    kernels, calls = _counted(cache)
    together = simulate_members([runs[0], fast], cache, kernels)
    assert calls[0] == 2 and together[1].trajectory["vx_mps"].iloc[0] == 1e25
    _assert_each_alone([runs[0], fast], together)
