"""What a user waits for in the studies, measured by ``make bench``:

- ``member_cache_reuse``: after a family run as ``make reproduce`` runs it, the tune's held-out
  judgement of the untuned method (the same members on the same backend) restores them from
  the member cache: members reused over members shared (1.0: none simulated again), with
  ``member_cache_resimulated`` the shared members simulated again (goal 0). What is shared is
  computed apart from the cache, from the members' config hashes.
- ``coordinator_ms_per_trial``: the tune process's own CPU milliseconds per trial told while
  its studies run (the members run on two workers): a tune of the quick space, two studies of
  24 trials on 6-member families (``--quick`` too); the full run's small tune gives it again.
- ``tune_core_utilisation``: CPU-seconds over (wall-clock seconds x cores) of a small tune (one
  replicate, 40-member training families, 16 trials per method, the default rungs), the tune's
  own process and its workers.
- ``pruned_over_unpruned_members``: members simulated per converged replicate by the pruned
  default tune over the unpruned one (``make tune`` and ``make tune-unpruned``), with their
  hypervolumes; read from those studies' summaries (None when either has not run: a converged
  comparison takes most of an hour, more than a benchmark should).
"""

from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path
from typing import Any


def measure_member_cache_reuse(members: int = 6) -> dict[str, Any]:
    """A ``make reproduce`` family, then the tune's held-out family of the same method."""
    from pipeline.config import CONF_DIR
    from pipeline.loop.scenario import family_members
    from pipeline.store.member_cache import MemberCache, MemberCounts
    from pipeline.studies.compose import composer
    from pipeline.studies.experiment import run_family
    from pipeline.studies.tune import load_tune_space
    from pipeline.studies.tune.search import Runner

    with tempfile.TemporaryDirectory(prefix="bench_member_cache_") as folder:
        root = Path(folder)
        cache = MemberCache(root / "cache")
        reproduce = composer([])[0](["method=improved", "scenario=family",
                                     f"scenario.family.size={members}"])
        run_family(reproduce, root / "reproduce", progress=False, member_cache=cache)
        space = load_tune_space(CONF_DIR / "tune" / "default.yaml",
                                [f"heldout_size={2 * members}"])
        runner = Runner(space, root / "study", [], lambda _: None)
        runner.member_cache, runner.counts = cache, MemberCounts()
        job = runner.job("improved", "default", {}, "heldout")
        runner.run([job], "held-out")

        def hashes(cfg) -> set[str]:
            return {dataclasses.replace(cfg, scenario=m).config_hash()
                    for m in family_members(cfg.scenario, cfg.vehicle.footprint_radius_m)}

        shared = len(hashes(reproduce) & hashes(job.cfg))
        reused = runner.counts.reused
    return {"member_cache_reuse": reused / shared if shared else None,
            "member_cache_shared": shared,
            "member_cache_resimulated": shared - reused}


def measure_tune_core_utilisation(trials: int = 16) -> dict[str, Any]:
    """A small tune's CPU-seconds over (wall x cores)."""
    from pipeline.config import CONF_DIR
    from pipeline.studies.tune import load_tune_space, run_tuning

    space = load_tune_space(CONF_DIR / "tune" / "default.yaml", [
        "name=bench", "replicates=1", f"min_trials={trials}", f"max_trials={trials}",
        f"convergence_window={trials // 2}", "heldout_size=20", "heldout_backend=daqp",
        "max_heldout_settings=1", "prune_after_trials=4"])
    with tempfile.TemporaryDirectory(prefix="bench_tune_") as folder:
        result = run_tuning(space, Path(folder), ["scenario.family.n_jobs=2"],
                            log=lambda _: None)
    value = result.summary.core_utilisation
    coordinator = result.summary.coordinator_ms_per_trial
    return {"tune_core_utilisation": round(value, 3) if value is not None else None,
            "coordinator_ms_per_trial": round(coordinator, 2) if coordinator is not None
            else None}


def measure_coordinator(trials: int = 24) -> dict[str, Any]:
    """The tune process's own CPU milliseconds per trial (asks, tells, compositions, rung
    tables, records; the members run on two workers): a tune of the quick space with two
    studies of ``trials`` trials each on 6-member training families (rungs at 3)."""
    from pipeline.config import CONF_DIR
    from pipeline.studies.tune import load_tune_space, run_tuning

    space = load_tune_space(CONF_DIR / "tune" / "quick.yaml", [
        "name=bench_coordinator", "replicates=1", f"min_trials={trials}",
        f"max_trials={trials}", f"convergence_window={trials // 2}", "population_size=8",
        "batch_size=4", "heldout_size=4"])
    with tempfile.TemporaryDirectory(prefix="bench_coordinator_") as folder:
        result = run_tuning(space, Path(folder), ["scenario.family.n_jobs=2"],
                            log=lambda _: None)
    value = result.summary.coordinator_ms_per_trial
    return {"coordinator_ms_per_trial": round(value, 2) if value is not None else None}


def pruning_comparison(pruned: Path, unpruned: Path, tolerance: float = 0.01
                       ) -> dict[str, Any]:
    """:func:`compare_pruning` of two trusted tune folders of the same space (the second with
    ``rungs: []``); None with the reason when either is missing or not trusted."""
    from pipeline.studies.results import TuneResult
    from pipeline.studies.results.base import ResultError

    try:
        a, b = TuneResult.load(pruned), TuneResult.load(unpruned)
    except ResultError as exc:
        return {"pruned_over_unpruned_members": None,
                "pruning_note": f"run make tune and make tune-unpruned first ({exc})"}
    return compare_pruning(a.summary.to_json(), b.summary.to_json(), a.trials, tolerance)


def compare_pruning(a: dict, b: dict, trials, tolerance: float = 0.01) -> dict[str, Any]:
    """Members per converged replicate, pruned over unpruned, at equal hypervolume: per
    replicate and method converged in both, the members the pruned tune (summary ``a``, its
    ``trials`` table) had simulated when its front first reached the unpruned one's (``b``)
    final hypervolume less ``tolerance`` (in trial order), over the members the unpruned tune
    simulated until it converged; with each final hypervolume and per claim both tuned
    answers."""
    note = {"pruned_over_unpruned_members": None}
    if b["settings"].get("rungs") or not a["settings"].get("rungs"):
        return {**note, "pruning_note": "the first tune must be pruned, the second not"}

    def per_replicate(summary: dict) -> dict[tuple[int, str], dict]:
        return {(h["replicate"], h["method"]): h for h in summary["replicates"]}

    ra, rb = per_replicate(a), per_replicate(b)
    keys = sorted(k for k in ra.keys() & rb.keys() if ra[k]["converged"] and rb[k]["converged"])
    if not keys:
        return {**note, "pruning_note": "no replicate converged in both"}
    size = int(b["settings"]["training_size"])
    rows, spent_a, spent_b = {}, 0, 0
    for replicate, method in keys:
        target = (1.0 - tolerance) * rb[(replicate, method)]["hypervolume"][-1]
        history = ra[(replicate, method)]["hypervolume"]
        members = trials[(trials["replicate"] == replicate) & (trials["method"] == method)] \
            .sort_values("trial")["members"].cumsum().to_numpy()
        reached = next((i for i, v in enumerate(history) if v >= target), None)
        unpruned_members = size * int(rb[(replicate, method)]["converged_at"])
        rows[f"{method} r{replicate}"] = {
            "hypervolume_pruned": round(history[-1], 4),
            "hypervolume_unpruned": round(rb[(replicate, method)]["hypervolume"][-1], 4),
            "members_to_equal_hypervolume": None if reached is None
            else int(members[min(reached, len(members) - 1)]),
            "members_unpruned": unpruned_members}
        spent_a += int(members[min(reached, len(members) - 1)]) if reached is not None \
            else int(members[-1])
        spent_b += unpruned_members
    answers = {c["claim"]: [c["counts"], d["counts"]]
               for c in a["claims"] for d in b["claims"] if c["claim"] == d["claim"]}
    never = [k for k, r in rows.items() if r["members_to_equal_hypervolume"] is None]
    return {"pruned_over_unpruned_members": round(spent_a / spent_b, 3),
            "pruning_by_replicate": rows, "pruning_answers_pruned_unpruned": answers,
            "pruning_note": ("" if not never else "never reached the unpruned hypervolume "
                             "(counted with all its members): " + ", ".join(never))}
