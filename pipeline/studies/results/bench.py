"""The benchmark's result (``make bench``): every measured row and the summary of ratios to
the solver's floor (the keys the checks read are the summary's)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from pipeline.studies.results.base import (
    ResultError,
    figure_files,
    trusted_summary,
    write_table_and_summary,
)

TABLE = "bench.csv"
SUMMARY = "bench_summary.json"
FILES = (TABLE, SUMMARY)
#: The command's figure: the controller step against the horizon.
SCALING_STEM = "scaling"


@dataclass(frozen=True)
class BenchResult:
    """``summary``: the benchmark's figures by key (``closed_loop_over_floor``,
    ``step_over_sparse_floor``, ``lateral``, ``peers``, ``pipeline``, ``kinematic``, ...);
    ``table``: every measured row; ``lateral``: the lateral controller's rows (the scaling
    figure's data)."""

    summary: Mapping[str, Any]
    table: pd.DataFrame
    lateral: pd.DataFrame | None = None
    folder: Path | None = None

    def __getitem__(self, key: str) -> Any:
        return self.summary[key]

    def get(self, key: str, default: Any = None) -> Any:
        return self.summary.get(key, default)

    def write(self, folder: Path) -> BenchResult:
        folder = write_table_and_summary(folder, "bench", self.table, TABLE, dict(self.summary),
                                         SUMMARY)
        return BenchResult(self.summary, self.table, self.lateral, folder)

    @staticmethod
    def present(folder: Path | None) -> bool:
        return folder is not None and (Path(folder) / SUMMARY).is_file()

    @classmethod
    def load(cls, folder: Path) -> BenchResult:
        """The result in ``folder``; :class:`ResultError` when it cannot be trusted."""
        folder = Path(folder)
        summary = trusted_summary(folder, "bench", FILES, SUMMARY, "benchmark")
        if not isinstance(summary, dict):
            raise ResultError(f"{SUMMARY} is not a mapping")
        try:
            table = pd.read_csv(folder / TABLE)
        except (OSError, ValueError) as exc:
            raise ResultError(f"{TABLE} cannot be read ({exc})") from None
        return cls(summary, table, None, folder)

    def scaling_figure(self) -> dict[str, Path] | None:
        """The command's scaling figure, if it is there."""
        return None if self.folder is None else figure_files(self.folder, SCALING_STEM)
