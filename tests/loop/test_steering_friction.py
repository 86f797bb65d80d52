"""The lateral MPC's steering bound by the tyres' friction (``controller.steering_friction_share``,
a choice we add for road speeds): the bound against its closed form, the QP's predicted steering
within it on both backends (Clarabel's statement with its rows scaled, DAQP's bounds), no bit
changed where it does not bind, and on a planted road a car parked in the lane ahead: at
12 m/s and 30 m, without the bound the evasive swerve ends in a skid off the road, with it the
car keeps to the road, and with the braking reading it stops short of the parked car; at
20 m/s and 33 m braking stops short only with a car's braking (``vehicle.brake_max_mps2``)."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from builders import make_inputs

from pipeline.errors import ConfigError
from pipeline.loop.commonroad_scenario import INSTALL_HINT, commonroad_missing
from pipeline.loop.controller import LateralMpc, QpCache
from pipeline.loop.controller.lateral_qp import friction_steering_bound_rad
from pipeline.loop.model import build_lateral_model

GRAVITY = 9.81


def test_the_bound_is_the_steering_at_which_the_lateral_acceleration_reaches_the_share(
        make_config):
    """``v^2 tan(bound) / L = share mu g`` where that is below ``steering_max``; the vehicle's
    ``steering_max_rad`` at low speeds and without a share."""
    vehicle = make_config().vehicle
    mu, wheelbase, steering_max = vehicle.tire_friction, vehicle.wheelbase_m, \
        vehicle.steering_max_rad
    for speed, share in ((12.0, 1.0), (20.0, 1.0), (12.0, 0.5), (30.0, 0.8)):
        bound = friction_steering_bound_rad(vehicle, share, speed)
        assert bound < steering_max
        assert speed ** 2 * math.tan(bound) / wheelbase == pytest.approx(share * mu * GRAVITY,
                                                                        rel=1e-12)
    # the paper's 3 m/s: mu g L / v^2 = 2.4, far above tan(0.4)
    assert friction_steering_bound_rad(vehicle, 1.0, 3.0) == steering_max
    assert friction_steering_bound_rad(vehicle, None, 20.0) == steering_max
    # where the friction bound meets the steering limit (about 7.2 m/s at a share of 1)
    meet = math.sqrt(mu * GRAVITY * wheelbase / math.tan(steering_max))
    assert friction_steering_bound_rad(vehicle, 1.0, meet * 0.99) == steering_max
    assert friction_steering_bound_rad(vehicle, 1.0, meet * 1.01) < steering_max


#: A state already turning (offset, heading error, yaw rate, steering 0.05 rad): the steering
#: rows' free response is not zero, so both halves of the scaled rows count
TURNING = np.array([0.2, 0.0, 0.03, 0.02, 0.05])


def _swerve(make_config, backend: str, share: float | None, speed_mps: float = 12.0,
            x0: np.ndarray = TURNING):
    """One step of the lateral MPC at ``speed_mps`` from ``x0`` asked to move 3 m sideways at
    once (the reference 3 m to the left over the whole horizon): the predicted steering
    angles, the step's bound and the plan."""
    overrides = [f"controller.backend={backend}"]
    if share is not None:
        overrides.append(f"controller.steering_friction_share={share}")
    cfg = make_config(overrides)
    mpc = LateralMpc(cfg.controller, cfg.vehicle, cfg.model, 0.1, QpCache())
    model = build_lateral_model(cfg.vehicle, speed_mps, 0.1)
    N = cfg.controller.horizon
    inputs = make_inputs(model, cfg.controller, x0, np.full(N, 3.0), np.zeros(N))
    step = mpc.solve(inputs)
    assert step.fallback == "none" and step.status == "optimal"
    bound = friction_steering_bound_rad(cfg.vehicle, share, speed_mps)
    return step.predicted_states[4, 1:], bound, step.planned


@pytest.mark.parametrize("backend", ["clarabel_direct", "daqp", "cvxpy"])
def test_every_predicted_steering_angle_stays_within_the_bound(make_config, backend):
    """At 12 m/s the bound is 0.15 rad; a swerve the unbounded MPC plans with 0.25 rad from
    a turning state (the planted effect) keeps every predicted angle within it, the bound
    binding."""
    free, steering_max, _ = _swerve(make_config, backend, None)
    assert np.max(np.abs(free)) > 0.2  # what the bound then cuts
    angles, bound, _ = _swerve(make_config, backend, 1.0)
    assert bound == pytest.approx(0.152, abs=2e-3) and bound < steering_max
    assert np.max(np.abs(angles)) <= bound + 1e-6
    assert np.max(np.abs(angles)) >= bound - 1e-4  # binding


@pytest.mark.parametrize("steering_now", [0.05, -0.08])
def test_the_backends_agree_on_the_bounded_qp(make_config, steering_now):
    """Clarabel (its statement's steering rows scaled) and DAQP (its bounds set to the bound)
    reach the same plan from a turning state: two solvers, one QP."""
    x0 = TURNING.copy()
    x0[4] = steering_now
    _, _, clarabel = _swerve(make_config, "clarabel_direct", 1.0, 15.0, x0)
    _, _, daqp = _swerve(make_config, "daqp", 1.0, 15.0, x0)
    assert np.allclose(clarabel, daqp, atol=1e-5)


@pytest.mark.parametrize("backend", ["clarabel_direct", "daqp"])
def test_steering_beyond_the_bound_comes_down_at_its_rate_instead_of_failing(make_config,
                                                                             backend):
    """At 15 m/s the bound is 0.098 rad; a car steering 0.3 rad now (its speed rose since)
    cannot be within it at the next step (1 rad/s for 0.1 s). The bound then is relaxed to
    what the rate allows, ``max(bound, 0.3 - 0.1 k)``: the QP keeps a plan (no fallback), the
    steering comes down at the full rate and is within the bound from the third step on."""
    from pipeline.loop.controller.lateral_qp import steering_bounds_from

    x0 = TURNING.copy()
    x0[4] = 0.3
    angles, bound, _ = _swerve(make_config, backend, 1.0, 15.0, x0)
    relaxed = steering_bounds_from(bound, 0.3, 1.0, 0.1, angles.size)
    assert relaxed[0] == pytest.approx(0.2) and relaxed[1] == pytest.approx(0.1)
    assert np.all(np.abs(angles) <= relaxed + 1e-6)
    assert angles[0] == pytest.approx(0.2, abs=1e-6)  # down at the full rate
    assert np.max(np.abs(angles[2:])) <= bound + 1e-6
    assert steering_bounds_from(bound, 0.05, 1.0, 0.1, 10) is None
    assert steering_bounds_from(bound, bound + 0.09, 1.0, 0.1, 10) is None  # one step away


def test_a_member_with_the_bound_never_steps_in_a_compiled_batch(make_config):
    """The compiled batches state the vehicle's steering bound alone: a controller with the
    share steps alone (no batch key), and controllers of different shares sharing one cache
    get their own predictions."""
    from pipeline.loop.compiled import COMPILED_KERNELS
    from pipeline.loop.controller.lateral_rows import batch_key

    cache = QpCache()
    plain_cfg = make_config()
    shared_cfg = make_config(["controller.steering_friction_share=1.0"])
    plain = LateralMpc(plain_cfg.controller, plain_cfg.vehicle, plain_cfg.model, 0.1, cache,
                       COMPILED_KERNELS)
    shared = LateralMpc(shared_cfg.controller, shared_cfg.vehicle, shared_cfg.model, 0.1, cache,
                        COMPILED_KERNELS)
    assert batch_key(plain, COMPILED_KERNELS) is not None
    assert batch_key(shared, COMPILED_KERNELS) is None
    model = build_lateral_model(plain_cfg.vehicle, 15.0, 0.1)
    assert plain.prediction(model).steering_bound_rad is None
    assert shared.prediction(model).steering_bound_rad == pytest.approx(
        friction_steering_bound_rad(shared_cfg.vehicle, 1.0, 15.0))


def test_where_the_bound_does_not_bind_no_bit_changes(make_config):
    """At the paper's 3 m/s the friction bound is above the steering limit: the statement's
    parameters are the same bits with and without the share, and the config hash without it
    is the hash before the key."""
    cfg = make_config()
    shared = make_config(["controller.steering_friction_share=1.0"])
    model = build_lateral_model(cfg.vehicle, 3.0, 0.1)
    N = cfg.controller.horizon
    inputs = make_inputs(model, cfg.controller, np.array([0.2, 0.1, 0.05, 0.02, 0.01]),
                         np.full(N, 1.0), np.zeros(N))
    plain = LateralMpc(cfg.controller, cfg.vehicle, cfg.model, 0.1, QpCache())
    bounded = LateralMpc(shared.controller, shared.vehicle, shared.model, 0.1, QpCache())
    from pipeline.loop.controller.lateral_qp import condensed_data

    a = condensed_data(plain.prediction(model), inputs, plain.weights)
    b = condensed_data(bounded.prediction(model), inputs, bounded.weights)
    assert bounded.prediction(model).steering_scale == 1.0
    assert np.array_equal(a.theta(), b.theta())
    assert make_config(["controller.steering_friction_share=null"]).config_hash() \
        == cfg.config_hash()
    assert shared.config_hash() != cfg.config_hash()


@pytest.mark.parametrize("overrides, fragment", [
    (["controller.steering_friction_share=0"], "[0.05, 1.0]"),
    (["controller.steering_friction_share=1.5"], "[0.05, 1.0]"),
    (["controller.steering_friction_share=1.0", "controller.backend=nmpc"], "nmpc"),
    (["method=mpc_dcbf", "controller.steering_friction_share=1.0"], "of one's own"),
])
def test_a_share_out_of_range_is_one_line_naming_the_key(make_config, overrides, fragment):
    with pytest.raises(ConfigError) as refusal:
        make_config(overrides)
    assert "controller.steering_friction_share" in str(refusal.value)
    assert fragment in str(refusal.value)


needs_extra = pytest.mark.skipif(commonroad_missing() is not None, reason=INSTALL_HINT)


def write_parked_car_road(path: Path, lanes: int = 2, speed_mps: float = 12.0,
                          gap_m: float = 30.0) -> Path:
    """A straight road along x (the ego's lane y in [-3.5, 0], with ``lanes=2`` a second lane
    y in [0, 3.5] beside it), a 4.5 x 1.8 m car parked in the ego's lane with its rear
    ``gap_m`` ahead of the ego's start (10, -1.75) at ``speed_mps`` heading along x, the goal a
    rectangle in the ego's lane near x = 180."""
    from commonroad.common.file_writer import CommonRoadFileWriter, OverwriteExistingFile
    from commonroad.common.util import Interval
    from commonroad.geometry.shape import Rectangle
    from commonroad.planning.goal import GoalRegion
    from commonroad.planning.planning_problem import PlanningProblem, PlanningProblemSet
    from commonroad.scenario.lanelet import Lanelet
    from commonroad.scenario.obstacle import ObstacleType, StaticObstacle
    from commonroad.scenario.scenario import Scenario, ScenarioID, Tag
    from commonroad.scenario.state import CustomState, InitialState

    scenario = Scenario(dt=0.1, scenario_id=ScenarioID(country_id="ZAM", map_name="Parked",
                                                        map_id=1))
    xs = np.linspace(0.0, 200.0, 21)

    def line(y: float) -> np.ndarray:
        return np.stack([xs, np.full_like(xs, y)], axis=1)

    two = lanes == 2
    scenario.add_objects(Lanelet(line(0.0), line(-1.75), line(-3.5), 1,
                                 adjacent_left=2 if two else None,
                                 adjacent_left_same_direction=True if two else None))
    if two:
        scenario.add_objects(Lanelet(line(3.5), line(1.75), line(0.0), 2, adjacent_right=1,
                                     adjacent_right_same_direction=True))
    start_x = 10.0
    scenario.add_objects(StaticObstacle(
        10, ObstacleType.PARKED_VEHICLE, Rectangle(4.5, 1.8),
        InitialState(position=np.array([start_x + gap_m + 2.25, -1.75]), orientation=0.0,
                     velocity=0.0, time_step=0)))
    goal = GoalRegion([CustomState(position=Rectangle(8.0, 3.5, center=np.array([180.0, -1.75])),
                                   time_step=Interval(0, 174))])
    problem = PlanningProblem(100, InitialState(
        position=np.array([start_x, -1.75]), orientation=0.0, velocity=speed_mps, time_step=0,
        yaw_rate=0.0, slip_angle=0.0), goal)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        CommonRoadFileWriter(scenario, PlanningProblemSet([problem]), author="tests",
                             affiliation="tests", source="tests", tags={Tag.URBAN}
                             ).write_to_file(str(path), OverwriteExistingFile.ALWAYS)
    return path


#: the paper's constant speed: a command line that sets the speed rule gets none of the road's
#: braking (pipeline.commonroad.road_overrides)
CONSTANT_SPEED = ["planner.velocity_planning=false"]


@needs_extra
@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_a_car_parked_in_the_lane_ahead_at_road_speed(tmp_path, make_config):
    """The road's settings of ``apf-mpc commonroad``: with its braking (the default) improved
    stops short of the car parked in its lane; at the paper's constant speed the road's edges
    and the friction bound keep it on the road past the car (it passes by steering alone,
    touching it at 12 m/s), and without the friction bound its swerve at up to 0.4 rad skids
    and it leaves the road for most of the run."""
    from pipeline.commonroad import road_overrides
    from pipeline.studies.commonroad import run_commonroad
    from pipeline.studies.results.commonroad import CommonRoadResult

    path = write_parked_car_road(tmp_path / "ZAM_Parked-1.xml")
    road = road_overrides("improved", path, [])
    steering = road_overrides("improved", path, CONSTANT_SPEED) + CONSTANT_SPEED
    assert "controller.steering_friction_share=1.0" in steering
    assert "planner.velocity_rule=predicted_clearance" in road

    def verdicts(name: str, overrides: list[str]) -> dict:
        cfg = make_config(["experiment=commonroad", f"scenario.commonroad.path={path}",
                           "method=improved", *overrides])
        run_commonroad(cfg, tmp_path / name)
        return CommonRoadResult.load(tmp_path / name).summary["verdicts"]

    bounded = verdicts("bounded", steering)
    assert bounded["off_road_steps"] <= 5 and bounded["goal_line_reached"]
    assert bounded["ours_true_shapes_collision"] is True
    unbounded = verdicts("unbounded", [o for o in steering if "friction" not in o])
    assert unbounded["off_road_steps"] > 50 and not unbounded["goal_line_reached"]
    braking = verdicts("braking", road)
    assert braking["checker_true_shapes_collision"] is False
    assert braking["ours_collision"] is False and braking["off_road_steps"] == 0
    assert braking["min_clearance_true_shapes_m"] > 0.5


@needs_extra
@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_at_20_mps_a_car_parked_33_m_ahead_is_stopped_short_of_only_with_a_cars_brakes(
        tmp_path, make_config):
    """A stop from 20 m/s needs 67 m at 3 m/s^2 (Appendix A's bound) and 25 m at 8: with the
    road's braking (planned at 6) the car hits the parked one when its plant brakes at 3
    (``vehicle.brake_max_mps2`` null: its acceleration limit) and stops short of it when it
    brakes at up to 8 (the road's default)."""
    from pipeline.commonroad import road_overrides
    from pipeline.studies.commonroad import run_commonroad
    from pipeline.studies.results.commonroad import CommonRoadResult

    path = write_parked_car_road(tmp_path / "ZAM_Parked-2.xml", speed_mps=20.0, gap_m=33.0)

    def verdicts(name: str, overrides: list[str]) -> dict:
        cfg = make_config(["experiment=commonroad", f"scenario.commonroad.path={path}",
                           "method=improved", *road_overrides("improved", path, overrides),
                           *overrides])
        run_commonroad(cfg, tmp_path / name)
        return CommonRoadResult.load(tmp_path / name).summary["verdicts"]

    assert verdicts("paper_brakes", ["vehicle.brake_max_mps2=null"])[
        "checker_true_shapes_collision"] is True
    car = verdicts("car_brakes", [])
    assert car["checker_true_shapes_collision"] is False and car["ours_collision"] is False
    assert car["off_road_steps"] == 0 and car["min_clearance_true_shapes_m"] > 0.3

