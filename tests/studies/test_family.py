"""Scenario family: seeded, machine-independent draws; family runs; the claims ledger."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pipeline.analysis.claims.catalogue import CLAIMS, OUTCOMES
from pipeline.analysis.claims.ledger import family_ledger, outcome_counts
from pipeline.analysis.claims.statistics import paired_differences
from pipeline.config import ClaimsConfig
from pipeline.loop.scenario import draw_family_member, family_members
from pipeline.studies.experiment import run_family


def test_member_depends_only_on_seed_and_index(make_config):
    small = make_config(["scenario=family", "scenario.family.size=4"]).scenario
    large = make_config(["scenario=family", "scenario.family.size=40"]).scenario
    assert family_members(small)[3] == family_members(large)[3]
    other_seed = make_config(["scenario=family", "scenario.family.seed=1"]).scenario
    assert draw_family_member(other_seed, 3) != draw_family_member(large, 3)


def test_member_zero_of_seed_zero_is_pinned(make_config):
    """PCG64 streams are platform-independent: these numbers are the same on every machine."""
    member = draw_family_member(make_config(["scenario=family"]).scenario, 0)
    first = member.obstacles[0]
    assert member.name == "family_s0_i0000"
    rng = np.random.default_rng([0, 0])
    rng.choice([1, 2, 3], p=[0.5, 0.3, 0.2])
    appear = rng.uniform(2.0, 4.0)
    assert first.appear_time_s == pytest.approx(appear, abs=1e-12)
    assert first.x_m == pytest.approx(3.0 * appear + rng.uniform(4.0, 8.0), abs=1e-12)
    assert first.y_m == pytest.approx(rng.uniform(-2.0, 2.0), abs=1e-12)


def test_family_draws_cover_the_stated_ranges(make_config):
    base = make_config(["scenario=family", "scenario.family.size=200"]).scenario
    members = family_members(base)
    counts = np.bincount([len(m.obstacles) for m in members], minlength=4)[1:]
    assert counts.sum() == 200 and np.all(counts > 20)
    first = [m.obstacles[0] for m in members]
    static = sum(o.vx_mps == 0 and o.vy_mps == 0 for o in first)
    oncoming = sum(o.vx_mps < 0 and o.vy_mps == 0 for o in first)
    crossing = sum(o.vy_mps != 0 for o in first)
    assert static > 20 and oncoming > 20 and crossing > 60
    for m in members:
        for o in m.obstacles:
            assert 0.3 <= o.radius_m <= 0.7
        o = m.obstacles[0]
        assert 2.0 <= o.appear_time_s <= 4.0
        assert 4.0 <= o.x_m - 3.0 * o.appear_time_s <= 8.0


def test_missing_values_are_counted_apart_in_paired_differences():
    claim = next(c for c in CLAIMS if c.claim_id == "C4")
    improved = pd.DataFrame({"scenario": ["a", "b", "c", "d"], "collision": [False] * 4,
                             claim.primary_metric: [1.0, np.nan, 2.0, np.nan]})
    baseline = pd.DataFrame({"scenario": ["d", "c", "b", "a"], "collision": [False] * 4,
                             claim.primary_metric: [np.nan, np.nan, 3.0, 3.0]})
    d = paired_differences(improved, baseline, claim)["d"].to_numpy()
    assert d[0] == -2.0 and np.isnan(d[1:]).all()


@pytest.fixture(scope="module")
def small_family(tmp_path_factory, make_config):
    tables = {}
    for method in ("baseline", "improved"):
        cfg = make_config([f"method={method}", "scenario=family", "scenario.family.size=4",
                           "scenario.family.n_jobs=2"])
        tables[method] = run_family(cfg, tmp_path_factory.mktemp(method), progress=False)
    return tables


def test_family_run_writes_a_row_and_a_run_folder_per_member(small_family):
    for method, table in small_family.items():
        assert table["member"].tolist() == [0, 1, 2, 3]
        assert (table["method"] == method).all()
        assert table["scenario"].tolist() == [f"family_s0_i{i:04d}" for i in range(4)]


def test_ledger_over_a_small_family(small_family):
    cfg = ClaimsConfig(min_pairs=2, n_resamples=199)
    ledger = family_ledger(small_family, cfg)
    rows, differences = ledger.records(), ledger.differences
    assert [r["claim"] for r in rows] == ["C0", "C1", "C2", "C3a", "C3b", "C4", "C5"]
    assert {r["comparison"] for r in rows} == {"baseline"}  # no baseline_matched table given
    for row in rows:
        assert row["n_pairs"] + row["n_missing"] <= 4
        assert row["n_better"] + row["n_tied"] + row["n_worse"] == row["n_pairs"]
        assert row["outcome"] in OUTCOMES
        if row["n_pairs"]:
            assert row["ci_low"] - 1e-12 <= row["estimate"] <= row["ci_high"] + 1e-12
        assert len(differences[(row["claim"], "baseline")]) == row["n_pairs"]
    counts = outcome_counts(small_family)
    assert [c["scenarios"] for c in counts] == [4, 4]


def test_a_workers_task_frees_the_last_tasks_cyclic_garbage_before_freezing():
    """_run_chunk moves what is alive into the collector's permanent generation (gc.freeze,
    so loky's collect after each task is cheap); cyclic garbage of the task before was frozen
    with it and never freed (a default tune's workers grew past loky's memory guard). A
    planted cycle must be gone after the next task starts, with the collector's own
    thresholds switched off."""
    import gc
    import weakref

    from pipeline.loop.controller import QpCache
    from pipeline.studies.experiment import _run_chunk

    class Node:
        pass

    was_enabled = gc.isenabled()
    gc.disable()
    try:
        node = Node()
        node.self = node  # a cycle: refcounting alone never frees it
        alive = weakref.ref(node)
        del node
        assert alive() is not None
        assert _run_chunk([], QpCache()) == []
        assert alive() is None
    finally:
        gc.unfreeze()
        if was_enabled:
            gc.enable()


def test_a_familys_chunks_shrink_towards_the_end_and_hold_every_member_once():
    """Guided chunks for two workers: each a quarter of the members left (at least 2), so the
    last ones are small (a worker never ends alone on a large one); every member exactly once;
    each chunk interleaved across the family (early and late members alike). One worker:
    four interleaved chunks, as before."""
    from pipeline.studies.experiment import _chunks

    members = list(range(200))
    chunks = _chunks(members, 2)
    sizes = [len(c) for c in chunks]
    assert sizes[:4] == [50, 38, 28, 21] and sizes == sorted(sizes, reverse=True)
    assert max(sizes[-3:]) <= 2 and sorted(sum(chunks, [])) == members
    assert min(chunks[0]) < 10 and max(chunks[0]) > 190  # early and late alike
    assert _chunks(list(range(6)), 1) == [[0, 4], [1, 5], [2], [3]]
    assert _chunks([], 2) == [] and _chunks([7], 2) == [[7]]
