"""A CommonRoad run judged twice: by our own checks and by CommonRoad's drivability checker.

A run's verdict is our own check on the true shapes: the ego as its car rectangle
(``vehicle_type``'s length and width, centred on the logged position along the logged heading)
and each obstacle as the file's shape at that time step, in contact where shapely's polygon
distance (GEOS, a library independent of the checker's) is 0. The drivability checker
(commonroad-drivability-checker, an independent C++ collision library) is asked the same at
every logged step, and its verdict must equal ours on every step.

Beside it, what our methods see (:func:`~pipeline.analysis.metrics.geometry.clearance_series`,
``ours_collision_steps``): the ego as its discs (``vehicle.footprint_radius_m`` at
``vehicle.footprint_discs`` centres along its heading; under ``obstacle_disc=cover`` its
rectangle's cover) and each obstacle as its discs, checked by the drivability checker too on
the same geometry: where it and our disc check disagree, one of the two checks is wrong. Where
the discs and the true shapes differ, the discs are the reason: a cover holds its rectangle,
so it sees contact a few steps longer.

Beside the verdicts: the clearance between the true shapes (shapely's polygon distance; a
circle at its full radius, not at the half radius of commonroad-io's own shapely circle), the
steps on which the car rectangle is not inside the road (the union of the lanelets), and whether
the goal was reached by CommonRoad's own definition (``PlanningProblem.goal_reached``: position,
time step, and any speed or orientation interval of the goal region).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import pandas as pd

from pipeline.analysis.metrics.geometry import clearance_series, ego_disc_view
from pipeline.loop.commonroad_scenario import CommonRoadCase, ego_states, shape_geometry
from pipeline.loop.trajectory import obstacle_indices


@dataclass(frozen=True)
class CommonRoadVerdicts:
    """Per-run counts over the logged steps (see the module docstring).

    Attributes
    ----------
    steps : int
    ours_collision_steps, checker_same_geometry_collision_steps,
    checker_true_shapes_collision_steps : int
        Steps on which each check sees a collision.
    agreement_same_geometry_steps, agreement_true_shapes_steps : int
        Steps on which the checker's verdict equals ours.
    min_clearance_ours_m : float
        Smallest sampled disc clearance (NaN when no obstacle is ever present).
    min_clearance_true_shapes_m : float
        Smallest distance between the car rectangle and an obstacle's shape (0 in contact).
    off_road_steps : int
        Steps on which the car rectangle is not inside the union of the lanelets, over the
        whole run.
    goal_reached_commonroad : bool
    goal_time_step : int or None
        The CommonRoad time step of the last state in the goal region.
    goal_note : str
        Why the goal could not be judged ("" when it was).
    goal_line_reached : bool
        Whether the run ended at our goal line (shown beside the file's goal).
    goal_disagreement : str
        Why the file's goal and our goal line disagree ("" when they agree:
        :func:`goal_disagreement`).
    """

    steps: int
    ours_collision_steps: int
    checker_same_geometry_collision_steps: int
    checker_true_shapes_collision_steps: int
    agreement_same_geometry_steps: int
    agreement_true_shapes_steps: int
    min_clearance_ours_m: float
    min_clearance_true_shapes_m: float
    off_road_steps: int
    goal_reached_commonroad: bool
    goal_time_step: int | None
    goal_note: str
    goal_line_reached: bool = False
    goal_disagreement: str = ""
    #: our own check on the true shapes (shapely's distance 0 between the car rectangle and
    #: an obstacle's shape) and the steps on which the checker's true-shape verdict equals it
    ours_true_shapes_collision_steps: int = 0
    agreement_ours_true_shapes_steps: int = 0
    #: steps off the road before the first contact on the true shapes (the whole run without
    #: one; -1: a result written before it): the field's convention that nothing after a
    #: crash is judged, as the Euro NCAP outcome reads its runs up to their first true overlap
    off_road_steps_before_contact: int = -1

    @property
    def ours_true_shapes_collision(self) -> bool:
        return self.ours_true_shapes_collision_steps > 0

    @property
    def success(self) -> bool:
        """The file's criterion: its goal region reached (position, time, orientation and speed
        intervals) without touching anything on the true shapes, by the run's verdict (our own
        check on the true shapes, which the checker's must equal on every step)."""
        return self.goal_reached_commonroad and not self.ours_true_shapes_collision

    @property
    def ours_collision(self) -> bool:
        return self.ours_collision_steps > 0

    @property
    def checker_same_geometry_collision(self) -> bool:
        return self.checker_same_geometry_collision_steps > 0

    @property
    def checker_true_shapes_collision(self) -> bool:
        return self.checker_true_shapes_collision_steps > 0

    def to_json(self) -> dict[str, Any]:
        data = asdict(self)
        data.update(ours_collision=self.ours_collision,
                    ours_true_shapes_collision=self.ours_true_shapes_collision,
                    checker_same_geometry_collision=self.checker_same_geometry_collision,
                    checker_true_shapes_collision=self.checker_true_shapes_collision,
                    success=self.success)
        for key in ("min_clearance_ours_m", "min_clearance_true_shapes_m"):
            data[key] = None if not np.isfinite(data[key]) else float(data[key])
        return data


def ours_colliding(trajectory: pd.DataFrame, ego_radius_m: float,
                   ego_offsets_m: tuple[float, ...] = (0.0,)) -> np.ndarray:
    """Our verdict per logged step: one of the ego's discs (``ego_offsets_m`` ahead of the
    logged position along its heading) overlaps a present obstacle's disc."""
    gaps = clearance_series(ego_disc_view(trajectory, ego_offsets_m), ego_radius_m)
    return np.nan_to_num(gaps, nan=np.inf) < 0.0


def checker_colliding_discs(trajectory: pd.DataFrame, ego_radius_m: float,
                            ego_offsets_m: tuple[float, ...] = (0.0,)) -> np.ndarray:
    """The drivability checker's verdict per logged step on our geometry (the ego's discs and
    the obstacles' discs as logged)."""
    from commonroad_dc import pycrcc

    x, y = trajectory["X_m"].to_numpy(float), trajectory["Y_m"].to_numpy(float)
    psi = trajectory["psi_rad"].to_numpy(float)
    hits = np.zeros(len(trajectory), bool)
    for j in obstacle_indices(trajectory.columns):
        ox, oy = trajectory[f"obs{j}_x_m"].to_numpy(float), \
            trajectory[f"obs{j}_y_m"].to_numpy(float)
        radius = trajectory[f"obs{j}_radius_m"].to_numpy(float)
        visible = trajectory[f"obs{j}_visible"].to_numpy(bool)
        for k in np.flatnonzero(visible & ~hits):
            other = pycrcc.Circle(float(radius[k]), float(ox[k]), float(oy[k]))
            c, s = float(np.cos(psi[k])), float(np.sin(psi[k]))
            hits[k] = any(pycrcc.Circle(ego_radius_m, float(x[k]) + d * c,
                                        float(y[k]) + d * s).collide(other)
                          for d in ego_offsets_m)
    return hits


def ego_rectangles(trajectory: pd.DataFrame, length_m: float, width_m: float) -> list[Any]:
    """The car rectangle at each logged step (shapely polygons, centred on the logged
    position, along the logged heading)."""
    from shapely.geometry import Polygon

    half = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]]) * [length_m / 2.0, width_m / 2.0]
    out = []
    for x, y, psi in trajectory[["X_m", "Y_m", "psi_rad"]].to_numpy(float):
        c, s = np.cos(psi), np.sin(psi)
        out.append(Polygon(half @ np.array([[c, s], [-s, c]]) + [x, y]))
    return out


def checker_colliding_shapes(case: CommonRoadCase, trajectory: pd.DataFrame,
                             length_m: float, width_m: float
                             ) -> tuple[np.ndarray, float, np.ndarray]:
    """The drivability checker's verdict per logged step on the true shapes (the car rectangle
    against every obstacle the file has at that time step, the ego's recording left out), the
    smallest distance between the true shapes, and our own verdict on them per step: the
    shapes' distance 0 (shapely, GEOS: a geometry library independent of the checker's)."""
    from commonroad_dc import pycrcc
    from commonroad_dc.collision.collision_detection.pycrcc_collision_dispatch import (
        create_collision_checker,
    )

    kept = [o for o in case.commonroad_scenario.obstacles
            if o.obstacle_id in set(case.obstacle_ids)]
    checker = create_collision_checker(_scenario_with(case.commonroad_scenario, kept))
    xy = trajectory[["X_m", "Y_m", "psi_rad"]].to_numpy(float)
    hits = np.zeros(len(trajectory), bool)
    ours = np.zeros(len(trajectory), bool)
    nearest = np.inf
    for k, ((x, y, psi), rectangle) in enumerate(zip(xy, ego_rectangles(trajectory, length_m,
                                                                        width_m), strict=True)):
        step = case.initial_time_step + k
        ego = pycrcc.RectOBB(length_m / 2.0, width_m / 2.0, float(psi), float(x), float(y))
        hits[k] = checker.time_slice(step).collide(ego)
        for obstacle in kept:
            occupancy = obstacle.occupancy_at_time(step)
            if occupancy is not None:
                gap = rectangle.distance(shape_geometry(occupancy.shape))
                nearest = min(nearest, gap)
                ours[k] = ours[k] or gap <= 0.0
    return hits, float(nearest), ours


def _scenario_with(scenario: Any, obstacles: list[Any]) -> Any:
    """A copy of ``scenario`` that holds only ``obstacles`` (the checker's input)."""
    from commonroad.scenario.scenario import Scenario

    copy = Scenario(scenario.dt, scenario.scenario_id)
    copy.add_objects(list(obstacles))
    return copy


def off_road_mask(case: CommonRoadCase, trajectory: pd.DataFrame, length_m: float,
                  width_m: float) -> np.ndarray:
    """Per logged step, whether the car rectangle is not inside the road: the union of the
    lanelets as the MPC has them (each widened by ``scenario.commonroad.lanelet_gap_m / 2``,
    :func:`~pipeline.loop.commonroad_scenario.road_polygons`), with 1 mm of tolerance; never
    for a file without lanelets."""
    from shapely.geometry import Polygon
    from shapely.ops import unary_union

    polygons = case.scenario.road_polygons_m
    if not polygons:
        return np.zeros(len(trajectory), bool)
    road = unary_union([Polygon(vertices).buffer(0) for vertices in polygons]).buffer(1e-3)
    return np.array([not road.contains(r) for r in ego_rectangles(trajectory, length_m,
                                                                   width_m)], bool)


def steps_before_first(flags: np.ndarray, counted: np.ndarray) -> int:
    """How many of ``counted``'s steps come before the first step ``flags`` holds (all of
    them when it never does)."""
    hits = np.flatnonzero(flags)
    end = int(hits[0]) if hits.size else len(counted)
    return int(np.count_nonzero(counted[:end]))


def goal_by_commonroad(case: CommonRoadCase, trajectory: pd.DataFrame
                       ) -> tuple[bool, int | None, str]:
    """``PlanningProblem.goal_reached`` on our run's states: reached, the time step of the last
    state in the goal region, and why it could not be judged ("" when it was)."""
    from commonroad.scenario.trajectory import Trajectory

    states = ego_states(trajectory, case.initial_time_step)
    try:
        reached, index = case.planning_problem.goal_reached(
            Trajectory(case.initial_time_step, states))
    except ValueError as exc:  # a goal on a state field the run does not have
        return False, None, (str(exc).splitlines() or [""])[0][:200]
    return bool(reached), (int(states[index].time_step) if reached else None), ""


#: The goal region's conditions, in the order they are named when none of a step's holds
GOAL_CONDITIONS = ("position", "time_step", "orientation", "velocity")


def goal_conditions_met(case: CommonRoadCase, trajectory: pd.DataFrame
                        ) -> list[dict[str, np.ndarray]]:
    """For each of the goal region's states, on which logged steps each condition
    (:data:`GOAL_CONDITIONS`) holds; a condition that goal state does not set holds on every
    step. The goal is reached on a step where every condition of one goal state holds."""
    states = ego_states(trajectory, case.initial_time_step)
    out = []
    for goal in case.planning_problem.goal.state_list:
        met = {name: np.ones(len(states), bool) for name in GOAL_CONDITIONS}
        for name in GOAL_CONDITIONS:
            condition = getattr(goal, name, None)
            if condition is None:
                continue
            for k, state in enumerate(states):
                if name == "position":
                    met[name][k] = bool(condition.contains_point(np.asarray(state.position)))
                elif name == "orientation":  # the heading taken into [start, start + 2 pi)
                    turned = condition.start + (float(state.orientation) - condition.start) \
                        % (2 * math.pi)
                    met[name][k] = bool(condition.start <= turned <= condition.end)
                else:
                    met[name][k] = bool(condition.contains(getattr(state, name)))
        out.append(met)
    return out


def goal_disagreement(case: CommonRoadCase, trajectory: pd.DataFrame, reached_file: bool,
                      reached_line: bool) -> str:
    """Why the file's goal (the success criterion) and our goal line disagree for one run, in
    one sentence ("" when they agree): the steps in the goal area and the conditions they
    missed (of the goal state that missed fewest), or the step the goal region was reached
    while our goal line was not."""
    if reached_file == reached_line:
        return ""
    t0 = case.initial_time_step
    per_state = goal_conditions_met(case, trajectory)
    if reached_file:
        every = np.logical_or.reduce([np.logical_and.reduce([met[n] for n in GOAL_CONDITIONS])
                                      for met in per_state])
        first = int(np.flatnonzero(every)[0]) if every.any() else 0
        return (f"the goal region reached at time step {t0 + first}; the run ended "
                f"({len(trajectory)} steps) before our goal line")
    candidates = []
    for met in per_state:
        inside = np.flatnonzero(met["position"])
        if inside.size:
            missed = [n for n in GOAL_CONDITIONS[1:] if not met[n][inside].any()]
            candidates.append((len(missed), inside, missed))
    if not candidates:
        return "never inside the goal area; our goal line crossed"
    _, inside, missed = min(candidates, key=lambda c: c[0])
    span = f"time steps {t0 + int(inside[0])}-{t0 + int(inside[-1])}"
    if missed:
        return f"inside the goal area on {span}, never within its {' and '.join(missed)} interval"
    return f"inside the goal area on {span}, never with every condition at once"


def judge_commonroad_run(case: CommonRoadCase, trajectory: pd.DataFrame, ego_radius_m: float,
                         length_m: float, width_m: float,
                         ego_offsets_m: tuple[float, ...] = (0.0,),
                         goal_line_reached: bool = False) -> CommonRoadVerdicts:
    """Both checks, the road and the goal for one logged run (see the module docstring); the
    ego as discs of ``ego_radius_m`` at ``ego_offsets_m`` along its heading; whether the run
    ended at our goal line (``goal_line_reached``), shown beside the file's goal."""
    ours = ours_colliding(trajectory, ego_radius_m, ego_offsets_m)
    same = checker_colliding_discs(trajectory, ego_radius_m, ego_offsets_m)
    true, true_clearance, ours_true = checker_colliding_shapes(case, trajectory, length_m,
                                                               width_m)
    gaps = clearance_series(ego_disc_view(trajectory, ego_offsets_m), ego_radius_m)
    off_road = off_road_mask(case, trajectory, length_m, width_m)
    reached, goal_step, note = goal_by_commonroad(case, trajectory)
    return CommonRoadVerdicts(
        steps=len(trajectory), ours_collision_steps=int(ours.sum()),
        checker_same_geometry_collision_steps=int(same.sum()),
        checker_true_shapes_collision_steps=int(true.sum()),
        agreement_same_geometry_steps=int((ours == same).sum()),
        agreement_true_shapes_steps=int((ours == true).sum()),
        min_clearance_ours_m=float(np.nanmin(gaps)) if np.isfinite(gaps).any() else np.nan,
        min_clearance_true_shapes_m=true_clearance,
        off_road_steps=int(off_road.sum()),
        off_road_steps_before_contact=steps_before_first(ours_true, off_road),
        goal_reached_commonroad=reached, goal_time_step=goal_step, goal_note=note,
        goal_line_reached=goal_line_reached,
        ours_true_shapes_collision_steps=int(ours_true.sum()),
        agreement_ours_true_shapes_steps=int((ours_true == true).sum()),
        goal_disagreement="" if note else goal_disagreement(case, trajectory, reached,
                                                            goal_line_reached))
