"""``scenario=commonroad``: one method on a CommonRoad scenario, judged by our check and by
CommonRoad's drivability checker (docs/commonroad.md).

:func:`run_commonroad` reads the file (:func:`~pipeline.loop.commonroad_scenario.
read_commonroad`), simulates the configured method at the scenario's own speed, writes the run
folder as any run's (:func:`~pipeline.studies.experiment.run_experiment`), then judges the run
(:func:`~pipeline.analysis.commonroad_check.judge_commonroad_run`) and writes the verdicts and
the ego's trajectory as a CommonRoad solution beside it
(:class:`~pipeline.studies.results.commonroad.CommonRoadResult`). :func:`run_and_log` is
that run as ``pipeline.run`` does it (the CommonRoad source's ``study``), with its log line.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.analysis.commonroad_check import CommonRoadVerdicts, judge_commonroad_run
from pipeline.analysis.objectives import objective_values
from pipeline.config import ExperimentConfig
from pipeline.loop.commonroad_scenario import (
    CommonRoadCase,
    ego_cover_vehicle,
    ego_solution,
    read_commonroad,
    vehicle_shape_m,
    write_solution,
)
from pipeline.store.runs import read_run
from pipeline.studies.experiment import RunSummary, run_experiment
from pipeline.studies.results.commonroad import CommonRoadResult

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CommonRoadRun:
    """What :func:`run_commonroad` produced: the run (as any run's summary), the verdicts and
    the written result."""

    run: RunSummary
    verdicts: CommonRoadVerdicts
    result: CommonRoadResult


def run_commonroad(cfg: ExperimentConfig, out_dir: Path) -> CommonRoadRun:
    """Run ``cfg``'s method on the CommonRoad scenario of ``cfg.scenario.commonroad`` into
    ``out_dir`` (always simulated again: the file may have changed under its path).

    Raises
    ------
    MissingExtraError, ConfigError
        Without the extra; a missing or unreadable file, no planning problem (one line each).
    """
    commonroad = cfg.scenario.commonroad
    if commonroad is None:
        raise ValueError("run_commonroad needs scenario=commonroad")
    case = read_commonroad(cfg.scenario)
    # the ego as the file's reading shapes it (under the cover: vehicle_type's rectangle)
    resolved = replace(cfg, scenario=case.scenario_config,
                       vehicle=ego_cover_vehicle(cfg.vehicle, commonroad))
    run = run_experiment(resolved, out_dir, resume=False, scenario=case.scenario)
    trajectory = read_run(run.out_dir).trajectory
    assert trajectory is not None  # read with its trajectory
    length_m, width_m = vehicle_shape_m(commonroad.vehicle_type)
    vehicle = resolved.vehicle
    verdicts = judge_commonroad_run(case, trajectory, vehicle.footprint_radius_m,
                                    length_m, width_m,
                                    tuple(float(c) for c in vehicle.footprint_offsets_m),
                                    goal_line_reached=run.info.termination == "goal_line")
    summary = {
        "file": {"path": str(commonroad.path), "sha256": case.file_sha256,
                 "benchmark_id": str(case.commonroad_scenario.scenario_id),
                 "planning_problem_id": int(case.planning_problem.planning_problem_id),
                 "initial_time_step": case.initial_time_step,
                 "obstacles": len(set(case.obstacle_ids)),
                 "obstacle_discs": len(case.obstacle_ids),
                 "obstacle_disc": commonroad.obstacle_disc,
                 "cover_discs": commonroad.cover_discs,
                 "ego_recording_dropped": list(case.ego_recording_ids)},
        "run": {"method": resolved.method_name, "termination": run.info.termination,
                "speed_mps": resolved.scenario.speed_mps,
                "sample_time_s": resolved.scenario.sample_time_s,
                "goal_reached_ours": run.info.termination == "goal_line",
                "collision_ours_continuous": bool(run.metrics.to_json().get("collision")),
                "ego_radius_m": vehicle.footprint_radius_m,
                "ego_discs": vehicle.footprint_discs,
                "ego_disc_span_m": vehicle.footprint_span_m,
                "ego_length_m": length_m, "ego_width_m": width_m,
                "vehicle_type": commonroad.vehicle_type},
        "verdicts": verdicts.to_json(),
    }
    summary["run"]["obstacles_seen_late"] = seen_late(case, trajectory)
    solution = ego_solution(case, trajectory, commonroad.vehicle_type)
    result = CommonRoadResult(summary).write(run.out_dir,
                                             lambda path: write_solution(solution, path))
    return CommonRoadRun(run, verdicts, result)


def seen_late(case: CommonRoadCase, trajectory: pd.DataFrame) -> int:
    """How many of the file's obstacles the ego first saw after the run's first step (out of
    range or hidden behind a static obstacle at first: what "appears" on a road)."""
    from pipeline.loop.trajectory import obstacle_indices

    first: dict[int, int] = {}
    for j in obstacle_indices(trajectory.columns):
        visible = np.flatnonzero(trajectory[f"obs{j}_visible"].to_numpy(bool))
        if visible.size:
            cr_id = case.obstacle_ids[j]
            first[cr_id] = min(first.get(cr_id, visible[0]), int(visible[0]))
    return sum(1 for step in first.values() if step > 0)


def run_and_log(experiment: ExperimentConfig, out_dir: Path) -> float | tuple[float, ...]:
    """``scenario=commonroad`` through ``pipeline.run``: the run, both collision verdicts, the
    road and the goal, logged in one line; returns ``tune.objectives`` (one float, or a tuple
    for several)."""
    done = run_commonroad(experiment, out_dir)
    v, m = done.verdicts, done.run.flat()
    log.info("%s on %s (%d steps at %.3g m/s): collision on the true shapes, ours %s (%d steps), "
             "the drivability checker's %s (agree on %d/%d steps); the MPC's discs %s (%d "
             "steps; the checker on them agrees on %d/%d steps); min clearance, true shapes "
             "%.3f m, discs %.3f m; off the road on %d steps (%d before the first contact on "
             "the true shapes); goal reached by CommonRoad's definition %s, by ours %s; "
             "success (the file's goal, no contact on the true shapes) %s -> %s", m["method"],
             m["scenario"], v.steps, done.result.summary["run"]["speed_mps"],
             v.ours_true_shapes_collision, v.ours_true_shapes_collision_steps,
             v.checker_true_shapes_collision, v.agreement_ours_true_shapes_steps, v.steps,
             v.ours_collision, v.ours_collision_steps, v.agreement_same_geometry_steps, v.steps,
             v.min_clearance_true_shapes_m, v.min_clearance_ours_m, v.off_road_steps,
             v.off_road_steps_before_contact,
             v.goal_reached_commonroad, m["termination"] == "goal_line", v.success, out_dir)
    values = objective_values(pd.DataFrame([m]), experiment.tune.objectives)
    return values[0] if len(values) == 1 else values
