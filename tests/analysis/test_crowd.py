"""Among walkers (issue 59): the social force against a hand-computed two-agent case, each
crossing's difficulty against a planted recording, the crowd metrics against closed forms on
planted trajectories, the scene draw's walkable places against a brute-force search, and the
closed loop: a platform that can stop does not touch a walker standing on its line, and a
run ends at its first contact."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from pipeline.analysis.crowd import crowd_metrics
from pipeline.analysis.metrics.criteria import compute_metrics
from pipeline.analysis.metrics.signals import TrajectoryContext
from pipeline.analysis.settings import MetricsConfig
from pipeline.loop.social_force import SocialForceSettings, social_accelerations


def test_the_social_force_of_two_walkers_and_the_platform_is_the_hand_computed_one():
    """Walker 0 at the origin walking +x at 1 m/s and wanting 1.2 m/s; walker 1 at (1, 0)
    standing; the platform at (0, -2). By hand (A = 2, B = 0.3, tau = 0.5, radii 0.3 and
    0.35): relaxation (1.2 - 1) / 0.5 = 0.4 along x; walker 1 pushes walker 0 by
    2 exp((0.6 - 1) / 0.3) along -x; the platform by 2 exp((0.65 - 2) / 0.3) along +y."""
    s = SocialForceSettings(tau_s=0.5, strength_mps2=2.0, range_m=0.3, walker_radius_m=0.3)
    positions = np.array([[0.0, 0.0], [1.0, 0.0], [5.0, 5.0]])
    velocities = np.array([[1.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    desired = np.array([[1.2, 0.0], [0.0, 0.0], [0.0, 0.0]])
    present = np.array([True, True, False])  # walker 2 is absent: it pushes no one
    acc = social_accelerations(positions, velocities, present, desired, np.array([0.0, -2.0]),
                               0.35, s)
    walker = 2.0 * math.exp((0.6 - 1.0) / 0.3)
    platform = 2.0 * math.exp((0.65 - 2.0) / 0.3)
    assert acc[0] == pytest.approx([0.4 - walker, platform], abs=1e-12)
    push_1 = 2.0 * math.exp((0.65 - math.hypot(1.0, 2.0)) / 0.3)
    assert acc[1] == pytest.approx([walker + push_1 / math.hypot(1, 2),
                                    push_1 * 2 / math.hypot(1, 2)], abs=1e-12)
    assert acc[2] == pytest.approx([0.0, 0.0])


def _planted_scene(folder: Path, rows: list[tuple[int, int, float, float]]) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "planted.txt").write_text("".join(f"{f}\t{p}\t{x}\t{y}\n" for f, p, x, y in rows))


def _member(make_config, data_dir: Path, start, goal, speed: float, extra=(), n_steps=120):
    """A drawn-looking member of the planted scene (window at the recording's start)."""
    cfg = make_config(["experiment=pedestrians", "planner=improved",
                       f"scenario.pedestrians.data_dir={data_dir}",
                       "scenario.pedestrians.scenes=[planted]", f"scenario.n_steps={n_steps}",
                       *extra])
    ped = dataclasses.replace(cfg.scenario.pedestrians, scene="planted", window_start_s=0.0)
    member = dataclasses.replace(cfg.scenario, name="planted_member", family=None,
                                 start_xy_m=list(start), goal_xy_m=list(goal),
                                 start_heading_rad=0.0, speed_mps=speed, pedestrians=ped)
    return dataclasses.replace(cfg, scenario=member)


def test_a_crossings_difficulty_is_read_from_the_recording_alone(make_config, tmp_path):
    """Planted: walker 1 crosses the line x = 5 m going +y at 1 m/s, at y = 0 at t = 5 s;
    walker 2 stands 3 m beside the start. A platform at 1 m/s along y = 0 is at x = 5 m at
    5 s: the straight line meets walker 1; at 2 m/s it is past by then (at x = 10 m at 5 s
    with the goal at 10 m: arrived), so it does not; standing still at the start is touched
    by neither (walker 1 never comes within 0.65 m of the start, walker 2 stays 3 m off)."""
    from pipeline.loop.pedestrians import CrossingDifficulty, crossing_difficulty

    rows = [(10 * k, 1, 5.0, -5.0 + 0.4 * k) for k in range(26)]
    rows += [(10 * k, 2, 0.0, 3.0) for k in range(26)]
    _planted_scene(tmp_path / "scene", sorted(rows))
    slow = _member(make_config, tmp_path / "scene", (0.0, 0.0), (10.0, 0.0), 1.0)
    fast = _member(make_config, tmp_path / "scene", (0.0, 0.0), (10.0, 0.0), 2.0)
    radius = slow.vehicle.footprint_radius_m
    assert crossing_difficulty(slow.scenario, radius) == CrossingDifficulty(True, False)
    assert crossing_difficulty(fast.scenario, radius).straight_line_meets is False
    # walker 2 on the start: standing still is touched
    _planted_scene(tmp_path / "touch", sorted([(10 * k, 2, 0.0, 3.0 - 0.2 * k)
                                               for k in range(26)]))
    touched = _member(make_config, tmp_path / "touch", (0.0, 0.0), (10.0, 0.0), 1.0)
    assert crossing_difficulty(touched.scenario, radius).standing_touched is True


def test_each_runs_metrics_carry_its_crossings_difficulty_and_the_report_reads_them(
        make_config, tmp_path):
    """The planted crossing above (the straight line at 1 m/s meets walker 1; standing still
    is not touched): the run's context and metrics hold crossing_difficulty's answer, and the
    report's difficulty is read from those columns (no family to draw again: a family.json
    without seed and size, which the earlier path needs)."""
    from pipeline.analysis.metrics.context import trajectory_context
    from pipeline.loop.pedestrians import crossing_difficulty
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate
    from pipeline.reporting.verdicts import _difficulty

    rows = [(10 * k, 1, 5.0, -5.0 + 0.4 * k) for k in range(26)]
    rows += [(10 * k, 2, 0.0, 3.0) for k in range(26)]
    _planted_scene(tmp_path / "scene", sorted(rows))
    cfg = _member(make_config, tmp_path / "scene", (0.0, 0.0), (10.0, 0.0), 1.0, n_steps=60)
    judged = crossing_difficulty(cfg.scenario, cfg.vehicle.footprint_radius_m)
    context = trajectory_context(cfg)
    assert context.crossing == (judged.straight_line_meets, judged.standing_touched) \
        == (True, False)
    run = simulate(cfg, build_scenario(cfg.scenario)).trajectory
    crowd = compute_metrics(run, context, cfg.metrics).crowd
    assert crowd is not None and crowd.straight_line_meets is True \
        and crowd.standing_touched is False
    # elsewhere: no crossing, no columns' values
    assert trajectory_context(make_config(["experiment=kinematic"])).crossing is None
    names = ["a", "b", "c", "d"]
    table = pd.DataFrame({"scenario": names, "collision": [True, False, True, False],
                          "straight_line_meets": [True, True, False, "False"],
                          "standing_touched": ["True", False, False, False]})
    out = _difficulty(cfg, {}, {"improved": table})
    assert out["crossings"] == 4 and out["straight_line_meets_share"] == 0.5
    assert out["standing_touched_share"] == 0.25 and out["standing_safe_crossings"] == 3
    assert out["collision_rate_standing_safe_improved"] == pytest.approx(1 / 3)
    # a column not recorded for every run (folders written before it): the family drawn
    # again, which needs the family's seed and size
    assert _difficulty(cfg, {}, {"improved": table.assign(standing_touched=None)}) == {}


def _straight_run(n: int = 101, walker_xy=(5.0, 0.9), walker_v=(0.0, 0.0)) -> pd.DataFrame:
    """The platform along y = 0 at 1 m/s (10 Hz), one walker (radius 0.3)."""
    t = np.arange(n) * 0.1
    wx = walker_xy[0] + walker_v[0] * t
    wy = walker_xy[1] + walker_v[1] * t
    return pd.DataFrame({"time_s": t, "X_m": t, "Y_m": 0.0 * t, "psi_rad": 0.0 * t,
                         "vx_mps": 1.0 + 0.0 * t, "vy_mps": 0.0 * t, "r_rad_s": 0.0 * t,
                         "delta_rad": 0.0 * t, "e_y_m": 0.0 * t, "e_psi_rad": 0.0 * t,
                         "obs0_x_m": wx, "obs0_y_m": wy, "obs0_radius_m": 0.3 + 0.0 * t,
                         "obs0_visible": True})


def test_the_crowd_metrics_are_the_closed_forms_on_planted_trajectories():
    """A straight 10 m run at 1 m/s past a walker standing 0.9 m off the line: the surface
    gap sqrt((x - 5)^2 + 0.81) - 0.65 is below 0.5 m exactly where |x - 5| < sqrt(1.15^2 -
    0.81); the path ratio is 1; no timeout, no contact. A walker coming head-on at 1 m/s on
    the line: the contact's relative speed is 2 m/s."""
    context = TrajectoryContext((0.0, 0.0), (10.0, 0.0), 0.35, personal_space_m=0.5,
                                obstacle_slots=3)
    run = _straight_run()
    crowd = compute_metrics(run, context, MetricsConfig(goal_tolerance_m=0.5)).crowd
    assert crowd is not None
    x = run["X_m"].to_numpy()
    inside = np.abs(x - 5.0) < math.sqrt(1.15 ** 2 - 0.81)
    assert crowd.personal_space_intrusion_share == pytest.approx(inside.mean())
    assert crowd.personal_space_entries == 1 and crowd.timeout is False
    assert crowd.path_ratio == pytest.approx(1.0)  # 10 m logged over the 10 m line
    assert crowd.walkers_beyond_slots_share == 0.0
    assert math.isnan(crowd.contact_relative_speed_mps)
    head_on = compute_metrics(_straight_run(walker_xy=(8.0, 0.0), walker_v=(-1.0, 0.0)),
                              context, MetricsConfig(goal_tolerance_m=0.5)).crowd
    assert head_on is not None
    assert head_on.contact_relative_speed_mps == pytest.approx(2.0, abs=1e-9)
    # a walker seen all along, met head-on: not a contact at its appearance
    assert head_on.contact_at_appearance is False
    assert crowd.contact_at_appearance is False  # no contact at all
    # a walker whose recorded track begins against the platform: logged (at its first
    # position) but not visible until step 51, when the platform is at x = 5.1 m and the
    # walker 0.5 m ahead of it on the line: surface gap 0.5 - 0.65 < 0, the contact comes on
    # the step it appears; the same walker visible from step 45 on (contact at step 50, x =
    # 5.0 m, gap 0.6 - 0.65) is one the platform saw
    pop_in = _straight_run(walker_xy=(5.6, 0.0))
    pop_in["obs0_visible"] = np.arange(101) >= 51
    appeared = compute_metrics(pop_in, context, MetricsConfig(goal_tolerance_m=0.5)).crowd
    assert appeared is not None and appeared.contact_at_appearance is True
    assert appeared.contact_relative_speed_mps == pytest.approx(1.0, abs=1e-9)
    # a contact on the first step (a run that ends there logs one row): at appearance, its
    # relative speed unknown (no second row to difference)
    first = compute_metrics(_straight_run(walker_xy=(0.2, 0.0)).iloc[:1], context,
                            MetricsConfig(goal_tolerance_m=0.5)).crowd
    assert first is not None and first.contact_at_appearance is True
    assert math.isnan(first.contact_relative_speed_mps)
    seen = pop_in.assign(obs0_visible=np.arange(101) >= 45)
    seen_crowd = compute_metrics(seen, context, MetricsConfig(goal_tolerance_m=0.5)).crowd
    assert seen_crowd is not None and seen_crowd.contact_at_appearance is False
    # no crowd block off the pedestrians' scenarios
    plain = TrajectoryContext((0.0, 0.0), (10.0, 0.0), 0.35)
    assert compute_metrics(run, plain, MetricsConfig(goal_tolerance_m=0.5)).crowd is None


def test_the_rates_intervals_are_clopper_pearson_and_the_medians_order_statistics():
    """Oracles: the exact binomial interval from the beta quantiles; the median's interval
    from the binomial order statistics (the 95 % interval of 20 values: the 6th and 15th)."""
    table = pd.DataFrame({"collision": [True] * 3 + [False] * 17,
                          "goal_reached": [False] * 3 + [True] * 15 + [False] * 2,
                          "time_to_goal_s": np.arange(20.0), "min_clearance_m": np.arange(20.0),
                          "path_ratio": 1.0 + np.arange(20.0) / 100,
                          "personal_space_intrusion_share": np.linspace(0, 0.2, 20)})
    m = crowd_metrics(table)
    low, high = stats.beta.ppf(0.025, 3, 18), stats.beta.ppf(0.975, 4, 17)
    assert (m["collision_rate"], m["collision_rate_low"], m["collision_rate_high"]) == \
        pytest.approx((0.15, low, high))
    assert m["success_rate"] == 15 / 20 and m["timeout_rate"] == 2 / 20
    # without the reachability check's column no avoidable rate is made up
    assert np.isnan(m["collision_avoidable_rate"])
    # two of the three contacts avoidable from the walker's appearance (a flag on a run
    # without a contact does not count)
    flagged = crowd_metrics(table.assign(collision_avoidable=[True, False, True] + [True]
                                         + [False] * 16))
    low, high = stats.beta.ppf(0.025, 2, 19), stats.beta.ppf(0.975, 3, 18)
    assert (flagged["collision_avoidable_rate"], flagged["collision_avoidable_rate_low"],
            flagged["collision_avoidable_rate_high"]) == pytest.approx((0.1, low, high))
    assert flagged["collision_rate"] == m["collision_rate"]
    # one of the three contacts at a walker's appearance (a flag on a run without a contact
    # does not count); none made up without the column
    assert np.isnan(m["collision_at_appearance_rate"])
    appeared = crowd_metrics(table.assign(contact_at_appearance=[False, True, False] + [True]
                                          + [False] * 16))
    low, high = stats.beta.ppf(0.025, 1, 20), stats.beta.ppf(0.975, 2, 19)
    assert (appeared["collision_at_appearance_rate"],
            appeared["collision_at_appearance_rate_low"],
            appeared["collision_at_appearance_rate_high"]) == pytest.approx((0.05, low, high))
    assert (m["min_distance_median_m"], m["min_distance_median_m_low"],
            m["min_distance_median_m_high"]) == pytest.approx((9.5, 5.0, 14.0))
    assert m["time_to_goal_median_s"] == pytest.approx(np.median(np.arange(3.0, 18.0)))
    assert m["intrusion_time_share"] == pytest.approx(0.1)
    assert m["intrusion_time_share_low"] < 0.1 < m["intrusion_time_share_high"]


def test_the_collision_rates_where_standing_is_safe_count_from_the_flags():
    """Planted: 8 crossings, contacts on 4 (rows 0-3); of those rows 1 and 2 avoidable, row 3
    at a walker's appearance (and row 5's flag, on a run without a contact, counts for
    nothing): all 4/8, avoidable 2/8, with a walker seen before 3/8 (rows 0-2). Without the
    columns the last two are NaN, and without rows all three."""
    from pipeline.analysis.crowd import collision_rates

    table = pd.DataFrame({"collision": [True] * 4 + [False] * 4,
                          "collision_avoidable": [False, True, True, False] + [True] * 4,
                          "contact_at_appearance": [False, False, False, True, False, True,
                                                    False, False]})
    assert collision_rates(table) == (0.5, 0.25, 0.375)
    everything, avoidable, seen = collision_rates(table[["collision"]])
    assert everything == 0.5 and np.isnan(avoidable) and np.isnan(seen)
    assert all(np.isnan(collision_rates(table.iloc[:0])))


def test_scene_draws_start_and_goal_where_someone_walked(make_config):
    """Every drawn start and goal lies within walkable_radius_m of a recorded position
    (brute force over the scene's every sample), the midpoint is one; the aimed draw (the
    stress variant) puts a walker within both radii of the straight line every time."""
    from pipeline.loop.pedestrians import crossing_difficulty, load_scene
    from pipeline.loop.scenario import family_members

    cfg = make_config(["experiment=pedestrians", "planner=improved", "scenario.family.size=12"])
    members = family_members(cfg.scenario, cfg.vehicle.footprint_radius_m)
    for member in members:
        tracks = load_scene(member.pedestrians, member.pedestrians.scene)
        points = np.concatenate([tracks.positions_m[j, :c]
                                 for j, c in enumerate(tracks.counts)])
        start, goal = np.array(member.start_xy_m), np.array(member.goal_xy_m)
        for end in (start, goal):
            assert np.min(np.hypot(*(points - end).T)) <= 1.0 + 1e-12
        assert np.min(np.hypot(*(points - (start + goal) / 2).T)) < 1e-9
    aimed = make_config(["experiment=pedestrians_aimed", "planner=improved",
                         "scenario.family.size=12"])
    radius = aimed.vehicle.footprint_radius_m
    assert all(crossing_difficulty(m, radius).straight_line_meets
               for m in family_members(aimed.scenario, radius))


def test_a_platform_that_can_stop_does_not_touch_a_walker_standing_on_its_line(make_config,
                                                                               tmp_path):
    """A walker stands at the middle of the 10 m crossing for the whole run: the sidewalk
    robot on the kinematic track (improved's APF) never touches it (dead ahead on the goal
    line the APF's forces balance: it brakes and stands 1.9 m short, the APF's classic local
    minimum, counted as a timeout, never a contact); with its avoidance off (the straight-to-goal planner, no half-planes) it touches it,
    and the run ends there (termination 'contact', the last logged step overlapping)."""
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate

    _planted_scene(tmp_path / "scene", [(10 * k, 1, 5.0, 0.0) for k in range(80)])
    cfg = _member(make_config, tmp_path / "scene", (0.0, 0.0), (10.0, 0.0), 1.0)
    result = simulate(cfg, build_scenario(cfg.scenario))
    traj = result.trajectory
    gap = np.hypot(traj["X_m"] - 5.0, traj["Y_m"]) - 0.3 - cfg.vehicle.footprint_radius_m
    assert gap.min() > 0.0
    last = traj[traj["time_s"] >= traj["time_s"].iloc[-1] - 5.0]
    assert np.ptp(last["X_m"]) < 0.05 and np.ptp(last["Y_m"]) < 0.05  # it stopped and stays
    blind = _member(make_config, tmp_path / "scene", (0.0, 0.0), (10.0, 0.0), 1.0,
                    extra=["planner=straight_to_goal", "controller.collision_constraints=false"])
    traj = simulate(blind, build_scenario(blind.scenario)).trajectory
    gap = np.hypot(traj["X_m"] - 5.0, traj["Y_m"]) - 0.3 - blind.vehicle.footprint_radius_m
    assert gap.iloc[-1] < 0.0 and (gap.iloc[:-1] >= 0.0).all()
    assert traj["X_m"].iloc[-1] < 5.0


def test_a_step_solves_the_smallest_qp_that_holds_its_half_planes(make_config, monkeypatch):
    """With 32 slots, a step whose half-planes use few of them solves a smaller compiled QP
    (empty slots are rows 0 + s >= 0): the same run as with every step on the full QP, to the
    solvers' tolerance accumulated over the run (1e-4 m), on a dense scene and a sparse one."""
    from pipeline.loop.controller import kinematic
    from pipeline.loop.scenario import build_scenario, family_members
    from pipeline.loop.simulate import simulate

    cfg = make_config(["experiment=pedestrians", "planner=improved", "scenario.family.size=2"])
    for member in family_members(cfg.scenario, cfg.vehicle.footprint_radius_m):
        one = dataclasses.replace(cfg, scenario=member)
        bucketed = simulate(one, build_scenario(member)).trajectory
        monkeypatch.setattr(kinematic, "SLOT_BUCKETS", ())
        full = simulate(one, build_scenario(member)).trajectory
        monkeypatch.undo()
        assert len(bucketed) == len(full)
        gap = np.abs(bucketed[["X_m", "Y_m"]].to_numpy() - full[["X_m", "Y_m"]].to_numpy())
        assert gap.max() < 1e-4, (member.name, gap.max())  # the solvers, over 220 steps


def test_reactive_walkers_step_aside_where_replayed_ones_walk_through(make_config, tmp_path):
    """The walkers switch (scenario.pedestrians.walkers): a walker recorded walking straight
    through the point where a platform stands. Replayed, it passes through the platform's
    centre (gap -0.6 m); reactive (the social force, told where the platform is each step),
    it is held off (measured: -0.12 m at the default A = 2.1 m/s^2, B = 0.3 m: head-on, the
    force mostly brakes it) and still follows its route (it ends within 1.5 m of its recorded
    end)."""
    from pipeline.loop.scenario import build_scenario

    _planted_scene(tmp_path / "scene", [(10 * k, 1, -5.0 + 0.4 * k, 0.0) for k in range(40)])
    platform = np.array([0.0, 0.05])
    gaps = {}
    for walkers in ("replayed", "reactive"):
        cfg = _member(make_config, tmp_path / "scene", (0.0, 0.05), (10.0, 0.05), 1.0,
                      extra=[f"scenario.pedestrians.walkers={walkers}"])
        scenario = build_scenario(cfg.scenario)
        motion = scenario.obstacle_motion
        closest, last = np.inf, None
        for k in range(100):
            time_s = 0.1 * k
            if hasattr(motion, "react"):
                motion.react(time_s, platform, cfg.vehicle.footprint_radius_m)
            positions, _, present = motion.states_at(time_s)
            if present[0]:
                closest = min(closest, float(np.hypot(*(positions[0] - platform))))
                last = positions[0]
        gaps[walkers] = closest - 0.3 - cfg.vehicle.footprint_radius_m
        assert last is not None and abs(last[0] - (-5.0 + 0.4 * 25)) < 1.0 + (
            0 if walkers == "replayed" else 0.5)
    assert gaps["replayed"] < -0.55 and gaps["reactive"] > gaps["replayed"] + 0.4


def test_the_walkers_at_every_step_at_once_are_those_of_each_step(make_config):
    """RecordedTrackMotion.positions_over (crossing_difficulty's every step at once) gives,
    bit for bit, each step's states_at positions and presence: before a track's first sample,
    between samples, on them and after its last, on a recorded scene."""
    from pipeline.loop.pedestrians import load_scene, pedestrians_near

    cfg = make_config(["experiment=pedestrians"]).scenario
    ped = cfg.pedestrians
    tracks = load_scene(ped, ped.scenes[0])
    which = pedestrians_near(tracks, np.array([0.0, 0.0]), np.array([10.0, 0.0]), 30.0,
                             60.0, 1e6)[:40]
    motion = tracks.motion(which, 30.0)
    times = np.arange(0, 601) * 0.1 - 5.0
    positions, present = motion.positions_over(times)
    for k, time_s in enumerate(times):
        one, _, seen = motion.states_at(float(time_s))
        np.testing.assert_array_equal(positions[k], one)
        np.testing.assert_array_equal(present[k], seen)
    assert present.any() and not present.all()
