"""The speed check's result (``make speed-check``): per variant and method the collision
counts, and the checks "slower is never less safe"."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from pipeline.store.files import json_safe
from pipeline.studies.results.base import ResultError, trusted_summary, write_table_and_summary

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
        folder = write_table_and_summary(folder, "speed", self.table, TABLE, self.to_json(),
                                         SUMMARY)
        return SpeedCheckResult(self.n_members, self.rows, self.checks, folder)

    @staticmethod
    def present(folder: Path | None) -> bool:
        return folder is not None and (Path(folder) / SUMMARY).is_file()

    @classmethod
    def load(cls, folder: Path) -> SpeedCheckResult:
        """The result in ``folder``; :class:`ResultError` when it cannot be trusted."""
        data = trusted_summary(folder, "speed", FILES, SUMMARY, "speed check")
        try:
            return cls(int(data["n_members"]), tuple(data["rows"]), tuple(data["checks"]),
                       Path(folder))
        except (KeyError, TypeError, ValueError) as exc:
            raise ResultError(f"{SUMMARY} is not a speed check's ({exc})") from None
