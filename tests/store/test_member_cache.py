"""The member cache (pipeline.store.member_cache): a member simulated by one study is restored,
byte for byte, by another with the same settings and code; a changed setting, other code or a
plug-in outside the package misses; a damaged entry is recomputed; concurrent writers of one
member leave one good entry; ``python -m pipeline.cache`` reports and cleans."""

from __future__ import annotations

import dataclasses
import json
import multiprocessing
import shutil
from pathlib import Path

import pytest

from pipeline.loop.scenario import family_members
from pipeline.store.manifest import check
from pipeline.store.member_cache import MemberCache, MemberCounts, environment_key
from pipeline.studies.experiment import run_families_together, run_family


def _family(make_config, size: int, extra: tuple[str, ...] = ()):
    return make_config(["method=improved", "scenario=family", f"scenario.family.size={size}",
                        "scenario.family.seed=3", "controller.backend=daqp",
                        "scenario.family.n_jobs=1", *extra])


def _member_hashes(cfg) -> set[str]:
    """The members' config hashes, computed apart from the cache (the oracle of sharing)."""
    return {dataclasses.replace(cfg, scenario=m).config_hash()
            for m in family_members(cfg.scenario, cfg.vehicle.footprint_radius_m)}


@pytest.fixture(scope="module")
def populated(make_config, tmp_path_factory):
    """A cache filled by a 4-member family, and a 6-member family run twice: once with the
    cache and once without (the reference bytes)."""
    root = tmp_path_factory.mktemp("member_cache")
    cache = MemberCache(root / "cache")
    small, large = _family(make_config, 4), _family(make_config, 6)
    first, second = MemberCounts(), MemberCounts()
    run_family(small, root / "first", progress=False, member_cache=cache, counts=first)
    run_family(large, root / "second", progress=False, member_cache=cache, counts=second)
    run_family(large, root / "uncached", progress=False, member_cache=None)
    return root, cache, small, large, first, second


def test_a_second_study_restores_exactly_the_shared_members(populated):
    root, cache, small, large, first, second = populated
    shared = len(_member_hashes(small) & _member_hashes(large))
    assert shared == 4
    assert (first.simulated, first.reused) == (4, 0)
    assert (second.reused, second.simulated, second.resumed) == (shared, 2, 0)
    # restored members are the simulated ones, byte for byte, and trusted like fresh runs
    assert (root / "second" / "family_metrics.csv").read_bytes() == \
        (root / "uncached" / "family_metrics.csv").read_bytes()
    for i in range(6):
        name = f"member_{i:04d}"
        assert check(root / "second" / name, "run") is None
        assert (root / "second" / name / "trajectory.csv").read_bytes() == \
            (root / "uncached" / name / "trajectory.csv").read_bytes()
    timing = json.loads((root / "second" / "timing.json").read_text())
    assert timing["member_cache"] == {"resumed": 0, "reused": 4, "simulated": 2}
    assert cache.size().entries == 6


def test_the_key_follows_the_settings_the_code_and_nothing_else(populated, make_config,
                                                                monkeypatch):
    _, cache, small, large, *_ = populated
    member = family_members(small.scenario)[1]
    a = cache.key(dataclasses.replace(small, scenario=member))
    assert a == cache.key(dataclasses.replace(large, scenario=member))  # family size: no
    other = _family(make_config, 4, ("planner.beta=0.5",))
    assert cache.key(dataclasses.replace(other, scenario=member)) != a
    backend = _family(make_config, 4, ("controller.backend=clarabel_direct",))
    assert cache.key(dataclasses.replace(backend, scenario=member)) != a
    plugin = dataclasses.replace(small, planner=dataclasses.replace(
        small.planner, _target_="my_lab.planners.Mine"))
    assert cache.key(plugin) is None
    import pipeline.store.member_cache as module

    environment_key.cache_clear()
    monkeypatch.setattr(module, "code_version", lambda: "other code")
    try:
        assert cache.key(dataclasses.replace(small, scenario=member)) != a
    finally:
        monkeypatch.undo()
        environment_key.cache_clear()
    assert cache.key(dataclasses.replace(small, scenario=member)) == a


def test_a_damaged_entry_is_recomputed_never_trusted(populated, caplog):
    root, cache, small, *_ = populated
    reference = (root / "first" / "family_metrics.csv").read_bytes()
    member = dataclasses.replace(small, scenario=family_members(small.scenario)[2])
    entry = cache.entry(cache.key(member))
    # a copy, so that the damage does not reach the member folders linked to the entry
    text = (entry / "trajectory.csv").read_text()
    (entry / "trajectory.csv").unlink()
    (entry / "trajectory.csv").write_text(text.replace("0.", "9.", 5))
    counts = MemberCounts()
    with caplog.at_level("WARNING"):
        run_family(small, root / "again", progress=False, member_cache=cache, counts=counts)
    assert (counts.reused, counts.simulated) == (3, 1)
    assert "not trusted" in caplog.text
    assert (root / "again" / "family_metrics.csv").read_bytes() == reference
    assert check(entry, "run", member.config_hash()) is None  # published again, whole


def test_families_sharing_one_pool_equal_families_run_one_by_one(populated, make_config):
    root, *_ = populated
    cfgs = [_family(make_config, 3), _family(make_config, 3, ("planner.beta=0.5",))]
    counts = MemberCounts()
    run_families_together([(c, root / f"together_{i}") for i, c in enumerate(cfgs)],
                          member_cache=None, counts=counts)
    assert counts.simulated == 6
    for i, cfg in enumerate(cfgs):
        run_family(cfg, root / f"alone_{i}", progress=False, member_cache=None)
        assert (root / f"together_{i}" / "family_metrics.csv").read_bytes() == \
            (root / f"alone_{i}" / "family_metrics.csv").read_bytes()
        assert check(root / f"together_{i}", "family", cfg.config_hash()) is None


def _publish_at_once(barrier, cache_root: str, cfg, folder: str, queue) -> None:
    barrier.wait()
    queue.put(MemberCache(Path(cache_root)).publish(cfg, Path(folder)))


def test_concurrent_writers_of_one_member_leave_one_good_entry(populated, tmp_path):
    root, _, small, *_ = populated
    member = dataclasses.replace(small, scenario=family_members(small.scenario)[0])
    context = multiprocessing.get_context("fork")
    for attempt in range(3):
        cache_root = tmp_path / f"cache_{attempt}"
        barrier, queue = context.Barrier(3), context.Queue()
        workers = [context.Process(target=_publish_at_once,
                                   args=(barrier, str(cache_root), member,
                                         str(root / "first" / "member_0000"), queue))
                   for _ in range(3)]
        for worker in workers:
            worker.start()
        for worker in workers:
            worker.join(60)
        results = [queue.get(timeout=5) for _ in workers]
        assert sorted(results) == [False, False, True]
        cache = MemberCache(cache_root)
        assert cache.size().entries == 1
        assert check(cache.entry(cache.key(member)), "run", member.config_hash()) is None
        assert not any((cache_root / "tmp").iterdir())  # no temporary left behind


def test_the_cache_command_reports_and_cleans(populated, tmp_path, capsys):
    from pipeline.cache import main

    root, cache, *_ = populated
    copy = tmp_path / "copy"
    shutil.copytree(cache.root, copy)
    assert main(["size", "--root", str(copy)]) == 0
    assert f"{MemberCache(copy).size().entries} members" in capsys.readouterr().out
    assert main(["clean", "--root", str(copy)]) == 0
    assert "removed 6 members" in capsys.readouterr().out
    assert MemberCache(copy).size().entries == 0
    # run folders keep their own copies: the family restored from the cache is still whole
    assert check(root / "second", "family") is None


def test_the_environment_variable_names_or_disables_the_cache(monkeypatch, tmp_path):
    monkeypatch.setenv("PIPELINE_MEMBER_CACHE", str(tmp_path / "c"))
    assert MemberCache.from_env() == MemberCache((tmp_path / "c").resolve())
    for off in ("off", "", "none"):
        monkeypatch.setenv("PIPELINE_MEMBER_CACHE", off)
        assert MemberCache.from_env(default=tmp_path) is None
    monkeypatch.delenv("PIPELINE_MEMBER_CACHE")
    assert MemberCache.from_env() is None
    assert MemberCache.from_env(default=tmp_path) == MemberCache(tmp_path.resolve())


def test_restore_asks_the_config_text_only_of_a_cached_member(populated, make_config,
                                                             tmp_path):
    """A family hands restore its members' hashes (computed at once) and their config YAML as
    a callable: a miss never builds the YAML, a hit writes exactly what the callable returns,
    and the key from a given hash is the key from the config's own."""
    root, cache, small, large, _, _ = populated
    unseen = _family(make_config, 3, ("scenario.family.seed=4",))  # never run: misses
    asked: list[str] = []

    def text(name: str):
        def make() -> str:
            asked.append(name)
            return f"{name}\n"
        return make

    hits, expected = [], []
    for label, cfg_family in (("large", large), ("unseen", unseen)):
        members = family_members(cfg_family.scenario, cfg_family.vehicle.footprint_radius_m)
        hashes = cfg_family.member_config_hashes(members)
        for i, member in enumerate(members):
            cfg = dataclasses.replace(cfg_family, scenario=member)
            assert hashes[i] == cfg.config_hash()
            assert cache.key(cfg, hashes[i]) == cache.key(cfg)
            name = f"{label}{i}"
            hit = cache.restore(cfg, tmp_path / name, text(name), hashes[i])
            hits.append(hit)
            expected.append(label == "large")
            if hit:
                assert (tmp_path / name / "config.yaml").read_text() == f"{name}\n"
                assert check(tmp_path / name, "run", hashes[i]) is None
    assert hits == expected and sum(hits) == 6
    assert asked == [f"large{i}" for i in range(6)]


def test_no_file_of_a_run_folder_shares_its_inode_with_the_cache_or_another(populated):
    """Restored members and entries are copies, never hard links: an in-place edit of one run
    folder's file cannot reach another run folder or the cache (the oracle is the inode)."""
    root, cache, *_ = populated
    owners: dict[tuple[int, int], Path] = {}
    files = [p for p in root.rglob("*") if p.is_file() and p.suffix in (".csv", ".json", ".npz")]
    assert len([p for p in files if cache.root in p.parents]) >= 4 * 5  # the entries' files
    for path in files:
        stat = path.stat()
        assert stat.st_nlink == 1, path
        assert (stat.st_dev, stat.st_ino) not in owners, (path, owners.get((stat.st_dev,
                                                                            stat.st_ino)))
        owners[(stat.st_dev, stat.st_ino)] = path


def test_cache_clean_refuses_a_folder_that_is_not_a_member_cache(make_config, tmp_path, capsys):
    """``cache clean --root`` of a folder without the cache's marker deletes nothing and says so
    in one line (it once removed that folder's members/ subtree and exited 0)."""
    from pipeline.cache import main

    other = tmp_path / "project"
    (other / "members" / "ab").mkdir(parents=True)
    (other / "members" / "ab" / "notes.txt").write_text("mine")
    (other / "README.md").write_text("mine too")
    assert main(["clean", "--root", str(other)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a member cache" in err[0] and "CACHEDIR.TAG" in err[0], err
    assert (other / "members" / "ab" / "notes.txt").read_text() == "mine"
    # the cache never writes into it either: a family pointed at it stops in one line
    from pipeline.errors import NotACacheError

    with pytest.raises(NotACacheError, match="not a member cache"):
        run_family(_family(make_config, 1), tmp_path / "family", progress=False,
                   member_cache=MemberCache(other))
    assert sorted(p.name for p in other.iterdir()) == ["README.md", "members"]


def test_cache_clean_empties_a_marked_cache_and_one_made_before_the_marker(populated, tmp_path,
                                                                           caplog):
    """A cache (marked, or of before the marker: .lock, members/, tmp/) is emptied with its
    tmp/ folder and no warning (cleaning once tried to rename tmp/ into itself)."""
    from pipeline.cache import main

    _, cache, *_ = populated
    assert (cache.root / "CACHEDIR.TAG").read_text().startswith(
        "Signature: 8a477f597d28d172789f06886806bc55")
    for marked in (True, False):
        copy = tmp_path / f"copy_{marked}"
        shutil.copytree(cache.root, copy)
        (copy / "tmp" / "publish-left-behind").mkdir(parents=True, exist_ok=True)
        if not marked:
            (copy / "CACHEDIR.TAG").unlink()
        with caplog.at_level("WARNING"):
            assert main(["clean", "--root", str(copy)]) == 0
        assert not [r for r in caplog.records if "could not" in r.getMessage()]
        assert sorted(p.name for p in copy.iterdir()) == [".lock", "CACHEDIR.TAG"]


def test_a_full_cache_disk_costs_the_cache_not_the_run(make_config, tmp_path, monkeypatch,
                                                        caplog):
    """The cache's disk full (ENOSPC while storing a member): the family completes and is
    trusted, the member is simply not cached, and the warning names the cache (it once named
    the run folder's metrics.json as if the run could not be written)."""
    import errno

    from pipeline.store import member_cache

    def full(source, target):
        raise OSError(errno.ENOSPC, "No space left on device", str(target))

    monkeypatch.setattr(member_cache, "_copy", full)
    cache = MemberCache(tmp_path / "cache")
    counts = MemberCounts()
    with caplog.at_level("WARNING"):
        run_family(_family(make_config, 2), tmp_path / "family", progress=False,
                   member_cache=cache, counts=counts)
    assert check(tmp_path / "family", "family") is None and counts.simulated == 2
    assert cache.size().entries == 0
    said = [r.getMessage() for r in caplog.records if "member cache" in r.getMessage()]
    assert said and all(str(cache.root) in s and "No space left" in s for s in said)
    assert not any("metrics.json" in s for s in said)
