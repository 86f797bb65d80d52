"""A report of what exists (issue 62, item 7): ``make pedestrians`` and ``make peers`` on a
fresh clone failed at their report step ("no complete run folders") because the report needed
make reproduce's runs beside them. Now the report shows what it can (the pedestrian section)
and lists what it cannot with the command that makes it."""

from __future__ import annotations

import pandas as pd


def test_pedestrian_families_alone_make_a_page_with_their_section(make_config, tmp_path):
    from pipeline.reporting.page import build_report
    from pipeline.studies.experiment import run_family

    root = tmp_path / "outputs"
    for planner in ("baseline", "improved"):
        run_family(make_config(["experiment=pedestrians", f"planner={planner}",
                                "scenario.family.size=4", "scenario.family.n_jobs=1"]),
                   root / "pedestrians" / planner, progress=False, member_cache=None)
    out = tmp_path / "report"
    build_report(root, out, "pytest", figure_jobs=1)
    html = (out / "index.html").read_text()
    assert 'id="pedestrians"' in html and 'id="pedestrians-metrics"' in html
    assert "make reproduce writes them" in html  # the sections it cannot show, and how
    # make pedestrians' reading of "passed" (C4, C5) is said beside its ledger
    assert "<code>metrics.pass_reading=last_threat</code>" in html
    # C1 and C4 with the runs that never reacted or settled ranked last (make pedestrians'
    # claims.pairs), the scenario family's rule beside them (oracle: the paired differences of
    # the two tables by each rule)
    from pipeline.analysis.claims.catalogue import ALL_CLAIMS
    from pipeline.analysis.claims.statistics import paired_differences

    ledger = pd.read_csv(out / "tables" / "claims_ledger_pedestrians.csv")
    other = pd.read_csv(out / "tables" / "claims_pedestrians_other_pairs.csv")
    assert sorted(other["claim"]) == ["C1", "C4"] and set(other["comparison"]) == {"baseline"}
    assert set(other["pairs_rule"]) == {"neither_collided"}
    assert set(other["pairs_rule_ledger"]) == {"unsettled_last"}
    tables = {m: pd.read_csv(root / "pedestrians" / m / "family_metrics.csv")
              for m in ("baseline", "improved")}
    whole = ledger[(ledger["scene"] == "all") & (ledger["comparison"] == "baseline")]
    for claim in (c for c in ALL_CLAIMS if c.claim_id in ("C1", "C4")):
        for rule, rows, column in (("unsettled_last", whole, "pairs"),
                                   ("neither_collided", other, "pairs")):
            d = paired_differences(tables["improved"], tables["baseline"], claim, rule)["d"]
            row = rows[rows["claim"] == claim.claim_id].iloc[0]
            assert row[column] == int(d.notna().sum())
            assert (row["n_better"], row["n_worse"]) == (int((d < 0).sum()),
                                                         int((d > 0).sum()))
    assert 'id="pedestrians-other-pairs"' in html and "claims.pairs=unsettled_last" in html
    metrics = pd.read_csv(out / "tables" / "pedestrians_metrics.csv")
    assert sorted(metrics["method"]) == ["baseline", "improved"]
    assert set(metrics["crossings"]) == {4}


def test_peer_families_alone_are_listed_as_needing_the_scenario_family(make_config, tmp_path):
    from pipeline.reporting.page import build_report
    from pipeline.studies.experiment import run_family

    root = tmp_path / "outputs"
    run_family(make_config(["method=vo", "scenario=family", "scenario.family.size=3",
                            "scenario.family.n_jobs=1"]), root / "peers" / "vo",
               progress=False, member_cache=None)
    out = tmp_path / "report"
    build_report(root, out, "pytest", figure_jobs=1)
    html = (out / "index.html").read_text()
    assert "judged against improved on the scenario family, which is not here" in html
    assert "make reproduce writes it" in html


def test_the_pedestrian_ledger_takes_the_pairs_rule_of_the_family_it_judges(make_config,
                                                                              tmp_path):
    """Two families of improved (``claims.pairs`` unsettled_last, make pedestrians', and
    neither_collided) and a baseline made with neither_collided: the ledger judges the family
    in improved's own folder and reads C1 and C4 by that family's rule, and the page says the
    rule the ledger used (not the first family's, the baseline's)."""
    from pipeline.reporting.inputs import ReportInputs
    from pipeline.reporting.verdicts import Verdicts
    from pipeline.studies.experiment import run_family

    root = tmp_path / "outputs"
    small = ["scenario.family.size=4", "scenario.family.n_jobs=1"]
    for folder, overrides in (("baseline", ["planner=baseline", "claims.pairs=neither_collided"]),
                              ("improved", ["planner=improved"]),
                              ("improved_neither", ["planner=improved",
                                                    "claims.pairs=neither_collided"])):
        run_family(make_config(["experiment=pedestrians", *overrides, *small]),
                   root / "pedestrians" / folder, progress=False, member_cache=None)
    inputs = ReportInputs.load(root)
    family = inputs.pedestrians
    label = family.label_of("improved")
    assert family.settings[label].claims.pairs == "unsettled_last"
    judged = Verdicts.compute(inputs).pedestrians
    assert judged is not None and judged.pairs_rule == "unsettled_last"
    assert {row["pairs_rule_ledger"] for row in judged.other_pairs} == {"unsettled_last"}


def test_a_tune_alone_makes_a_page_that_says_what_it_needs(tmp_path):
    """make tune on a fresh clone (outputs/tune and nothing of make reproduce's): its report
    step wrote nothing and make tune ended on 'no complete run folders'; now the page is
    written and says that the fair fight is shown beside the answer make reproduce writes."""
    from pipeline.reporting.page import build_report

    root = tmp_path / "outputs"
    (root / "tune").mkdir(parents=True)
    out = tmp_path / "report"
    build_report(root, out, "pytest", figure_jobs=1)
    html = (out / "index.html").read_text()
    assert "the fair fight (tuned vs tuned) is shown beside the answer" in html
    assert "make reproduce writes them" in html
