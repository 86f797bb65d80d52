"""``apf-mpc euro-ncap`` (:mod:`pipeline.studies.euro_ncap`): a small family on the lateral
track writes every test's protocol outcome, the counts per case and the ledger; the result
reads back; the report shows its section without the paper scenario; a second run resumes
every member."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

from pipeline.cli import main
from pipeline.studies.results.euro_ncap import EuroNcapResult


def test_a_small_family_writes_outcomes_counts_and_ledger_and_the_report_shows_them(
        tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("PIPELINE_MEMBER_CACHE", "off")
    out = tmp_path / "outputs" / "euro_ncap"
    assert main(["euro-ncap", "--family-size", "5", "--tracks", "lateral,lateral_braking",
                 "--out", str(out), "scenario.source.params.cases=[CPNA-25,CPFA-50]"]) == 0
    printed = capsys.readouterr().out
    assert "lateral improved:" in printed and "of 5 tests avoided" in printed
    result = EuroNcapResult.load(out)
    table = result.table
    assert len(table) == 5 * 6 and set(table["method"]) == {"improved", "baseline", "mpc_dcbf",
                                                            "cbf_filter"}
    # the braking track brakes: a member's speed reference falls below 90 % of its test speed;
    # on the steady track it stays the test speed
    from pipeline.store.runs import read_member

    braking = [read_member(out / "lateral_braking" / "improved", i).trajectory for i in range(5)]
    steady = [read_member(out / "lateral" / "improved", i).trajectory for i in range(5)]
    assert any(t["speed_ref_mps"].min() < 0.9 * t["vx_mps"].iloc[0] for t in braking)
    assert all(np.allclose(t["speed_ref_mps"].dropna(), t["vx_mps"].iloc[0]) for t in steady)
    table = table[table["track"] == "lateral"]
    assert set(table["case"]) <= {"CPNA-25", "CPFA-50"}
    # an impact speed exactly where the road user was hit; the test speed within 1 km/h
    assert (table["hit"] == table["impact_speed_kmh"].notna()).all()
    assert (np.abs(table["speed_kmh"] - table["nominal_speed_kmh"]) <= 1.0).all()
    # the counts are the table's
    for row in result.summary_rows("lateral"):
        part = table[table["method"] == row["method"]]
        assert row["tests"] == 5 and row["avoided"] == int((~part["hit"]).sum())
    # a hit on the true shapes is a collision of the run's own (disc covers hold the shapes);
    # the run goes on after it (end_at_contact=false)
    for _, row in table[table["hit"]].iterrows():
        members = pd.read_csv(out / "lateral" / row["method"] / "family_metrics.csv")
        assert bool(members.loc[members["scenario"] == row["scenario"], "collision"].iloc[0])
        assert row["termination"] != "contact"
    ledger = {(r["track"], r["comparison"], r["claim"]) for r in result.ledger}
    claims = ("C0", "C1", "C2", "C3a", "C3b", "C4", "C5")
    assert ledger == {("lateral", against, c) for c in claims
                      for against in ("baseline", "mpc_dcbf", "cbf_filter")} \
        | {("lateral_braking", "baseline", c) for c in claims}
    assert result.comparisons("lateral") == ("baseline", "mpc_dcbf", "cbf_filter")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["settings"]["cases"] == ["CPNA-25", "CPFA-50"]

    # again: every member complete with the same config hash, nothing simulated
    assert main(["euro-ncap", "--family-size", "5", "--tracks", "lateral,lateral_braking",
                 "--out", str(out), "scenario.source.params.cases=[CPNA-25,CPFA-50]"]) == 0
    pd.testing.assert_frame_equal(EuroNcapResult.load(out).table, result.table)

    # the report of this folder alone shows the section with each method's row
    report = tmp_path / "report"
    assert main(["report", str(tmp_path / "outputs"), "--out", str(report)]) == 0
    html = (report / "index.html").read_text()
    assert 'id="euro-ncap-lateral"' in html and 'id="euro-ncap-claims"' in html
    claims_table = html[html.index('id="euro-ncap-claims"'):]
    assert "<td>mpc_dcbf</td>" in claims_table and "<td>baseline</td>" in claims_table
    for method in ("improved", "baseline", "mpc_dcbf", "cbf_filter"):
        row = next(r for r in result.summary_rows("lateral") if r["method"] == method)
        assert f"<strong>{row['avoided']}/5</strong>" in html
