"""The opening summary's rules: only a study at its default budget, converged, writes it;
numbers to the precision their interval supports, words where numbers would mislead; true
provenance; the answer's figure links every interval."""

from __future__ import annotations

import re
from types import SimpleNamespace

import pytest

from pipeline.config import ClaimsConfig
from pipeline.reporting.explorer import explorer_href
from pipeline.reporting.figures.answer import AnswerPanel, AnswerRow, Interval, answer_svg
from pipeline.reporting.format import collision_words, decimals_for, effect
from pipeline.reporting.sections.answer import answer_section
from pipeline.reporting.sections.family import FamilySection
from pipeline.reporting.sections.methods import tracked_changes


@pytest.mark.parametrize(("args", "text"), [
    ((-0.3457875, -0.4012, -0.2933, "s"), "-0.35 [-0.40, -0.29] s"),
    # noise around zero reads at the interval's precision, never 6e-08
    ((6e-08, -0.0104, 0.0213, "share"), "0.000 [-0.010, 0.021] share"),
    ((12.34, 9.1, 15.7, "count"), "12.3 [9.1, 15.7] count"),
])
def test_an_effect_is_printed_to_the_precision_its_interval_supports(args, text):
    assert effect(*args) == text


def test_an_effect_without_pairs_or_differences_says_so_in_words():
    assert effect(0.0, 0.0, 0.0, "count", 200, 200) == "no difference: all 200 pairs tied"
    assert effect(None, None, None, "s", 0, 0) == "no pairs to compare"
    assert "too few pairs" in effect(1.2, float("nan"), float("nan"), "s", 3, 0)
    assert "—" not in effect(float("nan"), float("nan"), float("nan"), "s", 5, 0)
    # two significant digits of the width: 0.11 wide -> 2 decimals, 40 wide -> 0
    assert decimals_for(-0.06, 0.05) == 2 and decimals_for(0, 40) == 0
    assert decimals_for(0, 0) is None


def test_collision_counts_never_add_families_of_different_sizes():
    same = collision_words([{"method": "baseline", "collisions": 18, "scenarios": 200},
                            {"method": "improved", "collisions": 21, "scenarios": 200}])
    assert same == "in 200 scenarios each: baseline 18, improved 21"
    mixed = collision_words([{"method": "baseline", "collisions": 18, "scenarios": 200},
                             {"method": "improved", "collisions": 5, "scenarios": 50}])
    assert "baseline 18 of 200" in mixed and "improved 5 of 50" in mixed
    assert "different sizes" in mixed


def test_only_tracked_changes_make_a_checkout_dirty():
    # untracked files (a report's own output folder) never count; a rename counts its new name
    porcelain = "M pipeline/report.py\n?? reports/mine/\n M Makefile\nR  a.py -> b.py"
    assert tracked_changes(porcelain) == ("pipeline/report.py", "Makefile", "b.py")
    assert tracked_changes("?? reports/latest/\n") == ()


def test_make_report_stamps_the_make_command_that_ran():
    import os
    import subprocess
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    # as typed in a shell (make test itself exports its own command to its children)
    env = {k: v for k, v in os.environ.items() if k not in ("REPORT_COMMAND", "MAKEFLAGS",
                                                            "MAKELEVEL", "MFLAGS")}
    out = subprocess.run(["make", "-n", "--no-print-directory", "report", "TUNE=quick",
                          "STAMP=Makefile"], cwd=root, capture_output=True, text=True,
                         check=True, env=env).stdout
    command = re.search(r'--command "([^"]*)"', out).group(1).split()
    assert command[:2] == ["make", "report"]
    assert sorted(command[2:]) == ["STAMP=Makefile", "TUNE=quick"]


def test_the_answer_figure_links_every_interval_where_it_is_drawn():
    svg = answer_svg((AnswerPanel("C1", "faster", "s", 0.1, (
        AnswerRow("ours vs baseline", (Interval(-0.3, -0.4, -0.2, "supported",
                                                explorer_href("family", 17), "t"),),
                  "supported"),
        AnswerRow("APF alone", (Interval(0.5, 0.4, 0.6, "contradicted", "#x", "t"),)),
    ), "#ledger-C1-baseline"),), width_px=500, label_px=150, note_px=96)
    assert 'href="explorer.html#family/17"' in svg and 'href="#ledger-C1-baseline"' in svg
    # x range [-0.4, 0.6] padded by 6 % of its width: the estimate -0.3 sits at its share
    low, high = -0.4 - 0.06, 0.6 + 0.06
    expected = 150 + (500 - 96 - 150) * (-0.3 - low) / (high - low)
    dots = [float(x) for x in re.findall(r'<circle cx="([0-9.]+)"', svg)]
    assert dots[0] == pytest.approx(expected, abs=0.06)
    assert dots[1] > dots[0]


def _family(size: int = 12) -> FamilySection:
    row = {"claim": "C1", "comparison": "baseline", "outcome": "supported", "estimate": -0.3,
           "ci_low": -0.4, "ci_high": -0.2, "metric": "reaction_delay_s", "n_pairs": 10,
           "n_tied": 0, "margin": 0.05, "id": "ledger-C1-baseline", "movers": None}
    counts = ({"method": "baseline", "collisions": 1, "scenarios": size,
               "collisions_unavoidable": 0, "heading_validity_exceeded": 0},
              {"method": "improved", "collisions": 2, "scenarios": size,
               "collisions_unavoidable": 0, "heading_validity_exceeded": 0})
    return FamilySection(size, 0, "improved", ("baseline", "improved"), (row,), {}, "", counts,
                         "", None, (), (), ("C1 faster: supported vs baseline",))


@pytest.mark.parametrize("headline", [False, True])
def test_a_quick_tune_writes_nothing_of_the_opening_summary(headline):
    """After make tune TUNE=quick (below the default budget: headline False) the answer's
    lines and figure hold no tuned outcome and name the tuning as exploratory; a tuning at
    the default budget with every method converged does write them."""
    tuned = {"claim": "C1", "counts": "contradicted 1/1", "tuned_outcomes": ["contradicted"],
             "tuned_estimates": [0.2], "tuned_cis": [[0.1, 0.3]], "settled": True,
             "sentence": "C1 on 12 held-out scenarios: a tuning artefact."}
    fair_fight = SimpleNamespace(headline=headline, rows=(tuned,),
                                 label="" if headline else "below the default budget "
                                 "(replicates, max_trials)")
    answer = answer_section(_family(), None, fair_fight, None, ClaimsConfig())
    text = "\n".join(answer.lines) + " ".join(r["extra"] for r in answer.rows)
    assert ("tuning artefact" in text) == headline
    assert ("tuned vs tuned" in text) == headline
    assert ("tuned, 1 replicates" in answer.figure) == headline
    assert bool(answer.exploratory) != headline


def _tune_summary(replicates: int, **more):
    from pipeline.studies.results.tune import TuneSummary

    claim = {"claim": "C1", "text": "faster", "metric": "reaction_delay_s",
             "default": "supported", "default_estimate": -0.3,
             "tuned_outcomes": ["supported"] * replicates,
             "tuned_estimates": [-0.2] * replicates, "tuned_cis": [[-0.3, -0.1]] * replicates,
             "counts": f"supported {replicates}/{replicates}", "settled": True,
             "tuned": "supported", "answer": "C1: ...", "tuned_vs_matched": [],
             "holds_with_trials": [], "sentence": "C1 ..."}
    data = {"name": "t", "settings": {"methods": ["improved", "baseline"],
                                      "settled_share": 0.8},
            "budget": {"replicates": replicates}, "families": {"heldout": {"seed": 0,
                                                                           "size": 200}},
            "backend": "daqp", "objectives": [], "safety_threshold_collisions": {},
            "search_spaces": {}, "compromise_rule": "", "answer_rule": "", "compromise": {},
            "replicates": [], "parity": [], "below_default_budget": [], "unconverged": [],
            "headline": True, "dominance": {}, "claims": [{**claim, **more.pop("claim", {})}],
            **more}
    return TuneSummary.from_json(data)


def test_a_tune_settled_by_the_old_share_rule_never_writes_the_headline():
    """A summary written before the binomial test (no settle_test: its claims settled by 4 of
    5) is read and shown, labelled, but never writes the opening summary; one settled by the
    test does. And a tuning with too few replicates to ever settle says so (not refused):
    4 of 4 alike is p = 1/16 > 0.05, 5 of 5 is 1/32."""
    old = _tune_summary(5)
    assert old.headline and not old.writes_headline
    assert "earlier share rule (tune.settled_share)" in old.label
    test = {"settle_test": "binomial", "settle_alpha": 0.05, "fewest_replicates_to_settle": 5,
            "claim": {"leading": "supported", "leading_count": 5, "judged_replicates": 5,
                      "p_value": 1 / 32}}
    new = _tune_summary(5, **test)
    assert new.writes_headline and new.label == "" and new.can_settle
    assert new.settle_note == "" and new.claims[0].p_value == 1 / 32
    four = _tune_summary(4, **test)
    assert not four.can_settle
    assert four.settle_note == ("With 4 replicates no claim can be settled: even 4 of 4 alike "
                                "gives a one-sided binomial p = 0.0625 > alpha 0.05; at least 5 "
                                "are needed.")
