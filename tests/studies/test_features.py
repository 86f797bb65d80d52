"""'Does it look like the paper?': the paper's phrases as features of a run's metrics, their
thresholds as switches, and the report's table beside what the baseline's APF adds."""

from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd
import pytest

from pipeline.analysis.features import FEATURES, FeatureConfig, feature_row, paper_likeness
from pipeline.reporting.page import build_report
from pipeline.studies.experiment import run_experiment, run_family


def _metrics(**values) -> dict:
    base = {"reaction_delay_s": 0.2, "lateral_accel_max_mps2": 1.0, "overshoot_m": 0.0,
            "yaw_rate_sign_changes": 2, "lateral_jerk_max_mps3": 5.0,
            "lateral_jerk_rms_mps3": 1.0, "recovery_time_s": 2.0, "oscillation_count": 0}
    return {**base, **values}


def test_features_follow_their_thresholds():
    """Each phrase reads its metric against its threshold (closed form), and moving the
    threshold across the value flips it: every threshold is a live switch."""
    cfg = FeatureConfig()
    calm = feature_row(_metrics(), cfg)
    assert calm == {"slow_avoidance": False, "aggressive_curved": False,
                    "sharp_turns_after": False, "uncontrolled": False, "drops_sharply": False,
                    "fast_avoidance": True, "smooth_avoidance": True, "smooth_return": True,
                    "minimal_oscillation": True}
    wild = feature_row(_metrics(reaction_delay_s=None, lateral_accel_max_mps2=3.0,
                                overshoot_m=0.5, yaw_rate_sign_changes=9,
                                lateral_jerk_max_mps3=40.0, lateral_jerk_rms_mps3=6.0,
                                recovery_time_s=None, oscillation_count=3), cfg)
    assert all(wild[f.key] for f in FEATURES if f.describes == "baseline")
    assert not any(wild[f.key] for f in FEATURES if f.describes == "improved")
    assert paper_likeness(wild, calm) == len(FEATURES)
    assert paper_likeness(calm, wild) == 0
    for key, value, field, threshold in (
            ("reaction_delay_s", 0.4, "fast_reaction_s", 0.5),
            ("lateral_jerk_rms_mps3", 1.5, "smooth_jerk_rms_mps3", 1.4),
            ("lateral_accel_max_mps2", 2.5, "aggressive_lateral_accel_mps2", 2.6),
            ("overshoot_m", 0.3, "sharp_return_overshoot_m", 0.4)):
        run = _metrics(**{key: value})
        before = feature_row(run, cfg)
        after = feature_row(run, FeatureConfig(**{field: threshold}))
        assert before != after, field


def test_bad_feature_thresholds_name_their_key():
    from pipeline.errors import ConfigError

    with pytest.raises(ConfigError, match="features.fast_reaction_s"):
        FeatureConfig(fast_reaction_s=-1.0)
    with pytest.raises(ConfigError, match="features.sudden_jerk_mps3"):
        FeatureConfig(sudden_jerk_mps3=math.nan)


def test_report_has_the_feature_table_and_what_the_baseline_apf_adds(tmp_path, make_config):
    runs = tmp_path / "runs"
    for method in ("baseline", "improved", "mpc_no_apf"):
        run_experiment(make_config([f"method={method}"]), runs / "paper" / method)
        run_family(make_config([f"method={method}", "scenario=family",
                                "scenario.family.size=12", "scenario.family.n_jobs=1"]),
                   runs / "family" / method, progress=False)
    for planner in ("baseline_printed", "improved"):
        run_experiment(make_config(["experiment=kinematic", f"planner={planner}"]),
                       runs / "kinematic" / planner)
        literal = planner.replace("_printed", "")  # the literal reading: ref. [18]'s baseline
        run_experiment(make_config(["experiment=kinematic_readings", f"planner={literal}",
                                    "appendix_reading=literal"]),
                       runs / "kinematic_readings" / "literal" / literal)
    run_experiment(make_config(["experiment=kinematic_readings", "planner=baseline",
                                "appendix_reading=vehicle_anchor"]),
                   runs / "kinematic_readings" / "vehicle_anchor" / "baseline")
    run_experiment(make_config(["experiment=kinematic_readings", "planner=improved",
                                "appendix_reading=vehicle_anchor"]),
                   runs / "kinematic_readings" / "vehicle_anchor" / "improved")
    for planner in ("baseline_printed", "improved", "mpc_no_apf"):
        run_family(make_config(["experiment=kinematic_family", f"planner={planner}",
                                "scenario.family.size=8", "scenario.family.n_jobs=1"]),
                   runs / "kinematic_family" / planner.replace("_printed", ""), progress=False)
    page = build_report(runs, tmp_path / "report", "pytest").read_text()
    assert 'id="features-table"' in page and 'id="apf-adds"' in page
    # the Appendix-A track's own ledger, recomputed here from its family tables
    from pipeline.analysis.claims.ledger import family_ledger
    from pipeline.store.runs import read_family

    tables = {m: read_family(runs / "kinematic_family" / m).table
              for m in ("baseline", "improved", "mpc_no_apf")}
    claims = make_config(["experiment=kinematic_family"]).claims
    expected = family_ledger(tables, claims, None, "improved", ("baseline", "baseline_matched"),
                             sensitivity=False).to_frame()
    written = pd.read_csv(tmp_path / "report" / "tables" / "claims_ledger_kinematic_family.csv")
    assert list(written["outcome"]) == list(expected["outcome"])
    np.testing.assert_allclose(written["estimate"], expected["estimate"].astype(float))
    assert 'id="kinematic-family"' in page
    assert re.search(r"<strong>(<abbr [^>]*>)?Appendix-A track(</abbr>)?</strong>", page)
    assert (tmp_path / "report" / "tables"
            / "claims_ledger_baseline_vs_no_apf_kinematic_family.csv").is_file()
    readings = page[page.index('id="kinematic-readings"'):]
    readings = readings[:readings.index("</table>")]
    # literal: the baseline never meets the obstacle; vehicle-anchored: it does
    literal_row = readings[readings.index(">literal<"):].split("</tr>")[0]
    anchored_row = readings[readings.index(">vehicle_anchor<"):].split("</tr>")[0]
    assert "not comparable" in literal_row and "not comparable" not in anchored_row
    assert "Appendix-A track (8 scenarios)" in (tmp_path / "report" / "answer.txt").read_text()
    table = page[page.index('id="features-table"'):]
    table = table[:table.index("</table>")]
    assert "Appendix-A track, printed (default)" in table and "Appendix-A track, literal" in table
    assert table.count("<tr>") - 2 == len(FEATURES)
    assert "It picks the configured default (printed)" in page
    assert (tmp_path / "report" / "tables" / "claims_ledger_baseline_vs_no_apf.csv").is_file()
    answer = (tmp_path / "report" / "answer.txt").read_text()
    assert "mpc_no_apf" in answer
