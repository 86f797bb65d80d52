"""Manifests: which files a record folder of each kind holds, ``manifest.json`` (every file with
its size and SHA-256, the config hash and the code version) written last, :func:`check` of a
folder against it, and the sidecar manifest of a derived table."""

from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path

import pandas as pd

from pipeline.store.files import write_csv_atomic, write_json_atomic

RUN_FILES = ("config.yaml", "model.json", "trajectory.csv", "timing.json", "metrics.json")
#: What each step planned (the APF path, the MPC's horizon and half-planes), for the report's
#: scenario explorer: listed in a run's manifest when present (older runs have none).
HORIZON_FILE = "horizon.npz"
FAMILY_FILES = ("family_metrics.csv", "family.json")
#: The files a run's and a family's manifest must list (a study's result names its own and
#: passes them to :func:`check`).
REQUIRED = {"run": RUN_FILES, "family": FAMILY_FILES}
MANIFEST = "manifest.json"
SCHEMA = 1


def write_derived_table(path: Path, frame: pd.DataFrame, sources: dict[str, Path]) -> None:
    """Write a table computed from other records (e.g. a family re-scored under other metric
    settings) with a sidecar ``<name>.manifest.json``: the table's hash and the manifest
    hashes of the ``sources`` it was computed from (name -> record folder)."""
    path = Path(path)
    write_csv_atomic(path, frame)
    write_json_atomic(path.with_name(path.name + ".manifest.json"), {
        "schema": SCHEMA, "kind": "derived", "code_version": code_version(),
        "table": file_entry(path),
        "sources": {name: file_entry(Path(folder) / MANIFEST)["sha256"]
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
        entry = file_entry(path)
        if manifest["table"]["sha256"] != entry["sha256"]:
            return "the table differs from its manifest (changed after writing)"
        if set(manifest["sources"]) != set(sources):
            return "its sources are not the ones it was computed from (added or removed since)"
        for name, folder in sources.items():
            if manifest["sources"].get(name) != file_entry(Path(folder) / MANIFEST)["sha256"]:
                return f"its source {name} changed since"
    except (OSError, ValueError, KeyError, TypeError):
        return "its manifest is unreadable"
    return None


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


def file_entry(path: Path) -> dict:
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
                "files": {name: file_entry(folder / name) for name in files}, **(extra or {})}
    write_json_atomic(folder / MANIFEST, manifest)
    return manifest


def untrust(folder: Path) -> None:
    """Remove a folder's manifest: its files are being rewritten and must not be trusted until
    a new manifest is written last."""
    (Path(folder) / MANIFEST).unlink(missing_ok=True)


def refuse_other_record(folder: Path, kinds: tuple[str, ...], option: str = "--out") -> None:
    """Raise :class:`~pipeline.errors.ConfigError` (one line naming ``option``) when ``folder``
    holds the record of another kind than ``kinds`` (its ``manifest.json`` says so): a study
    written there would replace that record's ``manifest.json`` and ``summary.json`` (an
    nmpc_check into a tune's folder did). A folder without a readable manifest is left to the
    writer's own checks."""
    from pipeline.errors import ConfigError

    try:
        found = json.loads((Path(folder) / MANIFEST).read_text(encoding="utf-8")).get("kind")
    except (OSError, UnicodeDecodeError, ValueError, AttributeError):
        return
    if isinstance(found, str) and found not in kinds:
        raise ConfigError(option, str(folder), f"a new folder or one a {kinds[0]} wrote (this "
                          f"one holds a {found} record, whose files would be replaced)")


def load_manifest(folder: Path, kind: str, required: tuple[str, ...]
                  ) -> tuple[dict | None, str | None]:
    """``manifest.json`` of ``folder`` if it is a ``kind`` manifest, else the reason (a folder
    holding some of the ``required`` files without one was killed or is older)."""
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
    manifest, reason = load_manifest(folder, kind, required)
    if manifest is None:
        return reason
    missing = [n for n in required if n not in manifest["files"]]
    if missing:
        return f"{MANIFEST} does not list {', '.join(missing)}"
    for name, entry in manifest["files"].items():
        path = folder / name
        if not path.is_file():
            return f"{name} is missing"
        actual = file_entry(path)
        if actual["bytes"] != entry.get("bytes") or actual["sha256"] != entry.get("sha256"):
            return f"{name} differs from its manifest entry (changed or damaged after writing)"
    if expected_hash is not None and manifest.get("config_hash") != expected_hash:
        return (f"config hash {manifest.get('config_hash')} is not this configuration's "
                f"({expected_hash})")
    if kind == "family" and members:
        for name, digest in (manifest.get("members") or {}).items():
            member = folder / name / MANIFEST
            if not member.is_file() or file_entry(member)["sha256"] != digest:
                return f"member {name} changed after the family was written"
    return None
