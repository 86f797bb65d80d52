"""A sweep's aggregated result (``python -m pipeline.aggregate``, and the sweep's
``on_multirun_end`` callback): one summary row per job, which keys were swept, the claims'
verdicts per swept value, and the jobs passed over.

The summary is a cache of its jobs: it carries a manifest tied to the job folders it was
computed from, and :meth:`SweepSummary.load` refuses it when a job changed, appeared or went,
or when the table was edited (aggregate again).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from pipeline.store.files import write_csv_atomic, write_json_atomic
from pipeline.store.manifest import check_derived_table, write_derived_table
from pipeline.studies.results.base import ResultError, read_json, written
from pipeline.studies.sweep_jobs import Job, find_jobs, job_sources

SUMMARY = "summary.csv"
SWEPT_KEYS = "swept_keys.json"
VERDICTS = "verdicts.csv"
SKIPPED = "skipped.csv"
#: Where the figures of metric versus parameter are drawn.
FIGURES = "figures"


def summary_reason(sweep_dir: Path) -> str | None:
    """Why the summary of ``sweep_dir`` cannot be trusted as it is, or None (its manifest
    matches the table and the jobs now in the folder)."""
    jobs, _ = find_jobs(Path(sweep_dir))
    return check_derived_table(Path(sweep_dir) / SUMMARY, job_sources(sweep_dir, jobs))


def is_sweep_folder(folder: Path) -> bool:
    """A multirun folder whose swept keys go beyond the method (a parameter sweep)."""
    import json

    path = Path(folder) / SWEPT_KEYS
    if not path.is_file():
        return False
    swept = set(json.loads(path.read_text())["swept_keys"])
    return bool(swept - {"method", "run.method", "planner"})


@dataclass(frozen=True)
class SweepSummary:
    """``summary``: one row per job (ok, skipped or stale) with its overrides and metrics;
    ``swept_keys``: the override keys whose values differ between jobs; ``verdicts``: per
    improved job and claim the outcome against its partner (None when nothing is swept but
    the method)."""

    summary: pd.DataFrame
    override_keys: tuple[str, ...]
    swept_keys: tuple[str, ...]
    verdicts: pd.DataFrame | None
    skipped: pd.DataFrame
    folder: Path | None = None

    @property
    def name(self) -> str:
        return self.folder.name if self.folder is not None else ""

    def write(self, folder: Path, jobs: list[Job]) -> SweepSummary:
        """Write the tables into the sweep ``folder``; the summary last, with its manifest
        tied to ``jobs`` (the job folders it was computed from)."""
        folder = Path(folder)
        write_csv_atomic(folder / SKIPPED, self.skipped)
        write_json_atomic(folder / SWEPT_KEYS, {"override_keys": list(self.override_keys),
                                                "swept_keys": list(self.swept_keys)})
        if self.verdicts is not None:
            write_csv_atomic(folder / VERDICTS, self.verdicts)
        else:  # an earlier aggregation's verdicts are not this one's
            (folder / VERDICTS).unlink(missing_ok=True)
        write_derived_table(folder / SUMMARY, self.summary, job_sources(folder, jobs))
        return SweepSummary(self.summary, self.override_keys, self.swept_keys, self.verdicts,
                            self.skipped, folder)

    @classmethod
    def load(cls, folder: Path) -> SweepSummary:
        """The summary of the sweep in ``folder``; :class:`ResultError` when it is missing or
        no longer matches its jobs (aggregate again: ``python -m pipeline.aggregate``)."""
        folder = Path(folder)
        reason = summary_reason(folder)
        if reason is not None:
            raise ResultError(f"{SUMMARY} {reason}: aggregate it again (python -m "
                              f"pipeline.aggregate {folder})")
        keys = read_json(folder / SWEPT_KEYS)
        try:
            summary = pd.read_csv(folder / SUMMARY)
            verdicts = pd.read_csv(folder / VERDICTS) if (folder / VERDICTS).is_file() \
                else None
            skipped = pd.read_csv(folder / SKIPPED) if (folder / SKIPPED).is_file() \
                else pd.DataFrame()
        except (OSError, ValueError) as exc:
            raise ResultError(f"sweep tables cannot be read ({exc})") from None
        return cls(summary, tuple(keys.get("override_keys", ())), tuple(keys["swept_keys"]),
                   verdicts, skipped, folder)

    def figures(self) -> list[dict[str, Path]]:
        """The figures the aggregation drew (``png``, ``svg``), in name order."""
        if self.folder is None:
            return []
        return [{"png": png, "svg": png.with_suffix(".svg")}
                for png in sorted((self.folder / FIGURES).glob("*.png"))]

    def figure_folder(self) -> Path:
        """Where the command draws the figures of metric versus parameter."""
        return written(self.folder) / FIGURES
