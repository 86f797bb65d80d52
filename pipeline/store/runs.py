"""Run records: the one owner of a run folder's layout (its only writer, reader and finder).

A *run folder* holds ``config.yaml`` (resolved config), ``model.json``, ``trajectory.csv``,
``timing.json`` (wall-clock solve times, which differ between identical runs), ``metrics.json``
and, written last and atomically, ``manifest.json``: every file with its size and SHA-256, the
config hash and the code version. A *family folder* holds ``family_metrics.csv``, ``family.json``
and its own manifest, which also lists each member folder's manifest hash; a family whose
members keep no run folder (a tune's training families) holds their ``metrics.json`` mappings
in ``members.jsonl`` instead (:data:`MEMBER_ROWS`). A folder is trusted
only when its manifest matches what is on disk; resume, aggregate, report and verify all go
through :func:`check` and :func:`discover`, and every folder they pass over is listed with its
reason (:class:`Skipped`).

Every file is written to a hidden temporary name and renamed, so a killed write never leaves a
half-written file; the temporaries a killed process leaves behind are removed by the next write
into that folder (:func:`clean_leftovers`). The files themselves are :mod:`pipeline.store.files`'s,
the manifests and :func:`check` :mod:`pipeline.store.manifest`'s, the folder's lock
:mod:`pipeline.store.lock`'s.
"""

from __future__ import annotations

import json
import os
import zipfile
from collections.abc import Collection
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.analysis.metrics.results import RunMetrics
from pipeline.config import ExperimentConfig, experiment_config_from_data
from pipeline.errors import ConfigError, NonFiniteResultError, RunFolderError
from pipeline.loop.trajectory import TrajectoryTable
from pipeline.store.files import (
    clean_leftovers,
    csv_text,
    npz_bytes,
    write_bytes_atomic,
    write_csv_atomic,
    write_json_atomic,
    write_text_atomic,
)
from pipeline.store.manifest import (
    FAMILY_FILES,
    HORIZON_FILE,
    MANIFEST,
    RUN_FILES,
    check,
    file_entry,
    load_manifest,
    write_manifest,
)

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
    """Serialize a record file, refusing NaN and infinities with the key that holds one (the
    key searched for only when the encoder refused one: the search walked every value of a
    run's records each time, a tenth of writing a family member's folder)."""
    try:
        return json.dumps(data, indent=2, sort_keys=True, allow_nan=False) + "\n"
    except ValueError:
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
    def from_json(cls, data: dict) -> RunInfo:
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

    @property
    def settings(self) -> ExperimentConfig:
        """The settings the family was made with (a family read with its settings has them;
        one read with ``settings=False`` raises :class:`RunFolderError`)."""
        if self.config is None:
            raise RunFolderError(f"{self.folder}: read without its settings")
        return self.config


@dataclass
class Discovery:
    """What :func:`discover` found under a root."""

    runs: list[Path] = field(default_factory=list)
    families: list[Path] = field(default_factory=list)
    skipped: list[Skipped] = field(default_factory=list)


def folder_kind(folder: Path) -> str | None:
    """``"family"``, ``"run"`` or None: what kind of record a folder holds, by its files."""
    folder = Path(folder)
    if any((folder / name).is_file() for name in FAMILY_FILES):
        return "family"
    if any((folder / name).is_file() for name in RUN_FILES + (MANIFEST,)):
        return "run"
    return None


def write_run(folder: Path, *, config_text: str, model: dict,
              trajectory: pd.DataFrame | TrajectoryTable,
              timing: dict, metrics: RunMetrics, info: RunInfo,
              horizon: dict | None = None) -> Path:
    """Write a complete run folder: the files, then the manifest (last, atomically).

    An existing manifest is removed first, so a folder being rewritten is never trusted
    half-way; leftover temporaries of a killed write are removed. ``horizon`` (what each step
    planned, :mod:`pipeline.loop.horizon`) becomes ``horizon.npz`` when given.
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
    files: tuple[str, ...] = RUN_FILES
    if horizon:
        write_bytes_atomic(folder / HORIZON_FILE, npz_bytes(horizon))
        files = RUN_FILES + (HORIZON_FILE,)
    else:
        (folder / HORIZON_FILE).unlink(missing_ok=True)
    write_manifest(folder, "run", files, info.config_hash)
    return folder


def read_horizon(folder: Path) -> dict[str, np.ndarray] | None:
    """What each step of a run planned (``horizon.npz``: :data:`pipeline.loop.horizon.
    HORIZON_ARRAYS`), or None when the run has none (written before it was recorded) or it
    is not the file its manifest lists."""
    folder = Path(folder)
    path = folder / HORIZON_FILE
    try:
        entry = _read_json(folder / MANIFEST).get("files", {}).get(HORIZON_FILE)
        if not entry or file_entry(path) != entry:
            return None
        with np.load(path, allow_pickle=False) as data:
            return {name: data[name].astype(float) for name in data.files}
    except (OSError, ValueError, RunFolderError, zipfile.BadZipFile):
        return None


#: What depends on the process that wrote a family (compilations), apart from its results, so
#: that identical work gives identical ``family.json`` and ``family_metrics.csv`` bytes, resumed
#: or not. Listed in the manifest when present (older families have none).
FAMILY_TIMING = "timing.json"


def family_timing(folder: Path) -> dict:
    """A family folder's process bookkeeping (its ``timing.json``: compilations, where its
    members came from), or {} when it has none or it cannot be read."""
    try:
        data = json.loads((Path(folder) / FAMILY_TIMING).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


#: The ``metrics.json`` mappings of a family's members that keep no run folder of their own
#: (a tune's training members, :attr:`~pipeline.studies.tune.space.TuneSpace.
#: training_member_records`): one JSON object per line, ``member`` (the index) first, in member
#: order. Listed in the family's manifest when present; JSON keeps every float exactly, so a
#: later rung or a resumed tune takes a member's row as it took a member's ``metrics.json``.
MEMBER_ROWS = "members.jsonl"


def write_family(folder: Path, table: pd.DataFrame, info: dict, config_hash: str,
                 members: list[Path], timing: dict | None = None,
                 member_rows: list[dict] | None = None) -> Path:
    """Write a family folder's table, summary and (optional) process bookkeeping, then its
    manifest (with the members' manifest hashes). ``member_rows`` (members without run
    folders): each member's ``metrics.json`` mapping with its ``member`` index, written as
    :data:`MEMBER_ROWS`."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    clean_leftovers(folder)
    (folder / MANIFEST).unlink(missing_ok=True)
    write_csv_atomic(folder / "family_metrics.csv", table)
    write_json_atomic(folder / "family.json", info)
    files: tuple[str, ...] = FAMILY_FILES
    if timing is not None:
        write_json_atomic(folder / FAMILY_TIMING, timing)
        files = files + (FAMILY_TIMING,)
    if member_rows is not None:
        write_text_atomic(folder / MEMBER_ROWS, "".join(
            _json_line(MEMBER_ROWS, row) for row in member_rows))
        files = files + (MEMBER_ROWS,)
    else:
        (folder / MEMBER_ROWS).unlink(missing_ok=True)
    member_hashes = {m.name: file_entry(m / MANIFEST)["sha256"] for m in members}
    write_manifest(folder, "family", files, config_hash, {"members": member_hashes})
    return folder


def _json_line(name: str, data: dict) -> str:
    """One line of a JSON-lines record, NaN and infinities refused with the key that holds
    one (as :func:`_json_text`)."""
    key = _non_finite_key(data)
    if key is not None:
        raise NonFiniteResultError(
            f"error: the run produced a non-finite value in {name} at {key} (stage: metrics); "
            "no family record was written")
    return json.dumps(data, allow_nan=False) + "\n"


def read_member_rows(folder: Path, config_hash: str | None = None) -> dict[int, dict]:
    """The rows of :data:`MEMBER_ROWS` of a trusted family folder (of ``config_hash`` when
    given, else whatever its config hash: a later rung of a tune's trial reads the earlier
    rung's), by member index, each a member's ``metrics.json`` mapping; {} when the folder is
    not such a family or keeps no such rows (its members have run folders, or it was written
    before)."""
    folder = Path(folder)
    if check(folder, "family", config_hash, members=False) is not None:
        return {}
    try:
        if MEMBER_ROWS not in _read_json(folder / MANIFEST).get("files", {}):
            return {}
        rows = {}
        for line in (folder / MEMBER_ROWS).read_text(encoding="utf-8").splitlines():
            row = json.loads(line)
            if not isinstance(row, dict) or not isinstance(row.get("member"), int):
                return {}
            rows[row.pop("member")] = row
        return rows
    except (OSError, ValueError, RunFolderError):
        return {}


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


def read_run_trajectory(folder: Path) -> tuple[pd.DataFrame, dict]:
    """A trusted run's trajectory and ``metrics.json`` mapping, without its settings (a
    reader of many members of one family reads the settings once); :class:`RunFolderError`
    when the folder is not trusted or cannot be read."""
    folder = Path(folder)
    reason = check(folder, "run")
    if reason:
        raise RunFolderError(f"{folder}: {reason}")
    try:
        return pd.read_csv(folder / "trajectory.csv"), _read_json(folder / "metrics.json")
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        raise RunFolderError(f"{folder}: unreadable ({type(exc).__name__})") from None


def member_folders(folder: Path) -> list[Path]:
    """The member folders a family's manifest lists, in order."""
    manifest, reason = load_manifest(Path(folder), "family", FAMILY_FILES)
    if manifest is None:
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


def member_solve_times(folder: Path) -> tuple[float, float] | None:
    """The controller's solve time per step over a trusted family's members, pooled: its
    median and 95th percentile in seconds (each member's ``timing.json``; wall time, so it
    depends on the machine). None when no member recorded one."""
    times: list[float] = []
    for member in member_folders(folder):
        try:
            times += [float(t) for t in _read_json(member / "timing.json").get("solve_times_s")
                      or ()]
        except (OSError, ValueError, TypeError):
            continue
    if not times:
        return None
    return float(np.median(times)), float(np.percentile(times, 95))


def member_trajectories(folder: Path, columns: Collection[str] | None = None):
    """Each member of a trusted family as ``(index, trajectory, metrics.json mapping)``, every
    member checked against its manifest first (:class:`RunFolderError` when one is not);
    ``columns``: only those of the trajectory's columns (those it has), the others not parsed
    (a reader of a few columns of a thousand members: about half the time)."""
    usecols = None if columns is None else frozenset(columns).__contains__
    for member in member_folders(folder):
        reason = check(member, "run")
        if reason:
            raise RunFolderError(f"{member}: {reason}")
        try:
            yield (int(member.name.split("_")[1]),
                   pd.read_csv(member / "trajectory.csv", usecols=usecols),
                   _read_json(member / "metrics.json"))
        except (OSError, ValueError, pd.errors.ParserError) as exc:
            raise RunFolderError(f"{member}: unreadable ({type(exc).__name__})") from None


def member_settings(folder: Path, index: int) -> ExperimentConfig:
    """The settings member ``index`` of a family was run with (its ``config.yaml``; a member
    of a family whose members differ beyond their obstacles, e.g. crossings among walkers,
    has its own start and goal). Not checked against the manifest here: read it after
    :func:`member_trajectories` has checked the member. :class:`RunFolderError` when the
    settings cannot be read."""
    member = Path(folder) / f"member_{int(index):04d}"
    try:
        text = (member / "config.yaml").read_text()
    except OSError as exc:
        raise RunFolderError(f"{member}: unreadable ({type(exc).__name__})") from None
    return _settings(member, text)[0]


def run_scenario_data(folder: Path) -> dict:
    """The ``scenario`` section of a run's ``config.yaml`` as written (a mapping, not the
    typed settings: a reader of many members of one family, which differ in their scenario
    alone, types the family's settings once and reads each member's scenario here). Not
    checked against the manifest here: read it after the run's check. :class:`RunFolderError`
    when it cannot be read."""
    import yaml

    path = Path(folder) / "config.yaml"
    try:
        data = yaml.load(path.read_text(encoding="utf-8"),
                         Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    except (OSError, ValueError, yaml.YAMLError) as exc:
        raise RunFolderError(f"{folder}: settings in config.yaml cannot be read "
                             f"({type(exc).__name__})") from None
    scenario = data.get("scenario") if isinstance(data, dict) else None
    if not isinstance(scenario, dict):
        raise RunFolderError(f"{folder}: settings in config.yaml cannot be read (no scenario)")
    return scenario


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


def method_names(root: Path) -> set[str]:
    """The method names the run and family folders under ``root`` were made with (their
    ``family.json`` and ``metrics.json``; names only: nothing is trusted or judged here, and
    member folders are not visited)."""
    names: set[str] = set()
    for current, dirs, files in os.walk(root):
        dirs[:] = [d for d in dirs if not d.startswith(("member_", "."))]
        for name in ("family.json", "metrics.json"):
            if name in files:
                try:
                    method = json.loads((Path(current) / name).read_text("utf-8")).get("method")
                except (OSError, ValueError, AttributeError):
                    continue
                if isinstance(method, str) and method:
                    names.add(method)
    return names
