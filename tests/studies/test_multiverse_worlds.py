"""The multiverse over the world the methods meet: scenario-distribution and vehicle dimensions
(a list-valued range, labelled bundles of several keys) compose into the configs they name for
every method alike, round-trip through the design's CSV, and the robustness section names
the scenario under which a planted claim flips."""

from __future__ import annotations

import dataclasses
import types

import pandas as pd
import pytest
from hydra import compose, initialize_config_dir

from pipeline.config import ConfigError, register_configs, to_experiment_config
from pipeline.reporting.sections.robustness import _world_rows
from pipeline.studies.multiverse import (
    CONF_DIR,
    Dimension,
    Space,
    build_design,
    load_space,
    matches,
    robustness,
    simulation_overrides,
    value_text,
)

METHODS = ("baseline", "baseline_matched", "improved")
#: what each world dimension of the default space sets, per non-default value
EXPECTED = {
    "scenario.speed_mps": {"6.0": {"scenario.speed_mps": 6.0},
                           "1.5": {"scenario.speed_mps": 1.5}},
    "scenario.family.appear_time_s": {
        "[1.0, 2.0]": {"scenario.family.appear_time_s": [1.0, 2.0]},
        "[4.0, 6.0]": {"scenario.family.appear_time_s": [4.0, 6.0]}},
    "scenario.obstacle_kinds": {
        "all static": {"scenario.family.static_probability": 1.0,
                       "scenario.family.oncoming_probability": 0.0},
        "all crossing": {"scenario.family.static_probability": 0.0,
                         "scenario.family.oncoming_probability": 0.0}},
    "scenario.family.obstacle_count_probabilities": {
        "one obstacle": {"scenario.family.obstacle_count_probabilities": [1.0, 0.0, 0.0]},
        "three obstacles": {"scenario.family.obstacle_count_probabilities": [0.0, 0.0, 1.0]}},
    "vehicle.mass_and_inertia": {
        "20 % lighter": {"vehicle.mass_kg": 1200.0, "vehicle.yaw_inertia_kg_m2": 2000.0},
        "20 % heavier": {"vehicle.mass_kg": 1800.0, "vehicle.yaw_inertia_kg_m2": 3000.0}},
    "vehicle.cornering_stiffness": {
        "20 % softer tyres": {"vehicle.cornering_stiffness_front_n_per_rad": 48000.0,
                              "vehicle.cornering_stiffness_rear_n_per_rad": 48000.0},
        "20 % stiffer tyres": {"vehicle.cornering_stiffness_front_n_per_rad": 72000.0,
                               "vehicle.cornering_stiffness_rear_n_per_rad": 72000.0}},
}


def hydra_config(overrides: list[str]):
    """The checked configuration Hydra's compose API gives (as a run is made)."""
    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return to_experiment_config(compose(config_name="config", overrides=overrides))


def lookup(cfg, key: str):
    value = cfg
    for part in key.split("."):
        value = getattr(value, part)
    return list(value) if isinstance(value, (list, tuple)) else value


def test_world_dimensions_compose_into_the_configs_they_name_for_every_method():
    space = load_space(CONF_DIR / "multiverse" / "default.yaml")
    dims = {d.key: d for d in space.dimensions}
    assert {d.key for d in space.dimensions if d.group in ("scenario", "vehicle")} == \
        set(EXPECTED) | {"scenario.n_steps", "scenario.family.seed"}
    default = {d.key: d.default for d in space.dimensions}
    base = {m: hydra_config(simulation_overrides(default, space, m)) for m in METHODS}
    for key, values in EXPECTED.items():
        assert dims[key].applies_to is None  # the world is every method's
        for choice, settings in values.items():
            row = {**default, key: dims[key].values[[value_text(v) for v in
                                                     dims[key].values].index(choice)]}
            configs = {m: hydra_config(simulation_overrides(row, space, m)) for m in METHODS}
            for m, cfg in configs.items():
                for config_key, expected in settings.items():
                    assert lookup(cfg, config_key) == expected, (key, choice, m)
                # the scenario and the vehicle are the same for every method: pairs stay paired
                assert cfg.scenario == configs["improved"].scenario
                assert cfg.vehicle == configs["improved"].vehicle
                assert cfg.config_hash() != base[m].config_hash()
    # the defaults are the configuration's own: the default specification's world is the
    # family's as configured (only its size is the space's)
    plain = hydra_config(["method=improved", "scenario=family"])
    assert base["improved"].scenario == dataclasses.replace(
        plain.scenario, family=dataclasses.replace(plain.scenario.family,
                                                   size=space.family_size))
    assert base["improved"].vehicle == plain.vehicle


LIST_SPACE = Space("lists", (
    Dimension("scenario.family.appear_time_s", "simulation", ([2.0, 4.0], [1.0, 2.0])),
    Dimension("scenario.kinds", "simulation", ("default", "all static"),
              settings=({"scenario.family.static_probability": 0.25},
                        {"scenario.family.static_probability": 1.0})),
    Dimension("claims.estimator", "analysis", ("hodges_lehmann", "median")),
), n_specifications=8, simulation_pool=3)


def test_a_list_valued_dimension_round_trips(tmp_path):
    design = build_design(LIST_SPACE)
    row = design[design["scenario.family.appear_time_s"].map(value_text) == "[1.0, 2.0]"]
    overrides = simulation_overrides(row.iloc[0].to_dict(), LIST_SPACE, "improved")
    assert "scenario.family.appear_time_s=[1.0,2.0]" in overrides
    assert hydra_config(overrides).scenario.family.appear_time_s == [1.0, 2.0]
    # through the design's CSV (as a result is written and read) the choice is the same text
    path = tmp_path / "design.csv"
    design.to_csv(path, index=False)
    back = pd.read_csv(path)
    for value in LIST_SPACE.dimensions[0].values:
        assert (matches(back["scenario.family.appear_time_s"], value)
                == matches(design["scenario.family.appear_time_s"], value)).all()
        assert matches(back["scenario.family.appear_time_s"], value).any()
    # a labelled bundle: the design holds the label, the overrides its keys
    static = design[design["scenario.kinds"] == "all static"].iloc[0].to_dict()
    assert "scenario.family.static_probability=1.0" in simulation_overrides(static, LIST_SPACE,
                                                                             "baseline")


@pytest.mark.parametrize("text, match", [
    ("dimensions: [{key: scenario.speed_mps, stage: simulation, applies_to: [improved], "
     "values: [3.0, 6.0]}]", "pairs would not be paired"),
    ("dimensions: [{name: kinds, stage: simulation, values: [{scenario.family.static_probability:"
     " 0.25}, {scenario.family.static_probability: 1.0}]}]", "label"),
    ("dimensions: [{key: scenario.speed_mps, stage: simulation, labels: [a, a], "
     "values: [3.0, 6.0]}]", "distinct labels"),
    ("dimensions: [{key: claims.estimator, stage: analysis, labels: [a, b], "
     "values: [hodges_lehmann, median]}]", "simulation dimension only"),
])
def test_bad_world_dimensions_are_one_line_errors(tmp_path, text, match):
    path = tmp_path / "space.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match):
        load_space(path)


WORLD_SPACE = Space("planted", (
    Dimension("scenario.speed_mps", "simulation", (3.0, 6.0, 1.5)),
    Dimension("vehicle.mass_and_inertia", "simulation", ("compact", "heavier"),
              settings=({"vehicle.mass_kg": 1500.0}, {"vehicle.mass_kg": 1800.0})),
    Dimension("planner.beta", "simulation", (0.25, 1.0), ("improved",)),
    Dimension("claims.estimator", "analysis", ("hodges_lehmann", "median")),
), n_specifications=18, simulation_pool=6)  # all it can draw: 6 + 6 x 2


def test_the_robustness_section_names_the_scenario_a_claim_flips_under():
    """C1 planted to become equivalent at 6 m/s and nowhere else: the robustness table
    attributes it to the speed, and the section's scenario table marks that row alone."""
    design = build_design(WORLD_SPACE)
    rows = []
    for spec in design.to_dict("records"):
        fast = spec["scenario.speed_mps"] == 6.0
        for claim, outcome in (("C1", "equivalent" if fast else "supported"),
                               ("C4", "contradicted")):
            rows.append({"spec_id": spec["spec_id"], "claim": claim, "comparison": "baseline",
                         "estimate": 0.01 if outcome == "equivalent" else -0.3,
                         "outcome": outcome})
    robust, dims = robustness(pd.DataFrame(rows), design, WORLD_SPACE)
    c1 = robust.set_index("claim").loc["C1"]
    assert (c1["most_influential"], c1["flipping_values"]) == ("scenario.speed_mps", "6.0")
    info = types.SimpleNamespace(dimensions=tuple(
        {"key": d.key, "config_key": ", ".join(d.config_keys), "stage": d.stage,
         "group": d.group} for d in WORLD_SPACE.dimensions))
    worlds, claims = _world_rows(types.SimpleNamespace(dimensions=dims, info=info))
    assert claims == ["C1", "C4"]
    assert {(r["dimension"], r["value"]) for r in worlds} == {
        ("scenario.speed_mps", "3.0"), ("scenario.speed_mps", "6.0"),
        ("scenario.speed_mps", "1.5"), ("vehicle.mass_and_inertia", "compact"),
        ("vehicle.mass_and_inertia", "heavier")}  # the method's beta is not a world
    flips = [(r["dimension"], r["value"], c) for r in worlds
             for c, cell in r["cells"].items() if cell["flips"]]
    assert flips == [("scenario.speed_mps", "6.0", "C1")]
    fast = next(r for r in worlds if r["value"] == "6.0")
    assert fast["cells"]["C1"]["outcome"] == "equivalent"
    assert fast["cells"]["C1"]["flipped"] == "100 %"
    # written before groups were recorded: the group is read off the config keys
    old = types.SimpleNamespace(dimensions=tuple({k: v for k, v in d.items() if k != "group"}
                                                 for d in info.dimensions))
    assert _world_rows(types.SimpleNamespace(dimensions=dims, info=old))[0] == worlds
