"""The lateral peers tuned as improved and the baseline are (``make tune-peers``): each peer's
search space reaches its own settings, a peer as the control is refused a matched control that
is the baseline's, and a tiny tune improved vs vo runs end to end with improved's trials those
of the improved-vs-baseline tune under the same rules."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from pipeline.errors import ConfigError
from pipeline.peers.cbf_filter import CbfFilterSettings
from pipeline.peers.dwa import DwaSettings
from pipeline.peers.mpc_dcbf import DcbfParams
from pipeline.peers.velocity_obstacles import VoSettings
from pipeline.studies.tune import TuneSpace
from pipeline.studies.tune.search import Runner
from pipeline.studies.tune.space import search_space

#: the lateral peers, where each keeps its settings and the parser the peer reads them with
PEERS = {"mpc_dcbf": ("controller", DcbfParams.of),
         "cbf_filter": ("controller", CbfFilterSettings.of),
         "vo": ("planner", VoSettings.from_params),
         "dwa_kinematic": ("controller", DwaSettings.from_params)}
#: the tune's settings of a tuning on the Appendix-A track (make tune-peers' KINEMATIC_TUNE_SETS)
KINEMATIC = {"track": "kinematic", "backend": "clarabel_direct",
             "heldout_backend": "clarabel_direct"}


def _ends(distribution) -> list:
    """Both ends of a range (every choice of a categorical one)."""
    if hasattr(distribution, "choices"):
        return list(distribution.choices)
    return [distribution.low, distribution.high]


def _section(cfg, where: str) -> dict:
    return dict((cfg.controller if where == "controller" else cfg.planner).params)


@pytest.mark.parametrize("peer", sorted(PEERS))
def test_every_parameter_of_a_peers_space_reaches_its_settings(peer, tmp_path):
    """Each parameter at each end of its range, composed as a trial is (``Runner.job``):
    the value is in the composed ``<section>.params``, differs from the preset's at one end at
    least (it changes the run: the config hash moves), and the peer's own parser accepts it."""
    where, parse = PEERS[peer]
    distributions, reasons = search_space(peer)
    assert distributions and set(reasons) == set(distributions)
    track = KINEMATIC if peer.endswith("_kinematic") else {}
    runner = Runner(TuneSpace(methods=["improved", peer], matched_control="", **track),
                    tmp_path, [], lambda _: None)
    default = runner.job(peer, "default", {}, "training", 0)
    preset = _section(default.cfg, where)
    assert set(preset) >= {k.rsplit(".", 1)[1] for k in distributions}
    for name, distribution in distributions.items():
        section, params, key = name.split(".")
        assert (section, params) == (where, "params"), name
        moved = False
        for value in _ends(distribution):
            job = runner.job(peer, "trial", {name: value}, "training", 0)
            composed = _section(job.cfg, where)
            assert composed[key] == value, (name, value, composed[key])
            assert {k: v for k, v in composed.items() if k != key} == \
                {k: v for k, v in preset.items() if k != key}
            settings = parse(composed)
            assert getattr(settings, key) == pytest.approx(value) if not isinstance(
                value, str) else getattr(settings, key) == value
            if value != preset[key]:
                moved = True
                assert job.cfg.config_hash() != default.cfg.config_hash()
        assert moved, f"{name}: the preset's value at every end of its range"


def test_a_peer_as_control_gets_no_baselines_matched_control():
    with pytest.raises(ConfigError, match="tune.matched_control"):
        TuneSpace(methods=["improved", "vo"])
    space = TuneSpace(methods=["improved", "vo"], matched_control="")
    assert space.control == "vo" and space.feasibility_reference == "vo"
    with pytest.raises(ConfigError, match="tune.safety_reference"):
        TuneSpace(methods=["improved", "vo"], matched_control="", safety_reference="nothing")
    with pytest.raises(ConfigError, match="tune.methods"):
        TuneSpace(methods=["improved", "dwa"], matched_control="")


def test_a_tuning_on_the_appendix_a_track_composes_every_family_there(tmp_path):
    """tune.track kinematic: every method's training and held-out families (the treatment's,
    the peer's, the safety reference's) run the kinematic bicycle MPC from rest for 100 steps
    (make reproduce's kinematic_family), the dynamic window keeps its controller; the lateral
    track composes the lateral MPC at cruising speed; DAQP is refused there (no such QP)."""
    lateral = Runner(TuneSpace(methods=["improved", "vo"], matched_control=""), tmp_path, [],
                     lambda _: None)
    kinematic = Runner(TuneSpace(methods=["improved", "dwa_kinematic"], matched_control="",
                                 safety_reference="baseline", **KINEMATIC),
                       tmp_path, [], lambda _: None)
    for method in ("improved", "baseline", "dwa_kinematic"):
        for part in ("training", "heldout"):
            cfg = kinematic.job(method, "default", {}, part, 0).cfg
            assert cfg.controller.kind == "kinematic_mpc", (method, part)
            assert (cfg.scenario.initial_speed_mps, cfg.scenario.n_steps) == (0.0, 100)
    assert kinematic.job("dwa_kinematic", "default", {}, "training", 0).cfg.controller \
        ._target_ == "pipeline.peers.dwa.DynamicWindow"
    assert kinematic.job("improved", "default", {}, "training", 0).cfg.controller._target_ \
        is None
    flat = lateral.job("improved", "default", {}, "training", 0).cfg
    assert flat.controller.kind == "mpc" and flat.scenario.n_steps != 100
    assert flat.scenario.initial_speed_mps is None  # the scenario's cruising speed
    with pytest.raises(ConfigError, match="tune.backend"):
        TuneSpace(methods=["improved", "dwa_kinematic"], matched_control="", track="kinematic")
    with pytest.raises(ConfigError, match="tune.track"):
        TuneSpace(track="sideways")
    assert TuneSpace(**KINEMATIC).trial_key() != TuneSpace(
        backend="clarabel_direct", heldout_backend="clarabel_direct").trial_key()


def test_the_safety_reference_keys_the_trials_only_when_set():
    """Tunings without one keep their trial key (make tune's stored studies still resume)."""
    plain = TuneSpace()
    assert TuneSpace(safety_reference="").trial_key() == plain.trial_key()
    assert TuneSpace(safety_reference="baseline").trial_key() != plain.trial_key()
    assert TuneSpace(safety_reference="baseline").feasibility_reference == "baseline"


def _tiny(methods: list[str], **changes) -> TuneSpace:
    return TuneSpace(name="tiny", methods=methods, replicates=1, min_trials=2, max_trials=2,
                     convergence_window=1, batch_size=2, population_size=2, training_size=3,
                     heldout_size=4, heldout_backend="daqp", max_heldout_settings=1, rungs=[],
                     prune_after_trials=0, **changes)


def test_a_tiny_tune_against_vo_judges_vo_and_keeps_improveds_trials(tmp_path):
    """[improved, vo] with the baseline's feasibility threshold: the held-out ledgers compare
    improved with vo (no force claims: vo has no APF), and improved's trials are those of the
    [improved, baseline] tune with the same rules and seeds."""
    from pipeline.studies.tune import run_tuning

    folder = tmp_path / "outputs" / "tune_peers" / "vo"
    peer = run_tuning(_tiny(["improved", "vo"], matched_control="",
                            safety_reference="baseline"), folder, log=lambda _: None)
    for ledger in (peer.ledger_tuned, peer.ledger_default):
        assert len(ledger) and set(ledger["comparison"]) == {"vo"}
        assert {"C0", "C1", "C2", "C4"} <= set(ledger["claim"])
        assert not {"C3a", "C3b"} & set(ledger["claim"])
    claims = {c.claim: c for c in peer.summary.claims}
    assert "C1" in claims and "C3a" not in claims
    assert claims["C1"].tuned_outcomes == tuple(
        peer.ledger_tuned.loc[peer.ledger_tuned["claim"] == "C1", "outcome"])
    assert set(peer.trials["method"]) == {"improved", "vo"}
    vo_params = [p for p in peer.trials.loc[peer.trials["method"] == "vo", "params"]]
    assert all("planner.params.heading_count" in p for p in vo_params)

    base = run_tuning(_tiny(["improved", "baseline"]), tmp_path / "baseline",
                      log=lambda _: None)
    mine = peer.trials[peer.trials["method"] == "improved"].reset_index(drop=True)
    theirs = base.trials[base.trials["method"] == "improved"].reset_index(drop=True)
    pd.testing.assert_frame_equal(mine, theirs)
    assert peer.summary.safety_threshold_collisions == base.summary.safety_threshold_collisions
    assert not math.isnan(float(peer.ledger_tuned["estimate"].iloc[0]))
    _the_peers_section_reads_the_tuning(tmp_path / "outputs", peer)


def _the_peers_section_reads_the_tuning(root, peer) -> None:
    """The report reads ``tune_peers/<peer>`` and shows each claim tuned beside untuned."""
    from types import SimpleNamespace

    from pipeline.reporting.inputs import _Optional, _peer_tunes
    from pipeline.reporting.render import environment
    from pipeline.reporting.sections.peers import PeersSection, tuned_peers
    from pipeline.store.layout import OutputsLayout

    skipped: list = []
    tunes = _peer_tunes(OutputsLayout.load(root), _Optional(skipped))
    assert set(tunes) == {"vo"} and not skipped
    (shown,) = tuned_peers(SimpleNamespace(peer_tunes=tunes))
    assert (shown.peer, shown.treatment, shown.heldout, shown.replicates) == ("vo", "improved",
                                                                               4, 1)
    by_claim = {r["claim"]: r for r in shown.rows}
    for c in peer.summary.claims:
        assert by_claim[c.claim]["untuned"] == c.default
        assert by_claim[c.claim]["tuned"] == c.tuned
    assert "below the default budget" in shown.label
    assert shown.settings and shown.settings[0].startswith("replicate 0: ")
    html = environment().get_template("sections/peers.html.j2").render(
        peers=PeersSection("improved", (), (), (), (shown,)))
    assert 'id="peers-tuned-vo"' in html and by_claim["C1"]["counts"] in html


def test_the_peers_section_names_the_track_of_a_tuning():
    """A peer tuned on the Appendix-A track (dwa_kinematic) is captioned with its track and
    ordered with its peer (dwa, last); a lateral one is not."""
    from types import SimpleNamespace

    from pipeline.reporting.render import environment
    from pipeline.reporting.sections.peers import PeersSection, tuned_peers

    def result(control: str, track: str):
        summary = SimpleNamespace(methods=["improved", control], claims=(), compromise={},
                                  replicates=({"replicate": 0},), label="",
                                  families={"heldout": {"size": 200}},
                                  settings={"track": track})
        return SimpleNamespace(summary=summary)

    shown = tuned_peers(SimpleNamespace(peer_tunes={
        "dwa_kinematic": result("dwa_kinematic", "kinematic"), "vo": result("vo", "lateral")}))
    assert [(p.peer, p.track) for p in shown] == [("vo", "lateral"),
                                                  ("dwa_kinematic", "kinematic")]
    html = environment().get_template("sections/peers.html.j2").render(
        peers=PeersSection("improved", (), (), (), shown))
    assert "improved against dwa_kinematic, untuned and tuned (Appendix-A track, 200" in html
    assert "improved against vo, untuned and tuned (200 held-out" in html
