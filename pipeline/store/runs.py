"""Run records: the one owner of a run folder's layout (its only writer, reader and finder).

A *run folder* holds ``config.yaml`` (resolved config), ``model.json``, ``trajectory.csv``,
``timing.json`` (wall-clock solve times, which differ between identical runs), ``metrics.json``
and, written last and atomically, ``manifest.json``: every file with its size and SHA-256, the
config hash and the code version. A *family folder* holds ``family_metrics.csv``, ``family.json``
and its own manifest, which also lists each member folder's manifest hash. A folder is trusted
only when its manifest matches what is on disk; resume, aggregate, report and verify all go
through :func:`check` and :func:`discover`, and every folder they pass over is listed with its
reason (:class:`Skipped`).

Every file is written to a hidden temporary name and renamed, so a killed write never leaves a
half-written file; the temporaries a killed process leaves behind are removed by the next write
into that folder (:func:`clean_leftovers`).
"""

from __future__ import annotations

import contextlib
import errno
import functools
import hashlib
import json
import os
import tempfile
from dataclasses import dataclass, field, fields
from pathlib import Path

import pandas as pd

from pipeline.analysis.metrics import RunMetrics
from pipeline.config import ExperimentConfig, experiment_config_from_data
from pipeline.errors import (ConfigError, FolderBusyError, NonFiniteResultError,
                             OutputPathError, RunFolderError)

RUN_FILES = ("config.yaml", "model.json", "trajectory.csv", "timing.json", "metrics.json")
FAMILY_FILES = ("family_metrics.csv", "family.json")
#: The files a run's and a family's manifest must list (a study's result names its own and
#: passes them to :func:`check`).
REQUIRED = {"run": RUN_FILES, "family": FAMILY_FILES}
MANIFEST = "manifest.json"
SCHEMA = 1
#: Folder names that are Hydra's or submitit's bookkeeping, never runs.
BOOKKEEPING = (".hydra", ".submitit")


def _non_finite_key(data, path: str = "") -> str | None:
    import math

    if isinstance(data, float) and not math.isfinite(data):
        return path or "(value)"
    if isinstance(data, dict):
        for key, value in data.items():
            found = _non_finite_key(value, f"{path}.{key}" if path else str(key))
            if found:
                return found
    if isinstance(data, (list, tuple)):
        for i, value in enumerate(data):
            found = _non_finite_key(value, f"{path}[{i}]")
            if found:
                return found
    return None


def _json_text(name: str, data: dict) -> str:
    """Serialize a record file, refusing NaN and infinities with the key that holds one."""
    key = _non_finite_key(data)
    if key is not None:
        stage = {"model.json": "model", "metrics.json": "metrics",
                 "timing.json": "simulate"}.get(name, name)
        raise NonFiniteResultError(
            f"error: the run produced a non-finite value in {name} at {key} (stage: {stage}); "
            "no run folder was written. Check the physical parameters (vehicle.*, "
            "scenario.sample_time_s) for values outside their physical range")
    return json.dumps(data, indent=2, sort_keys=True, allow_nan=False) + "\n"


@dataclass(frozen=True)
class Skipped:
    """A folder passed over, and why."""

    folder: Path
    reason: str


@dataclass(frozen=True)
class RunInfo:
    """What a run was (bookkeeping written beside its metrics in ``metrics.json``)."""

    method: str
    scenario: str
    track: str
    config_hash: str
    termination: str
    compile_count: int

    def to_json(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_json(cls, data: dict) -> "RunInfo":
        return cls(str(data.get("method", "")), str(data.get("scenario", "")),
                   str(data.get("track", "lateral")), str(data.get("config_hash", "")),
                   str(data.get("termination", "")), int(data.get("compile_count") or 0))


@dataclass(frozen=True)
class RunRecord:
    """One trusted run folder, read and typed.

    Attributes
    ----------
    folder : Path
    config : ExperimentConfig
        The settings the run was made with (validated like a fresh configuration).
    config_data : dict
        The same, as the mapping in ``config.yaml`` (for labels and the register).
    metrics : RunMetrics
    info : RunInfo
    timing, model, manifest : dict
    trajectory : pandas.DataFrame or None
        None when read with ``trajectory=False``.
    """

    folder: Path
    config: ExperimentConfig
    config_data: dict
    metrics: RunMetrics
    info: RunInfo
    timing: dict
    model: dict
    manifest: dict
    trajectory: pd.DataFrame | None

    @property
    def method(self) -> str:
        return self.info.method

    def flat_metrics(self) -> dict:
        """``metrics.json`` as written: the metrics and the run's bookkeeping."""
        return {**self.metrics.to_json(), **self.info.to_json()}

    def as_dict(self) -> dict:
        """The report's view of the run (``dir``, ``config``, ``metrics``, ``timing``,
        ``trajectory``, ``claims``: the claims settings the run was made with)."""
        return {"dir": self.folder, "config": self.config_data, "metrics": self.flat_metrics(),
                "timing": self.timing, "trajectory": self.trajectory,
                "claims": self.config.claims}


@dataclass(frozen=True)
class FamilyRecord:
    """One trusted family folder, read: ``family.json``, the per-member table and the settings
    the family was made with (its first member's configuration)."""

    folder: Path
    info: dict
    table: pd.DataFrame
    manifest: dict
    config: ExperimentConfig | None
    config_data: dict | None
    #: ``timing.json``: what depends on the process (compilations); {} for older families
    timing: dict = field(default_factory=dict)


@dataclass
class Discovery:
    """What :func:`discover` found under a root."""

    runs: list[Path] = field(default_factory=list)
    families: list[Path] = field(default_factory=list)
    skipped: list[Skipped] = field(default_factory=list)


# --- writing ---------------------------------------------------------------------------------

def output_target(path: Path) -> Path:
    """Where a write to ``path`` lands: a symbolic link is followed to its target (the link
    stays a link); a path that exists and is not a regular file (a folder, a device, a pipe)
    is refused with :class:`OutputPathError`, so a write never replaces it."""
    import stat

    path = Path(path)
    if path.is_symlink():
        path = Path(os.path.realpath(path))
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        return path
    if stat.S_ISDIR(mode):
        raise OutputPathError(errno.EISDIR, "a folder, not a file", str(path))
    if not stat.S_ISREG(mode):
        raise OutputPathError(errno.EINVAL, "not a regular file (a device or a pipe)",
                              str(path))
    return path


def refuse_input_as_output(out: Path, inputs: list[Path], option: str = "--out") -> None:
    """Raise :class:`OutputPathError` when ``out`` is one of the command's ``inputs`` (the
    same file or folder, links followed): the output would destroy what it is computed from."""
    target = Path(os.path.realpath(out))
    for item in inputs:
        if item is None:
            continue
        if target == Path(os.path.realpath(item)):
            raise OutputPathError(errno.EINVAL, f"{option} is an input of this command "
                                  f"({item})", str(out))


def write_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` via a temporary file in the same folder and ``os.replace``;
    on any failure the previous file (if any) is left as it was. A symbolic link is written
    through to its target; a folder, device or pipe at ``path`` is refused
    (:func:`output_target`)."""
    path = output_target(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as handle:
            handle.write(text)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; results are meant to be shared
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_json_atomic(path: Path, data: dict) -> None:
    write_text_atomic(path, json.dumps(data, indent=2, sort_keys=True, allow_nan=False) + "\n")


def json_safe(value):
    """A copy of nested dicts and lists with NaN and infinities as None (what a study's
    summary.json may hold where a number is undefined)."""
    import math

    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_csv_atomic(path: Path, frame: pd.DataFrame) -> None:
    # fixed float format so identical runs give byte-identical files
    write_text_atomic(path, csv_text(frame))


_CSV_SPECIAL = (",", '"', "\r", "\n")


def _csv_cells(column: pd.Series) -> list[str] | None:
    """One column's cells as pandas writes them (``%.10g`` floats, empty for missing values),
    or None when the column needs pandas (quoting, an unusual dtype)."""
    kind = column.dtype.kind
    values = column.to_numpy().tolist()
    if kind == "f":
        return ["" if v != v else "%.10g" % v for v in values]
    if kind in "biu":
        return [str(v) for v in values]
    if kind in "OUT":
        cells = []
        for v in values:
            if v is None or (isinstance(v, float) and v != v):
                cells.append("")
            elif isinstance(v, (str, bool, int)):
                text = str(v)
                if any(c in text for c in _CSV_SPECIAL):
                    return None
                cells.append(text)
            else:
                return None
        return cells
    return None


def csv_text(frame: pd.DataFrame) -> str:
    """``frame.to_csv(index=False, float_format="%.10g", lineterminator="\\n")``, byte for byte,
    at a fraction of its cost for the plain tables the pipeline writes (floats, flags, short
    words); anything else (cells that need quoting, other dtypes) goes through pandas itself."""
    names = [str(c) for c in frame.columns]
    columns = [_csv_cells(frame[c]) for c in frame.columns] \
        if frame.shape[1] >= 2 and frame.columns.is_unique else [None]
    if any(c is None for c in columns) or any(ch in n for n in names for ch in _CSV_SPECIAL):
        return frame.to_csv(index=False, float_format="%.10g", lineterminator="\n")
    lines = [",".join(names)]
    lines.extend(",".join(row) for row in zip(*columns))
    return "\n".join(lines) + "\n"


LOCK = ".lock"


def _pid_alive(pid: int) -> bool:
    """Whether process ``pid`` exists (signal 0; another user's process counts as alive)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    return True


@contextlib.contextmanager
def folder_lock(folder: Path):
    """Hold ``folder/.lock`` (the writer's pid) while a run or family writes into ``folder``.
    A second writer raises :class:`FolderBusyError` naming the first; a lock whose process is
    gone (killed) is taken over. The lock is not part of any manifest."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    lock = folder / LOCK
    for _ in range(2):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            break
        except FileExistsError:
            try:
                pid = int(lock.read_text().split()[0])
            except (OSError, ValueError, IndexError):
                pid = None
            if pid is not None and pid != os.getpid() and _pid_alive(pid):
                raise FolderBusyError(f"{folder} is being written by another run (pid {pid}); "
                                      "wait for it to finish or choose another output folder")
            lock.unlink(missing_ok=True)  # left by a killed run
    else:
        raise FolderBusyError(f"{folder}: cannot take its lock ({lock})")
    try:
        os.write(fd, f"{os.getpid()}\n".encode())
    finally:
        os.close(fd)
    try:
        yield folder
    finally:
        lock.unlink(missing_ok=True)


def write_derived_table(path: Path, frame: pd.DataFrame, sources: dict[str, Path]) -> None:
    """Write a table computed from other records (e.g. a family re-scored under other metric
    settings) with a sidecar ``<name>.manifest.json``: the table's hash and the manifest
    hashes of the ``sources`` it was computed from (name -> record folder)."""
    path = Path(path)
    write_csv_atomic(path, frame)
    write_json_atomic(path.with_name(path.name + ".manifest.json"), {
        "schema": SCHEMA, "kind": "derived", "code_version": code_version(),
        "table": _file_entry(path),
        "sources": {name: _file_entry(Path(folder) / MANIFEST)["sha256"]
                    for name, folder in sources.items()}})


def check_derived_table(path: Path, sources: dict[str, Path]) -> str | None:
    """Why the derived table at ``path`` cannot be reused, or None: no sidecar manifest, the
    table changed after writing, or a source record changed since."""
    path = Path(path)
    sidecar = path.with_name(path.name + ".manifest.json")
    if not path.is_file():
        return "not computed yet"
    if not sidecar.is_file():
        return "no manifest (written by an older version, or not by this pipeline)"
    try:
        manifest = json.loads(sidecar.read_text(encoding="utf-8"))
        entry = _file_entry(path)
        if manifest["table"]["sha256"] != entry["sha256"]:
            return "the table differs from its manifest (changed after writing)"
        if set(manifest["sources"]) != set(sources):
            return "its sources are not the ones it was computed from (added or removed since)"
        for name, folder in sources.items():
            if manifest["sources"].get(name) != _file_entry(Path(folder) / MANIFEST)["sha256"]:
                return f"its source {name} changed since"
    except (OSError, ValueError, KeyError, TypeError):
        return "its manifest is unreadable"
    return None


def clean_leftovers(folder: Path) -> list[Path]:
    """Remove the hidden temporaries (``.<name>.<random>.tmp``) that a killed write left in
    ``folder``; returns what was removed."""
    folder = Path(folder)
    removed = []
    if folder.is_dir():
        for path in folder.glob(".*.tmp"):
            if path.is_file():
                path.unlink(missing_ok=True)
                removed.append(path)
    return removed


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """SHA-256 (first 16 hex digits) of the package's source files: which code wrote a run."""
    digest = hashlib.sha256()
    root = Path(__file__).resolve().parents[1]  # the package
    for path in sorted(root.rglob("*")):
        if path.suffix in (".py", ".j2") and "__pycache__" not in path.parts:
            digest.update(str(path.relative_to(root)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _file_entry(path: Path) -> dict:
    data = path.read_bytes()
    return {"bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}


def write_manifest(folder: Path, kind: str, files: tuple[str, ...], config_hash: str,
                   extra: dict | None = None) -> dict:
    """Write ``manifest.json`` for files already in ``folder`` (last, atomically)."""
    return _write_manifest(Path(folder), kind, files, config_hash, extra)


def _write_manifest(folder: Path, kind: str, files: tuple[str, ...], config_hash: str,
                    extra: dict | None = None) -> dict:
    manifest = {"schema": SCHEMA, "kind": kind, "config_hash": config_hash,
                "code_version": code_version(),
                "files": {name: _file_entry(folder / name) for name in files}, **(extra or {})}
    write_json_atomic(folder / MANIFEST, manifest)
    return manifest


def untrust(folder: Path) -> None:
    """Remove a folder's manifest: its files are being rewritten and must not be trusted until
    a new manifest is written last."""
    (Path(folder) / MANIFEST).unlink(missing_ok=True)


def folder_kind(folder: Path) -> str | None:
    """``"family"``, ``"run"`` or None: what kind of record a folder holds, by its files."""
    folder = Path(folder)
    if any((folder / name).is_file() for name in FAMILY_FILES):
        return "family"
    if any((folder / name).is_file() for name in RUN_FILES + (MANIFEST,)):
        return "run"
    return None


def write_run(folder: Path, *, config_text: str, model: dict, trajectory: pd.DataFrame,
              timing: dict, metrics: RunMetrics, info: RunInfo) -> Path:
    """Write a complete run folder: the files, then the manifest (last, atomically).

    An existing manifest is removed first, so a folder being rewritten is never trusted
    half-way; leftover temporaries of a killed write are removed.
    """
    folder = Path(folder)
    # everything serialized (and checked) before the folder is touched
    texts = {"config.yaml": config_text, "model.json": _json_text("model.json", model),
             "trajectory.csv": csv_text(trajectory),
             "timing.json": _json_text("timing.json", timing),
             "metrics.json": _json_text("metrics.json", {**metrics.to_json(),
                                                         **info.to_json()})}
    folder.mkdir(parents=True, exist_ok=True)
    clean_leftovers(folder)
    (folder / MANIFEST).unlink(missing_ok=True)
    for name in RUN_FILES:
        write_text_atomic(folder / name, texts[name])
    _write_manifest(folder, "run", RUN_FILES, info.config_hash)
    return folder


#: What depends on the process that wrote a family (compilations), apart from its results, so
#: that identical work gives identical ``family.json`` and ``family_metrics.csv`` bytes, resumed
#: or not. Listed in the manifest when present (older families have none).
FAMILY_TIMING = "timing.json"


def write_family(folder: Path, table: pd.DataFrame, info: dict, config_hash: str,
                 members: list[Path], timing: dict | None = None) -> Path:
    """Write a family folder's table, summary and (optional) process bookkeeping, then its
    manifest (with the members' manifest hashes)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    clean_leftovers(folder)
    (folder / MANIFEST).unlink(missing_ok=True)
    write_csv_atomic(folder / "family_metrics.csv", table)
    write_json_atomic(folder / "family.json", info)
    files = FAMILY_FILES
    if timing is not None:
        write_json_atomic(folder / FAMILY_TIMING, timing)
        files = FAMILY_FILES + (FAMILY_TIMING,)
    member_hashes = {m.name: _file_entry(m / MANIFEST)["sha256"] for m in members}
    _write_manifest(folder, "family", files, config_hash, {"members": member_hashes})
    return folder


# --- checking and reading --------------------------------------------------------------------

def _load_manifest(folder: Path, kind: str, required: tuple[str, ...]
                   ) -> tuple[dict | None, str | None]:
    path = folder / MANIFEST
    present = [n for n in required if (folder / n).exists()]
    if not path.is_file():
        if present:
            return None, (f"no {MANIFEST}: incomplete (killed or failed) or written by an older "
                          f"version; has {', '.join(present)}")
        return None, "empty folder"
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        return None, f"{MANIFEST} unreadable ({type(exc).__name__})"
    if not isinstance(manifest, dict) or manifest.get("kind") != kind \
            or not isinstance(manifest.get("files"), dict):
        return None, f"{MANIFEST} is not a {kind} manifest"
    return manifest, None


def check(folder: Path, kind: str = "run", expected_hash: str | None = None,
          members: bool = True, required: tuple[str, ...] | None = None) -> str | None:
    """Why ``folder`` cannot be trusted, or None when its manifest matches the disk.

    Parameters
    ----------
    kind : str
        ``run``, ``family``, or a study's kind (``multiverse``, ``tune``, ...).
    expected_hash : str, optional
        The config hash the folder must carry (resume).
    members : bool
        For a family, also compare each member's manifest with the hash recorded.
    required : tuple of str, optional
        The files the manifest must list (a study's result names its own); by default a run's
        or a family's.
    """
    folder = Path(folder)
    if not folder.is_dir():
        return "not a folder"
    required = tuple(required if required is not None else REQUIRED.get(kind, ()))
    manifest, reason = _load_manifest(folder, kind, required)
    if reason:
        return reason
    missing = [n for n in required if n not in manifest["files"]]
    if missing:
        return f"{MANIFEST} does not list {', '.join(missing)}"
    for name, entry in manifest["files"].items():
        path = folder / name
        if not path.is_file():
            return f"{name} is missing"
        actual = _file_entry(path)
        if actual["bytes"] != entry.get("bytes") or actual["sha256"] != entry.get("sha256"):
            return f"{name} differs from its manifest entry (changed or damaged after writing)"
    if expected_hash is not None and manifest.get("config_hash") != expected_hash:
        return (f"config hash {manifest.get('config_hash')} is not this configuration's "
                f"({expected_hash})")
    if kind == "family" and members:
        for name, digest in (manifest.get("members") or {}).items():
            member = folder / name / MANIFEST
            if not member.is_file() or _file_entry(member)["sha256"] != digest:
                return f"member {name} changed after the family was written"
    return None


def _read_json(path: Path) -> dict:
    data = json.loads(path.read_text(encoding="utf-8"))
    if not isinstance(data, dict):
        raise RunFolderError(f"{path}: not a JSON object")
    return data


def _settings(folder: Path, text: str) -> tuple[ExperimentConfig, dict]:
    """The typed settings of a ``config.yaml``; :class:`RunFolderError` when they cannot be
    read (never filled with defaults)."""
    import yaml

    try:
        # the C loader when PyYAML has it: the pure-Python one costs ~10 ms per config
        data = yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
        if not isinstance(data, dict):
            raise ValueError("not a mapping")
        return experiment_config_from_data(data), data
    except (ValueError, TypeError, yaml.YAMLError, ConfigError) as exc:
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise RunFolderError(f"{folder}: settings in config.yaml cannot be read ({message})"
                             ) from None


def read_metrics_json(folder: Path) -> dict:
    """``metrics.json`` of a folder already checked (resume of a complete run)."""
    return _read_json(Path(folder) / "metrics.json")


def read_run(folder: Path, trajectory: bool = True) -> RunRecord:
    """Read a trusted run folder; :class:`RunFolderError` (with the reason) otherwise.

    Parameters
    ----------
    trajectory : bool
        Also read ``trajectory.csv`` (False: ``RunRecord.trajectory`` is None).
    """
    folder = Path(folder)
    reason = check(folder, "run")
    if reason:
        raise RunFolderError(f"{folder}: {reason}")
    try:
        config, data = _settings(folder, (folder / "config.yaml").read_text())
        flat = _read_json(folder / "metrics.json")
        return RunRecord(folder=folder, config=config, config_data=data,
                         metrics=RunMetrics.from_json(flat), info=RunInfo.from_json(flat),
                         timing=_read_json(folder / "timing.json"),
                         model=_read_json(folder / "model.json"),
                         manifest=_read_json(folder / MANIFEST),
                         trajectory=pd.read_csv(folder / "trajectory.csv") if trajectory
                         else None)
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        if isinstance(exc, RunFolderError):
            raise
        raise RunFolderError(f"{folder}: unreadable ({type(exc).__name__}: "
                             f"{str(exc).splitlines()[0] if str(exc) else ''})") from None


def member_folders(folder: Path) -> list[Path]:
    """The member folders a family's manifest lists, in order."""
    manifest, reason = _load_manifest(Path(folder), "family", FAMILY_FILES)
    if reason:
        raise RunFolderError(f"{folder}: {reason}")
    return [Path(folder) / name for name in sorted(manifest.get("members") or {})]


def read_member(folder: Path, index: int) -> RunRecord:
    """Member ``index`` of a trusted family, checked against its manifest
    (:class:`RunFolderError` when it is missing or not trusted)."""
    wanted = f"member_{int(index):04d}"
    for member in member_folders(folder):
        if member.name == wanted:
            return read_run(member)
    raise RunFolderError(f"{folder}: no {wanted} in the family's manifest")


def member_trajectories(folder: Path):
    """Each member of a trusted family as ``(index, trajectory, metrics.json mapping)``, every
    member checked against its manifest first (:class:`RunFolderError` when one is not)."""
    for member in member_folders(folder):
        reason = check(member, "run")
        if reason:
            raise RunFolderError(f"{member}: {reason}")
        try:
            yield (int(member.name.split("_")[1]), pd.read_csv(member / "trajectory.csv"),
                   _read_json(member / "metrics.json"))
        except (OSError, ValueError, pd.errors.ParserError) as exc:
            raise RunFolderError(f"{member}: unreadable ({type(exc).__name__})") from None


def read_family(folder: Path, members: bool = True, settings: bool = True) -> FamilyRecord:
    """Read a trusted family folder; :class:`RunFolderError` (with the reason) otherwise.

    Parameters
    ----------
    members : bool
        Also check each member's manifest against the family's.
    settings : bool
        Read the settings the family was made with (its first member's ``config.yaml``); a
        family without readable settings is then an error. False: ``config`` is None, for a
        caller that judges the table with settings of its own and says so.
    """
    folder = Path(folder)
    reason = check(folder, "family", members=members)
    if reason:
        raise RunFolderError(f"{folder}: {reason}")
    try:
        config = data = None
        names = member_folders(folder)
        if settings and (not names or not (names[0] / "config.yaml").is_file()):
            raise RunFolderError(f"{folder}: settings cannot be read (no member config.yaml)")
        if settings:
            config, data = _settings(folder, (names[0] / "config.yaml").read_text())
        manifest = _read_json(folder / MANIFEST)
        timing = _read_json(folder / FAMILY_TIMING) \
            if FAMILY_TIMING in manifest.get("files", {}) else {}
        return FamilyRecord(folder=folder, info=_read_json(folder / "family.json"),
                            table=pd.read_csv(folder / "family_metrics.csv"),
                            manifest=manifest, config=config, config_data=data,
                            timing=timing)
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        if isinstance(exc, RunFolderError):
            raise
        raise RunFolderError(f"{folder}: unreadable ({type(exc).__name__})") from None


def discover(root: Path, exclude: tuple[str, ...] = ()) -> Discovery:
    """Every run and family folder under ``root``, trusted or skipped with its reason.

    Family members are part of their family, not separate runs. Folders whose path relative to
    ``root`` contains a part in ``exclude`` are not visited (other sections read them).
    """
    root = Path(root)
    found = Discovery()
    if not root.is_dir():
        found.skipped.append(Skipped(root, "no such folder"))
        return found
    for current, dirs, files in os.walk(root):
        here = Path(current)
        rel = here.relative_to(root).parts
        dirs[:] = sorted(d for d in dirs if d not in BOOKKEEPING and d not in exclude)
        names = set(files)
        if names & set(FAMILY_FILES):
            reason = check(here, "family")
            if reason:
                found.skipped.append(Skipped(here, reason))
            else:
                found.families.append(here)
            # members belong to the family: not listed as runs
            dirs[:] = [d for d in dirs if not d.startswith("member_")]
            continue
        if names & (set(RUN_FILES) | {MANIFEST}):
            reason = check(here, "run")
            if reason:
                found.skipped.append(Skipped(here, reason))
            else:
                found.runs.append(here)
            continue
        if any(part.startswith("member_") for part in rel):
            continue
    return found
