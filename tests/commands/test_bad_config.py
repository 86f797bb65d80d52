"""Bad configuration: every case is one line naming the key, the value and what is allowed.
Each case is checked where it is refused, at the typed config (Hydra's compose API and the
line the command layer prints for it, :func:`pipeline.errors.describe_config_error`: in
milliseconds); one case of each kind goes through the entry point itself (exit 2, the one
line, no traceback, nothing written), as `python -m pipeline.run` runs it."""

from __future__ import annotations

import sys

import pytest

from pipeline.run import main

CASES = [
    (["controller.horizon=0"], "controller.horizon=0", "integer in [1, 200]"),
    (["controller.horizon=-3"], "controller.horizon=-3", "integer in [1, 200]"),
    (["controller.horizon=3000"], "controller.horizon=3000", "GiB"),
    (["controller.horizon=1e20"], "controller.horizon", "Integer"),
    (["controller.horizon=ten"], "controller.horizon", "'ten'"),
    (["controller.control_horizon=11"], "controller.control_horizon=11", "[1, controller.horizon"),
    (["scenario.sample_time_s=0"], "scenario.sample_time_s=0.0", "[0.001, 1.0]"),
    (["scenario.sample_time_s=-0.1"], "scenario.sample_time_s=-0.1", "[0.001, 1.0]"),
    (["scenario.sample_time_s=1e308"], "scenario.sample_time_s=1e+308", "[0.001, 1.0]"),
    (["scenario.plant_substeps=100000000"], "scenario.plant_substeps", "[1, 1000]"),
    (["scenario.goal_xy_m=[1e200,0]"], "scenario.goal_xy_m[0]", "[-100000.0, 100000.0]"),
    (["scenario.name=../../x"], "scenario.name", "no '/'"),
    (["run.method=a/b"], "run.method", "no '/'"),
    (["metrics.goal_tolerance_m=0.3"], "metrics.goal_tolerance_m", "scenario.goal_tolerance_m"),
    (["vehicle.cornering_stiffness_front_n_per_rad=1e308"],
     "vehicle.cornering_stiffness_front_n_per_rad", "[10.0, 10000000.0]"),
    (["scenario.n_steps=1"], "scenario.n_steps=1", "must exceed sample_time_s"),
    (["scenario.obstacles.0.radius_m=-0.5"], "scenario.obstacles[0].radius_m=-0.5",
     "[0.001, 100.0]"),
    (["scenario.obstacles.0.radius_m=nan"], "scenario.obstacles[0].radius_m=nan", "finite"),
    (["planner.beta=inf"], "planner.beta=inf", "finite"),
    (["planner.step_size=0"], "planner.step_size=0.0", "> 0.0"),
    (["vehicle.mass_kg=-1"], "vehicle.mass_kg=-1.0", "[10.0, 100000.0]"),
    (["vehicle.mass_kg=1e-300"], "vehicle.mass_kg=1e-300", "[10.0, 100000.0]"),
    (["vehicle.steering_max_rad=0"], "vehicle.steering_max_rad=0.0", "[0.001, 1.2]"),
    (["scenario.speed_mps=nan"], "scenario.speed_mps=nan", "finite"),
    (["planner.repulsion_law=cubic"], "planner.repulsion_law='cubic'", "polynomial, exponential"),
    (["controller.q_lateral=-1"], "controller.q_lateral=-1.0", ">= 0.0"),
    (["metrics.threat_clearance_m=-1"], "metrics.threat_clearance_m=-1.0", "> 0.0"),
    (["metrics.attribution_switch_samples=-1"], "metrics.attribution_switch_samples=-1",
     "[0, 10]"),
    (["scenario=unknown_scenario"], "scenario='unknown_scenario'", "paper_sudden_obstacle"),
    (["planner=unknown"], "planner='unknown'", "baseline"),
    (["vehicle=unknown"], "vehicle='unknown'", "compact_car"),
    (["controller=unknown"], "controller='unknown'", "lateral_mpc"),
    (["method=unknown"], "method='unknown'", "apf_pursuit"),
    (["scenario.name=???"], "scenario.name is missing", "required"),
    (["scenario.goal_xy_m=[0.0,0.0]"], "scenario.goal_xy_m=[0.0, 0.0]", "farther than"),
    (["scenario.obstacles.0.x_m=0.5", "scenario.obstacles.0.y_m=0.0",
      "scenario.obstacles.0.appear_time_s=0.0"], "scenario.obstacles[0]=[0.5, 0.0]",
     "does not overlap the vehicle"),
    (["experiment=kinematic", "controller.accel_bounds_mps2=[3.0,-3.0]"],
     "controller.accel_bounds_mps2=[3.0, -3.0]", "low < high"),
    # a key of another controller kind: refused by the kind's schema, naming its keys
    (["controller.accel_bounds_mps2=[-3.0,3.0]"], "controller.accel_bounds_mps2 is invalid",
     "a key of MpcSettings"),
    (["method=apf_pursuit", "controller.frame=fixed"], "controller.frame is invalid",
     "controller=pure_pursuit"),
    (["controller.kind=kinematic_mpc"], "controller.kind='kinematic_mpc'", "controller=kinematic"),
    (["scenario.obstacles=[]"], "scenario.obstacles=[]", "non-empty obstacle list"),
    # the paper scenario has no family: OmegaConf stops the override with a bare assertion
    (["scenario.family.n_jobs=1"], "scenario.family.n_jobs cannot be set: scenario.family is null",
     "choose scenario=family first"),
    (["scenario.family={size:3}"], "scenario.family cannot be set: scenario.family is null",
     "choose scenario=family first"),
    (["scenario.obstacles=[{x_m:14.0,y_m:1.5},{x_m:14.0,y_m:1.5}]"], "scenario.obstacles[1]",
     "not exact duplicates"),
    (["scenario=family", "scenario.family.size=0"], "scenario.family.size=0", "integer >= 1"),
    (["scenario=family", "scenario.family.radius_m=[0.7,0.3]"], "scenario.family.radius_m",
     "low <= high"),
    (["+nonsense=1"], "nonsense", "not in"),
]


@pytest.mark.parametrize("overrides, key_and_value, allowed", CASES,
                         ids=[" ".join(c[0]) for c in CASES])
def test_bad_config_is_refused_in_one_line_at_the_typed_config(overrides, key_and_value,
                                                               allowed):
    from hydra import compose, initialize_config_dir

    from pipeline.config import CONF_DIR, register_configs, to_experiment_config
    from pipeline.errors import describe_config_error

    register_configs()
    with pytest.raises(Exception) as info, \
            initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        to_experiment_config(compose(config_name="config", overrides=overrides))
    line = describe_config_error(info.value)
    assert line is not None and "\n" not in line and line.startswith("config error: ")
    assert key_and_value in line and allowed in line, line


#: One case of each kind through the entry point: a range, an unknown preset, an unknown key.
THROUGH_MAIN = [CASES[0], next(c for c in CASES if c[0] == ["planner=unknown"]), CASES[-1]]


@pytest.mark.parametrize("overrides, key_and_value, allowed", THROUGH_MAIN,
                         ids=[" ".join(c[0]) for c in THROUGH_MAIN])
def test_bad_config_exits_2_with_one_line(monkeypatch, capsys, tmp_path, overrides,
                                          key_and_value, allowed):
    monkeypatch.setattr(sys, "argv", ["pipeline.run", *overrides, f"hydra.run.dir={tmp_path}"])
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    with pytest.raises(SystemExit) as exit_info:
        main()
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("config error: ")
    assert key_and_value in lines[0] and allowed in lines[0], lines[0]
    assert "Traceback" not in err
    assert not (tmp_path / "metrics.json").exists()


def test_full_traceback_on_request(monkeypatch, tmp_path):
    monkeypatch.setattr(sys, "argv", ["pipeline.run", "controller.horizon=0",
                                      f"hydra.run.dir={tmp_path}"])
    monkeypatch.setenv("HYDRA_FULL_ERROR", "1")
    with pytest.raises(Exception) as info:
        main()
    assert "controller.horizon" in str(info.value)
