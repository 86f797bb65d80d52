"""The nonlinear-MPC check's result (``make nmpc-check``): per track, how far the linear
MPC's paths and inputs are from the nonlinear MPC's, and whether the claims' outcomes agree."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from pipeline.store.files import json_safe
from pipeline.studies.results.base import ResultError, trusted_summary, write_table_and_summary

TABLE = "agreement.csv"
SUMMARY = "summary.json"
FILES = (TABLE, SUMMARY)


@dataclass(frozen=True)
class NmpcCheckResult:
    """``tracks``: per track (``lateral``, ``kinematic``) its summary (``paper``, ``family``,
    ``verdicts``, solve times, path agreement); ``table``: every run pair."""

    tracks: dict[str, dict[str, Any]]
    table: pd.DataFrame | None = None
    folder: Path | None = None

    def track(self, name: str) -> dict[str, Any] | None:
        """One track's summary, or None when the check did not run it."""
        return self.tracks.get(name) or None

    def to_json(self) -> dict:
        return json_safe({"tracks": self.tracks})

    def write(self, folder: Path) -> NmpcCheckResult:
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        table = self.table if self.table is not None else pd.DataFrame()
        folder = write_table_and_summary(folder, "nmpc_check", table, TABLE, self.to_json(),
                                         SUMMARY)
        return NmpcCheckResult(self.tracks, self.table, folder)

    @staticmethod
    def present(folder: Path | None) -> bool:
        return folder is not None and (Path(folder) / SUMMARY).is_file()

    @classmethod
    def load(cls, folder: Path) -> NmpcCheckResult:
        """The result in ``folder``; :class:`ResultError` when it cannot be trusted."""
        data = trusted_summary(folder, "nmpc_check", FILES, SUMMARY, "nmpc check")
        if not isinstance(data, dict):
            raise ResultError(f"{SUMMARY} is not a mapping")
        if not isinstance(data.get("tracks"), dict):
            raise ResultError(f"{SUMMARY} holds no tracks")
        return cls(dict(data["tracks"]), None, Path(folder))
