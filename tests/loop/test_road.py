"""The road's edges in the lateral MPC (``controller.road_edge_weight``,
:mod:`pipeline.loop.controller.road`): the road's reach along a station's normal in closed form,
adjacent lanelets merged, the rows the QP gets, every backend on them, and the switch: a run
whose obstacle pushes it off a narrow road stays nearer the road with the rows."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.loop.controller.road import road_halfplanes, road_interval
from pipeline.loop.scenario import build_scenario
from pipeline.loop.simulate import simulate

TWO_LANES = (np.array([[-50.0, -1.75], [100.0, -1.75], [100.0, 5.25], [-50.0, 5.25]]),)


def test_the_roads_reach_along_the_normal_in_closed_form():
    points = np.array([[0.0, 0.0], [10.0, 1.0], [20.0, -1.0]])
    for heading in (0.0, 0.5):
        normals = np.tile([-math.sin(heading), math.cos(heading)], (3, 1))
        low, high, stretch_low, stretch_high = road_interval(points, normals, TWO_LANES)
        # the normal line y = y0 + t cos(heading) meets the edges at t = (edge - y0) / cos, at
        # an angle whose sine is cos(heading): a disc touches them 1 / cos farther along it
        assert low == pytest.approx((-1.75 - points[:, 1]) / math.cos(heading))
        assert high == pytest.approx((5.25 - points[:, 1]) / math.cos(heading))
        assert stretch_low == pytest.approx(1.0 / math.cos(heading))
        assert stretch_high == pytest.approx(1.0 / math.cos(heading))


def test_adjacent_lanelets_are_one_road_and_a_station_off_it_takes_the_nearest():
    # two lanelets sharing the edge y = 1.75, and a separate one from y = 10 to 13
    lanes = (np.array([[0.0, -1.75], [50.0, -1.75], [50.0, 1.75], [0.0, 1.75]]),
             np.array([[0.0, 1.75], [50.0, 1.75], [50.0, 5.25], [0.0, 5.25]]),
             np.array([[0.0, 10.0], [50.0, 10.0], [50.0, 13.0], [0.0, 13.0]]))
    points = np.array([[10.0, 0.0], [10.0, 8.0], [70.0, 0.0]])
    normals = np.tile([0.0, 1.0], (3, 1))
    low, high, _, _ = road_interval(points, normals, lanes)
    assert (low[0], high[0]) == pytest.approx((-1.75, 5.25))
    assert (low[1], high[1]) == pytest.approx((2.0, 5.0))       # y 10..13 seen from y = 8
    assert np.isnan(low[2]) and np.isnan(high[2])               # beyond the road's end


def test_the_rows_keep_the_disc_inside_and_are_empty_without_a_road():
    points, headings = np.array([[0.0, 1.0], [5.0, 1.0]]), np.zeros(2)
    G, h = road_halfplanes(points, headings, TWO_LANES, reach_m=1.2, weight=3.0)
    # 3 d >= 3 (-2.75 + 1.2) and -3 d >= -3 (4.25 - 1.2)
    assert G.tolist() == [[3.0, -3.0], [3.0, -3.0]]
    assert h.ravel() == pytest.approx([3 * -1.55, -3 * 3.05] * 2)
    G0, h0 = road_halfplanes(points, headings, (), reach_m=1.2, weight=3.0)
    assert not G0.any() and not h0.any()
    # at 0.6 rad to the road the disc needs reach / cos(0.6) along the normal (the review's
    # case: -0.46 exact where the unstretched bound said -0.75)
    _, h_slant = road_halfplanes(np.array([[0.0, 0.0]]), np.array([0.6]), TWO_LANES,
                                 reach_m=1.2, weight=1.0)
    assert h_slant[0, 0] == pytest.approx((-1.75 + 1.2) / math.cos(0.6))
    # the disc at that offset along the normal touches the edge: its centre 1.2 m above it
    d = h_slant[0, 0]
    assert d * math.cos(0.6) - (-1.75) == pytest.approx(1.2)


def narrow_road_run(make_config, overrides, width=2.4):
    """The paper scenario on a road ``width`` wide centred on the start-goal line."""
    cfg = make_config(overrides)
    scenario = build_scenario(cfg.scenario)
    half = width / 2.0
    road = (np.array([[-20.0, -half], [60.0, -half], [60.0, half], [-20.0, half]]),)
    return cfg, simulate(cfg, dataclasses.replace(scenario, road_polygons_m=road))


@pytest.mark.parametrize("backend", ["clarabel_direct", "daqp"])
def test_the_road_keeps_a_swerve_nearer_the_road(make_config, backend):
    """The paper scenario's obstacle makes improved swerve; on a road 2.4 m wide its disc
    leaves the road without the rows; with them (weight 1) it leaves it less, on either
    backend; with no road (no polygons) the rows change nothing beyond the solver's tolerance."""
    base = ["method=improved", f"controller.backend={backend}"]
    _, free = narrow_road_run(make_config, base)
    cfg, kept = narrow_road_run(make_config, base + ["controller.road_edge_weight=1.0"])
    reach = cfg.vehicle.footprint_radius_m
    beyond = {name: np.maximum(np.abs(run.trajectory["Y_m"]) + reach - 1.2, 0.0).sum()
              for name, run in (("free", free), ("kept", kept))}
    assert beyond["free"] > 0.5
    assert beyond["kept"] < 0.5 * beyond["free"]
    # the logged slack is the obstacle rows' alone
    assert (kept.trajectory["max_slack_m"].dropna() >= 0).all()
    plain = simulate(cfg, build_scenario(cfg.scenario))
    unroaded = simulate(make_config(base), build_scenario(cfg.scenario))
    # empty rows: the same run up to the solver's tolerance (two more slack variables)
    assert np.allclose(plain.trajectory["Y_m"].to_numpy(),
                       unroaded.trajectory["Y_m"].to_numpy(), rtol=0.0, atol=1e-6)


def test_the_key_hashes_as_before_when_off_and_is_refused_where_it_cannot_act(make_config):
    assert make_config([]).config_hash() == "c3169d33ead55c88"
    assert make_config(["controller.road_edge_weight=1.0"]).config_hash() != "c3169d33ead55c88"
    for overrides, fragment in ((["controller.road_edge_weight=1.0", "controller.frame=fixed"],
                                 "controller.frame=fixed"),
                                (["controller.road_edge_weight=1.0", "controller.backend=nmpc"],
                                 "controller.backend=nmpc"),
                                (["controller.road_edge_weight=0"], "[0.001, 1000")):
        with pytest.raises(ConfigError) as refusal:
            make_config(overrides)
        assert "controller.road_edge_weight" in str(refusal.value) \
            and fragment in str(refusal.value)


def test_a_commonroad_run_gives_the_road_to_the_methods_whose_mpc_takes_it(tmp_path,
                                                                           make_config):
    """apf-mpc commonroad: the lateral MPC in the path frame gets the road's edges, the
    steering bound by the tyres' friction and braking from every obstacle's prediction (the
    Euro NCAP braking track's keys); the peers' own controllers get none, the fixed frame no
    edges; a user's explicit setting is never added to, and a user who turns velocity
    planning off gets no braking."""
    from pipeline.commonroad import road_overrides
    from pipeline.studies.euro_ncap import BRAKING, ROAD_EDGE_WEIGHT, STEERING_FRICTION_SHARE

    path = tmp_path / "any.xml"
    road = [f"controller.road_edge_weight={ROAD_EDGE_WEIGHT}"]
    friction = [f"controller.steering_friction_share={STEERING_FRICTION_SHARE}"]
    braking = list(BRAKING)
    assert road_overrides("improved", path, []) == road + friction + braking
    assert road_overrides("baseline", path, []) == road + friction + braking
    assert road_overrides("mpc_dcbf", path, []) == []
    assert road_overrides("cbf_filter", path, []) == []
    assert road_overrides("improved", path, ["controller.frame=fixed"]) == friction + braking
    assert road_overrides("improved", path, ["controller.road_edge_weight=3"]) == \
        friction + braking
    assert road_overrides("improved", path, ["controller.steering_friction_share=0.5"]) == \
        road + braking
    assert road_overrides("improved", path, ["controller.backend=nmpc"]) == []
    # the paper's constant speed: none of the braking keys
    assert road_overrides("baseline", path, ["planner.velocity_planning=false"]) == \
        road + friction
    # one braking key set by the user (another rule, another brake): the others still come
    for key, value in (("planner.velocity_rule", "stopping_distance"),
                       ("vehicle.brake_max_mps2", "6")):
        assert road_overrides("improved", path, [f"{key}={value}"]) == \
            road + friction + [b for b in braking if not b.startswith(f"{key}=")]
    # no hand-over to the kinematic model: no floor of 0 either (the default floor stays, and
    # the run composes)
    without_handover = ["vehicle.kinematic_below_mps=null"]
    added = road_overrides("improved", path, without_handover)
    assert not any(a.startswith(("planner.speed_floor_mps=", "vehicle.kinematic_below_mps="))
                   for a in added)
    make_config(["experiment=commonroad", f"scenario.commonroad.path={path}",
                 "method=improved", *added, *without_handover])
