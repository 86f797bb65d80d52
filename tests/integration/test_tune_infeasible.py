"""A replicate in which a method has no feasible setting (every trial collided more often than
the untuned reference on its training family): the tune judges the other replicates and counts
that one as "no feasible setting of <method>" per claim, instead of stopping with nothing (the
reduced tune improved vs dwa on the Appendix-A track stopped so in its third replicate)."""

from __future__ import annotations

import pandas as pd
import pytest

from pipeline.studies.tune import TuneSpace
from pipeline.studies.tune import study as tune_study
from pipeline.studies.tune.study import (
    NoFeasibleSettingError,
    infeasible_outcome,
    pick_settings,
    replicates_without_setting,
)


def _space(**changes) -> TuneSpace:
    return TuneSpace(name="tiny", methods=["improved", "vo"], replicates=2, min_trials=2,
                     max_trials=2, convergence_window=1, batch_size=2, population_size=2,
                     training_size=3, heldout_size=4, heldout_backend="daqp",
                     max_heldout_settings=1, rungs=[], prune_after_trials=0,
                     matched_control="", safety_reference="baseline", **changes)


def _trials(pareto: dict[tuple[int, str], bool]) -> pd.DataFrame:
    """Two trials per replicate and method; a method's trials are on its front or not."""
    rows = []
    for (replicate, method), on_front in pareto.items():
        for trial in range(2):
            rows.append({"replicate": replicate, "method": method, "trial": trial,
                         "constraint": -1.0 if on_front else 2.0, "feasible": on_front,
                         "pareto": on_front, "params": "{}", "pruned_at": None,
                         "train:mean reaction_delay_s": 0.5 + trial,
                         "train:mean lateral_jerk_rms_mps3": 1.0 - 0.1 * trial,
                         "train:mean recovery_time_s": 3.0})
    return pd.DataFrame(rows)


def test_a_replicate_without_a_feasible_setting_is_left_out_and_named():
    space = _space()
    trials = _trials({(0, "improved"): True, (0, "vo"): True,
                      (1, "improved"): False, (1, "vo"): True})
    assert replicates_without_setting(trials, space) == {1: ["improved"]}
    chosen = pick_settings(trials, space)
    assert set(chosen) == {(0, "improved"), (0, "vo")}
    assert infeasible_outcome(["improved"]) == "no feasible setting of improved"


def test_no_replicate_with_every_method_feasible_is_one_line():
    space = _space()
    trials = _trials({(0, "improved"): False, (0, "vo"): True,
                      (1, "improved"): True, (1, "vo"): False})
    with pytest.raises(NoFeasibleSettingError) as info:
        pick_settings(trials, space)
    message = str(info.value)
    assert "\n" not in message
    assert "replicate 0: improved; replicate 1: vo" in message


def test_the_tune_counts_an_unjudged_replicate_and_never_heads_the_answer(tmp_path,
                                                                         monkeypatch):
    """A real tiny tune improved vs vo over 2 replicates, replicate 1's improved trials all
    marked as colliding too often: replicate 0 is judged, replicate 1 counts as "no feasible
    setting of improved" in every claim's outcomes, the summary names it, the tuning never
    writes the headline, and the report's peers section reads it."""
    from pipeline.studies.tune import run_tuning

    real = tune_study.trials_table

    def planted(studies, space, replicate):
        table = real(studies, space, replicate)
        if replicate == 1:
            mine = table["method"] == "improved"
            table.loc[mine, ["feasible", "pareto"]] = False
            table.loc[mine, "constraint"] = 5.0
        return table

    monkeypatch.setattr(tune_study, "trials_table", planted)
    lines: list[str] = []
    folder = tmp_path / "outputs" / "tune_peers" / "vo"
    result = run_tuning(_space(), folder, log=lines.append)
    summary = result.summary
    assert summary.without_feasible_setting == {"1": ["improved"]}
    assert any(line.startswith("replicate 1: no feasible setting of improved (") for line in lines)
    assert set(result.ledger_tuned["replicate"]) == {0}
    assert summary.claims
    for claim in summary.claims:
        assert len(claim.tuned_outcomes) == 2
        assert claim.tuned_outcomes[1] == "no feasible setting of improved"
        assert claim.tuned_estimates[1] is None and claim.tuned_cis[1] == (None, None)
        assert "no feasible setting of improved 1/2" in claim.counts
        # 1 of 1 judged replicate (the other is not among the n): p = 1/2, not settled
        assert claim.tuned == "not settled" and claim.judged_replicates == 1
        assert claim.p_value == pytest.approx(0.5)
    assert not summary.headline
    assert "not judged: replicate 1 (no feasible setting of improved)" in summary.label
    # written and read back as the report reads it
    from pipeline.studies.results.tune import TuneResult

    again = TuneResult.load(folder)
    assert again.summary.without_feasible_setting == {"1": ["improved"]}
    from types import SimpleNamespace

    from pipeline.reporting.sections.peers import tuned_peers

    (shown,) = tuned_peers(SimpleNamespace(peer_tunes={"vo": again}))
    assert "no feasible setting of improved 1/2" in " ".join(r["counts"] for r in shown.rows)


def test_the_tune_settles_at_the_claims_alpha_it_runs_with(tmp_path):
    """The settling test reads the run's claims.alpha: one judged replicate is 1 of 1 alike,
    p = 1/2, which settles at alpha 0.5 (and never at the default 0.05); the summary records
    that alpha and that 1 replicate can settle there."""
    import dataclasses

    from pipeline.studies.tune import run_tuning

    space = dataclasses.replace(_space(), replicates=1, methods=["improved", "baseline"],
                                safety_reference="")
    result = run_tuning(space, tmp_path / "tune",
                        ["claims.alpha=0.5"], log=lambda *a: None)
    summary = result.summary
    assert (summary.settle_alpha, summary.fewest_replicates_to_settle) == (0.5, 1)
    assert summary.can_settle and summary.claims
    for claim in summary.claims:
        assert claim.p_value == pytest.approx(0.5) and claim.judged_replicates == 1
        assert claim.settled and claim.tuned == claim.tuned_outcomes[0]
