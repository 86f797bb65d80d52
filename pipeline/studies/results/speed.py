"""The speed check's result (``make speed-check``): per variant and method the collision
counts, and the checks "slower is never less safe"."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from pipeline.store.files import json_safe, write_csv_atomic, write_json_atomic
from pipeline.store.manifest import check, untrust, write_manifest
from pipeline.studies.results.base import ResultError, read_json

TABLE = "speed.csv"
SUMMARY = "summary.json"
FILES = (TABLE, SUMMARY)


@dataclass(frozen=True)
class SpeedCheckResult:
    """``rows``: per variant and method the counts; ``checks``: per method, is each slower
    variant no less safe than the nominal speed."""

    n_members: int
    rows: tuple[dict[str, Any], ...]
    checks: tuple[dict[str, Any], ...]
    folder: Path | None = None

    @property
    def table(self) -> pd.DataFrame:
        return pd.DataFrame(list(self.rows))

    def to_json(self) -> dict:
        return json_safe({"n_members": self.n_members, "rows": list(self.rows),
                          "checks": list(self.checks)})

    def write(self, folder: Path) -> SpeedCheckResult:
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        untrust(folder)
        write_csv_atomic(folder / TABLE, self.table)
        write_json_atomic(folder / SUMMARY, self.to_json())
        write_manifest(folder, "speed", FILES, "")
        return SpeedCheckResult(self.n_members, self.rows, self.checks, folder)

    @staticmethod
    def present(folder: Path | None) -> bool:
        return folder is not None and (Path(folder) / SUMMARY).is_file()

    @classmethod
    def load(cls, folder: Path) -> SpeedCheckResult:
        """The result in ``folder``; :class:`ResultError` when it cannot be trusted."""
        reason = check(Path(folder), "speed", required=FILES)
        if reason:
            raise ResultError(f"speed check not trusted: {reason}")
        data = read_json(Path(folder) / SUMMARY)
        try:
            return cls(int(data["n_members"]), tuple(data["rows"]), tuple(data["checks"]),
                       Path(folder))
        except (KeyError, TypeError, ValueError) as exc:
            raise ResultError(f"{SUMMARY} is not a speed check's ({exc})") from None
