"""The methods the paper names in make reproduce's outputs (issue 42): the ``peers`` and
``kinematic_peers`` experiments compose every peer by ``_target_``, and the report judges the
treatment against each on the same scenarios as the track's ledger
(``tables/claims_ledger_peers.csv``), its C0 row the difference of collision counts read off
the families' tables on disk."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

LATERAL_PEERS = ("mpc_dcbf", "cbf_filter", "vo")
KINEMATIC_PEERS = ("mpc_dcbf", "cbf_filter", "vo", "dwa")
SMALL = ["scenario.family.size=8", "scenario.family.n_jobs=1"]
#: the lateral peers on the ledger's first 6 scenarios (as make reproduce runs them on its
#: first PEERS_FAMILY_SIZE)
FIRST = ["scenario.family.size=6", "scenario.family.n_jobs=1"]


def test_the_experiments_compose_every_peer_by_target(make_config):
    """Each peer of both experiments is a plug-in (``_target_`` of a planner or controller
    under ``pipeline.peers``) labelled by its own method name, on its track's plant."""
    for experiment, peers, kind in (("peers", LATERAL_PEERS, "mpc"),
                                    ("kinematic_peers", KINEMATIC_PEERS, "kinematic_mpc")):
        for peer in peers:
            method = peer if experiment == "peers" else f"{peer}_kinematic"
            cfg = make_config([f"experiment={experiment}", f"method={method}"])
            targets = [t for t in (cfg.planner._target_, cfg.controller._target_) if t]
            assert targets and all(t.startswith("pipeline.peers.") for t in targets), targets
            assert cfg.run.method == peer
            assert cfg.controller.kind == kind
            assert cfg.scenario.family is not None


@pytest.fixture(scope="module")
def outputs(tmp_path_factory, make_config):
    """The paper scenario, the default families of improved and baseline, and the peers' on
    the same 8 members, on both tracks."""
    from pipeline.studies.experiment import run_experiment, run_family

    root = tmp_path_factory.mktemp("outputs")
    for method in ("baseline", "improved"):
        run_experiment(make_config([f"method={method}"]), root / "paper" / method)
        run_family(make_config([f"method={method}", "scenario=family"] + SMALL),
                   root / "family" / method, progress=False)
    for planner, name in (("baseline_printed", "baseline"), ("improved", "improved")):
        run_family(make_config(["experiment=kinematic_family", f"planner={planner}"] + SMALL),
                   root / "kinematic_family" / name, progress=False)
    for peer in LATERAL_PEERS:
        run_family(make_config(["experiment=peers", f"method={peer}"] + FIRST),
                   root / "peers" / peer, progress=False)
    for peer in KINEMATIC_PEERS:
        run_family(make_config(["experiment=kinematic_peers", f"method={peer}_kinematic"]
                               + SMALL), root / "kinematic_peers" / peer, progress=False)
    return root


def _collisions(folder: Path, first: int | None = None) -> int:
    """Collisions over a family's (first) members, from its table on disk (the oracle)."""
    table = pd.read_csv(folder / "family_metrics.csv")
    return int(table["collision"].astype(bool).head(first or len(table)).sum())


def test_report_judges_improved_against_every_peer(outputs, tmp_path):
    from pipeline.reporting.page import build_report

    build_report(outputs, tmp_path, "pytest", figure_jobs=1)
    ledger = pd.read_csv(tmp_path / "tables" / "claims_ledger_peers.csv")
    for track, peers, default in (("lateral", LATERAL_PEERS, "family"),
                                  ("kinematic", KINEMATIC_PEERS, "kinematic_family")):
        rows = ledger[ledger["track"] == track]
        assert sorted(set(rows["comparison"])) == sorted(peers)
        # C3a and C3b read the APF's force, which no peer has: not judged
        assert set(rows["claim"]) == {"C0", "C1", "C2", "C4", "C5"}
        c0 = rows[rows["claim"] == "C0"].set_index("comparison")
        n = 6 if track == "lateral" else 8
        treated = _collisions(outputs / default / "improved", n)
        section = "peers" if track == "lateral" else "kinematic_peers"
        for peer in peers:
            # the same scenarios: improved's default family (its first n members) against
            # the peer's
            expected = (treated - _collisions(outputs / section / peer)) / n
            assert c0.loc[peer, "estimate"] == pytest.approx(expected, abs=1e-12)
            assert c0.loc[peer, "n_pairs"] == n
    counts = pd.read_csv(tmp_path / "tables" / "peers_collisions.csv")
    lateral = counts[counts["track"] == "lateral"].set_index("method")
    assert lateral.loc["vo", "collisions"] == _collisions(outputs / "peers" / "vo")
    assert (lateral["solve_time_median_s"] > 0).all()
    # every collision of every family once, with both labels; a collision another method
    # avoided is never published unavoidable, and the counts are the published ones
    labels = pd.read_csv(tmp_path / "tables" / "collision_labels.csv")
    assert len(labels) == sum(_collisions(f.parent) for f in outputs.glob("*/*/family.json"))
    avoided = labels["collision_avoided_by"].fillna("") != ""
    assert not (labels["collision_unavoidable"].astype(str) == "True")[avoided].any()
    for (track, method), row in counts.set_index(["track", "method"]).iterrows():
        mine = labels[(labels["track"] == track) & (labels["method"] == method)]
        if method != "improved":  # improved's row: the peers' scenarios only
            assert row["collisions_unavoidable"] == (
                mine["collision_unavoidable"].astype(str) == "True").sum()
            assert row["collisions_unavoidable_run"] == (
                mine["collision_unavoidable_run"].astype(str) == "True").sum()
    page = (tmp_path / "index.html").read_text()
    assert 'id="peers"' in page and 'href="#peers"' in page
    assert 'id="peers-kinematic-who-wins"' in page and "Fox, Burgard and Thrun" in page


def test_a_peer_family_of_other_scenarios_is_not_paired(outputs):
    """A peer drawn with another seed (or size) is not judged against the ledger's scenarios;
    the others still are."""
    import dataclasses

    from pipeline.reporting.inputs import ReportInputs
    from pipeline.reporting.verdicts import _peers

    inputs = ReportInputs.load(outputs)
    assert inputs.peers is not None and inputs.family is not None
    label = inputs.peers.label_of("vo")
    info = {**inputs.peers.info, label: {**inputs.peers.info[label], "seed": 7}}
    moved = dataclasses.replace(inputs.peers, info=info)
    judged = _peers("lateral", inputs.family, moved, inputs.claims)
    assert judged is not None and judged.peers == ("mpc_dcbf", "cbf_filter")
    assert set(judged.peers) | {"vo"} == set(_peers("lateral", inputs.family, inputs.peers,
                                                    inputs.claims).peers)
