"""The Euro NCAP crossings' result (``make euro-ncap``): every test's protocol outcome per
track and method, their counts per case, and the claims ledger per track."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from pipeline.store.files import json_safe
from pipeline.studies.results.base import ResultError, trusted_summary, write_table_and_summary

TABLE = "euro_ncap.csv"
SUMMARY = "summary.json"
FILES = (TABLE, SUMMARY)


@dataclass(frozen=True)
class EuroNcapResult:
    """``rows``: one per test and method; ``by_case``: per track, method and case the tests
    avoided and the impact speeds; ``ledger``: per track and claim the outcome of improved
    against the baseline; ``settings``: the family's ``scenario.source.params``."""

    n_members: int
    rows: tuple[dict[str, Any], ...]
    by_case: tuple[dict[str, Any], ...]
    ledger: tuple[dict[str, Any], ...]
    settings: dict[str, Any]
    folder: Path | None = None

    @property
    def table(self) -> pd.DataFrame:
        return pd.DataFrame(list(self.rows))

    def to_json(self) -> dict:
        return json_safe({"n_members": self.n_members, "by_case": list(self.by_case),
                          "ledger": list(self.ledger), "settings": self.settings})

    def write(self, folder: Path) -> EuroNcapResult:
        folder = write_table_and_summary(folder, "euro_ncap", self.table, TABLE,
                                         self.to_json(), SUMMARY)
        return EuroNcapResult(self.n_members, self.rows, self.by_case, self.ledger,
                              self.settings, folder)

    @staticmethod
    def present(folder: Path | None) -> bool:
        return folder is not None and (Path(folder) / SUMMARY).is_file()

    @classmethod
    def load(cls, folder: Path) -> EuroNcapResult:
        """The result in ``folder``; :class:`ResultError` when it cannot be trusted."""
        data = trusted_summary(folder, "euro_ncap", FILES, SUMMARY, "Euro NCAP study")
        try:
            table = pd.read_csv(Path(folder) / TABLE)
            return cls(int(data["n_members"]), tuple(table.to_dict("records")),
                       tuple(data["by_case"]), tuple(data["ledger"]), dict(data["settings"]),
                       Path(folder))
        except (KeyError, TypeError, ValueError, OSError) as exc:
            raise ResultError(f"{folder}: not a Euro NCAP study's result ({exc})") from None

    def summary_rows(self, track: str, case: str = "all") -> list[dict[str, Any]]:
        """The per-method rows of ``by_case`` for ``track`` and ``case``."""
        return [r for r in self.by_case if r["track"] == track and r["case"] == case]

    def comparisons(self, track: str) -> tuple[str, ...]:
        """The methods improved is judged against on ``track`` (the ledger's order)."""
        return tuple(dict.fromkeys(r["comparison"] for r in self.ledger if r["track"] == track))

    @property
    def tracks(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(r["track"] for r in self.by_case))

    @property
    def cases(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(r["case"] for r in self.by_case if r["case"] != "all"))
