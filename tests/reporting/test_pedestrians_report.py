"""The report's 'Real motion: recorded pedestrians' section (issue 43): from a small pedestrian
family of improved and baseline beside the paper scenario, it writes
``tables/claims_ledger_pedestrians.csv`` (a row per claim for the whole family and per scene),
the collision table (oracle: the families' own tables on disk), a figure, and every member's
link to the scenario explorer."""

from __future__ import annotations

import numpy as np
import pandas as pd

SMALL = ["scenario=pedestrians", "scenario.family.size=6", "scenario.family.n_jobs=1"]


def test_the_report_judges_the_pedestrian_family_overall_and_per_scene(make_config,
                                                                      tmp_path):
    from pipeline.reporting.page import build_report
    from pipeline.studies.experiment import run_experiment, run_family

    root = tmp_path / "outputs"
    for method in ("baseline", "improved"):
        run_experiment(make_config([f"method={method}"]), root / "paper" / method)
        run_family(make_config([f"method={method}"] + SMALL), root / "pedestrians" / method,
                   progress=False)
    out = tmp_path / "report"
    build_report(root, out, "pytest", figure_jobs=1)

    ledger = pd.read_csv(out / "tables" / "claims_ledger_pedestrians.csv")
    tables = {m: pd.read_csv(root / "pedestrians" / m / "family_metrics.csv")
              for m in ("baseline", "improved")}
    scenes = sorted({name.split("pedestrians_")[1].split("_s0_")[0]
                     for name in tables["improved"]["scenario"]})
    assert sorted(set(ledger["scene"])) == sorted(["all", *scenes])
    claims = ["C0", "C1", "C2", "C3a", "C3b", "C4", "C5"]
    for scene in ["all", *scenes]:
        assert ledger[ledger["scene"] == scene]["claim"].tolist() == claims
    assert set(ledger["comparison"]) == {"baseline"}
    # C0 over the whole family: the pairs are every member
    c0 = ledger[(ledger["scene"] == "all") & (ledger["claim"] == "C0")].iloc[0]
    assert c0["n_pairs"] == 6

    counts = pd.read_csv(out / "tables" / "pedestrians_collisions.csv")
    for method, table in tables.items():
        row = counts[(counts["scene"] == "all") & (counts["method"] == method)].iloc[0]
        assert row["collisions"] == int(table["collision"].astype(bool).sum())
        assert row["scenarios"] == 6
    html = (out / "index.html").read_text()
    assert 'id="pedestrians"' in html and "ends at its first contact" in html
    # a family with the scenario family's reading of "passed" says nothing more about it
    assert "metrics.pass_reading" not in html[html.index('id="pedestrians"'):]
    # the field's metrics lead the section: every column the issue names, both methods
    metrics = pd.read_csv(out / "tables" / "pedestrians_metrics.csv")
    assert {"family", "track", "method", "crossings", "success_rate", "collision_rate",
            "timeout_rate", "time_to_goal_median_s", "path_ratio_median",
            "min_distance_median_m", "intrusion_time_share"} <= set(metrics.columns)
    assert sorted(metrics["method"]) == ["baseline", "improved"]
    for method, table in tables.items():
        row = metrics[metrics["method"] == method].iloc[0]
        assert row["crossings"] == 6
        assert row["collision_rate"] == table["collision"].astype(bool).mean()
        # the avoidable ones: a contact the run's own reachability check calls avoidable, or
        # that the other method did not have on the same crossing (the published label)
        hit = {m: t["collision"].astype(bool).to_numpy() for m, t in tables.items()}
        avoidable = hit[method] & (table["collision_avoidable"].astype(bool).to_numpy()
                                   | ~np.logical_and.reduce(list(hit.values())))
        assert row["collision_avoidable_rate"] == avoidable.mean()
        assert 0.0 <= row["collision_rate_standing_safe_avoidable"] \
            <= row["collision_rate_standing_safe"]
        # the contacts at a walker's appearance, counted from the members' own flags
        appeared = table["collision"].astype(bool).to_numpy() \
            & table["contact_at_appearance"].astype(bool).to_numpy()
        assert row["collision_at_appearance_rate"] == appeared.mean()
        assert 0.0 <= row["collision_rate_standing_safe_seen"] \
            <= row["collision_rate_standing_safe"]
    assert html.index('id="pedestrians-metrics"') < html.index('id="pedestrians-verdicts"')
    for index in range(6):
        assert f'href="explorer.html#pedestrians/{index}"' in html
    assert (out / "figures" / "pedestrians_scene.png").is_file()
