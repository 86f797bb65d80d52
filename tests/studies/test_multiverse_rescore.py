"""The multiverse's re-scoring (:func:`pipeline.studies.multiverse.runs.rescore_family`) of a
family whose members differ beyond their obstacles: crossings among walkers each have their own
start and goal, so a member's metrics under another reading need that member's settings, not
the family's first member's (it once used the first member's for all: every later member's
lateral error was measured from a line it never drove)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd


def test_rescoring_a_crossing_family_uses_each_members_own_start_and_goal(make_config, tmp_path):
    from pipeline.analysis.metrics import compute_metrics
    from pipeline.store.runs import member_settings, member_trajectories, read_family
    from pipeline.studies.experiment import run_family, trajectory_context
    from pipeline.studies.multiverse.runs import family_table

    family = tmp_path / "pedestrians" / "baseline"
    run_family(make_config(["experiment=pedestrians", "planner=baseline", "scenario.n_steps=40",
                            "scenario.family.size=3", "scenario.family.n_jobs=1"]),
               family, progress=False, member_cache=None)
    stored = read_family(family, members=False)
    starts = {tuple(member_settings(family, i).scenario.start_xy_m) for i in range(3)}
    assert len(starts) == 3  # the members' crossings differ

    # a reading that moves only C1's band and the pass: every member's geometry comes back as
    # stored (to the trajectory file's rounding: it is re-scored from trajectory.csv)
    reading = dataclasses.replace(stored.settings.metrics, reaction_steering_band_rad=0.02,
                                  pass_reading="last_threat")
    table = family_table(family, reading, tmp_path / "multiverse").set_index("member")
    as_run = stored.table.set_index("member")
    for key in ("max_lateral_deviation_m", "path_length_m", "time_to_goal_s"):
        np.testing.assert_allclose(pd.to_numeric(table[key]), pd.to_numeric(as_run[key]),
                                   rtol=0, atol=1e-6, equal_nan=True, err_msg=key)
    # the changed reading against each member scored alone with its own settings (the oracle)
    for index, trajectory, _ in member_trajectories(family):
        alone = compute_metrics(trajectory, trajectory_context(member_settings(family, index)),
                                reading).to_json()
        for key in ("obstacle_passed_time_s", "recovery_time_s", "oscillation_count"):
            expected = np.nan if alone[key] is None else float(alone[key])
            assert np.isclose(float(table.loc[index, key]), expected, equal_nan=True), key
