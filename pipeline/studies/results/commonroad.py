"""A CommonRoad run's own result beside its run folder: both collision verdicts, the road and
the goal by CommonRoad's definition (``commonroad.json``), and the ego's trajectory as a
CommonRoad solution (``solution.xml``, commonroad-io's writer)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.store.files import json_safe, write_json_atomic
from pipeline.studies.results.base import ResultError, read_json

SUMMARY = "commonroad.json"
SOLUTION = "solution.xml"
FILES = (SUMMARY, SOLUTION)


@dataclass(frozen=True)
class CommonRoadResult:
    """``summary``: the file (path, SHA-256, benchmark id, planning problem, obstacles kept and
    dropped), the run (method, termination, our goal verdict) and the verdicts
    (:class:`~pipeline.analysis.commonroad_check.CommonRoadVerdicts`)."""

    summary: dict[str, Any]
    folder: Path | None = None

    def write(self, folder: Path, write_solution: Callable[[Path], Any]) -> CommonRoadResult:
        """``commonroad.json`` and, through ``write_solution(path)``, ``solution.xml`` into
        ``folder`` (the run's own folder)."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        write_solution(folder / SOLUTION)
        write_json_atomic(folder / SUMMARY, json_safe(self.summary))
        return CommonRoadResult(self.summary, folder)

    @staticmethod
    def present(folder: Path | None) -> bool:
        return folder is not None and (Path(folder) / SUMMARY).is_file()

    @staticmethod
    def solution_path(folder: Path) -> Path:
        return Path(folder) / SOLUTION

    @classmethod
    def load(cls, folder: Path) -> CommonRoadResult:
        """The result in ``folder``; :class:`ResultError` when it cannot be read."""
        data = read_json(Path(folder) / SUMMARY)
        if not isinstance(data, dict) or not isinstance(data.get("verdicts"), dict):
            raise ResultError(f"{SUMMARY} holds no verdicts")
        return cls(data, Path(folder))

    @classmethod
    def load_all(cls, root: Path) -> list[CommonRoadResult]:
        """Every readable result under ``root`` (``<scenario>/<method>/``), sorted by folder."""
        found = []
        for path in sorted(Path(root).glob(f"*/*/{SUMMARY}")):
            try:
                found.append(cls.load(path.parent))
            except ResultError:
                continue
        return found
