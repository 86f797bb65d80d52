"""The method registry (issue 57, item 1): a method's label, citation, colour, order and role
live in its preset (``conf/method/<name>.yaml``, ``run.*``), the report, figures, peers'
section and bench read them there (pipeline.methods), they never move a run's config hash, and
a peer of one's own brings its label and citation with its runs."""

from __future__ import annotations

import pytest

from pipeline.errors import ConfigError
from pipeline.methods import PRESENTATION_KEYS, method_info, method_registry

#: The lists the registry replaced (the oracle: the same order and the same peers).
ORDER_BEFORE = ("baseline", "baseline_matched", "improved", "velocity_aware", "mpc_no_apf",
                "apf_pursuit", "mpc_dcbf", "cbf_filter", "vo", "dwa")
NAMED_PEERS_BEFORE = {
    "lateral": (["method=improved"], {"mpc_dcbf": ["method=mpc_dcbf"],
                                      "cbf_filter": ["method=cbf_filter"],
                                      "vo": ["method=vo"]}),
    "kinematic": (["experiment=kinematic", "planner=improved"],
                  {name: ["experiment=kinematic", f"method={name}_kinematic"]
                   for name in ("mpc_dcbf", "cbf_filter", "vo", "dwa")}),
}


def test_every_preset_registers_its_method_in_the_earlier_order():
    from benchmarks.harness.named_peers import named_peers
    from pipeline.reporting.inputs import ordered

    registry = method_registry()
    assert set(registry) == set(ORDER_BEFORE)
    for info in registry.values():
        assert info.label and info.citation and info.color.startswith("#") and info.role
    assert ordered(reversed(ORDER_BEFORE + ("my_method",))) == [*ORDER_BEFORE, "my_method"]
    assert {m for m, i in registry.items() if i.role == "peer"} == {"mpc_dcbf", "cbf_filter",
                                                                    "vo", "dwa"}
    assert named_peers() == NAMED_PEERS_BEFORE
    assert method_info("vo").title == ("velocity obstacles feeding the same MPC (Fiorini and "
                                       "Shiller, IJRR 1998)")


def test_a_methods_colour_is_its_presets_in_every_figure_and_stable_otherwise():
    from pipeline.reporting.figures.colors import EXTRA_COLORS, method_color

    assert method_color("improved") == "#1f77b4" and method_color("baseline") == "#d62728"
    assert method_color("vo") == method_registry()["vo"].color
    assert method_color("someone_elses") in EXTRA_COLORS
    assert method_color("someone_elses") == method_color("someone_elses")


def test_presentation_never_moves_the_config_hash(make_config):
    plain = make_config(["method=vo"]).config_hash()
    dressed = make_config(["method=vo", "run.label=mine", "run.citation=me 2026",
                           "run.color='#000000'", "run.order=5", "run.role=reference"])
    assert dressed.config_hash() == plain and dressed.run.label == "mine"
    assert make_config(["method=vo", "run.method=vo2"]).config_hash() != plain
    assert set(PRESENTATION_KEYS) <= set(vars(dressed.run))


@pytest.mark.parametrize("override, key", [("run.color=red", "run.color"),
                                           ("run.role=hero", "run.role"),
                                           ("run.order=5000", "run.order")])
def test_a_bad_presentation_value_is_refused_naming_its_key(make_config, override, key):
    with pytest.raises(ConfigError) as info:
        make_config(["method=vo", override])
    assert info.value.key == key


PLANTED = """# @package _global_
defaults:
  - override /planner: straight_to_goal
  - override /controller: lateral_mpc

run:
  method: planted_peer
  label: "a planted peer"
  citation: "Nobody and Noone, 2026"
  color: "#123456"
  order: 95
  role: peer
"""


def test_a_peer_of_ones_own_brings_its_label_and_citation_to_the_report(make_config,
                                                                        tmp_path):
    """A peer from a config folder outside the package (hydra.searchpath), run on the family
    beside improved and the baseline: the peers' section names it by its own label and
    citation, and its ledger judges it; nothing in the package was touched."""
    import pandas as pd

    from pipeline.reporting.page import build_report
    from pipeline.studies.experiment import run_experiment, run_family

    (tmp_path / "conf" / "method").mkdir(parents=True)
    (tmp_path / "conf" / "method" / "planted_peer.yaml").write_text(PLANTED)
    search = f"hydra.searchpath=[file://{tmp_path / 'conf'}]"
    root = tmp_path / "outputs"
    family = ["scenario=family", "scenario.family.size=4", "scenario.family.n_jobs=1"]
    for method in ("improved", "baseline"):
        run_experiment(make_config([f"method={method}"]), root / "paper" / method)
        run_family(make_config([f"method={method}", *family]), root / "family" / method,
                   progress=False, member_cache=None)
    peer = make_config([search, "method=planted_peer", *family])
    assert peer.run.label == "a planted peer" and peer.config_hash()
    run_family(peer, root / "peers" / "planted_peer", progress=False, member_cache=None)
    build_report(root, tmp_path / "report", "pytest", figure_jobs=1)
    html = (tmp_path / "report" / "index.html").read_text()
    assert "a planted peer (Nobody and Noone, 2026)" in html
    ledger = pd.read_csv(tmp_path / "report" / "tables" / "claims_ledger_peers.csv")
    assert "planted_peer" in set(ledger["comparison"])
