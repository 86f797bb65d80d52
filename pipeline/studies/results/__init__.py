"""What each study leaves behind, typed: one result per study with ``write(folder)`` and
``load(folder)`` beside it, through the store's atomic writes and manifests.

A study computes and returns its result; its command writes it and draws its figures; the
report loads it (:class:`ResultError` with the reason when the folder cannot be trusted) and
never runs a study. Each module here is the only place that names its study's files.
"""

from pipeline.studies.results.base import ResultError
from pipeline.studies.results.bench import BenchResult
from pipeline.studies.results.multiverse import MultiverseInfo, MultiverseResult
from pipeline.studies.results.nmpc_check import NmpcCheckResult
from pipeline.studies.results.speed import SpeedCheckResult
from pipeline.studies.results.sweep import SweepSummary
from pipeline.studies.results.tune import TuneResult

__all__ = ["BenchResult", "MultiverseInfo", "MultiverseResult", "NmpcCheckResult",
           "ResultError", "SpeedCheckResult", "SweepSummary", "TuneResult"]
