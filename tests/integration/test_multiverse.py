"""The multiverse: design, a planted verdict that flips under exactly one dimension, the quick
space end to end (resume without recomputation), and bad space files."""

from __future__ import annotations

import dataclasses
import json

import pandas as pd
import pytest

from pipeline.config import ConfigError
from pipeline.reporting.sections.robustness import backends_text as _backends_text
from pipeline.studies.multiverse import (
    CONF_DIR,
    Dimension,
    Space,
    build_design,
    composer,
    family_config,
    load_space,
    qp_backend,
    robustness,
    simulation_overrides,
)

SPACE = Space("planted", (
    Dimension("planner.beta", "simulation", (0.25, 0.5, 1.0), ("improved",)),
    Dimension("planner.step_max_m", "simulation", (0.5, 0.3), ("improved",), cap=True),
    Dimension("metrics.lateral_accel", "analysis", ("vy_dot_plus_vx_r", "vx_r")),
    Dimension("claims.margin_scale", "analysis", (1.0, 2.0, 0.5)),
), n_specifications=20, simulation_pool=4)


def test_design_has_default_every_one_at_a_time_change_and_a_seeded_sample():
    design = build_design(SPACE)
    assert len(design) == 20 and design["kind"].iloc[0] == "default"
    assert (design["kind"] == "one_at_a_time").sum() == 2 + 1 + 1 + 2
    assert design.drop(columns="spec_id").duplicated().sum() == 0
    sampled = design[design["kind"] == "sampled"]
    assert len(sampled[["planner.beta", "planner.step_max_m"]].drop_duplicates()) <= 4
    pd.testing.assert_frame_equal(design, build_design(SPACE))


def test_cap_sets_the_matched_baseline_step_and_improved_only_keys_stay_off_the_baselines():
    row = {"planner.beta": 1.0, "planner.step_max_m": 0.3}
    assert "planner.beta=1.0" in simulation_overrides(row, SPACE, "improved")
    assert "planner.step_max_m=0.3" in simulation_overrides(row, SPACE, "improved")
    matched = simulation_overrides(row, SPACE, "baseline_matched")
    assert "planner.step_size=0.3" in matched and not any("beta" in o for o in matched)
    assert not any("planner" in o for o in simulation_overrides(row, SPACE, "baseline"))


def test_a_verdict_that_flips_under_one_dimension_is_attributed_to_it():
    design = build_design(SPACE)
    rows = []
    for spec in design.to_dict("records"):
        flipped = spec["metrics.lateral_accel"] == "vx_r"
        for claim in ("C1", "C2"):
            outcome = "contradicted" if (claim == "C2" and flipped) else "supported"
            estimate = 0.3 if outcome == "contradicted" else -0.3 + 0.01 * spec["planner.beta"]
            rows.append({"spec_id": spec["spec_id"], "claim": claim, "comparison": "baseline",
                         "estimate": estimate, "outcome": outcome})
    robust, dims = robustness(pd.DataFrame(rows), design, SPACE)
    c2 = robust.set_index("claim").loc["C2"]
    assert c2["most_influential"] == "metrics.lateral_accel"
    assert c2["flipping_values"] == "vx_r" and c2["influence"] == 1.0
    assert c2["label"] in ("sensitive", "fragile")
    c1 = robust.set_index("claim").loc["C1"]
    assert c1["label"] == "robust" and c1["influence"] == 0.0 and c1["agree_share"] == 1.0
    flips = dims[(dims["claim"] == "C2") & (dims["flipped_share"] == 1.0)]
    assert flips[["dimension", "value"]].values.tolist() == [["metrics.lateral_accel", "vx_r"]]


def test_quick_space_end_to_end_and_resume(tmp_path):
    from pipeline.multiverse import main

    out = tmp_path / "mv"
    assert main(["--space", "quick", "--out", str(out), "scenario.family.n_jobs=1"]) == 0
    specs = pd.read_csv(out / "specifications.csv")
    robust = pd.read_csv(out / "robustness.csv")
    space = load_space(CONF_DIR / "multiverse" / "quick.yaml")
    assert specs["spec_id"].nunique() == space.n_specifications
    assert set(specs["claim"]) == {"C0", "C1", "C2", "C3a", "C3b", "C4", "C5"}
    assert set(specs["comparison"]) == {"baseline", "baseline_matched"}
    assert {"estimate", "ci_low", "ci_high", "outcome", "planner.beta"} <= set(specs.columns)
    assert len(robust) == 14 and set(robust["label"]) <= {"robust", "sensitive", "fragile"}
    assert "holds_with" in robust.columns
    assert (out / "figures" / "specification_curve_C1.png").is_file()
    info = json.loads((out / "space.json").read_text())
    # the runs solved their QPs on the space's backend, and say so
    assert space.backend == "daqp" and info["backend"] == "daqp"
    assert info["backends"] == {"baseline": "daqp", "baseline_matched": "daqp",
                                "improved": "daqp"}
    import yaml

    members = sorted((out / "runs" / "improved").glob("*/member_0000/config.yaml"))
    assert members and all(yaml.safe_load(m.read_text())["controller"]["backend"] == "daqp"
                           for m in members)
    # every metric reading computed in one pass: each member trajectory read at most once
    assert 0 < info["member_reads_per_member"] <= 1
    # runs are shared: two simulation choices with two values, the baselines shared by both
    # betas -> fewer family folders than specifications x methods
    folders = list((out / "runs").glob("*/*/family.json"))
    assert len(folders) < 3 * info["n_simulation_configurations"]
    stamps = {p: p.stat().st_mtime_ns for p in folders}
    assert main(["--space", "quick", "--out", str(out), "scenario.family.n_jobs=1"]) == 0
    assert {p: p.stat().st_mtime_ns for p in folders} == stamps  # nothing re-simulated
    pd.testing.assert_frame_equal(pd.read_csv(out / "specifications.csv"), specs)
    # a forged re-scoring table is caught by its manifest and recomputed, never trusted
    tables = sorted((out / "rescored").glob("*.csv"))
    assert tables and all((t.parent / (t.name + ".manifest.json")).is_file() for t in tables)
    original = tables[0].read_bytes()
    forged = pd.read_csv(tables[0])
    forged["reaction_delay_s"] = forged["reaction_delay_s"] + 1.0
    forged.to_csv(tables[0], index=False)
    assert main(["--space", "quick", "--out", str(out), "scenario.family.n_jobs=1"]) == 0
    assert tables[0].read_bytes() == original
    pd.testing.assert_frame_equal(pd.read_csv(out / "specifications.csv"), specs)
    # the report built after it leads with robustness and has a curve per claim
    from hydra import compose, initialize_config_dir

    from pipeline.config import to_experiment_config
    from pipeline.reporting.page import build_report
    from pipeline.studies.experiment import run_experiment

    for method in ("baseline", "improved"):
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
            cfg = to_experiment_config(compose(config_name="config",
                                               overrides=[f"method={method}"]))
        run_experiment(cfg, tmp_path / "runs" / "paper" / method)
    page = build_report(tmp_path / "runs", tmp_path / "report", "pytest",
                        multiverse_dir=out).read_text()
    assert 'id="robustness"' in page and 'id="robustness-summary"' in page
    assert page.index('id="robustness-summary"') < page.index('id="paths"')
    assert page.count('id="fig-specification_curve_C') == 7
    assert "QP backend of these runs: daqp (baseline, baseline_matched, improved)" in page


@pytest.mark.parametrize("text, match", [
    ("dimensions: []", "at least one dimension"),
    ("dimensions: [{key: planner.beta, stage: later, values: [1, 2]}]", "simulation or analysis"),
    ("dimensions: [{key: planner.beta, stage: simulation, values: [1]}]", "two or more"),
    ("dimensions: [{key: planner.beta, stage: analysis, values: [1, 2]}]", "metrics"),
    ("dimensions: [", "valid YAML")])
def test_bad_space_files_are_one_line_errors(tmp_path, text, match):
    path = tmp_path / "space.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match):
        load_space(path)


def test_the_space_backend_is_the_lateral_mpcs_and_an_explicit_override_wins():
    compose, _ = composer([])
    row = {d.key: d.default for d in SPACE.dimensions}
    daqp = family_config(row, SPACE, "improved", compose)
    clarabel = family_config(row, dataclasses.replace(SPACE, backend="clarabel_direct"),
                             "improved", compose)
    assert (daqp.controller.backend, clarabel.controller.backend) == ("daqp", "clarabel_direct")
    assert daqp.config_hash() != clarabel.config_hash()  # their runs never mix
    assert dataclasses.replace(daqp, controller=clarabel.controller) == clarabel
    # a run override names the backend: it wins over the space's
    user, _ = composer(["controller.backend=clarabel_direct"])
    assert family_config(row, SPACE, "baseline", user).controller.backend == "clarabel_direct"
    # a controller without a QP has no backend at all (its kind's schema has no such key)
    pursuit = family_config(row, SPACE, "apf_pursuit", compose)
    assert pursuit.controller.kind == "pure_pursuit" and not hasattr(pursuit.controller,
                                                                     "backend")
    # what space.json records and the report says
    backends = {m: qp_backend(c) for m, c in (("improved", daqp), ("apf_pursuit", pursuit))}
    assert backends == {"improved": "daqp", "apf_pursuit": "no QP"}
    assert _backends_text(backends) == "daqp (improved); no QP (apf_pursuit)"


def test_a_space_backend_outside_the_qp_backends_is_a_one_line_error(tmp_path):
    path = tmp_path / "space.yaml"
    path.write_text("backend: gurobi\ndimensions: [{key: planner.beta, stage: simulation, "
                    "values: [1, 2]}]")
    with pytest.raises(ConfigError, match="backend"):
        load_space(path)


def test_unknown_space_exits_2(capsys):
    from pipeline.multiverse import main

    assert main(["--space", "no_such_space"]) == 2
    assert "conf/multiverse" in capsys.readouterr().err


def test_default_space_covers_every_free_parameter_of_both_apfs():
    """k_rep's source and constant for the improved APF; the baseline's own step and rho0 as
    dimensions of their own, set for the baseline alone."""
    from pipeline.studies.multiverse import simulation_overrides

    space = load_space(CONF_DIR / "multiverse" / "default.yaml")
    keys = {d.key for d in space.dimensions}
    assert {"planner.k_rep_source", "planner.k_rep_constant", "planner.beta", "planner.alpha_e",
            "planner.rho0_m", "planner.step_max_m", "planner.step_size[baseline]",
            "planner.rho0_m[baseline]"} <= keys
    row = {d.key: d.default for d in space.dimensions}
    row["planner.rho0_m[baseline]"] = 3.0
    row["planner.rho0_m"] = 5.0
    assert "planner.rho0_m=3.0" in simulation_overrides(row, space, "baseline")
    assert "planner.rho0_m=5.0" not in simulation_overrides(row, space, "baseline")
    assert "planner.rho0_m=5.0" in simulation_overrides(row, space, "improved")
    assert "planner.rho0_m=3.0" not in simulation_overrides(row, space, "improved")


def test_the_composer_gives_hydras_configs_at_a_fraction_of_the_composes():
    """The composer composes each set of structural overrides once and sets a run's values on a
    copy of the typed config: for one value of every simulation dimension of the default space
    (each method it applies to), a tuning's backend key and a user's extra override, it returns
    exactly the config Hydra's full path gives; a bad value still fails in Hydra's words."""
    from hydra import compose, initialize_config_dir

    from pipeline.config import to_experiment_config
    from pipeline.studies.multiverse import composer

    def hydra_path(overrides):
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
            return to_experiment_config(compose(config_name="config", overrides=overrides))

    space = load_space(CONF_DIR / "multiverse" / "default.yaml")
    extra = ["scenario.family.n_jobs=1"]
    make, _ = composer(extra)
    methods = ("baseline", "baseline_matched", "improved")
    rows = [{d.key: d.values[k if k < len(d.values) else -1] for d in space.dimensions}
            for k in (0, 1, 2)]
    cases = [simulation_overrides(row, space, m) for row in rows for m in methods]
    cases.append(["method=improved", "scenario=family", "controller.backend=daqp",
                  "planner.k_rep_source=constant", "planner.k_rep_constant=5"])
    keys = {o.split("=")[0] for case in cases for o in case}
    # every dimension is set (each key of a bundle)
    assert {k for d in space.of("simulation") for k in d.config_keys} <= keys
    for overrides in cases:
        fast = make(overrides)
        reference = hydra_path(overrides + extra)
        assert fast == reference and fast.config_hash() == reference.config_hash(), overrides
    # the values differ between cases, the structure hardly: a Hydra compose per method
    assert len(make.typed_bases) == 3 < len(cases) and make.fallbacks == []
    with pytest.raises(ConfigError, match="planner.beta"):
        make(["method=improved", "scenario=family", "planner.beta=-1"])
    with pytest.raises(Exception, match="no_such_key"):
        make(["method=improved", "scenario=family", "planner.no_such_key=1"])
    assert len(make.fallbacks) == 2


def test_reading_flips_name_the_registered_readings_that_change_an_outcome():
    """A planted multiverse: C2 flips under one value of a registered reading (a bundle of
    keys), C1 under a parameter that no register entry names (not a reading: left out), and
    nothing flips C3a; the flips are exactly those the one-at-a-time specifications show."""
    from pipeline.studies.results.multiverse import MultiverseInfo, MultiverseResult

    dims = ({"name": "controller.path_reference", "key": "controller.path_reference",
             "config_key": "controller.path_lookahead_m, controller.path_reference"},
            {"name": "planner.beta", "key": "planner.beta", "config_key": "planner.beta"})
    specs = []
    for spec, kind, reference, beta in (("s0", "default", "rollout", 0.25),
                                        ("s1", "one_at_a_time", "pursuit 2.5", 0.25),
                                        ("s2", "one_at_a_time", "pursuit 4.0", 0.25),
                                        ("s3", "one_at_a_time", "rollout", 1.0),
                                        ("s4", "sampled", "pursuit 4.0", 1.0)):
        for claim, outcome in (("C1", "inconclusive" if beta == 1.0 else "supported"),
                               ("C2", "supported" if reference == "pursuit 4.0"
                                else "contradicted"),
                               ("C3a", "contradicted")):
            specs.append({"spec_id": spec, "kind": kind, "claim": claim,
                          "comparison": "baseline", "outcome": outcome, "estimate": 0.1,
                          "controller.path_reference": reference, "planner.beta": beta})
    info = MultiverseInfo("planted", 5, 1, 100, "daqp", {}, 1.0, "", 0.9, 0.5, dims)
    empty = pd.DataFrame()
    result = MultiverseResult(info, empty, pd.DataFrame(specs), empty, empty)
    flips = result.reading_flips({"controller.path_reference", "controller.frame"})
    assert [(f.claim, f.dimension, f.value, f.outcome, f.default_outcome) for f in flips] == [
        ("C2", "controller.path_reference", "pursuit 4.0", "supported", "contradicted")]
    assert flips[0].words == "controller.path_reference = pursuit 4.0: supported"
    assert {f.claim for f in result.reading_flips({"planner.beta"})} == {"C1"}
