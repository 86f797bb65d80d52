"""Multi-fidelity trials (pipeline.studies.tune.search.evaluate_in_rungs, Rungs): a planted
dominated trial stops after its first rung, a trial that can no longer be feasible stops
there too, one that would move the front by more than the gain goes on to the whole family
(the gain checked against hypervolumes computed by hand); the front it is judged against is
read from the study; a changed space never resumes another's trials."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipeline.studies.tune.search import CANNOT_MOVE_FRONT_AT_RUNG, Rungs, evaluate_in_rungs

BOUNDS = ((0.0, 1.2), (0.5, 3.0), (2.0, 5.0))
FRONT_AT_10 = np.array([[0.20, 1.00, 3.00]])
#: normalized by BOUNDS, the front is the point (1/6, 0.2, 1/3): its hypervolume against (1, 1, 1)
#: is 5/6 * 0.8 * 2/3 = 0.4444

#: per setting and rung: (objective values, collisions); the threshold is 2 collisions
PLANTED = {
    "good": {10: ([0.10, 1.20, 2.90], 0), 20: ([0.12, 1.1, 2.9], 0), 40: ([0.1, 1.1, 2.9], 1)},
    "dominated": {10: ([0.50, 1.50, 3.50], 0), 20: ([0.5, 1.5, 3.5], 0),
                  40: ([0.5, 1.5, 3.5], 0)},
    # better than the front on the first objective only, by 0.012 (normalized 0.01): it adds
    # 0.01 * (1 - 0.4) * (1 - 0.5) = 0.003 of volume, 0.675 % of the front's
    "slightly_better": {10: ([0.188, 1.50, 3.50], 0), 20: ([0.19, 1.5, 3.5], 0),
                        40: ([0.19, 1.5, 3.5], 0)},
    "colliding": {10: ([0.10, 1.00, 2.50], 3)},
}


@dataclass(frozen=True)
class _Job:
    name: str
    members: int


class _PlantedRunner:
    """Stands in for the tune's Runner: a family 'table' is the planted (values, collisions)
    of its setting at its rung; every family asked for is recorded."""

    def __init__(self) -> None:
        self.ran: list[tuple[str, int]] = []
        self.parts: set[str] = set()

    def job(self, method, setting, params, part, replicate=None, members=None):
        return _Job(params["name"], members)

    def run(self, jobs, label, part="heldout"):
        self.ran += [(j.name, j.members) for j in jobs]
        self.parts.add(part)
        return [pd.DataFrame({"planted": [PLANTED[j.name][j.members]]}) for j in jobs]


def _measure(table: pd.DataFrame):
    values, collisions = table["planted"].iloc[0]
    return list(values), collisions


def _rungs(gain: float = 0.001) -> Rungs:
    return Rungs((10, 20, 40), gain, 0, BOUNDS)


def _evaluate(rungs: Rungs, front=None):
    runner = _PlantedRunner()
    settings = [{"name": name} for name in PLANTED]
    results = evaluate_in_rungs(runner, "improved", 0, settings, 2, rungs,
                                {10: FRONT_AT_10} if front is None else front, _measure)
    # rungs are training families (their members keep no horizon record by default)
    assert runner.parts == {"training"}
    return dict(zip(PLANTED, results, strict=True)), runner.ran


def test_a_planted_dominated_trial_stops_after_its_first_rung():
    results, ran = _evaluate(_rungs())
    values, constraint, attrs = results["dominated"]
    assert attrs["pruned_at"] == 10 and attrs["pruned_by"] == "front"
    assert attrs["members"] == 10 and constraint == CANNOT_MOVE_FRONT_AT_RUNG
    assert ("dominated", 20) not in ran and ("dominated", 40) not in ran
    assert values == PLANTED["dominated"][10][0]
    # a trial that can no longer be feasible stops at its first rung as well (3 > 2 already)
    _, constraint, attrs = results["colliding"]
    assert attrs["pruned_by"] == "collisions" and constraint == 1 and attrs["members"] == 10
    # the others run the whole family: every rung once, in order, with their rung values kept
    for name in ("good", "slightly_better"):
        assert [m for n, m in ran if n == name] == [10, 20, 40]
        values, constraint, attrs = results[name]
        assert "pruned_at" not in attrs and attrs["members"] == 40
        assert values == PLANTED[name][40][0]
        assert attrs["rungs"]["10"] == PLANTED[name][10][0]
    assert results["good"][1] == 1 - 2  # collisions minus the threshold


def test_the_gain_and_the_front_decide():
    # the slightly better trial adds 0.675 % of the front's hypervolume: stopped at a gain of
    # 1 %, not at 0.5 %
    results, _ = _evaluate(_rungs(gain=0.01))
    assert results["slightly_better"][2].get("pruned_at") == 10
    results, _ = _evaluate(_rungs(gain=0.005))
    assert results["slightly_better"][2].get("pruned_at") is None
    assert results["dominated"][2].get("pruned_at") == 10
    # no front yet (too few complete trials): only the colliding trial stops early
    results, ran = _evaluate(_rungs(), front={})
    assert [n for n, r in results.items() if r[2].get("pruned_at")] == ["colliding"]
    assert ("dominated", 40) in ran


def _study_with(trials: list[dict]):
    import optuna
    from optuna.distributions import FloatDistribution

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(directions=["minimize"] * 3)
    for i, t in enumerate(trials):
        study.add_trial(optuna.trial.create_trial(
            params={"x": float(i)}, distributions={"x": FloatDistribution(0, 100)},
            values=t["values"], user_attrs=t["attrs"]))
    return study


def test_the_front_at_a_rung_is_the_full_front_read_at_that_rung():
    on_front = {"values": [0.2, 1.0, 3.0],
                "attrs": {"constraint": 0.0, "rungs": {"10": [0.21, 1.1, 3.1]}}}
    dominated = {"values": [0.5, 1.5, 3.5],
                 "attrs": {"constraint": 0.0, "rungs": {"10": [0.0, 0.6, 2.1]}}}
    infeasible = {"values": [0.0, 0.5, 2.0],
                  "attrs": {"constraint": 3.0, "rungs": {"10": [0.0, 0.5, 2.0]}}}
    pruned = {"values": [0.0, 0.5, 2.0],
              "attrs": {"constraint": 0.5, "pruned_at": 10, "rungs": {"10": [0.0, 0.5, 2.0]}}}
    study = _study_with([on_front, dominated, infeasible, pruned])
    front = _rungs().front_at_rungs(study)
    assert list(front) == [10]
    # the feasible trials that ran the whole family, read at the rung (not the stopped or the
    # infeasible ones, however good they looked)
    np.testing.assert_allclose(front[10], [[0.21, 1.1, 3.1], [0.0, 0.6, 2.1]])
    # before prune_after_trials complete trials, no front: nothing is stopped by it
    late = Rungs((10, 20, 40), 0.001, 5, BOUNDS)
    assert late.front_at_rungs(study) == {}


def test_a_changed_space_is_another_study(tmp_path):
    from pipeline.config import CONF_DIR
    from pipeline.errors import ConfigError
    from pipeline.studies.tune import load_tune_space

    path = CONF_DIR / "tune" / "default.yaml"
    pruned, unpruned = load_tune_space(path), load_tune_space(path, ["rungs=[]"])
    assert pruned.rungs == [5, 10, 20] and unpruned.rungs == []
    assert pruned.trial_key() != unpruned.trial_key()
    assert unpruned.name == "default_changed"
    for bad in (["rungs=[20, 10]"], ["rungs=[40]"], ["prune_gain=2"], ["nope=1"],
                ["rungs"]):
        with pytest.raises(ConfigError):
            load_tune_space(path, bad)
    assert Path(path).is_file()


def no_trial_lost_or_run_twice(folder: Path) -> None:
    """Every trial asked was told once (numbers 0..n-1, all complete); every member of every
    family was simulated exactly once over all rungs and families."""
    import json

    from optuna.trial import TrialState

    from pipeline.studies.tune.search import STORE_FILE
    from tests.builders import stored_trials

    by_study: dict[str, list[int]] = {}
    for study, trial in stored_trials(folder / STORE_FILE):
        assert trial.state == TrialState.COMPLETE
        by_study.setdefault(study, []).append(trial.number)
    assert all(sorted(n) == list(range(len(n))) for n in by_study.values()) and by_study
    summary = json.loads((folder / "summary.json").read_text())
    # every member simulated once: the held-out and untuned members' folders, and the rows
    # the training families keep (a family's last record holds every member it ran)
    members = {p.parent for p in (folder / "runs").rglob("member_*/manifest.json")}
    rows = sum(len(p.read_text().splitlines())
               for p in (folder / "runs" / "training").rglob("members.jsonl"))
    assert summary["members"]["simulated"] == len(members) + rows


def test_members_at_equal_hypervolume_are_read_off_the_two_tunes(tmp_path):
    """Planted: the unpruned tune converged at 5 trials (5 x 40 members) with hypervolume 0.50;
    the pruned one's front first reached 0.495 (0.50 less 1 %) at its 4th trial, when it had
    simulated 40 + 10 + 10 + 40 members: 100 / 200."""
    from benchmarks.harness.studies import compare_pruning, pruning_comparison

    def summary(rungs, history, converged_at, claims) -> dict:
        return {"settings": {"rungs": rungs, "training_size": 40},
                "replicates": [{"replicate": 0, "method": "improved", "converged": True,
                                "converged_at": converged_at, "hypervolume": history}],
                "claims": [{"claim": "C1", "counts": claims}]}

    pruned = summary([10, 20], [0.1, 0.2, 0.3, 0.496, 0.52, 0.53], 6, "supported 5/5")
    unpruned = summary([], [0.1, 0.3, 0.4, 0.45, 0.50], 5, "supported 4/5")
    trials = pd.DataFrame({"replicate": 0, "method": "improved", "trial": range(6),
                           "members": [40, 10, 10, 40, 20, 40]})
    out = compare_pruning(pruned, unpruned, trials)
    assert out["pruned_over_unpruned_members"] == 0.5
    row = out["pruning_by_replicate"]["improved r0"]
    assert row["members_to_equal_hypervolume"] == 100 and row["members_unpruned"] == 200
    assert out["pruning_answers_pruned_unpruned"] == {"C1": ["supported 5/5", "supported 4/5"]}
    # the order of the two matters: an unpruned tune is never read as the pruned one
    assert compare_pruning(unpruned, pruned, trials)["pruned_over_unpruned_members"] is None
    # folders that hold no trusted tune: no ratio, the reason instead
    out = pruning_comparison(tmp_path / "a", tmp_path / "b")
    assert out["pruned_over_unpruned_members"] is None and "make tune-unpruned" in \
        out["pruning_note"]


def test_side_by_side_on_two_workers_tunes_as_one_after_the_other_on_one(tmp_path,
                                                                          monkeypatch):
    """Every study's batches at once on one pool of two workers (the local default) against
    each study's batches one after the other (what SLURM runs, Runner.local false) with the
    members in the coordinator (scenario.family.n_jobs=1): the same trials, values and
    verdicts over two replicates and both methods, nothing lost or run twice in either. The
    switches are real: the side-by-side run interleaves the studies' trials (a trial of
    replicate 1 completes before replicate 0's last), the other does not; the coordinator's
    CPU per trial is measured with two workers (a few to tens of ms, far below a trial's
    members, 6 x 25-35 ms at the least), not with one, whose members ran in the coordinator.
    (One pair of tunes for both invariances: each alone is its own pair.)"""
    import json

    from pipeline.config import CONF_DIR
    from pipeline.studies.tune import load_tune_space, run_tuning
    from pipeline.studies.tune.search import Runner

    space = load_tune_space(CONF_DIR / "tune" / "quick.yaml",
                            ["heldout_size=8", "max_trials=6", "min_trials=6"])

    def completion_order(folder: Path) -> list[str]:
        from pipeline.studies.tune.search import STORE_FILE
        from tests.builders import stored_trials

        trials = stored_trials(folder / STORE_FILE)
        return [name for name, _ in sorted(trials, key=lambda e: (e[1].datetime_complete,
                                                                  e[1]._trial_id))]

    run_tuning(space, tmp_path / "together", ["scenario.family.n_jobs=2"], log=lambda _: None)
    monkeypatch.setattr(Runner, "local", property(lambda self: False))
    run_tuning(space, tmp_path / "apart", ["scenario.family.n_jobs=1"], log=lambda _: None)
    for name in ("trials.csv", "ledger_tuned.csv", "settings_outcomes.csv"):
        a, b = (tmp_path / "together" / name).read_text(), (tmp_path / "apart" / name).read_text()
        assert a == b, f"{name} differs:\n" + "\n".join(
            f"{x}\n{y}" for x, y in zip(a.splitlines(), b.splitlines(), strict=False) if x != y)
    for folder in ("together", "apart"):
        no_trial_lost_or_run_twice(tmp_path / folder)

    def interleaved(order: list[str]) -> bool:
        last_r0 = max(i for i, name in enumerate(order) if "-r0-" in name)
        return any("-r1-" in name for name in order[:last_r0])

    assert interleaved(completion_order(tmp_path / "together"))
    assert not interleaved(completion_order(tmp_path / "apart"))
    measured = [json.loads((tmp_path / f / "summary.json").read_text())[
        "coordinator_ms_per_trial"] for f in ("apart", "together")]
    assert measured[0] is None and 0.5 < measured[1] < 150.0, measured
