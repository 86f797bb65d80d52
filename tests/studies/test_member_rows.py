"""Families that keep their members' rows instead of their folders (``record_members`` false,
a tune's training families; ``members.jsonl``, pipeline.store.runs.MEMBER_ROWS): the same
family table and summary bytes as with the members' folders, each row the member's
``metrics.json`` mapping exactly, no member folder written; a later rung takes the earlier
rung's rows, a damaged record or another setting's rows are simulated again, a member in the
member cache gives its metrics without a copy; the tune's switch and its refusal."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.loop.controller import QpCache
from pipeline.loop.scenario import family_members
from pipeline.store.member_cache import MemberCache, MemberCounts
from pipeline.store.runs import MEMBER_ROWS, read_member_rows
from pipeline.studies.experiment import run_family
from pipeline.studies.family_pool import FamilyPool


def _family(make_config, size: int, extra: tuple[str, ...] = ()):
    return make_config(["method=improved", "scenario=family", f"scenario.family.size={size}",
                        "scenario.family.seed=5", "controller.backend=daqp",
                        "scenario.family.n_jobs=1", *extra])


def _rows(folder):
    return [json.loads(line) for line in (folder / MEMBER_ROWS).read_text().splitlines()]


def test_rows_instead_of_folders_give_the_same_family_record(tmp_path, make_config):
    """Oracle: the same family with its members' folders. The table and summary are the same
    bytes; each row is its member's metrics.json mapping (member index first), exactly; the
    record-less folder has no member folder and its manifest lists the rows and no member."""
    cfg = _family(make_config, 4)
    run_family(cfg, tmp_path / "folders", progress=False, member_cache=None)
    counts = MemberCounts()
    run_family(cfg, tmp_path / "rows", progress=False, member_cache=None, counts=counts,
               record_members=False)
    assert counts.simulated == 4
    for name in ("family_metrics.csv", "family.json"):
        assert (tmp_path / "rows" / name).read_bytes() == \
            (tmp_path / "folders" / name).read_bytes(), name
    assert not list((tmp_path / "rows").glob("member_*"))
    assert len(list((tmp_path / "folders").glob("member_*/manifest.json"))) == 4
    manifest = json.loads((tmp_path / "rows" / "manifest.json").read_text())
    assert MEMBER_ROWS in manifest["files"] and manifest["members"] == {}
    rows = _rows(tmp_path / "rows")
    assert [row["member"] for row in rows] == [0, 1, 2, 3]
    for row in rows:
        index = row.pop("member")
        expected = json.loads((tmp_path / "folders" / f"member_{index:04d}"
                               / "metrics.json").read_text())
        assert row == expected
    assert read_member_rows(tmp_path / "rows") == {i: r for i, r in enumerate(rows)}
    # a family with its members' folders keeps no rows
    assert read_member_rows(tmp_path / "folders") == {}


def test_a_rung_then_the_whole_family_takes_the_rungs_rows(tmp_path, make_config):
    """A tune's rung (2 members) without its family record asked (record=False), then the
    whole family (4), both record-less: the rung's record is written all the same (it keeps
    its members), the whole family simulates only the other two, and its table is
    run_family's with the members' folders, byte for byte."""
    whole = _family(make_config, 4)
    rung = dataclasses.replace(whole, scenario=dataclasses.replace(
        whole.scenario, family=dataclasses.replace(whole.scenario.family, size=2)))
    run_family(whole, tmp_path / "reference", progress=False, member_cache=None)
    counts = MemberCounts()
    pool = FamilyPool(2, QpCache(), None, counts)
    pool.submit(rung, tmp_path / "f", lambda: None, record=False, record_members=False)
    pool.run_until_idle()
    assert [row["member"] for row in _rows(tmp_path / "f")] == [0, 1]
    pool.submit(whole, tmp_path / "f", lambda: None, whole_hash=None, record_members=False)
    pool.run_until_idle()
    pool.close()
    assert (counts.simulated, counts.resumed) == (4, 2)
    assert (tmp_path / "f" / "family_metrics.csv").read_bytes() == \
        (tmp_path / "reference" / "family_metrics.csv").read_bytes()
    assert not list((tmp_path / "f").glob("member_*"))


def test_damaged_rows_or_another_settings_rows_are_simulated_again(tmp_path, make_config):
    """A record whose rows were edited is not trusted (its manifest's hash): every member is
    simulated again. Rows of another setting in the same folder (their config hashes) are not
    taken either."""
    cfg = _family(make_config, 3)
    run_family(cfg, tmp_path / "f", progress=False, member_cache=None, record_members=False)
    path = tmp_path / "f" / MEMBER_ROWS
    path.write_text(path.read_text().replace('"member": 1', '"member": 7'))
    assert read_member_rows(tmp_path / "f") == {}
    counts = MemberCounts()
    run_family(cfg, tmp_path / "f", progress=False, member_cache=None, counts=counts,
               record_members=False)
    assert (counts.simulated, counts.resumed) == (3, 0)
    other = _family(make_config, 3, ("planner.beta=0.3",))
    counts = MemberCounts()
    run_family(other, tmp_path / "f", progress=False, member_cache=None, counts=counts,
               record_members=False)
    assert (counts.simulated, counts.resumed) == (3, 0)
    hashes = other.member_config_hashes(family_members(other.scenario,
                                                       other.vehicle.footprint_radius_m))
    assert [row["config_hash"] for row in _rows(tmp_path / "f")] == hashes


def test_a_cached_member_gives_its_metrics_without_a_copy(tmp_path, make_config):
    """Members published to the member cache by a family with folders: a record-less family of
    the same settings takes their metrics from the cache (reused, none simulated), writes no
    member folder, and its rows are the cached metrics.json mappings."""
    cfg = _family(make_config, 3)
    cache = MemberCache(tmp_path / "cache")
    run_family(cfg, tmp_path / "folders", progress=False, member_cache=cache)
    counts = MemberCounts()
    run_family(cfg, tmp_path / "rows", progress=False, member_cache=cache, counts=counts,
               record_members=False)
    assert (counts.simulated, counts.reused) == (0, 3)
    assert not list((tmp_path / "rows").glob("member_*"))
    for row in _rows(tmp_path / "rows"):
        index = row.pop("member")
        assert row == json.loads((tmp_path / "folders" / f"member_{index:04d}"
                                  / "metrics.json").read_text())
    # and a record-less family publishes nothing: a fresh cache stays empty
    empty = MemberCache(tmp_path / "empty")
    run_family(_family(make_config, 2, ("planner.beta=0.3",)), tmp_path / "rows2",
               progress=False, member_cache=empty, record_members=False)
    assert not list((tmp_path / "empty").rglob("metrics.json"))


def test_the_tunes_switch_and_its_refusal(tmp_path):
    """tune.training_member_records: off by default (the training members keep rows, the
    held-out members folders), on or with tune.training_horizon the training members keep
    folders; a value that is not a flag is one line naming the key."""
    from pipeline.conf_dir import CONF_DIR
    from pipeline.studies.tune import load_tune_space
    from pipeline.studies.tune.search import Runner

    space = load_tune_space(CONF_DIR / "tune" / "default.yaml")
    assert space.training_member_records is False

    def records(**changes) -> tuple[bool, bool]:
        runner = Runner.__new__(Runner)
        runner.space = dataclasses.replace(space, **changes)
        return runner.records_members("training"), runner.records_members("heldout")

    assert records() == (False, True)
    assert records(training_member_records=True) == (True, True)
    assert records(training_horizon=True) == (True, True)
    with pytest.raises(ConfigError, match="tune.training_member_records"):
        dataclasses.replace(space, training_member_records="maybe")


def test_the_tune_reads_a_rungs_own_record_from_its_rows(tmp_path, make_config):
    """A rung's own record (an early rung of a trial asked again: before the rows it had no
    record, and its members' metrics.json gave its table) is read by the tune (Runner.table)
    as the very table the run handed over, every float exact; a whole family's record is read
    from its family_metrics.csv (10 digits), as before the rows, rung or not."""
    import pandas as pd

    from pipeline.studies.tune.search import FamilyJob, Runner

    whole = _family(make_config, 4)
    rung = dataclasses.replace(whole, scenario=dataclasses.replace(
        whole.scenario, family=dataclasses.replace(whole.scenario.family, size=2)))
    fresh = run_family(rung, tmp_path / "f", progress=False, member_cache=None,
                       record_members=False)
    runner = Runner.__new__(Runner)
    read = runner.table(FamilyJob("improved", "trial", rung, tmp_path / "f", 0,
                                  whole.config_hash()))
    pd.testing.assert_frame_equal(read, fresh, check_exact=True)
    run_family(whole, tmp_path / "f", progress=False, member_cache=None, record_members=False)
    from_csv = pd.read_csv(tmp_path / "f" / "family_metrics.csv")
    for job in (FamilyJob("improved", "trial", whole, tmp_path / "f", 0),
                FamilyJob("improved", "trial", rung, tmp_path / "f", 0, whole.config_hash())):
        size = job.cfg.scenario.family.size
        pd.testing.assert_frame_equal(runner.table(job), from_csv.iloc[:size],
                                      check_exact=True)
    # the two differ (what reading the CSV for the rung's own record would give)
    numbers = [c for c in fresh.columns if fresh[c].dtype.kind == "f"]
    assert not all(np.array_equal(from_csv[c].to_numpy(float)[:2], fresh[c].to_numpy(float),
                                  equal_nan=True) for c in numbers)


def test_an_earlier_rung_asked_later_keeps_the_later_rungs_rows(tmp_path, make_config):
    """The whole family (4) is in the folder's record, then the same setting is asked at a
    rung (2) without the whole family's hash (a trial asked again at an earlier rung while a
    later one held the record): the rung's record keeps all four rows, so the whole family
    asked again simulates nothing (a full tune simulated 420 members twice before)."""
    whole = _family(make_config, 4)
    rung = dataclasses.replace(whole, scenario=dataclasses.replace(
        whole.scenario, family=dataclasses.replace(whole.scenario.family, size=2)))
    run_family(whole, tmp_path / "f", progress=False, member_cache=None, record_members=False)
    counts = MemberCounts()
    run_family(rung, tmp_path / "f", progress=False, member_cache=None, counts=counts,
               record_members=False)
    assert (counts.simulated, counts.resumed) == (0, 2)
    assert [row["member"] for row in _rows(tmp_path / "f")] == [0, 1, 2, 3]
    counts = MemberCounts()
    run_family(whole, tmp_path / "f", progress=False, member_cache=None, counts=counts,
               record_members=False)
    assert (counts.simulated, counts.resumed) == (0, 4)


@pytest.mark.parametrize("n_jobs", [1, 2])
def test_an_earlier_rung_in_the_pool_keeps_the_later_rungs_rows(tmp_path, make_config, n_jobs):
    """As above, through the tune's pool, whose record is written by a worker (n_jobs=2) or
    here (1): the rung's record keeps the whole family's four rows, read by the record's
    writer, and the whole family asked again simulates nothing."""
    whole = _family(make_config, 4)
    rung = dataclasses.replace(whole, scenario=dataclasses.replace(
        whole.scenario, family=dataclasses.replace(whole.scenario.family, size=2)))
    counts = MemberCounts()
    pool = FamilyPool(n_jobs, QpCache(), None, counts)
    pool.submit(whole, tmp_path / "f", lambda: None, record_members=False)
    pool.run_until_idle()
    assert (counts.simulated, counts.resumed) == (4, 0)
    pool.submit(rung, tmp_path / "f", lambda: None, record_members=False)
    pool.run_until_idle()
    assert (counts.simulated, counts.resumed) == (4, 2)
    assert [row["member"] for row in _rows(tmp_path / "f")] == [0, 1, 2, 3]
    pool.submit(whole, tmp_path / "f", lambda: None, record_members=False)
    pool.run_until_idle()
    pool.close()
    assert (counts.simulated, counts.resumed) == (4, 6)
