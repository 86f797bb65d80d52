"""The fair fight's result (``make tune``): every trial, the held-out judgement, the two
ledgers, which settings make each claim hold, and the summary (budget, spaces, picks, per
claim the default beside the tuned verdict)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import pandas as pd

from pipeline.store.files import json_safe, write_csv_atomic, write_json_atomic
from pipeline.store.manifest import check, untrust, write_manifest
from pipeline.studies.results.base import ResultError, figure_files, read_json, written

TRIALS = "trials.csv"
HELDOUT = "heldout.csv"
LEDGER_DEFAULT = "ledger_default.csv"
LEDGER_TUNED = "ledger_tuned.csv"
SETTINGS_OUTCOMES = "settings_outcomes.csv"
SUMMARY = "summary.json"
#: The folder's files, in the manifest's order.
FILES = (TRIALS, HELDOUT, LEDGER_DEFAULT, LEDGER_TUNED, SETTINGS_OUTCOMES, SUMMARY)
#: Where the command draws the Pareto fronts: ``figures/pareto_fronts_<part>``.
FIGURES = "figures"
PARTS = ("training", "heldout")


@dataclass(frozen=True)
class TunedClaim:
    """One claim against the control on held-out scenarios: the verdict with our settings
    (replicate 0's held-out family), the tuned outcome in every replicate (each on its own
    held-out family) and their count, settled or not by the binomial test, against the
    matched control, the replicates' settings under which it holds."""

    claim: str
    text: str
    metric: str
    default: str
    default_estimate: float | None
    tuned_outcomes: tuple[str, ...]
    tuned_estimates: tuple[float | None, ...]
    tuned_cis: tuple[tuple[float | None, float | None], ...]
    counts: str
    settled: bool
    tuned: str
    answer: str
    tuned_vs_matched: tuple[str, ...]
    holds_with_trials: tuple[tuple[int, int], ...]
    sentence: str
    #: the most frequent outcome among the judged replicates, its count, their number and the
    #: one-sided exact binomial test's p-value that settles it or not ("", None: a summary
    #: written before the test, settled by the earlier share rule)
    leading: str = ""
    leading_count: int | None = None
    judged_replicates: int | None = None
    p_value: float | None = None

    @classmethod
    def from_json(cls, data: dict) -> TunedClaim:
        return cls(**{**data, "tuned_outcomes": tuple(data["tuned_outcomes"]),
                      "tuned_estimates": tuple(data["tuned_estimates"]),
                      "tuned_cis": tuple(tuple(c) for c in data["tuned_cis"]),
                      "tuned_vs_matched": tuple(data.get("tuned_vs_matched", ())),
                      "holds_with_trials": tuple(tuple(t) for t in
                                                 data.get("holds_with_trials", ()))})

    def to_json(self) -> dict:
        return json_safe({f.name: getattr(self, f.name) for f in fields(self)})


@dataclass(frozen=True)
class TuneSummary:
    """``summary.json`` (its keys are these fields)."""

    name: str
    settings: dict[str, Any]
    budget: dict[str, Any]
    families: dict[str, dict[str, Any]]
    backend: str
    objectives: tuple[str, ...]
    safety_threshold_collisions: dict[str, int]
    search_spaces: dict[str, dict[str, str]]
    compromise_rule: str
    answer_rule: str
    compromise: dict[str, dict[str, Any]]
    replicates: tuple[dict[str, Any], ...]
    parity: tuple[dict[str, Any], ...]
    below_default_budget: tuple[str, ...]
    unconverged: tuple[str, ...]
    headline: bool
    dominance: dict[str, dict[str, int]]
    claims: tuple[TunedClaim, ...]
    #: how a trial is stopped early on a share of its training family ("" before pruning)
    pruning_rule: str = ""
    #: where this run's members came from: simulated, reused from the member cache, resumed
    members: dict[str, int] = field(default_factory=dict)
    #: CPU-seconds over (wall-clock seconds x cores) of the tuning's own process and its
    #: workers (None before it was measured)
    core_utilisation: float | None = None
    #: the tuning process's own CPU milliseconds per trial told while its studies ran (asks,
    #: tells, compositions, rung tables, records; the members run on the workers), None where
    #: the members ran in it too (one worker) or before it was measured
    coordinator_ms_per_trial: float | None = None
    #: wall-clock seconds of the tuning's last run (a resumed tune: its own run only) and the
    #: cores it had (None before they were recorded)
    wall_s: float | None = None
    cores: int | None = None
    #: the run overrides every family of both methods was composed with (none of them sets
    #: what the tune controls: pipeline.studies.overrides); empty for a tune without any
    overrides: tuple[str, ...] = ()
    #: the key of the trial store the trials came from (space, budget, families, code)
    store_key: str = ""
    #: per replicate (its number as text), the methods without a feasible setting in it: that
    #: replicate was not judged and counts as "no feasible setting of ..." per claim
    without_feasible_setting: dict[str, list[str]] = field(default_factory=dict)
    #: how the replicates' outcomes settle a claim (``tune.settled_test``: "binomial") and the
    #: alpha it was read at (the claims' ``alpha``); "" and None: a summary written before the
    #: test, whose claims were settled by the earlier share rule (``tune.settled_share``)
    settle_test: str = ""
    settle_alpha: float | None = None
    #: the fewest judged replicates that can settle a claim at that alpha (n of n alike)
    fewest_replicates_to_settle: int | None = None

    @property
    def methods(self) -> list[str]:
        """``[treatment, control]``."""
        return list(self.settings["methods"])

    @property
    def trials_by_method(self) -> dict[str, list[int]]:
        """Complete trials per method, one number per replicate."""
        return {p["method"]: list(p["trials"]) for p in self.parity}

    @property
    def can_settle(self) -> bool:
        """Whether this tuning's replicates are enough to settle a claim at its alpha (a
        summary written before the binomial test: False)."""
        return (self.fewest_replicates_to_settle is not None
                and int(self.budget["replicates"]) >= self.fewest_replicates_to_settle)

    @property
    def settle_note(self) -> str:
        """One sentence when no claim can be settled with this many replicates ("" when one
        can; shown, never refused)."""
        if not self.settle_test or self.can_settle:
            return ""
        n, alpha = int(self.budget["replicates"]), self.settle_alpha
        return (f"With {n} replicates no claim can be settled: even {n} of {n} alike gives a "
                f"one-sided binomial p = {0.5 ** n:.3g} > alpha {alpha:g}; at least "
                f"{self.fewest_replicates_to_settle} are needed.")

    @property
    def writes_headline(self) -> bool:
        """Whether this tuning may write the opening summary: :attr:`headline`, and its claims
        settled by the binomial test (not by the earlier share rule)."""
        return self.headline and bool(self.settle_test)

    @property
    def label(self) -> str:
        """Why this tuning may not write the headline ("" when it may)."""
        reasons = []
        if not self.settle_test:
            reasons.append("its claims settled by the earlier share rule (tune.settled_share), "
                           "not by the binomial test (tune.settled_test)")
        if self.below_default_budget:
            reasons.append("below the default budget (" + ", ".join(self.below_default_budget)
                           + ")")
        if self.unconverged:
            reasons.append("unconverged: " + ", ".join(self.unconverged))
        if self.without_feasible_setting:
            reasons.append("not judged: " + ", ".join(
                f"replicate {r} (no feasible setting of {' and '.join(m)})"
                for r, m in sorted(self.without_feasible_setting.items())))
        return "; ".join(reasons)

    @classmethod
    def from_json(cls, data: dict) -> TuneSummary:
        return cls(**{**data, "objectives": tuple(data["objectives"]),
                      "replicates": tuple(data["replicates"]),
                      "parity": tuple(data["parity"]),
                      "below_default_budget": tuple(data["below_default_budget"]),
                      "unconverged": tuple(data["unconverged"]),
                      "overrides": tuple(data.get("overrides", ())),
                      "claims": tuple(TunedClaim.from_json(c) for c in data["claims"])})

    def to_json(self) -> dict:
        data = {f.name: getattr(self, f.name) for f in fields(self)}
        data["claims"] = [c.to_json() for c in self.claims]
        return json_safe(data)


@dataclass(frozen=True)
class TuneResult:
    """Everything :func:`pipeline.studies.tune.run_tuning` found; ``folder`` is where it was
    read from (None before it is written)."""

    summary: TuneSummary
    trials: pd.DataFrame
    heldout: pd.DataFrame
    ledger_default: pd.DataFrame
    ledger_tuned: pd.DataFrame
    settings_outcomes: pd.DataFrame
    folder: Path | None = None

    def tables(self) -> dict[str, pd.DataFrame]:
        """The tables by file name (the report copies them as ``tune_<name>``)."""
        return {TRIALS: self.trials, HELDOUT: self.heldout, LEDGER_DEFAULT: self.ledger_default,
                LEDGER_TUNED: self.ledger_tuned, SETTINGS_OUTCOMES: self.settings_outcomes}

    def table_files(self) -> dict[str, Path]:
        """The tables' files as written (a reader copies them byte for byte)."""
        if self.folder is None:
            raise ResultError("the tuning's result was not written yet")
        return {name: self.folder / name for name in self.tables()}

    def write(self, folder: Path) -> TuneResult:
        """Write the tables and ``summary.json``, then the manifest (last)."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        untrust(folder)
        for name, table in self.tables().items():
            write_csv_atomic(folder / name, table)
        write_json_atomic(folder / SUMMARY, self.summary.to_json())
        write_manifest(folder, "tune", FILES, self.summary.name)
        return TuneResult(self.summary, self.trials, self.heldout, self.ledger_default,
                          self.ledger_tuned, self.settings_outcomes, folder)

    @staticmethod
    def present(folder: Path | None) -> bool:
        """Whether ``folder`` holds a tuning's result (trusted or not)."""
        return folder is not None and (Path(folder) / SUMMARY).is_file()

    @classmethod
    def load(cls, folder: Path) -> TuneResult:
        """The result in ``folder``; :class:`ResultError` when it cannot be trusted."""
        folder = Path(folder)
        reason = check(folder, "tune", required=FILES)
        if reason:
            raise ResultError(f"tuning tables not trusted: {reason}")
        try:
            tables = [pd.read_csv(folder / name) for name in FILES[:5]]
            summary = TuneSummary.from_json(read_json(folder / SUMMARY))
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ResultError(f"tuning folder cannot be read ({type(exc).__name__}: "
                              f"{exc})") from None
        trials, heldout, ledger_default, ledger_tuned, outcomes = tables
        return cls(summary, trials, heldout, ledger_default, ledger_tuned, outcomes, folder)

    def front_figure(self, part: str) -> dict[str, Path] | None:
        """The Pareto fronts on the ``part`` family the command drew, if they are there."""
        if self.folder is None:
            return None
        return figure_files(self.folder / FIGURES, self.front_stem(part))

    @staticmethod
    def front_stem(part: str) -> str:
        """The file stem of the Pareto fronts on the ``part`` family."""
        return f"pareto_fronts_{part}"

    #: the file stem of the hypervolume histories
    HISTORY_STEM = "hypervolume_history"

    def history_figure(self) -> dict[str, Path] | None:
        """The hypervolume histories the command drew, if they are there."""
        if self.folder is None:
            return None
        return figure_files(self.folder / FIGURES, self.HISTORY_STEM)

    def figure_folder(self) -> Path:
        """Where the command draws the Pareto fronts."""
        return written(self.folder) / FIGURES
