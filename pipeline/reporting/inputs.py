"""Everything the report reads, read once through its owners (the store for run and family
folders, each study's typed result for its folder), before anything is computed.

:meth:`ReportInputs.load` never simulates and never runs a study; a folder that cannot be read
or trusted becomes a :class:`~pipeline.store.runs.Skipped` with its reason (listed on the page
and on stderr), never a crash. It also decides which run of each method is judged (make
reproduce's own, else the one labelled with the bare method name) and with which claims
settings (those the runs were made with, the command's treatment and controls over them).
"""

from __future__ import annotations

import dataclasses
import json
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import pandas as pd

from pipeline.analysis.metrics import LateralJerk
from pipeline.analysis.unavoidable import (
    AVOIDED_BY,
    LABEL,
    RUN_LABEL,
    collision_rows,
    label_across_methods,
)
from pipeline.analysis.validity import ValidityTable
from pipeline.config import ClaimsConfig, ExperimentConfig
from pipeline.store.collection import (
    LabelledRun,
    RunCollection,
    family_tables_by_method,
    interpretation_tables,
    load_runs,
    model_validity_table,
    trusted_families,
)
from pipeline.store.layout import OutputsLayout
from pipeline.store.runs import FamilyRecord, Skipped
from pipeline.studies.results import (
    BenchResult,
    MultiverseResult,
    NmpcCheckResult,
    ResultError,
    SpeedCheckResult,
    SweepSummary,
    TuneResult,
)
from pipeline.studies.results.commonroad import CommonRoadResult
from pipeline.studies.results.sweep import is_sweep_folder

log = logging.getLogger("pipeline.reporting")

T = TypeVar("T")

#: What an optional input that cannot be read may raise (it is then skipped, with its reason).
UNREADABLE = (OSError, ValueError, KeyError, TypeError, IndexError, pd.errors.ParserError)


def ordered(methods) -> list[str]:
    """Registered methods first in their order (``run.order`` of their presets,
    :mod:`pipeline.methods`), labelled variants right after their method."""
    from pipeline.methods import method_info

    def rank(label: str) -> tuple:
        base = label.split(" (")[0].split(" #")[0]
        return (method_info(base).order, base, label != base, label)

    return sorted(dict.fromkeys(methods), key=rank)


def choose_per_method(items: dict, method_of, kind: str, use: str, canonical: tuple[str, ...],
                      folder_of=None) -> tuple[dict, list[str]]:
    """One item per method and a note for every method given more than once. The pick: the
    run make reproduce wrote (``<section>/<method>``, ``canonical`` naming the sections), else
    the one labelled with the bare method name, else the first; the note names it and the ones
    left out."""
    def made_by_reproduce(folder, method: str) -> bool:
        path = Path(str(folder)) if folder else None
        return path is not None and path.name == method and path.parent.name in canonical

    groups: dict[str, list[str]] = {}
    for label, item in items.items():
        groups.setdefault(method_of(label, item), []).append(label)
    chosen, notes = {}, []
    for method, labels in groups.items():
        picked = [label for label in labels
                  if folder_of is not None and made_by_reproduce(folder_of(label, items[label]),
                                                                 method)]
        pick = picked[0] if picked else method if method in labels else labels[0]
        chosen[method] = items[pick]
        if len(labels) > 1:
            why = "the run make reproduce wrote" if picked else \
                "no run in make reproduce's place: the first"
            notes.append(f"{len(labels)} {kind} of {method} were given; {use} '{pick}' ({why}); "
                         f"left out of the claims: {'; '.join(x for x in labels if x != pick)} "
                         "(shown apart).")
    return chosen, notes


@dataclass(frozen=True)
class TrackRuns:
    """The single runs of one track on one scenario: the judged run of each method (in method
    order), the other runs given (shown, never judged), and notes on what was picked."""

    scenario: str
    by_method: dict[str, LabelledRun]
    extra: tuple[LabelledRun, ...]
    notes: tuple[str, ...]
    #: every run given, in the order they were found
    runs: tuple[LabelledRun, ...] = ()

    @property
    def methods(self) -> list[str]:
        return list(self.by_method)

    def metrics(self) -> dict[str, dict]:
        """Every metric of each judged run, by method."""
        return {m: r.metrics() for m, r in self.by_method.items()}

    @classmethod
    def of(cls, runs: list[LabelledRun], canonical: tuple[str, ...]) -> TrackRuns:
        by_label = {r.label: r for r in runs}
        primary, notes = choose_per_method({m: by_label[m] for m in ordered(by_label)},
                                           lambda label, run: run.method, "runs",
                                           "the claims use", canonical,
                                           folder_of=lambda label, run: run.folder)
        by_method = {m: primary[m] for m in ordered(primary)}
        judged = {id(r) for r in by_method.values()}
        extra = tuple(r for r in by_label.values() if id(r) not in judged)
        return cls(runs[0].scenario, by_method, extra, tuple(notes), tuple(runs))


@dataclass(frozen=True)
class FamilyInputs:
    """The scenario families of one section: every table by label, the one judged per method
    (:attr:`primary`), their ``family.json`` and settings, and notes on what was picked;
    :attr:`jerks`: the judged runs' lateral jerk by method and scenario (what C2 on a window
    common to both runs of a pair reads; only where :meth:`with_jerks` read them)."""

    tables: dict[str, pd.DataFrame]
    info: dict[str, dict]
    settings: dict[str, ExperimentConfig]
    primary: dict[str, pd.DataFrame]
    notes: tuple[str, ...]
    jerks: dict[str, dict[str, LateralJerk]] = field(default_factory=dict)

    @classmethod
    def of(cls, collection: RunCollection, canonical: tuple[str, ...]) -> FamilyInputs:
        info = collection.family_info
        primary, notes = choose_per_method(
            collection.family_tables, lambda label, _: info.get(label, {}).get("method", label),
            "families", "the ledger uses", canonical,
            folder_of=lambda label, _: info.get(label, {}).get("dir"))
        return cls(collection.family_tables, info, collection.family_settings, primary,
                   tuple(notes))

    def judgeable(self, cfg: ClaimsConfig) -> bool:
        """Whether the ledger can be made: the treatment and a control are among the
        families."""
        return cfg.treatment in self.primary and any(c in self.primary for c in cfg.controls)

    def label_of(self, method: str) -> str | None:
        """The label of the family judged for ``method`` (None when there is none)."""
        table = self.primary.get(method)
        return next((label for label, t in self.tables.items() if t is table), None)

    def with_tables(self, tables: dict[str, pd.DataFrame]) -> FamilyInputs:
        """These inputs with each table replaced by the one of the same label in ``tables``
        (the judged ones too: :attr:`primary` keeps pointing at the tables of its labels)."""
        new = {label: tables.get(label, table) for label, table in self.tables.items()}
        primary = {method: new[label] if (label := self.label_of(method)) is not None
                   else table for method, table in self.primary.items()}
        return dataclasses.replace(self, tables=new, primary=primary)

    def with_jerks(self, methods: tuple[str, ...]) -> FamilyInputs:
        """These inputs with the lateral jerk of every member of the judged families of
        ``methods`` (each from its stored trajectory, read with the family's own metric
        settings); a family whose table has no recorded window is left out (C2 on a common
        window cannot be read on it)."""
        from pipeline.analysis.claims.windows import WINDOW_START
        from pipeline.analysis.metrics import lateral_jerk_signal
        from pipeline.analysis.metrics.context import trajectory_context
        from pipeline.analysis.metrics.signals import SIGNAL_COLUMNS
        from pipeline.store.runs import member_trajectories

        jerks: dict[str, dict[str, LateralJerk]] = {}
        for method in methods:
            label = self.label_of(method)
            if label is None or label not in self.settings or \
                    WINDOW_START not in self.primary[method]:
                continue
            settings = self.settings[label]
            context = trajectory_context(settings)
            jerks[method] = {
                str(metrics.get("scenario")): lateral_jerk_signal(trajectory, context,
                                                                  settings.metrics)
                for _, trajectory, metrics in member_trajectories(Path(self.info[label]["dir"]),
                                                                  SIGNAL_COLUMNS)}
        return dataclasses.replace(self, jerks=jerks)


@dataclass(frozen=True)
class ValidityInputs:
    """What the model-validity section reads: the pooled table of the families' model checks,
    and the default and other frame's families."""

    table: ValidityTable
    families: tuple[FamilyRecord, ...]
    other_frame: tuple[FamilyRecord, ...]


@dataclass(frozen=True)
class ReportInputs:
    """Everything the report shows, read (see the module docstring)."""

    run_root: Path
    layout: OutputsLayout
    claims: ClaimsConfig
    lateral: TrackRuns | None = None
    kinematic: TrackRuns | None = None
    other_runs: tuple[LabelledRun, ...] = ()
    family: FamilyInputs | None = None
    kinematic_family: FamilyInputs | None = None
    #: the family without the MPC's collision half-planes ("APF by itself", make reproduce)
    apf_alone: FamilyInputs | None = None
    #: the family under the nonlinear MPC (make nmpc-family: the judge of record)
    nmpc_family: FamilyInputs | None = None
    #: the methods the paper names, on the family and on the Appendix-A track's family
    peers: FamilyInputs | None = None
    kinematic_peers: FamilyInputs | None = None
    #: the treatment and the baseline among recorded pedestrians (make pedestrians)
    pedestrians: FamilyInputs | None = None
    #: the same among recorded pedestrians in each variant of make pedestrians (car, aimed,
    #: reactive: ``pedestrians_variants/<variant>/<method>``), by variant
    pedestrian_variants: dict[str, FamilyInputs] = field(default_factory=dict)
    #: every collision of those families with the run's own label, the published one (across
    #: the methods that ran the same scenario, :mod:`pipeline.analysis.unavoidable`) and the
    #: methods that avoided it
    collision_labels: pd.DataFrame | None = None
    #: per track ("lateral", "kinematic") and method: the solve time per step over its
    #: family's members, median and 95th percentile in seconds (peers and the treatment)
    solve_times: dict[str, dict[str, tuple[float, float]]] = field(default_factory=dict)
    readings: dict[str, list[LabelledRun]] = field(default_factory=dict)
    ablation: dict[str, pd.DataFrame] = field(default_factory=dict)
    interpretations: dict[str, dict[str, pd.DataFrame]] = field(default_factory=dict)
    validity: ValidityInputs | None = None
    sweeps: tuple[SweepSummary, ...] = ()
    bench: BenchResult | None = None
    multiverse: MultiverseResult | None = None
    tune: TuneResult | None = None
    #: per lateral peer that ``make tune-peers`` tuned against the treatment (its folder
    #: ``tune_peers/<peer>``), that tuning
    peer_tunes: dict[str, TuneResult] = field(default_factory=dict)
    nmpc: NmpcCheckResult | None = None
    speed: SpeedCheckResult | None = None
    skipped: tuple[Skipped, ...] = ()
    #: runs on CommonRoad scenarios (``make commonroad``), shown only
    commonroad: tuple[CommonRoadResult, ...] = ()
    #: every registered study's typed result found in its folder, by the study's name
    #: (:func:`study_results`; ``nmpc``, ``speed``, ``multiverse`` and ``tune`` come from here)
    studies: dict[str, Any] = field(default_factory=dict)

    @property
    def has_runs(self) -> bool:
        """Whether there is a paper scenario to show (else the page shows sweeps only)."""
        return self.lateral is not None

    @classmethod
    def load(cls, run_root: Path, sweep_dirs: tuple[Path, ...] = (),
             bench_dir: Path | None = None, multiverse_dir: Path | None = None,
             tune_dir: Path | None = None, treatment: str | None = None,
             controls: tuple[str, ...] = (), skipped: list[Skipped] | None = None
             ) -> ReportInputs:
        """Read every input (see the module docstring); ``skipped`` receives what was passed
        over. Raises FileNotFoundError when there are neither runs nor sweeps."""
        run_root = Path(run_root)
        skipped = skipped if skipped is not None else []
        layout = OutputsLayout.load(run_root)
        sweep_dirs = tuple(Path(d) for d in sweep_dirs)
        if is_sweep_folder(run_root):
            sweep_dirs, collection = (run_root,) + sweep_dirs, RunCollection()
        else:
            log.info("report: reading the run folders")
            try:
                collection = load_runs(run_root, skipped)
            except FileNotFoundError:
                # families alone (make pedestrians on a fresh clone): their sections are read
                # below, the rest listed as skipped with the command that makes it
                if not run_root.is_dir() or not _families_alone(layout):
                    raise
                collection = RunCollection()
        for item in skipped:
            log.warning("skipped %s: %s", item.folder, item.reason)
        optional = _Optional(skipped)
        sweeps = tuple(s for s in (optional(SweepSummary.load, d, "sweep section")
                                   for d in sweep_dirs) if s is not None)
        bench = optional(BenchResult.load, bench_dir, "performance section") \
            if BenchResult.present(bench_dir) else None
        # every registered study's typed result found in its folder (by the study's name)
        studies = study_results(layout, optional)
        # a folder named on the command line is read (or skipped with its reason) even when it
        # holds no result: a mistyped --tune left the section out without a word
        multiverse = studies.get("multiverse") if multiverse_dir is None else \
            optional(MultiverseResult.load, multiverse_dir, "robustness section")
        tune = studies.get("tune") if tune_dir is None else \
            optional(TuneResult.load, tune_dir, "fair fight section")
        claims = _claims(collection, treatment, controls)
        commonroad = tuple(CommonRoadResult.load_all(layout.folder("commonroad")))
        if not collection.runs:
            families = _families_alone(layout)
            if not sweeps and not families:
                raise FileNotFoundError(f"no single runs (the paper scenario) under {run_root}")
            pedestrians, variants = _pedestrian_families(layout, optional, skipped) \
                if families else (None, {})
            if families:
                skipped.extend(_alone_skipped(layout))
            return cls(run_root, layout, claims, sweeps=sweeps, bench=bench,
                       skipped=tuple(skipped), commonroad=commonroad,
                       pedestrians=pedestrians, pedestrian_variants=variants, studies=studies)
        inputs = cls._with_runs(run_root, layout, claims, collection, optional, skipped,
                                sweeps=sweeps, bench=bench, multiverse=multiverse, tune=tune)
        return dataclasses.replace(inputs, commonroad=commonroad, studies=studies,
                                   nmpc=studies.get("nmpc-check"),
                                   speed=studies.get("speed-check"))

    @classmethod
    def _with_runs(cls, run_root: Path, layout: OutputsLayout, claims: ClaimsConfig,
                   collection: RunCollection, optional: _Optional, skipped: list[Skipped],
                   *, sweeps: tuple[SweepSummary, ...], bench: BenchResult | None,
                   multiverse: MultiverseResult | None, tune: TuneResult | None
                   ) -> ReportInputs:
        """The inputs of a report over runs: the tracks, the families, the Appendix-A
        readings, the ablation and interpretations and the checks, with the studies' results
        read before (sweeps, bench, multiverse, tuning)."""
        runs = collection.runs
        kinematic_runs = [r for r in runs if r.track == "kinematic"]
        lateral_runs = [r for r in runs if r.track == "lateral"] or runs
        paper = [r for r in lateral_runs if r.scenario == "paper_sudden_obstacle"] \
            or lateral_runs
        lateral = TrackRuns.of(paper, layout.canonical)
        others = tuple(r for r in lateral_runs if r.scenario != lateral.scenario)
        family = FamilyInputs.of(collection, layout.canonical)
        if family.judgeable(claims):
            # C2 on a window common to both runs of a pair reads the judged runs' jerk
            log.info("report: the lateral jerk of the judged families' members")
            family = optional(lambda _root: family.with_jerks(
                (claims.treatment, *claims.controls)), layout.root,
                "C2 on a common window") or family
        kin_family_dir = layout.folder("kinematic_family")
        kinematic_family = optional(lambda folder: FamilyInputs.of(load_runs(folder, []),
                                                                   layout.canonical),
                                    kin_family_dir, "kinematic family section") \
            if kin_family_dir.is_dir() else None
        apf_alone = optional(lambda folder: _apf_alone(folder, layout, skipped),
                             layout.folder("apf_alone"), "APF-by-itself section") \
            if layout.folder("apf_alone").is_dir() else None
        if apf_alone is not None and claims.c2_window == "common" \
                and apf_alone.judgeable(claims):
            # its ledger reads C2 as the default ledger does: on the common window
            alone: FamilyInputs = apf_alone
            apf_alone = optional(lambda _root: alone.with_jerks(
                (claims.treatment, *claims.controls, "mpc_no_apf")),
                layout.folder("apf_alone"), "C2 on a common window (APF by itself)") or alone
        nmpc_family = optional(lambda folder: _nmpc_family(folder, layout, skipped),
                               layout.folder("nmpc_family"), "judge of record (NMPC)") \
            if layout.folder("nmpc_family").is_dir() else None
        peers = optional(lambda folder: FamilyInputs.of(load_runs(folder, skipped),
                                                        layout.canonical),
                         layout.folder("peers"), "peers section") \
            if layout.folder("peers").is_dir() else None
        kinematic_peers = optional(lambda folder: FamilyInputs.of(load_runs(folder, skipped),
                                                                  layout.canonical),
                                   layout.folder("kinematic_peers"), "peers section") \
            if layout.folder("kinematic_peers").is_dir() else None
        pedestrians, pedestrian_variants = _pedestrian_families(layout, optional, skipped)
        # the published collision label: across every method that ran the same scenario
        sections = {"family": family, "kinematic_family": kinematic_family,
                    "apf_alone": apf_alone, "peers": peers,
                    "kinematic_peers": kinematic_peers, "pedestrians": pedestrians}
        labelled, collision_labels = label_collisions(sections)
        family = labelled["family"] or family
        kinematic_family, apf_alone = labelled["kinematic_family"], labelled["apf_alone"]
        peers, kinematic_peers = labelled["peers"], labelled["kinematic_peers"]
        pedestrians = labelled["pedestrians"]
        solve_times = optional(lambda _root: _solve_times(
            claims.treatment, {"lateral": (family, peers),
                               "kinematic": (kinematic_family, kinematic_peers)}),
            layout.root, "peers section (solve times)") or {}
        # the model checks are read only when there is a ledger to put beside them
        # (a failure is listed against the outputs root, the folder the checks come from)
        validity = optional(lambda _root: _validity(layout), layout.root,
                            "validity section") if family.judgeable(claims) else None
        return cls(
            run_root, layout, claims, lateral=lateral,
            kinematic=TrackRuns.of(kinematic_runs, layout.canonical) if kinematic_runs
            else None,
            other_runs=lateral.extra + others, family=family,
            kinematic_family=kinematic_family, apf_alone=apf_alone,
            nmpc_family=nmpc_family, peers=peers,
            kinematic_peers=kinematic_peers, pedestrians=pedestrians,
            pedestrian_variants=pedestrian_variants, collision_labels=collision_labels, solve_times=solve_times,
            readings=_readings(layout),
            ablation=family_tables_by_method(layout.folder("ablation"), skipped),
            interpretations=interpretation_tables(layout.folder("interpretations"), skipped),
            validity=validity, sweeps=sweeps, bench=bench, multiverse=multiverse, tune=tune,
            peer_tunes=_peer_tunes(layout, optional),
            skipped=tuple(skipped))


def label_collisions(sections: dict[str, FamilyInputs | None]
                     ) -> tuple[dict[str, FamilyInputs | None], pd.DataFrame]:
    """Every family of ``sections`` (by section name: ``family``, ``peers``, ``apf_alone``, ...)
    with the published collision label (:func:`~pipeline.analysis.unavoidable.label_across_methods`),
    and one row per collision (section, track, method, scenario, the run's label, the
    published one, the methods that avoided it).

    The families of one track drawn from the same scenario settings (their first member's
    scenario: seed, obstacles, timing; the family's size aside) form a pool; the judged family
    of each method vouches for the scenarios it ran without a collision. A method is named as
    the ledger names it; a family of the APF by itself, or a name already taken, carries its
    section in brackets (``improved (apf_alone)``)."""
    # per track (the pools never cross one): name -> table, and where each name comes from
    tracks: dict[str, dict[str, pd.DataFrame]] = {}
    vouchers: list[tuple[str, str]] = []
    pools: dict[tuple[str, str], tuple[str, str]] = {}
    where: dict[tuple[str, str], tuple[str, str]] = {}
    for section, inputs in sections.items():
        if inputs is None:
            continue
        judged = {id(t) for t in inputs.primary.values()}
        for label, table in inputs.tables.items():
            pool = _pool(inputs.settings.get(label), section, label)
            tables = tracks.setdefault(pool[0], {})
            name = label if section != "apf_alone" and label not in tables \
                else f"{label} ({section})"
            tables[name] = table
            where[(pool[0], name)], pools[(pool[0], name)] = (section, label), pool
            if id(table) in judged:
                vouchers.append((pool[0], name))
    labelled: dict[tuple[str, str], pd.DataFrame] = {}
    frames = []
    for track, tables in tracks.items():
        done = label_across_methods(tables, tuple(n for t, n in vouchers if t == track),
                                    {name: pools[(track, name)] for name in tables})
        labelled.update({(track, name): table for name, table in done.items()})
        rows = collision_rows(done)
        rows.insert(0, "section", [where[(track, n)][0] for n in rows["method"]])
        rows.insert(1, "track", track)
        frames.append(rows)
    out: dict[str, FamilyInputs | None] = dict(sections)
    for section, inputs in sections.items():
        if inputs is not None:
            out[section] = inputs.with_tables({label: labelled[key]
                                               for key, (s, label) in where.items()
                                               if s == section})
    columns = ["section", "track", "method", "scenario", RUN_LABEL, LABEL, AVOIDED_BY]
    return out, pd.concat(frames, ignore_index=True)[columns] if frames \
        else pd.DataFrame(columns=columns)


def _pool(settings: ExperimentConfig | None, section: str, label: str) -> tuple[str, str]:
    """The scenario family a table was drawn from: its track and its first member's scenario
    (which fixes the family's seed and drawing; its size aside); a table whose settings are
    unknown is a pool of its own."""
    if settings is None:
        return ("?", f"{section}/{label}")
    track = "kinematic" if settings.controller.kind == "kinematic_mpc" else "lateral"
    scenario = dataclasses.asdict(settings.scenario)
    return (track, json.dumps(scenario, sort_keys=True, default=str))


def study_results(layout: OutputsLayout, optional: _Optional) -> dict[str, Any]:
    """Each registered study's typed result (its entry's ``result``: ``present(folder)`` and
    ``load(folder)``) from the study's folder, by the study's name; a study without a result
    or a folder, or whose folder holds none, is absent; one that cannot be read is skipped and
    listed (the section it feeds left out)."""
    from pipeline.store.study_registry import load_studies, resolve

    found: dict[str, Any] = {}
    for study in load_studies():
        if study.result is None or study.folder is None:
            continue
        result_type: Any = resolve(study.result, f"{study.source}: result")
        folder = layout.folder(study.folder)
        if result_type.present(folder):
            what = f"{(study.section_key or study.name).replace('_', ' ')} section"
            value = optional(result_type.load, folder, what)
            if value is not None:
                found[study.name] = value
    return found


def _peer_tunes(layout: OutputsLayout, optional: _Optional) -> dict[str, TuneResult]:
    """The tunings of ``make tune-peers``, one folder per peer (``tune_peers/<peer>``), by
    their control; a folder that cannot be read is skipped and listed."""
    root = layout.folder("tune_peers")
    out: dict[str, TuneResult] = {}
    if not root.is_dir():
        return out
    for folder in sorted(p for p in root.iterdir() if p.is_dir()):
        if TuneResult.present(folder):
            result = optional(TuneResult.load, folder, "peers section (tuned)")
            if result is not None:
                out[result.summary.methods[1]] = result
    return out


#: why a report of families alone has no paper-scenario sections (and how to make them)
_ALONE_REASON = ("the paper scenario, the scenario family and the sections judged on them "
                 "(the answer, the ledger, the checks) left out: no paper-scenario run here; "
                 "make reproduce writes them")


#: Sections whose folders a report lists without the paper scenario, each with why it cannot
#: be shown alone (None: it can) and what makes what it needs.
_ALONE_SECTIONS = {
    "pedestrians": None, "pedestrians_variants": None, "commonroad": None, "euro_ncap": None,
    "peers": "the methods the paper names are judged against improved on the scenario "
             "family, which is not here; make reproduce writes it",
    "kinematic_peers": "the methods the paper names (Appendix-A track) are judged against "
                       "improved on the Appendix-A family, which is not here; make reproduce "
                       "writes it",
    # make tune on a fresh clone: its report is written (listing what is missing) instead of
    # make tune ending on 'no complete run folders'
    "tune": "the fair fight (tuned vs tuned) is shown beside the answer on the scenario "
            "family, which is not here; make reproduce writes it, then make report shows both",
    "tune_peers": "the fair fights against the methods the paper names are shown beside the "
                  "answer on the scenario family, which is not here; make reproduce writes it"}


def _families_alone(layout: OutputsLayout) -> bool:
    """Whether the outputs hold something a report can show, or list, without the paper
    scenario (``make pedestrians``, ``make peers``, ``make commonroad``, ``make euro-ncap`` or
    ``make tune`` on a fresh clone)."""
    return any(layout.folder(section).is_dir() for section in _ALONE_SECTIONS)


def _alone_skipped(layout: OutputsLayout) -> list[Skipped]:
    """The sections of a report without the paper scenario that cannot be shown, each with
    the command that makes what it needs."""
    return [Skipped(layout.folder("paper"), _ALONE_REASON)] + [
        Skipped(layout.folder(section), reason) for section, reason in _ALONE_SECTIONS.items()
        if reason is not None and layout.folder(section).is_dir()]


def _pedestrian_families(layout: OutputsLayout, optional: _Optional, skipped: list[Skipped]
                         ) -> tuple[FamilyInputs | None, dict[str, FamilyInputs]]:
    """The recorded-pedestrian family (``pedestrians/``) and its variants
    (``pedestrians_variants/<variant>/``), each read or skipped with its reason."""
    pedestrians = optional(lambda folder: FamilyInputs.of(load_runs(folder, skipped),
                                                          layout.canonical),
                           layout.folder("pedestrians"), "pedestrians section") \
        if layout.folder("pedestrians").is_dir() else None
    variants_dir = layout.folder("pedestrians_variants")
    variants = {} if not variants_dir.is_dir() else {
        folder.name: read for folder in sorted(p for p in variants_dir.iterdir() if p.is_dir())
        if (read := optional(lambda f: FamilyInputs.of(load_runs(f, skipped),
                                                       layout.canonical),
                             folder, "pedestrians section (variant)")) is not None}
    return pedestrians, variants


class _Optional:
    """Calls a reader of an optional input; one that cannot be read is skipped with its
    reason (listed on the page and on stderr), never a crash."""

    def __init__(self, skipped: list[Skipped]) -> None:
        self.skipped = skipped

    def __call__(self, read: Callable[[Path], T], folder, what: str) -> T | None:
        try:
            return read(folder)
        except (ResultError, *UNREADABLE) as exc:
            text = str(exc).splitlines()[0][:120] if str(exc) else ""
            reason = f"{what} left out ({type(exc).__name__}: {text})"
            self.skipped.append(Skipped(Path(folder), reason))
            log.warning("skipped %s: %s", folder, reason)
            return None


def _claims(collection: RunCollection, treatment: str | None,
            controls: tuple[str, ...]) -> ClaimsConfig:
    """The claims settings the runs were made with, never defaults rebuilt from text; what is
    compared with what: the command's treatment and controls, else those settings'."""
    cfg = collection.claims_settings(treatment or "improved") \
        or collection.claims_settings("improved") or ClaimsConfig()
    return dataclasses.replace(cfg, treatment=treatment or cfg.treatment,
                               controls=list(controls) if controls else list(cfg.controls))


def reading_of(baseline_config: dict) -> str:
    """Which Appendix-A reading a kinematic baseline run was made under."""
    if baseline_config.get("scenario", {}).get("obstacle_anchor", "world") == "vehicle":
        return "vehicle_anchor"
    alignment = baseline_config.get("controller", {}).get("reference_alignment", "literal")
    if alignment != "literal":
        return alignment
    return "literal" if baseline_config.get("planner", {}).get("normalize_step", True) \
        else "printed"


def _readings(layout: OutputsLayout) -> dict[str, list[LabelledRun]]:
    """The Appendix-A readings' runs (``kinematic_readings``) by reading, in name order."""
    root = layout.folder("kinematic_readings")
    by_variant: dict[str, list[LabelledRun]] = {}
    if root.is_dir():
        for run in load_runs(root, []).runs:
            by_variant.setdefault(run.config["run"].get("variant", "?"), []).append(run)
    return dict(sorted(by_variant.items()))


def _solve_times(treatment: str,
                 tracks: dict[str, tuple[FamilyInputs | None, FamilyInputs | None]]
                 ) -> dict[str, dict[str, tuple[float, float]]]:
    """Per track with peers: the treatment's solve time per step over its default family and
    each peer's over its own (:func:`~pipeline.store.runs.member_solve_times`)."""
    from pipeline.store.runs import member_solve_times

    found: dict[str, dict[str, tuple[float, float]]] = {}
    for track, (default, peers) in tracks.items():
        if peers is None:
            continue
        by_method: dict[str, tuple[float, float]] = {}
        sources = [(treatment, default)] + [(m, peers) for m in peers.primary]
        for method, family in sources:
            label = family.label_of(method) if family is not None else None
            folder = family.info.get(label, {}).get("dir") if family and label else None
            times = member_solve_times(Path(folder)) if folder else None
            if times is not None:
                by_method[method] = times
        found[track] = by_method
    return found


def _families_made_with(folder: Path, layout: OutputsLayout, skipped: list[Skipped],
                        made: Callable[[ExperimentConfig], bool], refused: str
                        ) -> FamilyInputs | None:
    """The families of ``folder`` whose settings satisfy ``made``; any other is skipped with
    ``refused`` as its reason. None when none is left."""
    found = load_runs(folder, skipped)
    kept = []
    for label, settings in found.family_settings.items():
        if made(settings):
            kept.append(label)
        else:
            skipped.append(Skipped(Path(str(found.family_info[label].get("dir", folder))),
                                   refused))
    if not kept:
        return None
    return FamilyInputs.of(RunCollection(
        family_tables={k: found.family_tables[k] for k in kept},
        family_info={k: found.family_info[k] for k in kept},
        family_settings={k: found.family_settings[k] for k in kept}), layout.canonical)


def _apf_alone(folder: Path, layout: OutputsLayout, skipped: list[Skipped]
               ) -> FamilyInputs | None:
    """The families of ``folder`` made without the MPC's collision half-planes, as their
    settings record them (``controller.collision_constraints``); a family made with them is
    skipped with its reason (it would not be the APF by itself). None when none is left."""
    return _families_made_with(
        folder, layout, skipped, lambda settings: not getattr(settings.controller, "collision_constraints", True),
        "APF-by-itself section: left out (made with the MPC's collision half-planes on)")


def _nmpc_family(folder: Path, layout: OutputsLayout, skipped: list[Skipped]
                 ) -> FamilyInputs | None:
    """The families of ``folder`` made with the lateral MPC on the nonlinear model, as their
    settings record them (``controller.backend=nmpc``); any other is skipped with its reason
    (it would not be the judge of record). None when none is left."""
    return _families_made_with(
        folder, layout, skipped, lambda settings: getattr(settings.controller, "backend", None) == "nmpc",
        "judge of record: left out (not made with controller.backend=nmpc)")


def _validity(layout: OutputsLayout) -> ValidityInputs:
    return ValidityInputs(model_validity_table(layout),
                          tuple(trusted_families(layout.folder("family"))),
                          tuple(trusted_families(layout.folder("frames"))))
