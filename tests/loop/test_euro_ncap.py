"""The Euro NCAP crossings (``scenario=euro_ncap``, :mod:`pipeline.loop.euro_ncap`): the
geometry against a hand computation, occlusion behind the parked cars in closed form, the
family's draw, the refusals, the protocol's outcome on planted trajectories, and each
registered key's switch (``tests/loop/test_register_switches.py`` names this module)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pandas as pd
import pytest

from pipeline.errors import ConfigError
from pipeline.loop.euro_ncap import (
    CASES,
    EuroNcapSettings,
    EuroNcapSource,
    ego_vehicle,
    encounter,
    protocol_outcome,
)
from pipeline.loop.scenario import build_scenario

KMH = 1.0 / 3.6


@pytest.fixture()
def base(make_config):
    return make_config(["scenario=euro_ncap"])


def source_with(base, **params):
    """The source of ``base`` with ``params`` set in ``scenario.source.params``."""
    scenario = base.scenario
    merged = {**scenario.source.params, **params}
    return EuroNcapSource(dataclasses.replace(
        scenario, source=dataclasses.replace(scenario.source, params=merged)))


def member_with(base, case, speed_kmh, **params):
    """The first member of ``case`` at ``speed_kmh`` (no speed tolerance) and its scenario."""
    source = source_with(base, cases=[case], ego_speeds_kmh=[speed_kmh],
                         speed_tolerance_kmh=0.0, **params)
    member = source.member(0, 0)
    return source, member, build_scenario(member)


@pytest.mark.parametrize("case, speed_kmh, user_kmh, start_y, impact_y", [
    # near side: the road user starts 4 m right of the centreline; the impact position is a
    # fraction of the 1.8 m width from the right edge (y = -0.9)
    ("CPNA-25", 30.0, 5.0, -4.0, -0.45),
    ("CPNA-75", 50.0, 5.0, -4.0, 0.45),
    ("CPNC-50", 20.0, 5.0, -4.0, 0.0),
    ("CBNAO-50", 40.0, 15.0, -4.0, 0.0),
    # far side: 6 m left, the fraction from the left edge (y = +0.9)
    ("CPFA-50", 60.0, 8.0, 6.0, 0.0),
])
def test_an_ego_holding_its_lane_meets_the_road_user_at_the_impact_position(
        base, case, speed_kmh, user_kmh, start_y, impact_y):
    """By hand: the road user stands still for lead_time_s = 1 s, then walks |start - impact|
    at its speed; the ego's front (2.25 m ahead of its centre) reaches the crossing line at
    that moment, driving at the test speed from x = 0."""
    _, member, scenario = member_with(base, case, speed_kmh)
    walk_s = abs(start_y - impact_y) / (user_kmh * KMH)
    impact_s = 1.0 + walk_s
    crossing_x = 2.25 + speed_kmh * KMH * impact_s
    assert member.speed_mps == pytest.approx(speed_kmh * KMH)
    centre = scenario.obstacles_at(impact_s).positions_m
    n_user = scenario.user_discs
    assert np.mean(centre[:n_user], axis=0) == pytest.approx([crossing_x, impact_y], abs=1e-9)
    # still at its start before it moves; the ego's front on the line at the impact time
    assert np.mean(scenario.obstacles_at(0.5).positions_m[:n_user], axis=0) == \
        pytest.approx([crossing_x, start_y])
    ego_front_x = 2.25 + member.speed_mps * impact_s
    assert ego_front_x == pytest.approx(crossing_x)
    assert scenario.goal_m[0] == pytest.approx(crossing_x + 20.0)


def test_the_child_is_hidden_behind_the_parked_cars_until_it_walks_out(base):
    """CPNC-50 at 30 km/h: the child (at y = -4) stands between two cars parked 1 m right of
    the ego (y from -3.7 to -1.9), 1 m apart around its line. From the ego's start the sight
    line to it crosses the nearer car (closed form below); once the child is at y = -1.5,
    in front of the cars, the line passes clear of them."""
    _, member, scenario = member_with(base, "CPNC-50", 30.0)
    x_c = scenario.obstacle_start_m[0, 0]
    # the sight line from the origin to (x_c, -4) is between y = -1.9 and -3.7 for x in
    # [x_c 1.9/4, x_c 3.7/4]; the nearer car spans x in [x_c - 5, x_c - 0.5]
    assert max(x_c * 1.9 / 4.0, x_c - 5.0) < min(x_c * 3.7 / 4.0, x_c - 0.5)
    ego = np.zeros(2)
    hidden = scenario.sense(scenario.obstacles_at(0.0), ego, 2.5)
    # the child hidden; the nearer car's three discs seen, the farther car behind it not
    assert hidden.visible.tolist() == [False, True, True, True, False, False, False]
    out_s = 1.0 + 2.5 / (5.0 * KMH)                               # walked from -4 to -1.5
    seen = scenario.sense(scenario.obstacles_at(out_s), ego, 2.5)
    assert scenario.obstacles_at(out_s).positions_m[0, 1] == pytest.approx(-1.5)
    assert seen.visible[0]
    # occlusion off: seen from the start
    _, _, open_road = member_with(base, "CPNC-50", 30.0, occlusion=False)
    assert open_road.sense(open_road.obstacles_at(0.0), ego, 2.5).visible[0]
    # anything within the ego's reach is seen, hidden or not
    near = np.array([x_c - 1.0, -2.5])
    assert scenario.sense(scenario.obstacles_at(0.0), near, 2.5).visible[0]


def test_the_family_walks_the_grid_once_then_again_at_speeds_within_the_tolerance(base):
    source = EuroNcapSource(base.scenario)
    grid = {(c.name, f, s) for c, f, s in source.combinations()}
    assert len(grid) == 5 * 11
    first = [source.draw(0, i) for i in range(55)]
    assert {(c.name, f, s) for c, s, f, _ in first} == grid
    again = [source.draw(0, i) for i in range(55, 110)]
    assert [(c.name, s) for c, s, _, _ in again] == [(c.name, s) for c, s, _, _ in first]
    assert all(abs(v - s) <= 1.0 for _, s, _, v in first + again)
    assert all(v != w for (_, _, _, v), (_, _, _, w) in zip(first, again, strict=True))
    # the same on every machine: a second source draws the same members
    assert EuroNcapSource(base.scenario).member(3, 17) == source.member(3, 17)
    other = source.member(4, 17)
    assert other != source.member(3, 17)


def test_the_speed_grid_and_cases_are_what_the_family_draws(base):
    source = source_with(base, cases=["CPFA-50", "CPNA-75"], ego_speeds_kmh=[20, 40])
    drawn = {(c.name, s) for c, s, _, _ in (source.draw(0, i) for i in range(40))}
    assert drawn == {("CPFA-50", 20.0), ("CPFA-50", 40.0), ("CPNA-75", 20.0),
                     ("CPNA-75", 40.0)}
    exact = source_with(base, speed_tolerance_kmh=0.0)
    assert all(s == v for _, s, _, v in (exact.draw(0, i) for i in range(20)))


@pytest.mark.parametrize("key, value, allowed", [
    ("cases", ["CPXX-50"], "a non-empty list of distinct cases"),
    ("cases", [], "a non-empty list"),
    ("ego_speeds_kmh", [0.0], "speeds in [5, 130] km/h"),
    ("child_speed_kmh", -1.0, "a number in [0.5, 30]"),
    ("cover_discs", 2.5, "an integer"),
    ("occlusion", "yes", "true or false"),
    ("typo_m", 1.0, "one of the Euro NCAP keys"),
    ("near_start_m", 2.0, "a number in (3.7, 30]"),
])
def test_a_bad_value_is_refused_naming_its_key(base, key, value, allowed):
    with pytest.raises(ConfigError) as refusal:
        source_with(base, **{key: value})
    line = str(refusal.value)
    assert f"scenario.source.params.{key}" in line and allowed in line
    assert "\n" not in line


def test_road_users_speeds_starts_and_lead_time_move_the_encounter():
    s = EuroNcapSettings()
    child = encounter(s, CASES["CPNC-50"], 30.0, 0.5, 0.1)
    faster = encounter(dataclasses.replace(s, child_speed_kmh=10.0), CASES["CPNC-50"], 30.0,
                       0.5, 0.1)
    assert child.velocity_mps[1] == pytest.approx(5.0 * KMH)
    assert faster.velocity_mps[1] == pytest.approx(10.0 * KMH)
    assert faster.impact_time_s - 1.0 == pytest.approx((child.impact_time_s - 1.0) / 2.0)
    far = encounter(dataclasses.replace(s, adult_far_speed_kmh=4.0), CASES["CPFA-50"], 30.0,
                    0.5, 0.1)
    assert far.velocity_mps[1] == pytest.approx(-4.0 * KMH)
    bike = encounter(dataclasses.replace(s, cyclist_speed_kmh=20.0), CASES["CBNAO-50"], 30.0,
                     0.5, 0.1)
    assert bike.velocity_mps[1] == pytest.approx(20.0 * KMH)
    assert bike.user_discs.shape == (3, 2) and np.ptp(bike.user_discs[:, 1]) == \
        pytest.approx(2 * 1.9 / 3)
    wider = encounter(dataclasses.replace(s, near_start_m=6.0), CASES["CPNA-25"], 30.0, 0.25,
                      0.1)
    assert wider.start_m[1] == -6.0
    later = encounter(dataclasses.replace(s, lead_time_s=2.0), CASES["CPNA-25"], 30.0, 0.25,
                      0.1)
    assert later.move_time_s == 2.0
    assert later.crossing_x_m - encounter(s, CASES["CPNA-25"], 30.0, 0.25, 0.1).crossing_x_m \
        == pytest.approx(30.0 * KMH)
    gap = encounter(dataclasses.replace(s, parked_lateral_gap_m=2.0), CASES["CPNC-50"], 30.0,
                    0.5, 0.1)
    assert gap.parked_m[:, :, 1].max() == pytest.approx(-2.9)
    assert child.parked_m[:, :, 1].max() == pytest.approx(-1.9)


def planted_run(xs, ys, psis, speed_mps, obstacles):
    """A trajectory with the ego at (xs, ys, psis) and obstacles ``[(x, y, r), ...]``."""
    n = len(xs)
    t = {"time_s": 0.1 * np.arange(n), "X_m": xs, "Y_m": ys, "psi_rad": psis,
         "vx_mps": np.full(n, speed_mps), "vy_mps": np.zeros(n)}
    for j, (ox, oy, r) in enumerate(obstacles):
        t[f"obs{j}_x_m"], t[f"obs{j}_y_m"] = np.full(n, ox), np.full(n, oy)
        t[f"obs{j}_radius_m"] = np.full(n, r)
    return pd.DataFrame(t)


def test_the_protocol_outcome_of_planted_runs_on_the_true_shapes():
    """The 4.5 x 1.8 m car driving along y = 0 at 10 m/s, 0.1 m per step: an adult (0.3 m
    disc) at (20, 0) is first overlapped where x + 2.25 >= 19.7, step 175; one at (20, 1.25)
    stays 1.25 - 0.9 - 0.3 = 0.05 m from the car's side (its disc cover, 0.27 m wider, would
    touch it); a bicycle (1.9 x 0.6 m across the road) centred at (20, 0) from step 175 too; a
    parked car on the path is touched, one beside the road is not."""
    s = EuroNcapSettings()
    adult = encounter(s, CASES["CPNA-25"], 36.0, 0.25, 0.1)
    xs = 0.1 * np.arange(200)
    zeros = np.zeros(200)
    out = protocol_outcome(planted_run(xs, zeros, zeros, 10.0, [(20.0, 0.0, 0.3)]), adult, s)
    assert out.hit and out.impact_time_s == pytest.approx(17.5)
    assert out.impact_speed_kmh == pytest.approx(36.0) and out.least_gap_m == 0.0
    assert not out.other_contact and out.steps_off_road == 0
    beside = protocol_outcome(planted_run(xs, zeros, zeros, 10.0, [(20.0, 1.25, 0.3)]), adult, s)
    assert not beside.hit and math.isnan(beside.impact_speed_kmh)
    assert beside.least_gap_m == pytest.approx(0.05)
    bike = encounter(s, CASES["CBNAO-50"], 36.0, 0.5, 0.1)
    discs = [(20.0, dy, bike.user_radius_m) for dy in bike.user_discs[:, 1]]
    ridden = protocol_outcome(planted_run(xs, zeros, zeros, 10.0, discs), bike, s)
    assert ridden.hit and ridden.impact_time_s == pytest.approx(17.5)
    assert not ridden.other_contact   # its parked car stands beside the road, 1 m off the side
    on_path = dataclasses.replace(adult, parked_m=np.array(
        [[[15.0, -0.5], [19.5, -0.5], [19.5, 1.3], [15.0, 1.3]]]))
    assert protocol_outcome(planted_run(xs, zeros, zeros, 10.0, [(50.0, 50.0, 0.3)]), on_path,
                            s).other_contact
    # at y = 4 the rectangle reaches 4.9 (within the left edge, 1.75 + 3.5 = 5.25); turned 90
    # degrees it reaches 2.25 m to each side, beyond it; a narrower road or one lane: beyond
    far = [(50.0, 50.0, 0.3)]
    ys = np.full(200, 4.0)
    assert protocol_outcome(planted_run(xs, ys, np.full(200, math.pi / 2), 10.0, far), adult,
                            s).steps_off_road == 200
    straight = planted_run(xs, ys, zeros, 10.0, far)
    assert protocol_outcome(straight, adult, s).steps_off_road == 0
    assert protocol_outcome(straight, adult,
                            dataclasses.replace(s, lane_width_m=3.0)).steps_off_road == 200
    assert protocol_outcome(straight, adult,
                            dataclasses.replace(s, oncoming_lane=False)).steps_off_road == 200


def test_the_true_shapes_gap_against_a_closed_form():
    """polygon_gap: two unit squares 0.5 m apart side by side, then overlapping; disc_gap: a
    disc of 0.3 m 1 m beyond a rectangle's corner diagonally."""
    from pipeline.loop.euro_ncap import disc_gap, polygon_gap, rectangle_corners

    one = np.ones(1)
    a = rectangle_corners(0.0 * one, 0.0 * one, 0.0 * one, 1.0, 1.0)
    b = rectangle_corners(1.5 * one, 0.0 * one, 0.0 * one, 1.0, 1.0)
    assert polygon_gap(a, b) == pytest.approx([0.5])
    c = rectangle_corners(0.9 * one, 0.2 * one, 0.3 * one, 1.0, 1.0)
    assert polygon_gap(a, c) == pytest.approx([0.0])
    rect = rectangle_corners(0.0 * one, 0.0 * one, 0.0 * one, 4.0, 2.0)
    corner = np.array([[2.0 + 1.0 / math.sqrt(2), 1.0 + 1.0 / math.sqrt(2)]])
    assert disc_gap(rect, 0.0 * one, 4.0, 2.0, corner, 0.3) == pytest.approx([0.7])


def test_a_test_ends_at_its_impact_on_any_of_the_egos_discs(make_config, base):
    """end_at_contact=true: the run stops at the first step any ego disc touches (the front one
    here, before the centre disc could); with false (the default) it drives on."""
    from pipeline.loop.simulate import simulate

    settings = EuroNcapSettings.of(dict(base.scenario.source.params))
    cfg = make_config(["scenario=euro_ncap", "controller.max_obstacles=9",
                       "controller.collision_constraints=false", "planner=straight_to_goal"])
    cfg = dataclasses.replace(cfg, vehicle=ego_vehicle(cfg.vehicle, settings))
    ends = {}
    for end in (True, False):
        _, member, scenario = member_with(base, "CPNA-75", 40.0, end_at_contact=end)
        run = simulate(dataclasses.replace(cfg, scenario=member), scenario)
        ends[end] = run
        geometry = encounter(settings, CASES["CPNA-75"], 40.0, 0.75, 0.1)
        outcome = protocol_outcome(run.trajectory, geometry, settings)
        assert outcome.hit
    assert ends[True].termination == "contact"
    assert ends[False].termination != "contact"
    # the default: the run goes on (its check sees the covers); the outcome is the true shapes'
    assert not settings.end_at_contact
    last = ends[True].trajectory.iloc[-1]
    # the front disc overlaps, the centre disc alone would not
    centre_gap = math.hypot(last["obs0_x_m"] - last["X_m"], last["obs0_y_m"] - last["Y_m"]) \
        - last["obs0_radius_m"] - cfg.vehicle.footprint_radius_m
    assert centre_gap > 0.0
