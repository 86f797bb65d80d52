"""scenario=commonroad (issue 43): the reader on scenarios written here with commonroad-io's own
API (no third-party XML in the repository), our collision check against CommonRoad's
drivability checker on planted geometry, a whole run, the exported trajectory, and the one-line
errors. Without the optional extra these tests skip with the install line as their reason."""

from __future__ import annotations

import math
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipeline.errors import ConfigError, MissingExtraError
from pipeline.loop.commonroad_scenario import (
    INSTALL_HINT,
    commonroad_missing,
    ego_solution,
    read_commonroad,
    require_commonroad,
    write_solution,
)
from pipeline.run import main

needs_extra = pytest.mark.skipif(commonroad_missing() is not None, reason=INSTALL_HINT)
# commonroad-io's generated protobuf modules warn on import under protobuf 3.20
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

CAR_LENGTH_M, CAR_WIDTH_M = 4.5, 1.8
ONCOMING_MPS = 4.0


def write_scenario(path: Path, *, initial_time_step: int = 0, ego_recording: bool = True,
                   goal_steps: tuple[int, int] = (0, 100), obstacles: str = "both",
                   planning_problem: bool = True, uncertain: bool = False) -> Path:
    """A straight two-lane road (y in [-3.5, 3.5], x in [0, 150]) written with commonroad-io:
    a parked disc (id 10, radius 0.5 at (40, 0.8)), an oncoming car (id 11, 4.5 x 1.8, on
    y = -2 from x = 90 at step 0, 4 m/s, recorded for steps 0-79), optionally the ego's own
    recording (id 12), and planning problem 100: start (5, 0) heading 0 at 10 m/s at
    ``initial_time_step``, goal a 6 x 7 m rectangle around (80, 0) in ``goal_steps``; with
    ``uncertain``, a parked car (id 13) whose position is a rectangle around (60, 2) and whose
    orientation is an interval around pi / 2."""
    from commonroad.common.file_writer import CommonRoadFileWriter, OverwriteExistingFile
    from commonroad.common.util import Interval
    from commonroad.geometry.shape import Circle, Rectangle
    from commonroad.planning.goal import GoalRegion
    from commonroad.planning.planning_problem import PlanningProblem, PlanningProblemSet
    from commonroad.prediction.prediction import TrajectoryPrediction
    from commonroad.scenario.lanelet import Lanelet
    from commonroad.scenario.obstacle import DynamicObstacle, ObstacleType, StaticObstacle
    from commonroad.scenario.scenario import Scenario, ScenarioID, Tag
    from commonroad.scenario.state import CustomState, InitialState
    from commonroad.scenario.trajectory import Trajectory

    scenario = Scenario(dt=0.1, scenario_id=ScenarioID(country_id="ZAM", map_name="Planted",
                                                        map_id=1))
    scenario.add_objects(Lanelet(np.array([[0.0, 3.5], [150.0, 3.5]]),
                                 np.array([[0.0, 0.0], [150.0, 0.0]]),
                                 np.array([[0.0, -3.5], [150.0, -3.5]]), 1))
    if obstacles in ("both", "parked"):
        scenario.add_objects(StaticObstacle(10, ObstacleType.PARKED_VEHICLE, Circle(0.5),
                                            InitialState(position=np.array([40.0, 0.8]),
                                                         orientation=0.0, velocity=0.0,
                                                         time_step=0)))

    def car(obstacle_id: int, x0: float, y: float, speed: float, heading: float) -> None:
        rectangle = Rectangle(CAR_LENGTH_M, CAR_WIDTH_M)
        step = speed * math.cos(heading) * 0.1
        states = [CustomState(position=np.array([x0 + step * k, y]), orientation=heading,
                              velocity=speed, time_step=k) for k in range(1, 80)]
        scenario.add_objects(DynamicObstacle(
            obstacle_id, ObstacleType.CAR, rectangle,
            InitialState(position=np.array([x0, y]), orientation=heading, velocity=speed,
                         time_step=0),
            TrajectoryPrediction(Trajectory(1, states), rectangle)))

    if uncertain:
        from commonroad.common.util import AngleInterval

        scenario.add_objects(StaticObstacle(
            13, ObstacleType.PARKED_VEHICLE, Rectangle(4.0, 2.0),
            InitialState(position=Rectangle(0.4, 0.2, center=np.array([60.0, 2.0])),
                         orientation=AngleInterval(math.pi / 2 - 0.1, math.pi / 2 + 0.1),
                         velocity=0.0, time_step=0)))
    if obstacles in ("both", "oncoming"):
        car(11, 90.0, -2.0, ONCOMING_MPS, math.pi)
    if ego_recording:  # the ego's own recording: at the start when the problem starts
        car(12, 5.0 - 10.0 * 0.1 * initial_time_step, 0.0, 10.0, 0.0)
    problems = []
    if planning_problem:
        goal = GoalRegion([CustomState(position=Rectangle(6.0, 7.0, center=np.array([80.0, 0.0])),
                                       time_step=Interval(*goal_steps))])
        problems.append(PlanningProblem(100, InitialState(
            position=np.array([5.0, 0.0]), orientation=0.0, velocity=10.0,
            time_step=initial_time_step, yaw_rate=0.0, slip_angle=0.0), goal))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the writer's notes on the defaults it fills in
        CommonRoadFileWriter(scenario, PlanningProblemSet(problems), author="tests",
                             affiliation="tests", source="tests", tags={Tag.URBAN}
                             ).write_to_file(str(path), OverwriteExistingFile.ALWAYS)
    return path


@pytest.fixture
def make_scenario_config(make_config):
    """``make_scenario_config(path, *overrides)``: the scenario config of
    ``scenario=commonroad`` on ``path``."""
    def make(path: Path, *overrides: str):
        return make_config(["scenario=commonroad", f"scenario.commonroad.path={path}",
                            *overrides]).scenario
    return make


def test_without_the_extra_it_says_in_one_line_how_to_install(monkeypatch, capsys, tmp_path):
    """Runs with or without the extra: the extra is hidden (an import of ``commonroad``
    fails), and ``scenario=commonroad`` prints the install line and exits 2, before anything
    else about the configuration (here the missing path)."""
    monkeypatch.setitem(sys.modules, "commonroad", None)
    assert commonroad_missing() == INSTALL_HINT
    with pytest.raises(MissingExtraError, match=r"pip install '\.\[commonroad\]'"):
        require_commonroad()
    monkeypatch.setattr(sys, "argv", ["pipeline.run", "scenario=commonroad",
                                      f"hydra.run.dir={tmp_path}"])
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    with pytest.raises(SystemExit) as exit_info:
        main()
    assert exit_info.value.code == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert lines == [f"config error: {INSTALL_HINT}"]


@needs_extra
@pytest.mark.parametrize("initial_time_step", [0, 5])
def test_the_reader_round_trips_a_scenario_written_by_commonroad_io(
        tmp_path, make_scenario_config, initial_time_step):
    path = write_scenario(tmp_path / "planted.xml", initial_time_step=initial_time_step,
                          goal_steps=(0, 100))
    case = read_commonroad(make_scenario_config(path, "scenario.commonroad.obstacle_disc="
                                                "circumscribed"))
    cfg = case.scenario_config
    # named by the file's stem (a file's benchmark id may be another file's name)
    assert cfg.name == "planted" and str(case.commonroad_scenario.scenario_id) == "ZAM_Planted-1"
    assert cfg.start_xy_m == [5.0, 0.0] and cfg.start_heading_rad == 0.0
    assert cfg.goal_xy_m == [80.0, 0.0]
    assert cfg.speed_mps == 10.0 and cfg.sample_time_s == 0.1
    assert cfg.n_steps == 100 - initial_time_step  # to the goal's last time step
    assert case.initial_time_step == initial_time_step
    assert case.obstacle_ids == (10, 11) and case.ego_recording_ids == (12,)
    ours = case.scenario
    assert ours.nearest_first
    assert ours.obstacle_radius_m == pytest.approx([0.5, math.hypot(CAR_LENGTH_M,
                                                                   CAR_WIDTH_M) / 2])
    # our time t is CommonRoad's time step initial_time_step + t / dt; the car is at
    # x = 90 - 4 t' (t' since its step 0), between samples too
    for time_s in (0.0, 1.0, 2.25):
        snap = ours.obstacles_at(time_s)
        elapsed = time_s + 0.1 * initial_time_step
        assert snap.positions_m[0] == pytest.approx([40.0, 0.8])
        assert snap.positions_m[1] == pytest.approx([90.0 - ONCOMING_MPS * elapsed, -2.0])
        assert snap.velocities_mps[1] == pytest.approx([-ONCOMING_MPS, 0.0])
        assert snap.velocities_mps[0] == pytest.approx([0.0, 0.0])
        assert snap.visible.tolist() == [True, True]
    # the car's recording ends at its step 79: invisible after that, the parked disc stays
    late = ours.obstacles_at(0.1 * (85 - initial_time_step))
    assert late.visible.tolist() == [True, False]


@needs_extra
def test_the_cover_makes_each_car_three_discs_along_its_heading(tmp_path, make_scenario_config,
                                                                make_config):
    """scenario.commonroad.obstacle_disc=cover (the default): the parked circle stays one disc;
    the oncoming car (heading pi, centre 90 - 4 t) is three discs of radius hypot(0.75, 0.9)
    at its centre and 1.5 m ahead and behind, each its own obstacle with the car's id; the ego
    is BMW_320i's rectangle covered the same way."""
    from pipeline.loop.commonroad_scenario import ego_cover_vehicle, vehicle_shape_m
    from pipeline.loop.cover import rectangle_cover

    path = write_scenario(tmp_path / "planted.xml", goal_steps=(0, 100))
    cfg = make_scenario_config(path)
    assert cfg.commonroad.obstacle_disc == "cover" and cfg.commonroad.cover_discs == 3
    case = read_commonroad(cfg)
    assert case.obstacle_ids == (10, 11, 11, 11)
    radius = math.hypot(CAR_LENGTH_M / 6, CAR_WIDTH_M / 2)
    assert case.scenario.obstacle_radius_m == pytest.approx([0.5, radius, radius, radius])
    snap = case.scenario.obstacles_at(1.0)
    centre = 90.0 - ONCOMING_MPS * 1.0
    # (the file holds the heading pi to its written digits: 1e-4 m across 1.5 m)
    assert sorted(snap.positions_m[1:, 0]) == pytest.approx([centre - 1.5, centre, centre + 1.5],
                                                            abs=1e-3)
    assert snap.positions_m[1:, 1] == pytest.approx([-2.0] * 3, abs=1e-3)
    vehicle = ego_cover_vehicle(make_config([]).vehicle, cfg.commonroad)
    length, width = vehicle_shape_m("BMW_320i")
    offsets, ego_radius = rectangle_cover(length, width, 3)
    assert vehicle.footprint_discs == 3
    assert vehicle.footprint_radius_m == pytest.approx(ego_radius)
    assert vehicle.footprint_offsets_m == pytest.approx(offsets)


@needs_extra
def test_the_other_disc_reading_and_no_ego_recording(tmp_path, make_scenario_config):
    path = write_scenario(tmp_path / "planted.xml", ego_recording=False)
    case = read_commonroad(make_scenario_config(path, "scenario.commonroad.obstacle_disc="
                                                "half_width"))
    assert case.ego_recording_ids == () and case.obstacle_ids == (10, 11)
    # a circle is its own disc; the car's disc has half its width
    assert case.scenario.obstacle_radius_m == pytest.approx([0.5, CAR_WIDTH_M / 2])


@needs_extra
def test_an_uncertain_position_and_orientation_read_as_their_middles(tmp_path,
                                                                     make_scenario_config):
    path = write_scenario(tmp_path / "planted.xml", obstacles="none", uncertain=True)
    case = read_commonroad(make_scenario_config(path, "scenario.commonroad.obstacle_disc="
                                                "circumscribed"))
    assert case.obstacle_ids == (13,)
    snap = case.scenario.obstacles_at(1.0)
    assert snap.positions_m[0] == pytest.approx([60.0, 2.0])
    assert snap.radii_m[0] == pytest.approx(math.hypot(4.0, 2.0) / 2)


@needs_extra
def test_the_source_builds_the_scenario_the_reader_makes(tmp_path, make_scenario_config):
    """build_scenario asks the CommonRoad source (scenario.source._target_): the file's
    recorded obstacles, as read_commonroad makes them (before the sources, a CommonRoad
    configuration built the scripted scenario of its empty obstacle list)."""
    from pipeline.loop.commonroad_scenario import CommonRoadScenario
    from pipeline.loop.scenario import build_scenario

    path = write_scenario(tmp_path / "planted.xml")
    cfg = make_scenario_config(path)
    built, read = build_scenario(cfg), read_commonroad(cfg).scenario
    # the parked circle and the car's three discs
    assert isinstance(built, CommonRoadScenario) and built.n_obstacles == 4
    for t in (0.0, 1.25, 4.0):
        a, b = built.obstacles_at(t), read.obstacles_at(t)
        assert np.array_equal(a.positions_m, b.positions_m)
        assert np.array_equal(a.visible, b.visible)


def _trajectory(case, poses: list[tuple[float, float, float]]) -> pd.DataFrame:
    """A logged run by hand: the ego at ``poses`` (x, y, heading) on consecutive steps, the
    obstacles as our scenario has them (the columns the loop logs)."""
    rows = []
    for k, (x, y, psi) in enumerate(poses):
        snap = case.scenario.obstacles_at(k * case.scenario.sample_time_s)
        row = {"time_s": k * 0.1, "X_m": x, "Y_m": y, "psi_rad": psi, "vx_mps": 10.0,
               "delta_rad": 0.0}
        for j in range(case.scenario.n_obstacles):
            row.update({f"obs{j}_x_m": snap.positions_m[j, 0], f"obs{j}_y_m": snap.positions_m[j, 1],
                        f"obs{j}_radius_m": snap.radii_m[j], f"obs{j}_visible": snap.visible[j]})
        rows.append(row)
    return pd.DataFrame(rows)


@needs_extra
def test_our_check_and_the_drivability_checker_agree_on_planted_geometry(
        tmp_path, make_scenario_config):
    """The parked disc (radius 0.5 at (40, 0.8)) against the ego as a 1 m disc (ours, and the
    checker on the same discs) and as a 4.5 x 1.8 car (the checker on the true shapes; the car
    of vehicle_type is not used here, the sizes are passed). Planted: a disc-only contact
    beside the car's flank, a car-only contact in front of its nose, both, neither."""
    from pipeline.analysis.commonroad_check import (
        checker_colliding_discs,
        checker_colliding_shapes,
        off_road_mask,
        ours_colliding,
        steps_before_first,
    )

    path = write_scenario(tmp_path / "planted.xml", obstacles="parked", ego_recording=False)
    case = read_commonroad(make_scenario_config(path))
    poses = [(40.0, 0.8 - 1.45, 0.0),     # centres 1.45 apart < 1.5: discs overlap; flank clear
             (40.0 - 1.6, 0.8, 0.0),      # 1.6 > 1.5: discs clear; nose 2.25 + 0.5 > 1.6
             (40.0 - 1.0, 0.8, 0.0),      # both
             (40.0, 0.8 - 6.0, 0.0),      # neither (and off the road: y = -5.2)
             (40.0, 0.8 - 1.45, math.pi / 2)]  # turned across: the car's nose reaches it
    trajectory = _trajectory(case, poses)
    ours = ours_colliding(trajectory, 1.0)
    assert ours.tolist() == [True, False, True, False, True]
    assert checker_colliding_discs(trajectory, 1.0).tolist() == ours.tolist()
    true, _, ours_true = checker_colliding_shapes(case, trajectory, CAR_LENGTH_M, CAR_WIDTH_M)
    assert true.tolist() == [False, True, True, False, True]
    # our own check on the true shapes (shapely) says the same on every planted pose
    assert ours_true.tolist() == true.tolist()
    _, clearance, _ = checker_colliding_shapes(
        case, trajectory.iloc[[3]].reset_index(drop=True), CAR_LENGTH_M, CAR_WIDTH_M)
    # (the drawn circle is a polygon through the disc's lowest point)
    assert clearance == pytest.approx(6.0 - CAR_WIDTH_M / 2 - 0.5, abs=1e-9)
    off_road = off_road_mask(case, trajectory, CAR_LENGTH_M, CAR_WIDTH_M)
    assert off_road.tolist() == [False, False, False, True, False]
    # off the road after the first contact (pose 1) counts for the whole run only; the same
    # poses with the off-road one first count before it too
    assert steps_before_first(ours_true, off_road) == 0
    first_off = [3, 0, 1, 2, 4]
    assert steps_before_first(ours_true[first_off], off_road[first_off]) == 1
    assert steps_before_first(np.zeros(5, bool), off_road) == 1  # no contact: the whole run


@needs_extra
@pytest.mark.parametrize("goal_steps, reached", [((0, 100), True), ((10, 100), False)])
def test_the_goal_by_commonroads_definition_checks_the_time_too(
        tmp_path, make_scenario_config, goal_steps, reached):
    from pipeline.analysis.commonroad_check import goal_by_commonroad

    path = write_scenario(tmp_path / "planted.xml", goal_steps=goal_steps)
    case = read_commonroad(make_scenario_config(path))
    # in the goal rectangle (80 +- 3, 0 +- 3.5) at steps 2 and 3, outside it at step 1
    trajectory = _trajectory(case, [(5.0, 0.0, 0.0), (70.0, 0.0, 0.0), (78.0, 1.0, 0.0),
                                    (82.0, -1.0, 0.0)])
    assert goal_by_commonroad(case, trajectory) == (reached, 3 if reached else None, "")


@needs_extra
def test_why_the_files_goal_and_our_goal_line_differ_is_said(tmp_path, make_scenario_config):
    """In the goal area at steps 2-3 but its time interval [10, 100] never met: the reason
    names the steps and the interval; reached at step 2 while our goal line was not: said so;
    both agree: no reason."""
    from pipeline.analysis.commonroad_check import goal_conditions_met, goal_disagreement

    poses = [(5.0, 0.0, 0.0), (70.0, 0.0, 0.0), (78.0, 1.0, 0.0), (82.0, -1.0, 0.0)]
    late = read_commonroad(make_scenario_config(
        write_scenario(tmp_path / "late.xml", goal_steps=(10, 100))))
    trajectory = _trajectory(late, poses)
    met, = goal_conditions_met(late, trajectory)
    assert met["position"].tolist() == [False, False, True, True]
    assert not met["time_step"].any() and met["velocity"].all()
    assert goal_disagreement(late, trajectory, False, True) == (
        "inside the goal area on time steps 2-3, never within its time_step interval")
    on_time = read_commonroad(make_scenario_config(
        write_scenario(tmp_path / "on_time.xml", goal_steps=(0, 100))))
    assert goal_disagreement(on_time, _trajectory(on_time, poses), True, False).startswith(
        "the goal region reached at time step 2;")
    assert goal_disagreement(on_time, _trajectory(on_time, poses), True, True) == ""


@needs_extra
def test_the_exported_trajectory_reads_back_as_a_commonroad_solution(
        tmp_path, make_scenario_config):
    from commonroad.common.solution import CommonRoadSolutionReader, VehicleModel, VehicleType

    path = write_scenario(tmp_path / "planted.xml", initial_time_step=5)
    case = read_commonroad(make_scenario_config(path))
    trajectory = _trajectory(case, [(5.0, 0.0, 0.0), (6.0, 0.01, 0.02), (7.0, 0.03, 0.04)])
    trajectory["delta_rad"] = [0.0, 0.1, -0.2]
    written = write_solution(ego_solution(case, trajectory, "BMW_320i"), tmp_path / "sol.xml")
    solution = CommonRoadSolutionReader.open(str(written))
    assert str(solution.scenario_id) == "ZAM_Planted-1"
    (answer,) = solution.planning_problem_solutions
    assert answer.planning_problem_id == 100
    assert answer.vehicle_model == VehicleModel.KS and answer.vehicle_type == VehicleType.BMW_320i
    states = answer.trajectory.state_list
    assert [s.time_step for s in states] == [5, 6, 7]
    assert [tuple(s.position) for s in states] == [(5.0, 0.0), (6.0, 0.01), (7.0, 0.03)]
    assert [s.orientation for s in states] == [0.0, 0.02, 0.04]
    assert [s.steering_angle for s in states] == [0.0, 0.1, -0.2]


@needs_extra
def test_a_run_on_a_planted_scenario_reaches_the_end_and_reports_both_verdicts(
        tmp_path, make_config):
    """The oncoming car alone, in the other lane: the run ends at the goal line; both checks
    speak, the checker on our discs agrees with ours on every step, and the exported
    trajectory is the logged one."""
    from commonroad.common.solution import CommonRoadSolutionReader

    from pipeline.store.runs import read_run
    from pipeline.studies.commonroad import run_commonroad
    from pipeline.studies.results.commonroad import CommonRoadResult

    path = write_scenario(tmp_path / "planted.xml", obstacles="oncoming")
    cfg = make_config(["scenario=commonroad", f"scenario.commonroad.path={path}"])
    done = run_commonroad(cfg, tmp_path / "run")
    record = read_run(tmp_path / "run")
    assert record.config.scenario.speed_mps == 10.0  # the scenario's own speed, recorded
    assert record.config.scenario.goal_xy_m == [80.0, 0.0]
    assert done.run.info.termination == "goal_line"
    summary = CommonRoadResult.load(tmp_path / "run").summary
    verdicts = summary["verdicts"]
    assert verdicts["steps"] == len(record.trajectory)
    assert verdicts["agreement_same_geometry_steps"] == verdicts["steps"]
    for key in ("ours_collision", "checker_same_geometry_collision",
                "checker_true_shapes_collision", "goal_reached_commonroad"):
        assert isinstance(verdicts[key], bool)
    assert verdicts["ours_collision"] is False and verdicts["checker_true_shapes_collision"] \
        is False
    assert verdicts["min_clearance_true_shapes_m"] > 0.0
    assert summary["file"]["ego_recording_dropped"] == [12]
    states = CommonRoadSolutionReader.open(
        str(CommonRoadResult.solution_path(tmp_path / "run"))
    ).planning_problem_solutions[0].trajectory.state_list
    assert len(states) == len(record.trajectory)
    assert states[-1].position == pytest.approx(record.trajectory[["X_m", "Y_m"]].iloc[-1],
                                                abs=1e-8)


@needs_extra
def test_bad_files_are_one_line_each(tmp_path, make_scenario_config):
    not_xml = tmp_path / "notes.xml"
    not_xml.write_text("hello")
    other = tmp_path / "map.xml"
    other.write_text("<osm><node/></osm>")
    no_problem = write_scenario(tmp_path / "no_problem.xml", planning_problem=False)
    cases = [(tmp_path / "missing.xml", "no such file"), (not_xml, "not XML"),
             (other, "root element is <osm>, not <commonRoad>"),
             (no_problem, "with a planning problem (this file has none")]
    for path, reason in cases:
        with pytest.raises(ConfigError) as info:
            read_commonroad(make_scenario_config(path))
        line = str(info.value)
        assert "\n" not in line and "scenario.commonroad.path" in line and reason in line, line


@needs_extra
@pytest.mark.parametrize("content, reason", [
    (None, "no such file"), ("<osm><node/></osm>", "not <commonRoad>")])
def test_bad_files_exit_2_with_one_line(monkeypatch, capsys, tmp_path, content, reason):
    path = tmp_path / "scenario.xml"
    if content is not None:
        path.write_text(content)
    monkeypatch.setattr(sys, "argv", ["pipeline.run", "scenario=commonroad",
                                      f"scenario.commonroad.path={path}",
                                      f"hydra.run.dir={tmp_path / 'run'}"])
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    with pytest.raises(SystemExit) as exit_info:
        main()
    assert exit_info.value.code == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("config error: scenario.commonroad.path=")
    assert reason in lines[0]


@needs_extra
def test_a_goal_beyond_the_run_bound_is_named_as_the_files_goal(tmp_path, make_scenario_config):
    """A goal time interval ending at step 5,000,000 was refused as ``scenario.n_steps``, a key
    the user never set; now the line names the file (its key) and its goal, and how to run
    fewer steps; with ``scenario.commonroad.n_steps`` set the same file reads."""
    path = write_scenario(tmp_path / "late goal.xml", goal_steps=(0, 5_000_000))
    with pytest.raises(ConfigError) as info:
        read_commonroad(make_scenario_config(f"'{path}'"))
    message = str(info.value)
    assert info.value.key == "scenario.commonroad.path" and "late goal.xml" in message
    assert "goal or recording ends 5000000 steps after time step 0" in message
    assert "scenario.commonroad.n_steps" in message and "scenario.n_steps" not in \
        message.replace("scenario.commonroad.n_steps", "")
    case = read_commonroad(make_scenario_config(f"'{path}'", "scenario.commonroad.n_steps=50"))
    assert case.scenario_config.n_steps == 50


@needs_extra
def test_make_commonroad_takes_a_path_with_spaces(tmp_path):
    """``make commonroad COMMONROAD='a dir/my scene.xml'`` quotes the path for Hydra (it was a
    parse error) and names the runs' folder after the file (issue 62, item 10)."""
    import subprocess

    root = Path(__file__).resolve().parents[2]
    (tmp_path / "a dir").mkdir()
    path = write_scenario(tmp_path / "a dir" / "my scene.xml")
    proc = subprocess.run(["make", "--no-print-directory", "commonroad", f"COMMONROAD={path}",
                           f"RUNS={tmp_path / 'out'}"], cwd=root, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    for method in ("improved", "baseline"):
        assert (tmp_path / "out" / "commonroad" / "my scene" / method / "manifest.json").is_file()


def test_a_line_of_sight_is_blocked_exactly_where_it_crosses_the_rectangle():
    """Closed form: from (0, 0) the segment to (10, h) crosses the square x in [4, 6],
    y in [-1, 1] iff 4 |h| / 10 <= 1; a target inside its own rectangle is not hidden by it;
    a viewer inside a rectangle is hidden nothing by it."""
    from pipeline.loop.commonroad_scenario import occluded

    square = np.array([[[4.0, -1.0], [6.0, -1.0], [6.0, 1.0], [4.0, 1.0]]])
    heights = np.linspace(-4.0, 4.0, 81)
    targets = np.stack([np.full(81, 10.0), heights], axis=1)
    hidden = occluded(np.zeros(2), targets, square, np.full(81, -1))
    assert hidden.tolist() == (np.abs(heights) * 0.4 <= 1.0 + 1e-12).tolist()
    inside = np.array([[5.0, 0.0], [12.0, 0.0]])
    assert occluded(np.zeros(2), inside, square, np.array([0, -1])).tolist() == [False, True]
    assert not occluded(np.array([5.0, 0.5]), targets, square, np.full(81, -1)).any()


@needs_extra
def test_a_walker_behind_a_parked_car_is_seen_once_the_line_of_sight_clears(
        tmp_path, make_scenario_config):
    """A parked car (x in [18, 22.5], y in [1.5, 3.3]) and a walker crossing at x = 25 from
    y = 6 towards the road: from the ego at (0, 0) the line to the walker at (25, y) crosses
    the car iff 22.5 y / 25 >= 1.5 and 18 y / 25 <= 3.3 (closed form: y in [1.667, 4.583]);
    within the ego's reach a walker is always seen; without occlusion it is seen throughout."""
    import warnings

    from commonroad.common.file_writer import CommonRoadFileWriter, OverwriteExistingFile
    from commonroad.common.util import Interval
    from commonroad.geometry.shape import Circle, Rectangle
    from commonroad.planning.goal import GoalRegion
    from commonroad.planning.planning_problem import PlanningProblem, PlanningProblemSet
    from commonroad.prediction.prediction import TrajectoryPrediction
    from commonroad.scenario.obstacle import DynamicObstacle, ObstacleType, StaticObstacle
    from commonroad.scenario.scenario import Scenario, ScenarioID, Tag
    from commonroad.scenario.state import CustomState, InitialState
    from commonroad.scenario.trajectory import Trajectory

    scenario = Scenario(dt=0.1, scenario_id=ScenarioID(country_id="ZAM", map_name="Hidden",
                                                        map_id=1))
    scenario.add_objects(StaticObstacle(20, ObstacleType.PARKED_VEHICLE, Rectangle(4.5, 1.8),
                                        InitialState(position=np.array([20.25, 2.4]),
                                                     orientation=0.0, velocity=0.0,
                                                     time_step=0)))
    states = [CustomState(position=np.array([25.0, 6.0 - 0.15 * k]), orientation=-math.pi / 2,
                          velocity=1.5, time_step=k) for k in range(1, 60)]
    scenario.add_objects(DynamicObstacle(
        21, ObstacleType.PEDESTRIAN, Circle(0.3),
        InitialState(position=np.array([25.0, 6.0]), orientation=-math.pi / 2, velocity=1.5,
                     time_step=0),
        TrajectoryPrediction(Trajectory(1, states), Circle(0.3))))
    goal = GoalRegion([CustomState(position=Rectangle(6.0, 7.0, center=np.array([60.0, 0.0])),
                                   time_step=Interval(0, 59))])
    problem = PlanningProblem(100, InitialState(position=np.array([-30.0, 0.0]),
                                                orientation=0.0, velocity=5.0, time_step=0,
                                                yaw_rate=0.0, slip_angle=0.0), goal)
    path = tmp_path / "hidden.xml"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        CommonRoadFileWriter(scenario, PlanningProblemSet([problem]), author="tests",
                             affiliation="tests", source="tests", tags={Tag.URBAN}
                             ).write_to_file(str(path), OverwriteExistingFile.ALWAYS)
    case = read_commonroad(make_scenario_config(path))
    ours = case.scenario
    assert ours.senses and ours.occluders_m.shape == (1, 4, 2)
    walker = [j for j, i in enumerate(case.obstacle_ids) if i == 21]
    assert len(walker) == 1
    seen, heights = [], []
    for k in range(60):
        snap = ours.obstacles_at(0.1 * k)
        heights.append(float(snap.positions_m[walker[0], 1]))
        seen.append(bool(ours.sense(snap, np.zeros(2), 1.0).visible[walker[0]]))
    heights_arr = np.array(heights)
    expected = ~((22.5 * heights_arr / 25 >= 1.5) & (18 * heights_arr / 25 <= 3.3))
    assert seen == expected.tolist() and not all(seen) and any(seen)
    # the parked car's own discs are never hidden by it
    parked = [j for j, i in enumerate(case.obstacle_ids) if i == 20]
    assert ours.sense(ours.obstacles_at(0.0), np.zeros(2), 1.0).visible[parked].all()
    # within the ego's reach (its centre distance <= reach + radius): seen though behind
    snap = ours.obstacles_at(0.1 * 15)        # the walker at y = 3.75, 25.3 m from (0, 0)
    assert not ours.sense(snap, np.zeros(2), 24.9).visible[walker[0]]
    assert ours.sense(snap, np.zeros(2), 25.1).visible[walker[0]]
    # ... whatever the sensor range
    from dataclasses import replace
    assert replace(ours, sensor_range_m=1.0).sense(snap, np.zeros(2), 25.1).visible[walker[0]]
    assert not replace(ours, sensor_range_m=1.0).sense(snap, np.zeros(2), 1.0).visible[walker[0]]
    plain = read_commonroad(make_scenario_config(path, "scenario.commonroad.occlusion=false",
                                                 "scenario.commonroad.sensor_range_m=null"))
    assert not plain.scenario.senses


def test_the_point_ahead_on_a_route_is_measured_along_it():
    """An L-shaped route (0, 0) -> (10, 0) -> (10, 10): from (4, 1) (projection (4, 0)) 3 m
    ahead is (7, 0), 8 m ahead (10, 2) round the corner; past the end, None."""
    from pipeline.loop.scenario import route_point_ahead

    route = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]]
    assert route_point_ahead(route, 4.0, 1.0, 3.0, -1.0, -1.0) == pytest.approx((7.0, 0.0))
    assert route_point_ahead(route, 4.0, 1.0, 8.0, -1.0, -1.0) == pytest.approx((10.0, 2.0))
    assert route_point_ahead(route, 4.0, 1.0, 17.0, -1.0, -1.0) == (-1.0, -1.0)  # past the end


@needs_extra
def test_the_route_is_the_shortest_lanelet_path_and_the_attraction_follows_it(
        tmp_path, make_scenario_config):
    """The planted road (one lanelet, y in [-3.5, 3.5], its centre y = 0) holds start and goal:
    the route is its centreline; with route_lookahead_m = 20 the attraction from (5, 1) is the
    point 20 m along it beyond the projection (5, 0), (25, 0); without the key, the goal
    point."""
    from pipeline.loop.commonroad_scenario import route_centreline

    path = write_scenario(tmp_path / "planted.xml")
    case = read_commonroad(make_scenario_config(path, "scenario.commonroad.route_lookahead_m=20"))
    network = case.commonroad_scenario.lanelet_network
    route = route_centreline(network, np.array([5.0, 1.0]), np.array([80.0, 1.0]))
    assert route[0] == pytest.approx([0.0, 0.0]) and route[-1] == pytest.approx([150.0, 0.0])
    ours = case.scenario
    assert ours.follows_road
    assert ours.attraction_goal_m(np.array([5.0, 1.0])) == pytest.approx([25.0, 0.0])
    plain = read_commonroad(make_scenario_config(
        path, "scenario.commonroad.route_lookahead_m=null",
        "scenario.commonroad.route_lookahead_s=null")).scenario
    assert not plain.follows_road
    assert read_commonroad(make_scenario_config(path)).scenario.attraction_route[1:] \
        == (10.0, 2.0)  # the defaults
    assert plain.attraction_goal_m(np.array([5.0, 0.0])).tolist() == plain.goal_m.tolist()
    # no lanelet under the start: no route
    assert route_centreline(network, np.array([5.0, -20.0]), None).shape == (0, 2)


@needs_extra
def test_the_route_changes_lane_to_reach_a_goal_in_the_other_lane():
    """Two lanes of two lanelets each (right: 1 -> 2, centre y = 0; left: 3 -> 4, centre
    y = 3.5; 1 and 3 neighbours in the same direction): from x = 5 in the right lane to a goal
    in lanelet 4 the route changes lanes at once (from lanelet 1's first vertex to the left
    lane, which it follows to (100, 3.5)); to a goal in lanelet 2 it stays right."""
    from commonroad.scenario.lanelet import Lanelet, LaneletNetwork

    from pipeline.loop.commonroad_scenario import route_centreline

    def lane(lanelet_id, x0, y, successor, left=None):
        xs = np.linspace(x0, x0 + 50.0, 11)
        return Lanelet(np.stack([xs, np.full(11, y + 1.75)], 1),
                       np.stack([xs, np.full(11, y)], 1),
                       np.stack([xs, np.full(11, y - 1.75)], 1), lanelet_id,
                       successor=successor, adjacent_left=left,
                       adjacent_left_same_direction=True if left else None)

    network = LaneletNetwork.create_from_lanelet_list([
        lane(1, 0.0, 0.0, [2], left=3), lane(2, 50.0, 0.0, []),
        lane(3, 0.0, 3.5, [4]), lane(4, 50.0, 3.5, [])])
    left = route_centreline(network, np.array([5.0, 0.0]), np.array([90.0, 3.5]))
    assert left[0] == pytest.approx([0.0, 0.0]) and left[-1] == pytest.approx([100.0, 3.5])
    # the change is made at once (at the start of lanelet 1), not at its end
    assert left[1] == pytest.approx([0.0, 3.5]) and np.allclose(left[1:, 1], 3.5)
    assert (left[1:, 0] >= left[:-1, 0] - 1e-9).all()   # never back along the road
    right = route_centreline(network, np.array([5.0, 0.0]), np.array([90.0, 0.0]))
    assert right[-1] == pytest.approx([100.0, 0.0]) and np.allclose(right[:, 1], 0.0)


@needs_extra
def test_lanelets_with_a_hairline_gap_are_one_road_once_widened():
    """Two lanelets side by side, y in [0, 3.5] and [-3.52, -0.02]: a 2 cm gap between their
    edges (USA_US101-23_1's lanelets leave up to 3 cm). As they are, the MPC's road reach
    along the normal at (50, 1.75) is the upper lanelet alone (low -1.75, high 1.75: the ego
    held in its lane) and a 4.5 x 1.8 car at (50, 0), over the gap, is off the road; each
    widened by lanelet_gap_m / 2 = 3 cm (``scenario.commonroad.lanelet_gap_m=0.06``), the
    reach is the whole road (low -(1.75 + 3.52 + 0.03), high 1.75 + 0.03) and that car is on
    it. A car at (50, 3.0) reaches y = 3.9, over the top edge, either way; one at (50, 1.75)
    is inside the upper lanelet either way."""
    from types import SimpleNamespace

    from commonroad.scenario.lanelet import Lanelet, LaneletNetwork

    from pipeline.analysis.commonroad_check import off_road_mask
    from pipeline.loop.commonroad_scenario import road_polygons
    from pipeline.loop.controller.road import road_interval

    xs = np.linspace(0.0, 100.0, 11)

    def line(y: float) -> np.ndarray:
        return np.stack([xs, np.full(xs.size, y)], 1)

    network = LaneletNetwork.create_from_lanelet_list([
        Lanelet(line(3.5), line(1.75), line(0.0), 1),
        Lanelet(line(-0.02), line(-1.77), line(-3.52), 2)])
    station, normal = np.array([[50.0, 1.75]]), np.array([[0.0, 1.0]])
    low, high, _, _ = road_interval(station, normal, road_polygons(network, 0.0))
    assert (low[0], high[0]) == pytest.approx((-1.75, 1.75), abs=1e-9)
    low, high, _, _ = road_interval(station, normal, road_polygons(network, 0.06))
    assert (low[0], high[0]) == pytest.approx((-(1.75 + 3.52 + 0.03), 1.75 + 0.03), abs=1e-9)
    poses = pd.DataFrame({"X_m": [50.0, 50.0, 50.0], "Y_m": [0.0, 1.75, 3.0],
                          "psi_rad": [0.0, 0.0, 0.0]})
    for gap, expected in ((0.0, [True, False, True]), (0.06, [False, False, True])):
        case = SimpleNamespace(scenario=SimpleNamespace(
            road_polygons_m=road_polygons(network, gap)))
        assert off_road_mask(case, poses, CAR_LENGTH_M, CAR_WIDTH_M).tolist() == expected, gap


@needs_extra
def test_the_key_widens_the_road_the_scenario_hands_the_mpc(tmp_path, make_scenario_config):
    """scenario.commonroad.lanelet_gap_m reaches the scenario's road: the planted lanelet
    (y in [-3.5, 3.5], x in [0, 150]) as it is at 0, 3 cm wider to every side at the default
    0.06 (its bounding box)."""
    path = write_scenario(tmp_path / "planted.xml")
    exact = read_commonroad(make_scenario_config(path, "scenario.commonroad.lanelet_gap_m=0"))
    widened = read_commonroad(make_scenario_config(path))
    (road_exact,) = exact.scenario.road_polygons_m
    (road_widened,) = widened.scenario.road_polygons_m
    assert road_exact.min(axis=0) == pytest.approx([0.0, -3.5], abs=1e-12)
    assert road_exact.max(axis=0) == pytest.approx([150.0, 3.5], abs=1e-12)
    assert road_widened.min(axis=0) == pytest.approx([-0.03, -3.53], abs=1e-9)
    assert road_widened.max(axis=0) == pytest.approx([150.03, 3.53], abs=1e-9)
