"""Settings travel with the runs they made (issue 20): a user's claims override changes the
ledger, the report, the sweep verdicts and the multiverse's default specification alike, and a
run folder whose settings cannot be read is skipped with its reason, never filled with
defaults."""

from __future__ import annotations

import shutil

import pandas as pd
import pytest

from pipeline.analysis.claims.ledger import family_ledger
from pipeline.config import CONF_DIR
from pipeline.reporting.page import build_report
from pipeline.store.collection import load_runs
from pipeline.studies.aggregate import aggregate
from pipeline.studies.experiment import run_experiment, run_family
from pipeline.studies.multiverse import (
    analyse_specification,
    analysis_settings,
    build_design,
    load_space,
    with_user_defaults,
)

#: a C2 margin far from the default (0.1), with the quick multiverse's statistics settings
USER = ["claims.catalogue.C2.margin=5.0", "claims.n_resamples=199", "claims.min_pairs=4"]
METHODS = ("improved", "baseline", "baseline_matched")


@pytest.fixture(scope="module")
def user_runs(tmp_path_factory, make_config):
    root = tmp_path_factory.mktemp("user_runs")
    for method in METHODS:
        run_experiment(make_config([f"method={method}"] + USER), root / "paper" / method)
        run_family(make_config([f"method={method}", "scenario=family", "scenario.family.size=8",
                                "scenario.family.n_jobs=1"] + USER),
                   root / "family" / method, progress=False)
    return root


def c2(frame: pd.DataFrame, outcome_column: str = "outcome") -> str:
    row = frame[(frame["claim"] == "C2") & (frame.get("comparison", "baseline") == "baseline")]
    return str(row[outcome_column].iloc[0])


def test_a_claims_override_reaches_the_ledger_report_sweep_and_multiverse(user_runs, tmp_path):
    collection = load_runs(user_runs)
    settings = collection.claims_settings("improved")
    assert settings.margins["C2"] == 5.0 and settings.n_resamples == 199
    ledger = family_ledger(collection.family_tables, settings)
    expected = str(ledger[("C2", "baseline")].outcome)
    assert ledger[("C2", "baseline")].margin == 5.0
    # the report
    build_report(user_runs, tmp_path / "report", "test", bench_dir=None)
    table = pd.read_csv(tmp_path / "report" / "tables" / "claims_ledger.csv")
    row = table[(table["claim"] == "C2") & (table["comparison"] == "baseline")].iloc[0]
    assert row["margin"] == 5.0 and row["outcome"] == expected
    # the sweep verdicts: the improved family as a sweep job, paired with the baseline family
    sweep = tmp_path / "sweep"
    shutil.copytree(user_runs / "family" / "improved", sweep / "0")
    (sweep / "0" / ".hydra").mkdir()
    (sweep / "0" / ".hydra" / "overrides.yaml").write_text("- method=improved\n")
    aggregate(sweep, baseline_dir=user_runs / "family" / "baseline", progress=False)
    verdicts = pd.read_csv(sweep / "verdicts.csv")
    assert verdicts.loc[verdicts["claim"] == "C2", "verdict"].iloc[0] == expected
    # the multiverse: its default specification is the user's configuration
    space = load_space(CONF_DIR / "multiverse" / "quick.yaml")
    base = collection.family_settings["improved"]
    space = with_user_defaults(space, base)
    default = build_design(space).to_dict("records")[0]
    assert default["kind"] == "default"
    _, claims = analysis_settings(default, space, base)
    assert claims.margins["C2"] == 5.0
    folders = {m: user_runs / "family" / m for m in METHODS}
    rows = pd.DataFrame(analyse_specification(default, folders, space, tmp_path / "mv"))
    assert c2(rows) == expected


def test_unreadable_settings_are_skipped_with_their_reason(user_runs, tmp_path):
    from pipeline.store.manifest import RUN_FILES, write_manifest

    broken = tmp_path / "runs" / "paper" / "baseline"
    shutil.copytree(user_runs / "paper" / "baseline", broken)
    shutil.copytree(user_runs / "paper" / "improved", tmp_path / "runs" / "paper" / "improved")
    text = (broken / "config.yaml").read_text().replace("alpha: 0.05", "alpha: 7.0")
    (broken / "config.yaml").write_text(text)
    write_manifest(broken, "run", RUN_FILES, "x")  # a consistent folder, invalid settings
    skipped = []
    collection = load_runs(tmp_path / "runs", skipped)
    assert [r.method for r in collection.runs] == ["improved"]
    assert len(skipped) == 1 and "settings in config.yaml cannot be read" in skipped[0].reason
    assert "claims.alpha" in skipped[0].reason


def test_settings_read_back_equal_a_fresh_composition(user_runs):
    """The store's fast reader gives the same typed settings (and hash) as OmegaConf's merge,
    and names an unknown key with its full path."""
    import yaml
    from omegaconf import OmegaConf

    from pipeline.config import experiment_config_from_data, to_experiment_config
    from pipeline.errors import ConfigError

    data = yaml.safe_load((user_runs / "family" / "baseline" / "member_0003" / "config.yaml")
                          .read_text())
    fast = experiment_config_from_data(data)
    slow = to_experiment_config(OmegaConf.create(data))
    assert fast == slow and fast.config_hash() == slow.config_hash()
    data["scenario"]["obstacles"][0]["foo"] = 1
    with pytest.raises(ConfigError, match=r"scenario\.obstacles\[0\]\.foo"):
        experiment_config_from_data(data)


def test_the_report_command_ends_with_the_answer_in_words(user_runs, tmp_path, capsys):
    """``python -m pipeline.report`` (and so ``make reproduce``) ends with one line per claim:
    the claim's words, its outcome against each comparison, the estimate with its interval
    and unit, and its pairs."""
    from pipeline.analysis.claims.catalogue import ALL_CLAIMS
    from pipeline.report import main as report_main

    assert report_main([str(user_runs), "--out", str(tmp_path / "r"),
                        "--bench", str(tmp_path / "none")]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    last = lines[-len(ALL_CLAIMS):]
    assert [line.split(" ", 1)[0] for line in last] == [c.claim_id for c in ALL_CLAIMS]
    for line, claim in zip(last, ALL_CLAIMS, strict=True):
        assert claim.text in line and "vs baseline" in line and "vs baseline_matched" in line
    assert "] s, " in last[1] and "] m/s³, " in last[2]   # C1 in seconds, C2 in m/s³
    assert all(" pairs" in line for line in last)
    # answer.txt: the collisions and the model-validity caveat first, the primary comparison
    # and which ledger judges, then the same verdicts; the command prints it whole, last
    answer = (tmp_path / "r" / "answer.txt").read_text().splitlines()
    assert answer[-len(last):] == last
    assert answer[0].startswith("Collisions in ") and " scenarios each: baseline " in answer[0]
    assert "validity bound" in answer[0]
    assert lines[-len(answer):] == answer
    assert any(line.startswith("Primary comparison: improved vs baseline; every interval at ")
               for line in answer[:-len(last)])


def test_a_run_folder_with_the_flat_controller_section_reads_as_its_kind(make_config):
    """A config.yaml written before each controller kind had its schema (every kind's keys in
    one section) reads back as its kind's settings with the same values; a key no schema ever
    had is still refused by name."""
    import dataclasses

    from pipeline.config import experiment_config_from_data
    from pipeline.errors import ConfigError
    from pipeline.loop.controller_settings import KinematicMpcSettings, MpcSettings

    flat_keys = {f.name: f.default for schema in (MpcSettings, KinematicMpcSettings)
                 for f in dataclasses.fields(schema)
                 if f.default is not dataclasses.MISSING}
    for override, schema in (("method=improved", MpcSettings),
                             ("experiment=kinematic", KinematicMpcSettings)):
        cfg = make_config([override])
        data = cfg.to_dict()
        own = data["controller"]
        # the old section: its own values over every other kind's keys
        data["controller"] = {**flat_keys, "lookahead_min_m": 2.0, "lookahead_time_s": 0.8,
                              "output_weights": [1.0, 1.0], "input_weights": [0.1, 0.1],
                              "input_rate_weights": [0.01, 0.01],
                              "accel_bounds_mps2": [-3.0, 3.0], **own}
        assert len(data["controller"]) > len(own)
        read = experiment_config_from_data(data)
        assert type(read.controller) is schema and read == cfg
        assert read.config_hash() == cfg.config_hash()
    data["controller"] = {**own, "no_such_key": 1}
    with pytest.raises(ConfigError, match=r"controller\.no_such_key"):
        experiment_config_from_data(data)
