"""A simulated run's columns as arrays (:class:`~pipeline.loop.trajectory.TrajectoryTable`):
the metrics and the trajectory file read from it are those of its pandas DataFrame, number for
number and byte for byte, on every track, an ego of several discs and a crowd; its columns read
as pandas reads a Series."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from pipeline.analysis.metrics.context import trajectory_context
from pipeline.analysis.metrics.criteria import compute_metrics, compute_metrics_readings
from pipeline.loop.controller import QpCache
from pipeline.loop.engine import simulate_members
from pipeline.loop.scenario import build_scenario, family_members
from pipeline.loop.trajectory import TrajectoryTable
from pipeline.store.files import csv_text

CASES = [
    ["method=improved", "controller.backend=daqp"],
    ["method=baseline", "controller=kinematic", "scenario.n_steps=60"],
    # an ego of three discs: the metrics' disc view assigns the obstacles' radii
    ["method=improved", "vehicle.footprint_discs=3", "vehicle.footprint_span_m=3.0",
     "vehicle.footprint_radius_m=1.17"],
    ["method=cbf_filter"],
    # a crowd: personal space, walkers beyond the slots, the kinematic sidewalk robot
    ["method=improved", "scenario=pedestrians", "scenario.n_steps=40"],
]


def _runs(make_config, overrides, size=3):
    cfg = make_config([*overrides, "scenario.family.size=3"]
                      if any(o.startswith("scenario=") for o in overrides)
                      else [*overrides, "scenario=family", f"scenario.family.size={size}"])
    members = family_members(cfg.scenario, cfg.vehicle.footprint_radius_m)
    runs = [(replace(cfg, scenario=member), build_scenario(member)) for member in members]
    return runs, simulate_members(runs, QpCache(compiled_kernels=True), record_horizon=False)


@pytest.mark.parametrize("overrides", CASES, ids=lambda o: " ".join(o))
def test_metrics_and_file_of_the_table_are_the_frames(make_config, overrides):
    runs, results = _runs(make_config, overrides)
    for (cfg, _), result in zip(runs, results, strict=True):
        table, frame = result.table, result.trajectory
        assert isinstance(table, TrajectoryTable) and isinstance(frame, pd.DataFrame)
        assert list(frame.columns) == table.columns and len(frame) == len(table)
        context = trajectory_context(cfg)
        from_table = compute_metrics(table, context, cfg.metrics).to_json()
        from_frame = compute_metrics(frame, context, cfg.metrics).to_json()
        assert json.dumps(from_table, sort_keys=True) == json.dumps(from_frame, sort_keys=True)
        # several readings at once (the multiverse's re-scoring) too
        strict = replace(cfg.metrics, threat_margin_m=0.9, reaction_interpolation="sample")
        assert [m.to_json() for m in compute_metrics_readings(table, context,
                                                              [cfg.metrics, strict])] \
            == [m.to_json() for m in compute_metrics_readings(frame, context,
                                                              [cfg.metrics, strict])]
        assert csv_text(table) == csv_text(frame) \
            == frame.to_csv(index=False, float_format="%.10g", lineterminator="\n")
        # the disc view and the metrics assign into a copy, never into the run's own log
        assert table.to_frame().equals(frame)


def test_a_runs_frame_is_built_once_and_only_when_asked(make_config):
    _, (result, *_) = _runs(make_config, CASES[0], size=1)
    assert "trajectory" not in vars(result)
    assert result.trajectory is result.trajectory


def test_columns_read_as_pandas_reads_a_series():
    text = np.array(["optimal", np.nan, "end", True, "safe_input"], dtype=object)
    flags = np.array([True, False, True, True, False])
    numbers = np.array([0.5, np.nan, 2.0, -1.0, 3.25])
    table = TrajectoryTable({"t": text, "f": flags, "x": numbers}, 5)
    frame = table.to_frame()
    for name in ("t", "f", "x"):
        ours, theirs = table[name].astype(str).to_numpy(), frame[name].astype(str).to_numpy()
        assert [None if pd.isna(v) else v for v in ours] \
            == [None if pd.isna(v) else v for v in theirs]
    for name, wanted in (("t", ["end", "safe_input"]), ("f", [True]), ("x", [2.0, 3.25])):
        assert (table[name].isin(wanted).to_numpy() == frame[name].isin(wanted).to_numpy()).all()
        assert table[name].isin(wanted).to_numpy().any()
    assert int((table["t"].astype(str) == "end").sum()) \
        == int((frame["t"].astype(str) == "end").sum()) == 1
    # a missing cell stays missing (pandas 2.x and later), never the word 'nan'
    assert int((table["t"].astype(str) == "nan").sum()) \
        == int((frame["t"].astype(str) == "nan").sum()) == 0
    np.testing.assert_array_equal(table[["x", "f"]].to_numpy(float),
                                  frame[["x", "f"]].to_numpy(float))
    assert table["x"].to_numpy(float).dtype == float and table["f"].to_numpy(bool).all() \
        == frame["f"].to_numpy(bool).all()
    assert "x" in table and "y" not in table and len(table) == 5
    # a reader cannot write into the run's log through the table (the file is written after)
    with pytest.raises(ValueError, match="read-only"):
        table["x"].to_numpy(float)[0] = 7.0
    assert numbers[0] == 0.5 and numbers.flags.writeable
    copy = table.copy()
    copy["x"] = numbers * 2
    np.testing.assert_array_equal(table["x"].to_numpy(), numbers)
    with pytest.raises(ValueError, match="rows"):
        copy["x"] = numbers[:3]
    with pytest.raises(ValueError, match="rows"):
        TrajectoryTable({"x": numbers[:2]}, 5)


def test_a_table_that_needs_quoting_is_written_by_pandas():
    table = TrajectoryTable({"time_s": np.array([0.0, 0.1]),
                             "note": np.array(["a,b", np.nan], dtype=object)}, 2)
    assert csv_text(table) == table.to_frame().to_csv(index=False, float_format="%.10g",
                                                      lineterminator="\n") \
        == 'time_s,note\n0,"a,b"\n0.1,\n'
