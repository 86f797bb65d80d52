"""Tuning to convergence (issue 40, parts 1-3): the hypervolume against an independent
implementation (Optuna's WFG), the convergence rule on planted fronts that keep improving in
steps (it must not stop) and that have converged (it must stop), the answer in counts over
replicates settled by a one-sided exact binomial test (issue 56, item 5: against p-values
computed by hand), the budget a headline needs, and the objectives' censoring."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pipeline.analysis.objectives import Objective, objective_values, tuning_table
from pipeline.config import CONF_DIR
from pipeline.studies.tune import (
    Convergence,
    TuneSpace,
    answer_in_counts,
    convergence_point,
    default_budget,
    hypervolume,
    hypervolume_history,
    load_tune_space,
    make_study,
    optimize,
)


@pytest.mark.parametrize("dims", [2, 3, 4])
def test_hypervolume_matches_optunas_wfg(dims):
    from optuna._hypervolume import compute_hypervolume

    rng = np.random.default_rng(dims)
    for _ in range(5):
        points = rng.random((int(rng.integers(1, 30)), dims))
        reference = np.full(dims, 1.05)
        assert hypervolume(points, reference) == pytest.approx(
            compute_hypervolume(points, reference), rel=1e-12)


def test_hypervolume_closed_forms():
    # one point: a box; two boxes overlapping in a corner: inclusion-exclusion
    assert hypervolume(np.array([[0.2, 0.5, 0.0]]), np.ones(3)) == pytest.approx(0.8 * 0.5)
    two = np.array([[0.0, 0.5], [0.5, 0.0]])
    assert hypervolume(two, np.ones(2)) == pytest.approx(0.5 + 0.5 - 0.25)
    # a point beyond the reference in any objective adds nothing
    assert hypervolume(np.array([[0.2, 1.2]]), np.ones(2)) == 0.0


def test_hypervolume_history_is_the_feasible_prefix_volume():
    rng = np.random.default_rng(1)
    values = rng.uniform(0.0, 3.0, (40, 3))
    feasible = rng.random(40) < 0.7
    bounds = [[0.0, 2.0], [0.0, 4.0], [0.0, 8.0]]
    history = hypervolume_history(values, feasible, bounds)
    scale = np.array([2.0, 4.0, 8.0])
    for n in (1, 7, 23, 40):
        prefix = values[:n][feasible[:n]] / scale
        assert history[n - 1] == pytest.approx(hypervolume(prefix, np.ones(3)), rel=1e-12)
    assert np.all(np.diff(history) >= -1e-15)
    # an infeasible trial never moves it
    assert all(history[i] == history[i - 1] for i in range(1, 40) if not feasible[i])


def test_the_kept_history_computes_only_new_trials_and_equals_the_prefix_volumes():
    """The tune asks a study's history after every batch: kept between calls, it equals the
    volume of each feasible prefix (the oracle: hypervolume of the prefix's points) with rows
    appended, NaN rows, a row's feasibility changed and a row replaced in the middle, and it
    computes volumes only for rows after the shared prefix where the front moved."""
    from pipeline.studies.tune.pareto import HypervolumeHistory

    rng = np.random.default_rng(7)
    bounds = [[0.0, 2.0], [0.0, 4.0], [0.0, 8.0]]
    scale = np.array([2.0, 4.0, 8.0])
    values = rng.uniform(0.0, 3.0, (60, 3))
    values[5] = np.nan  # a trial whose objective is undefined
    feasible = rng.random(60) < 0.7

    def oracle(v, f):
        out = []
        for n in range(1, len(v) + 1):
            pts = v[:n][f[:n]] / scale
            pts = pts[np.all(np.isfinite(pts), axis=1)]
            out.append(hypervolume(pts, np.ones(3)))
        return np.array(out)

    kept = HypervolumeHistory(bounds)
    calls = []
    import pipeline.studies.tune.pareto as pareto
    original = pareto.hypervolume

    def counted(points, reference):
        if np.size(reference) == 3:  # a front's volume, not one of its slices
            calls.append(1)
        return original(points, reference)

    pareto.hypervolume = counted
    try:
        for n in (10, 14, 30, 60):  # growing, a batch at a time
            expected = oracle(values[:n], feasible[:n])
            calls.clear()
            got = kept.of(values[:n], feasible[:n])
            assert got == pytest.approx(expected, rel=1e-12)
        # only the last 30 rows were computed, and only where the front moved
        moved = int(np.sum(np.diff(expected[29:]) > 1e-12))  # the oracle sums in another order
        assert moved <= len(calls) < 30
        calls.clear()
        assert np.array_equal(kept.of(values, feasible), got)
        assert not calls  # nothing new: nothing computed
        changed_f = feasible.copy()
        changed_f[20] = not changed_f[20]
        changed_v = values.copy()
        changed_v[40] = [0.01, 0.01, 0.01]  # a trial that dominates everything before it
        for v, f in ((values, changed_f), (changed_v, feasible), (values[:35], feasible[:35])):
            assert kept.of(v, f) == pytest.approx(oracle(v, f), rel=1e-12)
            assert np.array_equal(kept.of(v, f), hypervolume_history(v, f, bounds))
    finally:
        pareto.hypervolume = original


def stepped_history(n: int, plateau: int, step: float) -> np.ndarray:
    """A front that grows by ``step`` (relative) after every ``plateau`` trials: the measured
    shape of improved's front (plateaus of 20-40 trials between jumps)."""
    return 0.4 * (1.0 + step) ** (np.arange(n) // plateau)


def test_a_front_growing_in_steps_with_plateaus_shorter_than_the_window_never_stops():
    for plateau in (20, 30, 40):
        history = stepped_history(300, plateau, 0.05)
        assert convergence_point(history, 80, 60, 0.02) is None
        # the naive rule the issue measured (< 1 % over the last 20 % of the trials so far)
        # would have stopped it inside its first long plateau
        naive = next(n for n in range(10, 300)
                     if history[n - 1] - history[n - 1 - max(n // 5, 1)] <= 0.01 * history[n - 1])
        assert naive < 60


def test_a_converged_front_stops_at_the_first_window_without_growth():
    history = np.concatenate([np.linspace(0.3, 0.6, 50), np.full(200, 0.6)])
    # grows until trial 50; the 60-trial window ending at n holds no growth from n = 110 on,
    # but 1.9 % growth is allowed: the window may still hold the last 0.019 * 0.6 of growth
    stop = convergence_point(history, 80, 60, 0.02)
    growth = history[stop - 1] - history[stop - 1 - 60]
    assert growth <= 0.02 * history[stop - 1]
    earlier = stop - 1
    assert history[earlier - 1] - history[earlier - 1 - 60] > 0.02 * history[earlier - 1]
    assert convergence_point(np.full(100, 0.5), 80, 60, 0.02) == 80  # flat: at the minimum
    assert convergence_point(np.zeros(200), 80, 60, 0.02) is None    # nothing feasible yet


def _planted_study(rule: Convergence):
    """An in-memory study of improved over two objectives in the unit box, with ``rule``'s
    trial counts."""
    space = TuneSpace(name="planted", min_trials=rule.min_trials, max_trials=rule.max_trials,
                      convergence_window=rule.window, batch_size=4, population_size=8,
                      objectives=[Objective("reaction_delay_s"),
                                  Objective("lateral_jerk_rms_mps3")],
                      hypervolume_bounds=[[0.0, 1.0], [0.0, 1.0]])
    return make_study(space, "improved", 0, storage=None)


def _planted_run(values_of, rule: Convergence) -> tuple[np.ndarray, int | None, int]:
    from optuna.distributions import FloatDistribution

    study = _planted_study(rule)
    count = [0]

    def evaluate(settings):
        out = []
        for p in settings:
            out.append((values_of(count[0], p["planner.beta"]), -1.0))
            count[0] += 1
        return out

    history, converged = optimize(study, {"planner.beta": FloatDistribution(0.0, 1.0)},
                                  evaluate, rule, 4, log=lambda m: None)
    return history, converged, count[0]


def test_the_tune_does_not_stop_early_on_a_front_that_keeps_improving():
    """Every 32 trials the reachable front moves 10 % closer to the ideal: the tune runs to its
    cap and says it did not converge."""
    rule = Convergence(80, 200, 60, 0.02, ((0.0, 1.0), (0.0, 1.0)))

    def values_of(k, beta):
        shrink = 0.9 ** (k // 32)
        return (shrink * (0.3 + 0.5 * beta), shrink * (0.8 - 0.5 * beta))

    history, converged, evaluated = _planted_run(values_of, rule)
    assert converged is None and evaluated == 200 and len(history) == 200


def test_the_tune_stops_on_a_front_that_has_converged():
    """The planted front is fixed: its hypervolume stops growing once the sampler has spread
    along it, and the tune stops there, long before its cap."""
    rule = Convergence(40, 400, 30, 0.02, ((0.0, 1.0), (0.0, 1.0)))
    history, converged, evaluated = _planted_run(
        lambda k, beta: (0.3 + 0.5 * beta, 0.8 - 0.5 * beta), rule)
    assert converged is not None and 40 <= converged < 400
    # it stopped at the batch that first met the rule, never later
    assert evaluated == len(history) and evaluated - converged < 4
    assert convergence_point(history[:converged - 1], 40, 30, 0.02) is None


# P(X >= k) for X ~ Binomial(n, 1/2), by hand: sum of C(n, i) for i >= k over 2^n
@pytest.mark.parametrize("outcomes, p_value, sentence, settled", [
    # 9 of 10: (C(10,9) + C(10,10)) / 2^10 = 11/1024 = 0.0107 <= 0.05
    (["supported"] * 9 + ["inconclusive"], 11 / 1024,
     "C2: supported 9/10, inconclusive 1/10: settled (supported in 9 of 10 judged replicates, "
     "one-sided binomial p = 0.0107 <= alpha 0.05).", True),
    # 8 of 10: (45 + 10 + 1) / 1024 = 56/1024 = 0.0547 > 0.05 (the old share rule settled it)
    (["supported"] * 8 + ["equivalent"] * 2, 56 / 1024,
     "C2: supported 8/10, equivalent 2/10: not settled (supported in 8 of 10 judged "
     "replicates, one-sided binomial p = 0.0547 > alpha 0.05).", False),
    # 5 of 5: 1/32 = 0.03125 <= 0.05
    (["contradicted"] * 5, 1 / 32,
     "C4: contradicted 5/5: settled (contradicted in 5 of 5 judged replicates, one-sided "
     "binomial p = 0.0312 <= alpha 0.05).", True),
    # 4 of 4: 1/16 = 0.0625 > 0.05, and no count of 4 replicates can do better
    (["contradicted"] * 4, 1 / 16,
     "C4: contradicted 4/4: not settled (contradicted in 4 of 4 judged replicates, one-sided "
     "binomial p = 0.0625 > alpha 0.05; 4 judged replicates can never settle at alpha 0.05: "
     "at least 5 are needed).", False),
    # 4 of 5 (the old rule's "settled"): (5 + 1) / 32 = 0.1875
    (["supported"] * 4 + ["equivalent"], 6 / 32,
     "C2: supported 4/5, equivalent 1/5: not settled (supported in 4 of 5 judged replicates, "
     "one-sided binomial p = 0.188 > alpha 0.05).", False),
])
def test_the_answer_in_counts_follows_the_binomial_rule(outcomes, p_value, sentence, settled):
    claim = sentence.split(":")[0]
    answer = answer_in_counts(claim, outcomes, 0.05)
    assert answer.p_value == pytest.approx(p_value, rel=1e-12)
    assert answer.sentence == sentence and answer.settled == settled
    assert answer.outcome == (outcomes[0] if settled else None)
    assert (answer.leading, answer.count, answer.judged) == (
        outcomes[0], outcomes.count(outcomes[0]), len(outcomes))


def test_only_judged_replicates_count_in_the_test():
    """A replicate that was not judged (no feasible setting) is shown in the counts but is not
    among the n: 8 supported of 8 judged is 1/256; counted among 10 it would be 56/1024."""
    outcomes = ["supported"] * 8 + ["no feasible setting of improved"] * 2
    answer = answer_in_counts("C1", outcomes, 0.05, [True] * 8 + [False] * 2)
    assert answer.p_value == pytest.approx(1 / 256) and answer.settled
    assert (answer.count, answer.judged) == (8, 8)
    assert "no feasible setting of improved 2/10" in answer.sentence
    none = answer_in_counts("C1", outcomes[8:], 0.05, [False, False])
    assert not none.settled and none.p_value is None and "no replicate judged" in none.sentence


def test_the_fewest_replicates_that_can_settle():
    from pipeline.studies.tune.study import cannot_settle_sentence, fewest_replicates_to_settle

    # 2^-n <= alpha: 2^-4 = 0.0625 > 0.05 >= 2^-5 = 0.03125; 2^-7 = 0.0078 > 0.005 >= 2^-8
    assert fewest_replicates_to_settle(0.05) == 5 and fewest_replicates_to_settle(0.005) == 8
    assert fewest_replicates_to_settle(0.0625) == 4  # p <= alpha: 4 of 4 is exactly 1/16
    assert cannot_settle_sentence(5, 0.05) == "" and cannot_settle_sentence(10, 0.05) == ""
    assert cannot_settle_sentence(4, 0.05).startswith("4 replicates can never settle")
    # and the presets: the default can (9 of 10), the quick one's 2 cannot and says so
    assert default_budget().replicates >= 10
    quick = load_tune_space(CONF_DIR / "tune" / "quick.yaml")
    assert quick.replicates < fewest_replicates_to_settle(0.05)


def test_only_the_default_budget_may_write_the_headline():
    default = default_budget()
    assert default.below_budget(default) == []
    assert default.replicates >= 10 and default.heldout_size >= 200
    quick = load_tune_space(CONF_DIR / "tune" / "quick.yaml")
    assert {"replicates", "max_trials", "heldout_size"} <= set(quick.below_budget(default))
    looser = TuneSpace(convergence_tolerance=0.05)
    assert looser.below_budget(default) == ["convergence_tolerance"]
    # an edited space never resumes another's trials; the held-out size does not decide them
    assert TuneSpace(training_size=30).trial_key() != default.trial_key()
    assert TuneSpace(heldout_size=300).trial_key() == TuneSpace().trial_key()


def test_both_search_spaces_hold_every_free_apf_parameter_and_rho_p():
    from pipeline.studies.tune import search_space

    improved, _ = search_space("improved")
    baseline, _ = search_space("baseline")
    assert "planner.rho_p_m" in improved and "planner.rho_p_m" in baseline
    assert len(improved) == 10 and len(baseline) == 4


def test_objectives_read_members_as_the_ledger_does():
    """Collided members out; one that never recovers counted at the run's end (duration -
    passing time), not dropped; with censoring=drop it is left out."""
    table = pd.DataFrame({
        "collision": [False, False, True, False],
        "recovered": [True, False, True, True], "reacted": [True, True, True, False],
        "recovery_time_s": [1.0, np.nan, 9.0, 2.0],
        "obstacle_passed_time_s": [5.0, 6.0, 5.0, 5.0],
        "reaction_delay_s": [0.2, 0.4, 0.1, np.nan],
        "threat_appear_time_s": [2.0, 2.0, 2.0, 3.0],
        "duration_s": [13.0, 13.0, 13.0, 13.0]})
    objectives = [Objective("recovery_time_s"), Objective("reaction_delay_s")]
    censored = objective_values(tuning_table(table, "run_end"), objectives)
    assert censored == pytest.approx(((1.0 + 7.0 + 2.0) / 3, (0.2 + 0.4 + 10.0) / 3))
    dropped = objective_values(tuning_table(table, "drop"), objectives)
    assert dropped == pytest.approx(((1.0 + 2.0) / 2, (0.2 + 0.4) / 2))


def test_the_spaces_convergence_settings_reach_the_rule():
    """tune.convergence_window, tune.convergence_tolerance and tune.hypervolume_bounds as the
    loop reads them (Convergence.of): another value moves the stop or the volume."""
    history = np.concatenate([np.linspace(0.3, 0.6, 50), np.full(200, 0.6)])
    base = Convergence.of(TuneSpace())
    assert base.stop_at(history) != Convergence.of(TuneSpace(convergence_window=20)).stop_at(
        history)
    assert base.stop_at(history) != Convergence.of(
        TuneSpace(convergence_tolerance=0.2)).stop_at(history)
    values, feasible = np.array([[0.5, 1.5, 3.5]]), np.array([True])
    wide = Convergence.of(TuneSpace(hypervolume_bounds=[[0.0, 2.0], [0.0, 4.0], [0.0, 8.0]]))
    assert hypervolume_history(values, feasible, [list(b) for b in base.bounds])[0] \
        != hypervolume_history(values, feasible, [list(b) for b in wide.bounds])[0]
    # and the settling test reads its alpha: 9 of 10 (p = 11/1024) settles at 0.05, not at 0.01
    nine = ["supported"] * 9 + ["equivalent"]
    assert answer_in_counts("C2", nine, 0.05).settled
    assert not answer_in_counts("C2", nine, 0.01).settled


@pytest.mark.parametrize("where", ["file", "set"])
def test_the_old_settled_share_is_refused_naming_the_test(tmp_path, where):
    from pipeline.errors import ConfigError

    path = CONF_DIR / "tune" / "quick.yaml"
    changes = ["settled_share=0.8"] if where == "set" else []
    if where == "file":
        path = tmp_path / "old.yaml"
        path.write_text((CONF_DIR / "tune" / "quick.yaml").read_text().replace(
            "settled_test: binomial", "settled_share: 0.8"))
    with pytest.raises(ConfigError) as caught:
        load_tune_space(path, changes)
    message = str(caught.value)
    assert "\n" not in message and "tune.settled_share" in message
    assert "tune.settled_test" in message and "binomial" in message
    with pytest.raises(ConfigError, match="tune.settled_test"):
        load_tune_space(CONF_DIR / "tune" / "quick.yaml", ["settled_test=share"])


def test_convergence_counts_simulated_members_when_trials_stop_early():
    """A front that stops growing after 100 trials converges at 100 + the window's trials when
    every trial runs its whole family; when three in four trials stop at a quarter of it, the
    window of 60 whole trials' work spans 60 / (1/4 + 3/4 * 1/4) = 137 trials (rounded up)."""
    from pipeline.studies.tune.pareto import convergence_point

    history = np.concatenate([np.linspace(0.1, 0.5, 100), np.full(300, 0.5)])
    whole = convergence_point(history, 80, 60, 0.0)
    assert whole == 160  # 60 flat trials after the last growth at trial 100
    fractions = np.tile([1.0, 0.25, 0.25, 0.25], 100)
    effort = np.cumsum(fractions)
    stop = convergence_point(history, 80, 60, 0.0, effort)
    # the last growth is at trial 100 (effort 43.75 + ...); converged once 60 whole trials of
    # work lie between it and now
    done_at_100 = effort[99]
    expected = int(np.searchsorted(effort, done_at_100 + 60, side="left")) + 1
    assert stop == expected and stop > whole
    # without the effort the early-stopped trials would count as whole ones
    assert convergence_point(history, 80, 60, 0.0, np.arange(1, 401.0)) == whole


def test_a_pruned_tune_counts_and_logs_whole_trial_equivalents():
    """With pruning the cap is on members simulated: trials that each ran a quarter of a
    10-member family (``members`` = 2.5 of 10, planted) count a quarter each, so a cap of 20
    whole trials takes 80 trials, and the progress line says both counts (before, it said
    "trials 80 ... cap 20" and looked like a cap overrun)."""
    from optuna.distributions import FloatDistribution

    rule = Convergence(10, 20, 5, 0.0, ((0.0, 1.0), (0.0, 1.0)))  # any growth: not converged
    study = _planted_study(rule)
    step = [0]

    def evaluate(settings):
        out = []
        for _ in settings:
            step[0] += 1  # a front that keeps moving: never converges
            out.append(((0.9 ** step[0], 0.9 ** step[0]), -1.0, {"members": 2.5}))
        return out

    lines: list[str] = []
    history, converged = optimize(study, {"planner.beta": FloatDistribution(0.0, 1.0)},
                                  evaluate, rule, 4, log=lines.append, family_size=10)
    assert converged is None and len(history) == 80
    assert lines[-1].startswith("trials 80, 20 whole-trial equivalents (")
    assert lines[0].startswith("trials 4, 1 whole-trial equivalents (")
