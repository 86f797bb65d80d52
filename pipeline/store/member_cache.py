"""One member cache for every study: a family member's run, stored under a key of everything
that decides its trajectory, and restored into any family folder that needs the same member.

The key is the SHA-256 of the member's config hash (its resolved settings: scenario, vehicle,
model, planner, controller, metrics; :meth:`pipeline.config.ExperimentConfig.config_hash`) and
of the *environment*: the package's code version (every source file,
:func:`pipeline.store.manifest.code_version`), the versions of the numerical packages a run
goes through and the Python version. A member whose planner or controller is a plug-in outside
the package is never cached: its code is not in the key.

An entry is a run folder (``config.yaml``, ``model.json``, ``trajectory.csv``, ``timing.json``,
``metrics.json`` and its ``manifest.json``) under ``<root>/members/<key[:2]>/<key>/``. Safe under
concurrent writers and on a shared file system:

- an entry is built in a private temporary folder and published with one atomic ``rename``
  (a second writer of the same key finds it there and drops its own copy);
- readers and writers hold a shared kernel lock (``flock``; the Linux NFS client maps it onto
  the server's byte-range locks) on ``<root>/.lock``, and cleaning holds it exclusively;
- an entry is trusted only when its manifest matches every file (size and SHA-256), its config
  hash and its code version: a damaged entry is removed and the member simulated again;
- a family that keeps its members' rows instead of their folders (a tune's training
  families) takes a cached member's ``metrics.json`` alone (:meth:`MemberCache.metrics`), and
  publishes nothing: its members have no folder to publish;
- a restored member gets its own files (copies, reflinks where the file system makes them:
  an edit in one run folder never reaches another or the cache; entries are copies too) and
  its own ``config.yaml`` and manifest, written last, like a fresh run's;
- the cache's folder carries a marker (``CACHEDIR.TAG``, the cache-directory tag backup tools
  know) written when it is made: cleaning refuses a folder without it, so ``--root`` naming
  some other folder deletes nothing.

The wall-clock solve times in ``timing.json`` are the ones measured when the entry was made.
``PIPELINE_MEMBER_CACHE`` names the root (the Makefile sets ``outputs/member_cache``); empty or
``off`` disables the cache.
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import hashlib
import json
import logging
import os
import shutil
import sys
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from pipeline.errors import NotACacheError
from pipeline.numerics import numerical_kernels
from pipeline.store.files import write_text_atomic
from pipeline.store.manifest import (
    HORIZON_FILE,
    MANIFEST,
    RUN_FILES,
    check,
    code_version,
    write_manifest,
)

logger = logging.getLogger(__name__)

#: The environment variable that names the cache's root folder.
ENV = "PIPELINE_MEMBER_CACHE"
#: Packages whose version can change a member's numbers (solvers, linear algebra, kernels).
NUMERICAL_PACKAGES = ("numpy", "scipy", "cvxpy", "clarabel", "daqp", "numba", "control",
                      "casadi", "pandas")
#: The files an entry shares with the member folders restored from it (config.yaml is written
#: per member: it carries settings outside the config hash, such as the claims' readings).
SHARED_FILES = tuple(name for name in RUN_FILES if name != "config.yaml")
#: The marker a member cache's folder carries from its making (https://bford.info/cachedir/).
MARKER = "CACHEDIR.TAG"
MARKER_TEXT = ("Signature: 8a477f597d28d172789f06886806bc55\n"
               "# This folder is the member cache of apf-mpc-repro (pipeline.store.member_cache):\n"
               "# simulated family members, restored into run folders; safe to delete.\n")


@functools.lru_cache(maxsize=1)
def environment_key() -> str:
    """SHA-256 (first 16 hex digits) of the code version, the numerical packages' versions, the
    Python version and the kernels numpy and OpenBLAS run (:func:`pipeline.numerics.
    numerical_kernels`): what, beside the settings, decides a member's numbers."""
    from importlib import metadata

    versions: dict[str, str | None] = {}
    for name in NUMERICAL_PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    text = json.dumps({"code": code_version(), "packages": versions,
                       "python": sys.version.split()[0], "kernels": numerical_kernels()},
                      sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@dataclass
class MemberCounts:
    """Where a study's members came from: already complete in their family folder (resumed),
    restored from the member cache (reused) or simulated."""

    resumed: int = 0
    reused: int = 0
    simulated: int = 0

    def add(self, other: MemberCounts) -> None:
        self.resumed += other.resumed
        self.reused += other.reused
        self.simulated += other.simulated

    def to_json(self) -> dict:
        return {"resumed": self.resumed, "reused": self.reused, "simulated": self.simulated}

    @classmethod
    def from_json(cls, data: dict | None) -> MemberCounts:
        data = data or {}
        return cls(int(data.get("resumed", 0)), int(data.get("reused", 0)),
                   int(data.get("simulated", 0)))

    def sentence(self) -> str:
        total = self.resumed + self.reused + self.simulated
        return (f"{total} members: {self.simulated} simulated, {self.reused} reused from the "
                f"member cache, {self.resumed} already complete")


@dataclass(frozen=True)
class CacheSize:
    """What a cache holds: entries, files and bytes (a file shared with run folders is
    counted once, with the cache)."""

    entries: int
    files: int
    bytes: int

    def sentence(self, root: Path) -> str:
        return (f"member cache {root}: {self.entries} members, {self.files} files, "
                f"{self.bytes / 1e6:.1f} MB")


@dataclass(frozen=True)
class MemberCache:
    """The member cache at ``root`` (created on first use)."""

    root: Path

    @classmethod
    def from_env(cls, default: Path | None = None) -> MemberCache | None:
        """The cache named by ``PIPELINE_MEMBER_CACHE``, else ``default`` (None: no cache)."""
        value = os.environ.get(ENV)
        if value is not None:
            value = value.strip()
            if value.lower() in ("", "off", "none", "0"):
                return None
            return cls(Path(value).expanduser().resolve())
        return cls(Path(default).resolve()) if default is not None else None

    # --- keys and places -------------------------------------------------------------------

    def key(self, cfg, config_hash: str | None = None) -> str | None:
        """The member's cache key, or None when it must not be cached (a plug-in outside the
        package: its code is not in the key); ``config_hash``: ``cfg.config_hash()`` when the
        caller has it (a family computes its members' hashes at once)."""
        for section in (cfg.planner, cfg.controller):
            target = getattr(section, "_target_", None)
            if target and not str(target).startswith("pipeline."):
                return None
        text = f"{config_hash or cfg.config_hash()}:{environment_key()}"
        return hashlib.sha256(text.encode()).hexdigest()[:32]

    def entry(self, key: str) -> Path:
        return self.root / "members" / key[:2] / key

    @contextlib.contextmanager
    def _lock(self, exclusive: bool = False):
        """The cache's kernel lock: shared for readers and writers, exclusive for cleaning."""
        self._claim()
        fd = os.open(self.root / ".lock", os.O_CREAT | os.O_RDWR, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
            yield
        finally:
            os.close(fd)  # releases the lock

    def _discard(self, path: Path) -> None:
        """Move ``path`` out of the way atomically, then delete it."""
        trash = self.root / "tmp" / f"discard-{uuid.uuid4().hex}"
        trash.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.rename(path, trash)
        except FileNotFoundError:
            return
        except OSError as exc:
            logger.warning("member cache: could not remove %s (%s)", path, exc)
            return
        shutil.rmtree(trash, ignore_errors=True)

    def _trusted(self, entry: Path, config_hash: str) -> bool:
        """Whether ``entry`` can be used; a damaged one is removed (and said so)."""
        if not entry.is_dir():
            return False
        reason = check(entry, "run", config_hash)
        if reason is None:
            try:
                manifest = json.loads((entry / MANIFEST).read_text(encoding="utf-8"))
            except (OSError, ValueError):
                manifest = {}
            if manifest.get("code_version") != code_version():
                reason = "written by other code"
        if reason is not None:
            logger.warning("member cache: entry %s not trusted (%s); removed, the member is "
                           "simulated again", entry.name, reason)
            self._discard(entry)
            return False
        return True

    # --- use -------------------------------------------------------------------------------

    def restore(self, cfg, folder: Path, config_text: str | Callable[[], str],
                config_hash: str | None = None) -> bool:
        """Fill the member folder ``folder`` from the cache (its files, then ``config_text``
        (or what it returns, asked only for a cached member) as its ``config.yaml``, then its
        manifest, last); False when the member is not cached. ``config_hash``:
        ``cfg.config_hash()`` when the caller has it."""
        config_hash = config_hash or cfg.config_hash()
        key = self.key(cfg, config_hash)
        if key is None:
            return False
        entry = self.entry(key)
        if not entry.is_dir():  # not cached: no lock needed to say so (a miss costs a stat)
            return False
        with self._lock():
            if not self._trusted(entry, config_hash):
                return False
            folder = Path(folder)
            folder.mkdir(parents=True, exist_ok=True)
            (folder / MANIFEST).unlink(missing_ok=True)
            # the horizon record (the report's explorer) when the entry has one
            optional = (HORIZON_FILE,) if (entry / HORIZON_FILE).is_file() else ()
            try:
                for name in SHARED_FILES + optional:
                    _copy_atomic(entry / name, folder / name)
            except FileNotFoundError:  # removed by a cleaner between the check and the copy
                return False
            if not optional:
                (folder / HORIZON_FILE).unlink(missing_ok=True)
        write_text_atomic(folder / "config.yaml",
                          config_text if isinstance(config_text, str) else config_text())
        write_manifest(folder, "run", RUN_FILES + optional, config_hash,
                       {"member_cache": key})
        return True

    def metrics(self, cfg, config_hash: str | None = None) -> dict | None:
        """The cached member's ``metrics.json`` mapping, nothing copied (a family that keeps
        its members' rows, not their folders), or None when the member is not cached (or its
        entry is not trusted: removed, as for :meth:`restore`)."""
        config_hash = config_hash or cfg.config_hash()
        key = self.key(cfg, config_hash)
        if key is None:
            return None
        entry = self.entry(key)
        if not entry.is_dir():
            return None
        with self._lock():
            if not self._trusted(entry, config_hash):
                return None
            try:
                data = json.loads((entry / "metrics.json").read_text(encoding="utf-8"))
            except (OSError, ValueError):  # removed by a cleaner after the check
                return None
        return data if isinstance(data, dict) else None

    def publish(self, cfg, folder: Path) -> bool:
        """Store the complete member folder ``folder`` (its manifest written) in the cache;
        False when it is not cacheable or already there."""
        config_hash = cfg.config_hash()
        key = self.key(cfg, config_hash)
        if key is None:
            return False
        entry = self.entry(key)
        with self._lock():
            if entry.is_dir() and self._trusted(entry, config_hash):
                return False
            tmp = self.root / "tmp" / f"publish-{uuid.uuid4().hex}"
            try:
                optional = (HORIZON_FILE,) if (Path(folder) / HORIZON_FILE).is_file() else ()
                try:
                    tmp.mkdir(parents=True)
                    for name in (*RUN_FILES, *optional, MANIFEST):
                        _copy(Path(folder) / name, tmp / name)
                except FileNotFoundError:
                    raise
                except OSError as exc:
                    # the cache's disk (full, read-only): the run is whole without it
                    logger.warning("member cache: cannot store a member in %s (%s); the "
                                   "run folder is complete, the member is not cached",
                                   self.root, exc.strerror or exc)
                    return False
                if check(tmp, "run", config_hash) is not None:
                    return False  # the member folder changed under us: never publish it
                entry.parent.mkdir(parents=True, exist_ok=True)
                try:
                    os.rename(tmp, entry)
                except OSError:  # another writer published the same member first
                    return False
                return True
            finally:
                if tmp.exists():
                    shutil.rmtree(tmp, ignore_errors=True)

    # --- upkeep ----------------------------------------------------------------------------

    def size(self) -> CacheSize:
        """Entries, files and bytes (each inode once)."""
        entries = files = total = 0
        seen: set[tuple[int, int]] = set()
        members = self.root / "members"
        if members.is_dir():
            for entry in members.glob("*/*"):
                if not entry.is_dir():
                    continue
                entries += 1
                for path in entry.iterdir():
                    stat = path.stat()
                    files += 1
                    if (stat.st_dev, stat.st_ino) not in seen:
                        seen.add((stat.st_dev, stat.st_ino))
                        total += stat.st_size
        return CacheSize(entries, files, total)

    def is_cache(self) -> bool:
        """Whether ``root`` is a member cache's folder (it carries :data:`MARKER`)."""
        return (self.root / MARKER).is_file()

    def _claim(self) -> None:
        """Make ``root`` a member cache's folder, marked, when it is new or empty (or a cache
        of before the marker: ``.lock`` and nothing but ``members/`` and ``tmp/`` beside it);
        any other folder is not the cache's to write into.

        Raises
        ------
        NotACacheError
            ``root`` holds something else.
        """
        if self.is_cache():
            return
        self.root.mkdir(parents=True, exist_ok=True)
        # hidden names are the cache's own in passing (.lock, a marker being written by a
        # concurrent first user, .discard-*)
        names = {p.name for p in self.root.iterdir() if not p.name.startswith(".")}
        if MARKER in names:  # another process made the folder meanwhile: it is the cache
            return
        if names and not ((self.root / ".lock").exists() and names <= {"members", "tmp"}):
            raise NotACacheError(
                f"{self.root} is not a member cache (it holds other files and no {MARKER}); "
                f"name an empty or new folder in {ENV} or --root")
        write_text_atomic(self.root / MARKER, MARKER_TEXT)

    def clean(self) -> CacheSize:
        """Remove every entry (holding the lock exclusively: no study reads or writes
        meanwhile); returns what was removed. Run folders keep their own copies.

        Raises
        ------
        NotACacheError
            When ``root`` exists without the cache's marker: nothing is deleted."""
        if not self.root.exists():
            return CacheSize(0, 0, 0)
        if not self.is_cache():
            if not any(self.root.iterdir()):
                return CacheSize(0, 0, 0)
            try:
                self._claim()  # a cache of before the marker
            except NotACacheError:
                raise NotACacheError(
                    f"{self.root} is not a member cache (it has no {MARKER}, which the cache "
                    "writes when it makes its folder); nothing was deleted") from None
        with self._lock(exclusive=True):
            removed = self.size()
            for name in ("members", "tmp"):
                if (self.root / name).exists():
                    # beside, not into tmp/: tmp itself is removed the same way
                    trash = self.root / f".discard-{uuid.uuid4().hex}"
                    os.rename(self.root / name, trash)
                    shutil.rmtree(trash, ignore_errors=True)
        return removed



def _copy_atomic(source: Path, target: Path) -> None:
    """``target`` becomes a copy of ``source`` (its own inode), replacing whatever was there
    in one rename."""
    tmp = target.with_name(f".{target.name}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        _copy(source, tmp)
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)


def _copy(source: Path, target: Path) -> None:
    """Copy ``source`` to a new file ``target``: the kernel's ``copy_file_range`` (which a
    copy-on-write file system such as btrfs or XFS answers with a reflink: no bytes copied),
    else :func:`shutil.copyfile`. Never a hard link: the two names must be two files."""
    with open(source, "rb") as src:
        size = os.fstat(src.fileno()).st_size
        with open(target, "xb") as dst:
            try:
                copied = 0
                while copied < size:
                    n = os.copy_file_range(src.fileno(), dst.fileno(), size - copied)
                    if n == 0:
                        break
                    copied += n
                if copied == size:
                    return
            except (AttributeError, OSError):  # no such call, or not between these files
                pass
            src.seek(0)
            dst.seek(0)
            dst.truncate()
            shutil.copyfileobj(src, dst)
