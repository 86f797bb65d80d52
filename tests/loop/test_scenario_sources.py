"""Scenario sources behind one protocol (issue 57): ``scenario.source._target_`` chooses the class
that builds a scenario and draws a family's members. The built-in sources draw and build what
the code drew before the protocol (``tests/data/sources/``, written by commit cc1aa3c); a
scenario without the key reads as the built-in its shape implies, with its config hash; the
refusals are one line naming the key; and a source planted from a temporary folder runs a family
through ``pipeline.run`` and the report without touching the package."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from pipeline.config import ScenarioConfig, experiment_config_from_data
from pipeline.errors import ConfigError, MissingExtraError
from pipeline.loop.commonroad_scenario import COMMONROAD_EXTRA, CommonRoadSource
from pipeline.loop.scenario import (
    Extra,
    build_scenario,
    family_members,
    scenario_source,
    source_extra,
)
from pipeline.loop.settings import PedestrianConfig, ScenarioSourceConfig
from pipeline.run import main

ROOT = Path(__file__).resolve().parents[2]
BEFORE = json.loads((ROOT / "tests" / "data" / "sources" /
                     "members_before_sources.json").read_text())
DEFAULT_CONFIG_HASH = "c3169d33ead55c88"  # tests/studies/test_pins.py's


def _same(fresh, pinned, where: str = "") -> None:
    """``fresh`` equals ``pinned`` (nested lists and mappings; numbers within 1e-9)."""
    if isinstance(pinned, dict):
        assert isinstance(fresh, dict) and sorted(fresh) == sorted(pinned), where
        for key in pinned:
            _same(fresh[key], pinned[key], f"{where}.{key}")
    elif isinstance(pinned, list):
        assert len(fresh) == len(pinned), where
        for i, (a, b) in enumerate(zip(fresh, pinned, strict=True)):
            _same(a, b, f"{where}[{i}]")
    elif isinstance(pinned, float) and not isinstance(fresh, bool):
        assert math.isclose(fresh, pinned, rel_tol=1e-9, abs_tol=1e-12), (where, fresh, pinned)
    else:
        assert fresh == pinned, (where, fresh, pinned)


@pytest.mark.parametrize("case", BEFORE["cases"], ids=lambda c: " ".join(c["overrides"]))
def test_built_in_sources_draw_and_build_the_members_drawn_before_the_protocol(make_config,
                                                                               case):
    """member(seed, i) of the scripted and the pedestrian source is member i as the code before
    the protocol drew it (its configuration), and build() makes the scenario it made (its
    obstacles' starts, radii and places at 4.5 s, the sensor range); family_members agrees.
    Pedestrians with their tracks as recorded (track_extension_s=0, the reading they were
    drawn with: an extended walker is present earlier, which moves an aimed draw)."""
    walkers = any("pedestrians" in o for o in case["overrides"])
    cfg = make_config(case["overrides"]
                      + (["scenario.pedestrians.track_extension_s=0"] if walkers else []))
    base = cfg.scenario
    source = scenario_source(base, cfg.vehicle.footprint_radius_m)
    members = family_members(base, cfg.vehicle.footprint_radius_m)
    for row in case["members"]:
        member = source.member(base.family.seed, row["index"])
        assert member == members[row["index"]]
        assert member.source == base.source  # a member keeps its family's source
        drawn = dataclasses.asdict(member)
        drawn.pop("source")  # the key the protocol added
        if drawn.get("pedestrians") is not None:  # the keys added since (issue 59)
            for key in PedestrianConfig.BEFORE_KEYS:
                drawn["pedestrians"].pop(key)
        _same(json.loads(json.dumps(drawn, default=str)), row["config"], member.name)
        built = source.build(member)
        snap = built.obstacles_at(4.5)
        _same({"obstacle_start_m": built.obstacle_start_m.tolist(),
               "obstacle_radius_m": built.obstacle_radius_m.tolist(),
               "positions_at_4_5_s": snap.positions_m.tolist(),
               "visible_at_4_5_s": snap.visible.tolist(),
               "sensor_range_m": built.sensor_range_m, "nearest_first": built.nearest_first},
              row["scenario"], member.name)


def test_member_takes_its_seed_from_the_call(make_config):
    """member(seed, i) draws from the seed it is given, not the base's: member 3 of seed 7
    from a seed-0 base is member 3 of the seed-7 family."""
    seed0 = make_config(["scenario=family"]).scenario
    seed7 = make_config(["scenario=family", "scenario.family.seed=7"]).scenario
    assert scenario_source(seed0).member(7, 3) == scenario_source(seed7).member(7, 3)
    assert scenario_source(seed0).member(7, 3) != scenario_source(seed0).member(0, 3)
    assert scenario_source(seed0).member(7, 3).name == "family_s7_i0003"


def test_the_source_is_chosen_by_its_target_and_a_scenario_without_one_keeps_its_shape(
        make_config):
    """Every built-in YAML names its source; a null target (a scenario YAML without the key, or
    a run's config.yaml written before it) reads as the built-in its shape implies, with the
    same config hash; a source of one's own enters the hash."""
    paper = make_config([])
    assert paper.scenario.source._target_ == ScenarioSourceConfig.SCRIPTED
    assert make_config(["scenario=family"]).scenario.source_target == \
        ScenarioSourceConfig.SCRIPTED
    pedestrians = make_config(["scenario=pedestrians"]).scenario
    assert pedestrians.source._target_ == ScenarioSourceConfig.PEDESTRIANS
    commonroad = make_config(["scenario=commonroad", "scenario.commonroad.path=x.xml"])
    assert commonroad.scenario.source._target_ == ScenarioSourceConfig.COMMONROAD
    for cfg in (paper, make_config(["scenario=pedestrians"]), commonroad):
        unnamed = make_config([*_overrides_of(cfg), "scenario.source._target_=null"])
        assert unnamed.scenario.source._target_ is None
        assert unnamed.scenario.source_target == cfg.scenario.source._target_
        assert unnamed.config_hash() == cfg.config_hash()
    assert paper.config_hash() == DEFAULT_CONFIG_HASH
    # a run folder's config.yaml from before the key
    data = paper.to_dict()
    del data["scenario"]["source"]
    old = experiment_config_from_data(data)
    assert old.scenario.source_target == ScenarioSourceConfig.SCRIPTED
    assert old.config_hash() == DEFAULT_CONFIG_HASH
    own = make_config(["scenario.source._target_=my_sources.Gate"])
    assert own.scenario.source_target == "my_sources.Gate"
    assert own.config_hash() != DEFAULT_CONFIG_HASH
    assert make_config(["+scenario.source.params.a=1"]).config_hash() != DEFAULT_CONFIG_HASH


def _overrides_of(cfg) -> list[str]:
    if cfg.scenario.commonroad is not None:
        return ["scenario=commonroad", "scenario.commonroad.path=x.xml"]
    return ["scenario=pedestrians"] if cfg.scenario.pedestrians is not None else []


def test_hash_view_leaves_out_only_the_built_in_of_the_shape():
    """The scenario the hash reads: ``source`` is left out where it is the built-in the shape
    implies (the reading from before the key) and kept otherwise."""
    scripted = {"name": "x", "pedestrians": None, "commonroad": None,
                "source": {"_target_": ScenarioSourceConfig.SCRIPTED, "params": {}}}
    assert "source" not in ScenarioConfig.hash_view(scripted)
    assert "source" in scripted  # not changed in place
    other = {**scripted, "source": {"_target_": ScenarioSourceConfig.PEDESTRIANS,
                                    "params": {}}}
    assert ScenarioConfig.hash_view(other)["source"]["_target_"] == \
        ScenarioSourceConfig.PEDESTRIANS
    with_params = {**scripted, "source": {"_target_": None, "params": {"a": 1}}}
    assert ScenarioConfig.hash_view(with_params)["source"]["params"] == {"a": 1}


@pytest.mark.parametrize("overrides, needs", [
    (["scenario=pedestrians", "scenario.source._target_=pipeline.loop.scenario.ScriptedSource"],
     "PedestrianSource"),
    (["scenario.source._target_=pipeline.loop.pedestrians.PedestrianSource"],
     "scenario.pedestrians"),
    (["scenario.source._target_=pipeline.loop.commonroad_scenario.CommonRoadSource"],
     "scenario.commonroad"),
    (["scenario.source._target_=no_such_module_57.Source"], "PYTHONPATH"),
    (["scenario.source._target_=pipeline.loop.scenario.Scenario"], "no build(), member()"),
])
def test_a_source_that_does_not_fit_is_one_line_naming_the_key(make_config, overrides, needs):
    """A built-in source given another source's block (it would ignore it) or missing its own,
    a target that does not import, a class that is no source: one line naming
    scenario.source._target_, before any member is drawn."""
    cfg = make_config(overrides)
    with pytest.raises(ConfigError) as caught:
        if cfg.scenario.family is not None:
            family_members(cfg.scenario)
        else:
            build_scenario(cfg.scenario)
    message = str(caught.value)
    assert caught.value.key == "scenario.source._target_" and needs in message
    assert "\n" not in message


def test_a_malformed_target_and_a_family_of_a_file_are_refused(make_config):
    with pytest.raises(ConfigError, match=r"scenario\.source\._target_"):
        make_config(["scenario.source._target_=not a path"])
    commonroad = make_config(["scenario=commonroad", "scenario.commonroad.path=x.xml"])
    with pytest.raises(ConfigError, match=r"scenario\.family") as caught:
        CommonRoadSource(commonroad.scenario).member(0, 0)
    assert "one file is one scenario" in str(caught.value)


def test_the_extra_a_source_needs_is_asked_of_the_source(make_config, monkeypatch):
    """needs_extra: CommonRoad's extra for scenario=commonroad (typed or as the raw composed
    mapping), none for the others; an extra whose module does not import gives its install
    line."""
    commonroad = make_config(["scenario=commonroad", "scenario.commonroad.path=x.xml"])
    assert source_extra(commonroad.scenario) is COMMONROAD_EXTRA
    assert source_extra({"commonroad": {"path": "???"}}) is COMMONROAD_EXTRA
    assert source_extra(make_config(["scenario=pedestrians"]).scenario) is None
    assert source_extra(make_config([]).scenario) is None
    extra = Extra("x", ("json", "no_such_module_57"), "pip install x")
    assert extra.missing() == "pip install x"
    with pytest.raises(MissingExtraError, match="^config error: pip install x$"):
        extra.require()
    assert Extra("y", ("json",), "pip install y").missing() is None
    monkeypatch.setitem(sys.modules, "vehiclemodels", None)
    assert COMMONROAD_EXTRA.missing() == COMMONROAD_EXTRA.install_line


NEEDY = '''
from pipeline.loop.scenario import Extra, ScriptedSource


class NeedySource(ScriptedSource):
    needs_extra = Extra("needy", ("no_such_module_57",), "needs the extra: pip install needy")
'''


def test_a_planted_sources_missing_extra_stops_the_run_in_one_line(tmp_path, monkeypatch,
                                                                   capsys):
    """pipeline.run asks the source for its extra, before any other check (here the
    obstacle list's, which an empty list would fail)."""
    (tmp_path / "needy_source_57.py").write_text(NEEDY)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(sys, "argv", [
        "pipeline.run", "scenario.source._target_=needy_source_57.NeedySource",
        "scenario.obstacles=[]", f"hydra.run.dir={tmp_path / 'run'}"])
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    with pytest.raises(SystemExit) as exit_info:
        main()
    assert exit_info.value.code == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert lines == ["config error: needs the extra: pip install needy"]
    assert not (tmp_path / "run" / "metrics.json").exists()


def test_the_tune_asks_the_source_for_its_parts(tmp_path):
    """The tune's held-out parts come from the source (its parts_key): the pedestrians' scenes,
    none for the scripted family; the key is then the tune's to set."""
    from pipeline.config import CONF_DIR
    from pipeline.studies.tune.space import load_tune_space, search_space, tuned_scenario_source
    from pipeline.studies.tune.study import controlled_keys

    assert tuned_scenario_source("pedestrians").parts_key == "scenario.pedestrians.scenes"
    assert getattr(tuned_scenario_source("family"), "parts_key", None) is None
    with pytest.raises(ConfigError, match="tune.scenario"):
        tuned_scenario_source("paper_sudden_obstacle")  # no family to tune on
    for preset, parts in (("pedestrians", True), ("quick", False)):
        space = load_tune_space(CONF_DIR / "tune" / f"{preset}.yaml")
        keys = controlled_keys(space, {m: search_space(m) for m in space.methods})
        assert ("scenario.pedestrians.scenes" in keys) is parts


# a planted source: a post that appears ahead and crosses the line, its place and time drawn
# per member from the ranges in source.params (the single run reads the base's own values)
PLANTED = '''
from dataclasses import replace

import numpy as np

from pipeline.loop.scenario import Scenario


class GateSource:
    needs_extra = None

    def __init__(self, scenario, vehicle_radius_m):
        self.base = scenario

    def member(self, seed, index):
        p = self.base.source.params
        rng = np.random.default_rng([seed, index, 57])
        drawn = {"post_x_m": round(float(rng.uniform(*p["post_x_range_m"])), 3),
                 "appear_s": round(float(rng.uniform(*p["appear_range_s"])), 1)}
        return replace(self.base, name=f"gate_s{seed}_i{index:04d}", family=None,
                       source=replace(self.base.source, params={**p, **drawn}))

    def build(self, cfg):
        p = cfg.source.params
        return Scenario(
            name=cfg.name, start_m=np.array(cfg.start_xy_m, float),
            start_heading_rad=cfg.start_heading_rad, goal_m=np.array(cfg.goal_xy_m, float),
            goal_tolerance_m=cfg.goal_tolerance_m, speed_mps=cfg.speed_mps,
            initial_speed_mps=cfg.speed_mps, sample_time_s=cfg.sample_time_s,
            n_steps=cfg.n_steps, plant_substeps=cfg.plant_substeps,
            obstacle_start_m=np.array([[p["post_x_m"], 1.5]]),
            obstacle_velocity_mps=np.array([[0.0, -0.4]]), obstacle_radius_m=np.array([0.5]),
            obstacle_appear_s=np.array([p["appear_s"]]))
'''

GATE_YAML = '''
defaults:
  - scenario_schema
  - _self_

name: gate
obstacles: []            # the source brings its own
source:
  _target_: my_tmp_source.GateSource
  params:
    post_x_m: 14.0
    appear_s: 3.5
    post_x_range_m: [12.0, 16.0]
    appear_range_s: [2.5, 3.5]
family:
  seed: 0
  size: 6
  n_jobs: 1
'''


def _run(args, env):
    return subprocess.run([sys.executable, "-m", *args], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=600)


def test_a_planted_source_runs_a_family_through_run_and_the_report(tmp_path):
    """A module on PYTHONPATH and a scenario YAML on hydra.searchpath, nothing in the package:
    pipeline.run draws the family with the planted member() (its names, its appearance times)
    and simulates what the planted build() makes (its post, absent from the empty obstacle
    list the scripted builder would have run), for two methods and a single run each; the
    report judges the family and shows its members."""
    (tmp_path / "mod").mkdir()
    (tmp_path / "mod" / "my_tmp_source.py").write_text(PLANTED)
    (tmp_path / "conf" / "scenario").mkdir(parents=True)
    (tmp_path / "conf" / "scenario" / "gate.yaml").write_text(GATE_YAML)
    env = {**os.environ, "PYTHONPATH": str(tmp_path / "mod"), "PIPELINE_MEMBER_CACHE": "off"}
    search = f"hydra.searchpath=[file://{tmp_path / 'conf'}]"
    runs = tmp_path / "runs"
    for kind, extra in (("family", []), ("paper", ["scenario.family=null"])):
        # both methods in one multirun, each in its own folder (runs/<kind>/<method>)
        proc = _run(["pipeline.run", "-m", search, "method=improved,baseline", "scenario=gate",
                     *extra, f"hydra.sweep.dir={runs / kind}", "hydra.sweep.subdir=${planner.name}"],
                    env)
        assert proc.returncode == 0, proc.stderr[-2000:]
    # the planted rule, computed here: member i from default_rng([0, i, 57])
    expected = {}
    for i in range(6):
        rng = np.random.default_rng([0, i, 57])
        rng.uniform(12.0, 16.0)
        expected[f"gate_s0_i{i:04d}"] = round(float(rng.uniform(2.5, 3.5)), 1)
    for method in ("improved", "baseline"):
        table = pd.read_csv(runs / "family" / method / "family_metrics.csv")
        assert dict(zip(table["scenario"], table["obstacle_appear_time_s"], strict=True)) == \
            pytest.approx(expected, abs=1e-9)
        assert table["min_clearance_m"].between(0.0, 5.0).all()  # the post was there
        single = json.loads((runs / "paper" / method / "metrics.json").read_text())
        assert single["scenario"] == "gate"
        assert single["obstacle_appear_time_s"] == pytest.approx(3.5, abs=1e-9)
    member = yaml.safe_load((runs / "family" / "improved" / "member_0002" /
                             "config.yaml").read_text())["scenario"]
    assert member["source"]["_target_"] == "my_tmp_source.GateSource"
    assert member["obstacles"] == [] and member["family"] is None
    assert member["source"]["params"]["appear_s"] == expected["gate_s0_i0002"]
    proc = _run(["pipeline.report", str(runs), "--out", str(tmp_path / "report"),
                 "--treatment", "improved", "--controls", "baseline"], env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    ledger = pd.read_csv(tmp_path / "report" / "tables" / "claims_ledger.csv")
    assert set(ledger["comparison"]) == {"baseline"} and len(ledger) == 7
    assert set(ledger["n_scenarios"]) == {6}
    page = (tmp_path / "report" / "index.html").read_text()
    assert "gate_s0_i00" in page
