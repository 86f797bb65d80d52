"""What every study result shares: the error a reader raises, and reading a trusted folder."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pandas as pd

from pipeline.errors import StudyError
from pipeline.store.files import write_csv_atomic, write_json_atomic
from pipeline.store.manifest import check, untrust, write_manifest


class ResultError(StudyError, ValueError):
    """A study's folder cannot be read as its result (missing, incomplete, not trusted, or
    broken); the message says why in one line."""


def written(folder: Path | None) -> Path:
    """The folder a result was written to or read from (an unwritten one has none)."""
    if folder is None:
        raise ResultError("the result was not written yet")
    return folder


def write_table_and_summary(folder: Path, kind: str, table: pd.DataFrame, table_name: str,
                            summary: dict[str, Any], summary_name: str) -> Path:
    """A study's table and summary written into ``folder`` (untrusted while they are), then
    its manifest (last)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    untrust(folder)
    write_csv_atomic(folder / table_name, table)
    write_json_atomic(folder / summary_name, summary)
    write_manifest(folder, kind, (table_name, summary_name), "")
    return folder


def trusted_summary(folder: Path, kind: str, files: tuple[str, ...], summary_name: str,
                    what: str) -> Any:
    """The summary of a study's ``folder`` after its manifest check; :class:`ResultError`
    naming ``what`` when the folder cannot be trusted."""
    reason = check(Path(folder), kind, required=files)
    if reason:
        raise ResultError(f"{what} not trusted: {reason}")
    return read_json(Path(folder) / summary_name)


def figure_files(folder: Path, stem: str) -> dict[str, Path] | None:
    """``{"png": ..., "svg": ...}`` of a figure a study's command drew into ``folder`` (the
    SVG may be absent), or None when there is no PNG."""
    png = Path(folder) / f"{stem}.png"
    if not png.is_file():
        return None
    return {"png": png, "svg": png.with_suffix(".svg")}


def read_json(path: Path) -> Any:
    """A JSON file's content; a broken or missing one raises :class:`ResultError`."""
    try:
        return json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ResultError(f"{Path(path).name} is missing") from None
    except (OSError, ValueError) as exc:
        raise ResultError(f"{Path(path).name} cannot be read ({type(exc).__name__}: "
                          f"{str(exc).splitlines()[0] if str(exc) else ''})") from None
