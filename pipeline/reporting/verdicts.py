"""Every ledger the report shows, computed once from its inputs: the paper scenario's claims
on each track, the family ledgers (lateral and Appendix-A track), what the baseline's APF adds,
the claims with the MPC's collision half-planes off (the APF by itself), the Appendix-A
readings, the ablation's effects and flips, and the claims again where the MPC's model held
and in the other frame. The sections only format these."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from pipeline.analysis.ablation import ablation_effects, ablation_roles, interpretation_flips
from pipeline.analysis.claims import (
    IntervalMemo,
    Ledger,
    LedgerRow,
    adjust_answer,
    claims_of,
    claims_table,
    family_ledger,
    force_claims,
    outcome_counts,
)
from pipeline.analysis.validity import valid_scenario_ledgers
from pipeline.config import ClaimsConfig
from pipeline.reporting.inputs import FamilyInputs, ReportInputs, TrackRuns, ordered, reading_of
from pipeline.store.collection import LabelledRun


def rate_claims(cfg: ClaimsConfig) -> frozenset[str]:
    """The claims of ``cfg`` whose outcome is a rate (judged even where the methods never met
    the obstacle)."""
    return frozenset(c.claim_id for c in claims_of(cfg) if c.is_rate)


@dataclass(frozen=True)
class TrackClaims:
    """The paper scenario's claims on one track: one row per claim (each method's primary
    metric, the outcome per comparison) and the comparisons made."""

    rows: tuple[dict, ...]
    comparisons: tuple[str, ...]
    comparability: tuple[str, ...] = ()


@dataclass(frozen=True)
class C2Windows:
    """C2 on each run's own avoidance window and on a window common to both runs of a pair
    (``claims.c2_window``; the rule ``claims.common_window``), per comparison: the ledger's
    C2 rows under each reading, the ledger's own reading marked. ``note`` says why a reading
    is missing (empty rows)."""

    rule: str
    in_ledger: str
    own: tuple[LedgerRow, ...] = ()
    common: tuple[LedgerRow, ...] = ()
    note: str = ""

    def rows(self) -> list[dict]:
        """One row per reading and comparison (``tables/claims_c2_common_window.csv``)."""
        out = []
        for reading, rows in (("own", self.own), ("common", self.common)):
            for row in rows:
                r = row.result
                out.append({
                    "claim": row.claim_id, "reading": reading,
                    "window": "each run's own avoidance window" if reading == "own"
                    else f"the {self.rule} of both runs' avoidance windows",
                    "in_ledger": reading == self.in_ledger, "comparison": row.comparison,
                    "metric": row.claim.primary_metric, "outcome": str(row.outcome),
                    "estimate": r.estimate, "ci_low": r.ci_low, "ci_high": r.ci_high,
                    "p_holm": row.p_holm, "prob_improvement": r.prob_improvement,
                    "pi_low": r.pi_low, "pi_high": r.pi_high, "n_better": r.n_better,
                    "n_tied": r.n_tied, "n_worse": r.n_worse, "n_missing": r.n_missing,
                    "n_pairs": r.n_pairs, "margin": row.margin, "note": row.note})
        return out


@dataclass(frozen=True)
class FamilyVerdicts:
    """A family's ledger, its outcome counts per method, what the baseline's APF adds
    (the baseline against ``mpc_no_apf``; None without both) and C2 on both windows (None
    on a family without them)."""

    tables: dict[str, pd.DataFrame]
    ledger: Ledger
    counts: tuple[dict, ...]
    apf_adds: Ledger | None
    c2_windows: C2Windows | None = None


@dataclass(frozen=True)
class ApfAloneVerdicts:
    """The claims judged with the MPC's collision half-planes off (``apf_alone``): the
    ledger (the treatment against each control and against ``mpc_no_apf``, no APF at all),
    and the outcome counts per method without the half-planes and, from the default family,
    with them."""

    tables: dict[str, pd.DataFrame]
    ledger: Ledger
    comparisons: tuple[str, ...]
    counts: tuple[dict, ...]
    counts_with: tuple[dict, ...]


@dataclass(frozen=True)
class PeerVerdicts:
    """The treatment against the methods the paper names (``make reproduce``'s ``peers`` and
    ``kinematic_peers`` families), on one track: the ledger (each claim, treatment vs each
    peer, by the default ledger's rules with C2 on each run's own window) over the same
    scenarios as the track's default ledger, and the outcome counts per method."""

    track: str
    peers: tuple[str, ...]
    ledger: Ledger
    counts: tuple[dict, ...]


@dataclass(frozen=True)
class PedestrianVerdicts:
    """The treatment against its controls among recorded pedestrians (``make
    pedestrians``): the ledger over the whole family and one per scene (by the default
    ledger's rules, C2 on each run's own window, no all-pairs sensitivity), and the outcome
    counts per method overall and per scene. ``tables``: each method's family table with a
    ``scene`` column."""

    scenes: tuple[str, ...]
    comparisons: tuple[str, ...]
    ledger: Ledger
    by_scene: tuple[tuple[str, Ledger], ...]
    counts: tuple[dict, ...]
    scene_counts: tuple[dict, ...]
    tables: dict[str, pd.DataFrame]
    #: the family: ``family`` (default, or its variant's name), ``platform`` (the vehicle),
    #: ``track``, ``draw`` and ``walkers``
    about: dict = field(default_factory=dict)
    #: the crowd-navigation metrics per method (:func:`~pipeline.analysis.crowd.crowd_metrics`)
    metrics: pd.DataFrame | None = None
    #: from the recording alone: the shares of crossings whose straight line meets a walker
    #: and where a platform standing still is touched, and each method's collision rate on
    #: the crossings where standing still is safe
    difficulty: dict = field(default_factory=dict)
    #: C1 and C4 of the whole family's ledger again by the other rule of their pairs
    #: (``unsettled_last`` beside ``neither_collided`` and the reverse, at each row's level and
    #: margin): one dict per row (:func:`_other_pairs`)
    other_pairs: tuple[dict, ...] = ()
    #: the pairs rule of :attr:`ledger` (``claims.pairs`` of the treatment's family)
    pairs_rule: str = "neither_collided"

    def frame(self) -> pd.DataFrame:
        """Every ledger as one table, ``family`` and ``scene`` columns first (``all``: the
        whole family; ``tables/claims_ledger_pedestrians.csv``), ``pairs`` the pairs each
        row rests on."""
        frames = []
        for scene, ledger in (("all", self.ledger), *self.by_scene):
            frame = ledger.to_frame()
            frame.insert(0, "scene", scene)
            frame.insert(0, "family", self.about.get("family", "default"))
            frame["pairs"] = frame["n_pairs"]
            frames.append(frame)
        return pd.concat(frames, ignore_index=True)


@dataclass(frozen=True)
class NmpcVerdicts:
    """The judge of record (``make nmpc-family``): the treatment against its controls on the
    default family with the lateral MPC stated on the plant's nonlinear model, judged by the
    default ledger's rules (C2 on each run's own window, the worst-rank sensitivity); its
    collisions per method; the share of steps on which the linear MPC's model left its
    small-angle bound, per method of the default family; and whether that makes this ledger
    the judge of record (a share above ``claims.nmpc_judge_share``)."""

    ledger: Ledger
    counts: tuple[dict, ...]
    linear_beyond_share: dict[str, float]
    judge_of_record: bool


@dataclass(frozen=True)
class ValidityVerdicts:
    """The claims again: the default ledger without the all-pairs sensitivity, per comparison
    on the scenarios where both models held (with their number), in the other frame."""

    comparisons: tuple[str, ...]
    default: Ledger | None
    valid: dict[str, tuple[Ledger, int]]
    other: Ledger | None
    #: the same comparisons on the nonlinear MPC (make nmpc-family), when it ran
    nmpc: Ledger | None = None

    def rows(self) -> list[dict]:
        """Per claim and comparison: the outcome with its pairs, on the valid scenarios, in
        the other frame, on the nonlinear MPC (``tables/claims_model_validity.csv``)."""
        rows = []
        for row in (self.default or ()):
            valid_ledger, n_valid = self.valid.get(row.comparison, (None, 0))
            valid_row = valid_ledger.get(row.key) if valid_ledger is not None else None
            other_row = self.other.get(row.key) if self.other is not None else None
            nmpc_row = self.nmpc.get(row.key) if self.nmpc is not None else None
            rows.append({
                "claim": row.claim_id, "comparison": row.comparison,
                "outcome": str(row.outcome), "n": row.result.n_pairs,
                "valid_outcome": str(valid_row.outcome) if valid_row else "—",
                "valid_n": valid_row.result.n_pairs if valid_row else 0,
                "valid_scenarios": n_valid,
                "other_outcome": str(other_row.outcome) if other_row else "—",
                "other_n": other_row.result.n_pairs if other_row else 0,
                "nmpc_outcome": str(nmpc_row.outcome) if nmpc_row else "—",
                "nmpc_n": nmpc_row.result.n_pairs if nmpc_row else 0})
        return rows


@dataclass(frozen=True)
class Verdicts:
    """See the module docstring; each part None when its inputs were not given."""

    claims: ClaimsConfig
    paper: TrackClaims | None = None
    kinematic: TrackClaims | None = None
    family: FamilyVerdicts | None = None
    kinematic_family: FamilyVerdicts | None = None
    apf_alone: ApfAloneVerdicts | None = None
    peers: tuple[PeerVerdicts, ...] = ()
    pedestrians: PedestrianVerdicts | None = None
    readings: tuple[tuple[str, dict[str, str]], ...] = ()
    ablation_effects: pd.DataFrame | None = None
    ablation_roles: tuple[str, str] = ("improved", "baseline")
    flips: pd.DataFrame | None = None
    validity: ValidityVerdicts | None = None
    notes: tuple[str, ...] = field(default_factory=tuple)
    nmpc: NmpcVerdicts | None = None
    #: the variants of make pedestrians (car, aimed, reactive), judged as the default one
    pedestrian_variants: tuple[PedestrianVerdicts, ...] = ()

    @classmethod
    def compute(cls, inputs: ReportInputs, claims: ClaimsConfig | None = None,
                memo: IntervalMemo | None = None) -> Verdicts:
        """Every ledger of ``inputs``, judged with ``claims`` (the inputs' by default), the
        bootstrap results recalled from ``memo`` where it holds them (the same numbers:
        :class:`~pipeline.analysis.claims.memo.IntervalMemo`) and kept in it."""
        cfg = claims or inputs.claims
        if inputs.lateral is None:  # a page of sweeps or of families alone
            return cls(cfg, pedestrians=_pedestrians(inputs.pedestrians, cfg, memo=memo)
                       if inputs.pedestrians is not None else None,
                       pedestrian_variants=tuple(
                           judged for name, variant in inputs.pedestrian_variants.items()
                           if (judged := _pedestrians(variant, cfg, name, memo)) is not None))
        paper = track_claims(inputs.lateral, cfg)
        kinematic = track_claims(inputs.kinematic, cfg, comparable_only=True) \
            if inputs.kinematic is not None else None
        family = _family(inputs.family, cfg, inputs.lateral.metrics(), paper_ledger=True,
                         memo=memo) \
            if inputs.family is not None and inputs.family.judgeable(cfg) else None
        # C2 on a common window is read on the lateral family (whose runs' jerk is read);
        # every other ledger reads each run's own window
        own = dataclasses.replace(cfg, c2_window="own")
        kinematic_family = _family(inputs.kinematic_family, own, None, paper_ledger=False,
                                   memo=memo) \
            if inputs.kinematic is not None and inputs.kinematic_family is not None \
            and inputs.kinematic_family.judgeable(cfg) else None
        effects, roles = None, ablation_roles(inputs.ablation, own)
        if roles[1] in inputs.ablation and roles[0] in inputs.ablation:
            effects = ablation_effects(inputs.ablation, own)
        apf_alone = _apf_alone(inputs.apf_alone, cfg, family, inputs.family, memo) \
            if inputs.apf_alone is not None and inputs.apf_alone.judgeable(cfg) else None
        peers = tuple(judged for judged in (
            _peers("lateral", inputs.family, inputs.peers, cfg, memo),
            _peers("kinematic", inputs.kinematic_family, inputs.kinematic_peers, cfg, memo))
            if judged is not None)
        pedestrians = _pedestrians(inputs.pedestrians, cfg, memo=memo) \
            if inputs.pedestrians is not None else None
        pedestrian_variants = tuple(judged for name, variant in inputs.pedestrian_variants.items()
                                    if (judged := _pedestrians(variant, cfg, name, memo))
                                    is not None)
        nmpc = _nmpc(inputs.nmpc_family, family, cfg, memo) \
            if inputs.nmpc_family is not None and inputs.nmpc_family.judgeable(cfg) else None
        validity = _validity(inputs.family, inputs, own, memo) if inputs.family is not None \
            and family is not None else None
        if validity is not None and nmpc is not None:
            validity = dataclasses.replace(validity, nmpc=nmpc.ledger)
        verdicts = cls(cfg, paper, kinematic, family, kinematic_family, apf_alone, peers,
                       pedestrians, _readings(inputs.kinematic, inputs.readings, cfg)
                       if inputs.kinematic is not None else (),
                       effects, roles, interpretation_flips(inputs.interpretations, own),
                       validity, nmpc=nmpc, pedestrian_variants=pedestrian_variants)
        return verdicts.adjusted()

    def adjusted(self) -> Verdicts:
        """These verdicts after the answer's family-wise rule
        (:func:`~pipeline.analysis.claims.adjust_answer`): every ledger the answer publishes
        (the family's controls, the baseline against no APF on both tracks, C2 on the other
        window, the Appendix-A track, the APF by itself, the methods the paper names), each
        claim's rows one Holm family, the family's first control the primary comparison. The
        judge of record's ledger (the same comparison on the nonlinear MPC) and the checks of
        the validity section are not new comparisons: they are left as they are."""
        cfg = self.claims
        named: list[tuple[str, Ledger]] = []
        family, kin = self.family, self.kinematic_family
        if family is not None:
            named.append(("family", family.ledger))
            if family.apf_adds is not None:
                named.append(("family_apf_adds", family.apf_adds))
            windows = family.c2_windows
            if windows is not None:
                other = windows.common if windows.in_ledger == "own" else windows.own
                named.append(("family_c2_other_window", Ledger(other, cfg.treatment)))
        if kin is not None:
            named.append(("kinematic_family", kin.ledger))
            if kin.apf_adds is not None:
                named.append(("kinematic_apf_adds", kin.apf_adds))
        if self.apf_alone is not None:
            named.append(("apf_alone", self.apf_alone.ledger))
        named += [(f"peers_{p.track}", p.ledger) for p in self.peers]
        if not named or family is None:
            return self
        first = cfg.controls[0] if cfg.controls else "baseline"
        new = dict(zip((name for name, _ in named),
                       adjust_answer(named, ("family", first), cfg), strict=True))
        family = dataclasses.replace(
            family, ledger=new["family"], apf_adds=new.get("family_apf_adds", family.apf_adds),
            c2_windows=_windows_after(family.c2_windows, new))
        if kin is not None:
            kin = dataclasses.replace(kin, ledger=new["kinematic_family"],
                                      apf_adds=new.get("kinematic_apf_adds", kin.apf_adds))
        apf_alone = dataclasses.replace(self.apf_alone, ledger=new["apf_alone"]) \
            if self.apf_alone is not None else None
        peers = tuple(dataclasses.replace(p, ledger=new[f"peers_{p.track}"]) for p in self.peers)
        nmpc = self.nmpc
        if nmpc is not None:
            # the judge of record's rows stand in for the family's in the same families
            named[0] = ("family", nmpc.ledger)
            judged = adjust_answer(named, ("family", first), cfg)[0]
            nmpc = dataclasses.replace(nmpc, ledger=judged.with_rows(tuple(
                dataclasses.replace(row, role="judge of record" if row.role == "primary"
                                    else row.role) for row in judged)))
        return dataclasses.replace(self, family=family, kinematic_family=kin,
                                   apf_alone=apf_alone, peers=peers, nmpc=nmpc)


def _windows_after(windows: C2Windows | None, new: dict[str, Ledger]) -> C2Windows | None:
    """C2's two window readings with the adjusted rows: the ledger's reading from the
    adjusted family ledger, the other from its own adjusted rows."""
    if windows is None:
        return None
    in_ledger = tuple(row for row in new["family"] if row.claim_id == "C2")
    other = new["family_c2_other_window"].rows if "family_c2_other_window" in new else ()
    own, common = (in_ledger, other) if windows.in_ledger == "own" else (other, in_ledger)
    return dataclasses.replace(windows, own=own if windows.own else (),
                               common=common if windows.common else ())


def _nmpc(nmpc: FamilyInputs, family: FamilyVerdicts | None, cfg: ClaimsConfig,
          memo: IntervalMemo | None = None) -> NmpcVerdicts:
    """The nonlinear MPC's ledger (:class:`NmpcVerdicts`): the treatment against the controls
    present, C2 on each run's own window; the linear MPC's share of steps beyond its model's
    bound per method from the default family's tables (``share_steps_beyond_bound``)."""
    own = dataclasses.replace(cfg, c2_window="own")
    tables = {m: nmpc.primary[m] for m in ordered(nmpc.primary)}
    comparisons = tuple(c for c in cfg.controls if c in tables)
    ledger = family_ledger(tables, own, None, cfg.treatment, comparisons, memo=memo)
    beyond = beyond_bound_shares(family, cfg)
    judge = any(share > cfg.nmpc_judge_share for share in beyond.values())
    return NmpcVerdicts(ledger, tuple(outcome_counts(tables)), beyond, judge)


def beyond_bound_shares(family: FamilyVerdicts | None, cfg: ClaimsConfig) -> dict[str, float]:
    """Per judged method of the default family (the treatment and its controls), the mean
    over its members of the share of steps on which the linear MPC's model left its
    small-angle bound (``share_steps_beyond_bound``; absent where no member logged it)."""
    beyond: dict[str, float] = {}
    for method, table in (family.tables.items() if family is not None else ()):
        if method in (cfg.treatment, *cfg.controls) and "share_steps_beyond_bound" in table:
            share = pd.to_numeric(table["share_steps_beyond_bound"], errors="coerce")
            if share.notna().any():
                beyond[method] = float(share.mean())
    return beyond


def track_claims(runs: TrackRuns, cfg: ClaimsConfig, comparable_only: bool = False
                  ) -> TrackClaims:
    """The claims on one track's paper scenario. With ``comparable_only`` a comparison is made
    only when both methods come within ``cfg.comparable_clearance_m`` of the obstacle:
    otherwise they did not meet the same threat and each claim but the rates is "not
    comparable"."""
    metrics = runs.metrics()
    comparisons = tuple(c for c in cfg.controls if c in runs.by_method)
    rows = claims_table(metrics, cfg.margins, comparisons, improved=cfg.treatment,
                        claims=claims_of(cfg))
    comparability = []
    if comparable_only:
        def met(method: str) -> bool:
            clearance = metrics.get(method, {}).get("min_clearance_m")
            return clearance is not None and clearance <= cfg.comparable_clearance_m

        for comparison in comparisons:
            if met(comparison) and met(cfg.treatment):
                comparability.append(f"vs {comparison}: comparable.")
                continue
            far = [m for m in (comparison, cfg.treatment) if not met(m)]
            comparability.append(f"vs {comparison}: not comparable ({', '.join(far)} never "
                                 f"came within {cfg.comparable_clearance_m:g} m).")
            for row in rows:
                if row["claim"] not in rate_claims(cfg):
                    row[f"vs {comparison}"] = "not comparable"
    return TrackClaims(tuple(rows), comparisons, tuple(comparability))


def _family(family: FamilyInputs, cfg: ClaimsConfig, paper_metrics: dict | None,
            paper_ledger: bool, memo: IntervalMemo | None = None) -> FamilyVerdicts:
    """The lateral family's ledger (with the paper scenario's column, the all-pairs
    sensitivity and C2 on both windows), or the Appendix-A track's (without them)."""
    tables = {m: family.primary[m] for m in ordered(family.primary)} if paper_ledger \
        else family.primary
    judged = (cfg.treatment, *[c for c in cfg.controls if c in tables])
    jerks = family.jerks if all(m in family.jerks for m in judged) else None
    asked = cfg.c2_window
    if jerks is None:  # C2 on a common window cannot be read: said in C2Windows' note
        cfg = dataclasses.replace(cfg, c2_window="own")
    ledger = family_ledger(tables, cfg, paper_metrics, cfg.treatment, tuple(cfg.controls),
                           sensitivity=paper_ledger, jerks=jerks, memo=memo)
    counts = outcome_counts({m: family.tables[m] for m in ordered(family.tables)}
                            if family.tables else tables) if paper_ledger else ()
    apf = family_ledger(tables, dataclasses.replace(cfg, c2_window="own"), None, "baseline",
                        ("mpc_no_apf",), sensitivity=False, memo=memo) \
        if "baseline" in tables and "mpc_no_apf" in tables else None
    windows = _c2_windows(tables, cfg, ledger, jerks, asked, memo) if paper_ledger else None
    return FamilyVerdicts(tables, ledger, tuple(counts), apf, windows)


def _c2_windows(tables: dict[str, pd.DataFrame], cfg: ClaimsConfig, ledger: Ledger,
                jerks: dict | None, asked: str, memo: IntervalMemo | None = None
                ) -> C2Windows:
    """C2's rows under each window reading (:class:`C2Windows`): the ledger's, and those of
    the whole ledger under the other reading (its Holm adjustment over every claim)."""
    ledger_rows = tuple(row for row in ledger if row.claim_id == "C2")
    if jerks is None:
        return C2Windows(cfg.common_window, "own", ledger_rows, note=(
            "the runs' lateral jerk could not be read (or their metrics record no window): "
            "C2 on a common window is not shown"
            + (", and the ledger reads C2 on each run's own window although claims.c2_window "
               "is common" if asked == "common" else "")))
    other = "common" if cfg.c2_window == "own" else "own"
    other_ledger = family_ledger(tables, dataclasses.replace(cfg, c2_window=other), None,
                                 cfg.treatment, tuple(c for c in cfg.controls if c in tables),
                                 sensitivity=False, jerks=jerks, memo=memo)
    other_rows = tuple(row for row in other_ledger if row.claim_id == "C2")
    by_reading = {cfg.c2_window: ledger_rows, other: other_rows}
    return C2Windows(cfg.common_window, cfg.c2_window, by_reading["own"],
                     by_reading["common"])


def _peers(track: str, default: FamilyInputs | None, peers: FamilyInputs | None,
           cfg: ClaimsConfig, memo: IntervalMemo | None = None) -> PeerVerdicts | None:
    """The treatment (its default family on ``track``) against each peer of ``peers``, when
    both are there and drawn with the same seed, the peer's family no larger than the
    treatment's (member i is the same scenario in both: a smaller family pairs with the
    ledger's first members); None otherwise."""
    if default is None or peers is None or cfg.treatment not in default.primary \
            or not peers.primary:
        return None

    def drawn(family: FamilyInputs, method: str) -> tuple:
        info = family.info.get(family.label_of(method) or "", {})
        return info.get("size"), info.get("seed")

    size, seed = drawn(default, cfg.treatment)
    names = tuple(m for m in ordered(peers.primary) if m != cfg.treatment
                  and drawn(peers, m)[1] == seed
                  and int(drawn(peers, m)[0] or 0) <= int(size or 0))
    if not names:
        return None
    # the treatment on the peers' scenarios only (its counts beside theirs; the pairs are the
    # same either way)
    shared = set().union(*(set(peers.primary[m]["scenario"]) for m in names))
    treated = default.primary[cfg.treatment]
    tables = {cfg.treatment: treated[treated["scenario"].isin(shared)],
              **{m: peers.primary[m] for m in names}}
    ledger = family_ledger(tables, dataclasses.replace(cfg, c2_window="own"), None,
                           cfg.treatment, names, sensitivity=False, memo=memo)
    ledger = ledger.without_claims(force_claims(cfg))
    return PeerVerdicts(track, names, ledger, tuple(outcome_counts(tables)))


def _pedestrians(family: FamilyInputs, cfg: ClaimsConfig, name: str = "default",
                 memo: IntervalMemo | None = None) -> PedestrianVerdicts | None:
    """The pedestrian ledgers (:class:`PedestrianVerdicts`) of the family ``name`` (default,
    or a variant's); None without the treatment and a control. The scene of each member is
    read from its name (``scene_of``), the scenes from the family's settings."""
    from pipeline.analysis.crowd import crowd_metrics
    from pipeline.loop.pedestrians import scene_of

    if not family.judgeable(cfg):
        return None
    # the pairs rule the treatment's family was made with (make pedestrians': unsettled_last),
    # C2 on each run's own window
    label = family.label_of(cfg.treatment)
    made_with = family.settings.get(label) if label is not None else None
    pairs = made_with.claims.pairs if made_with is not None else cfg.pairs
    own = dataclasses.replace(cfg, c2_window="own", pairs=pairs)
    scenes: list[str] = []
    for settings in family.settings.values():
        ped = settings.scenario.pedestrians
        scenes += [s for s in (ped.scenes if ped is not None else ()) if s not in scenes]
    tables = {}
    for method, table in family.primary.items():
        table = table.copy()
        table["scene"] = [scene_of(str(name), scenes) or "?" for name in table["scenario"]]
        tables[method] = table
    comparisons = tuple(c for c in cfg.controls if c in tables and c != cfg.treatment)
    present = tuple(s for s in scenes if any((t["scene"] == s).any() for t in tables.values()))
    ledger = family_ledger(tables, own, None, cfg.treatment, comparisons, sensitivity=False,
                           memo=memo)
    # by scene for the default family alone: a variant's 30 crossings leave 7-8 a scene,
    # too few for a ledger of their own (and the report's time is make pedestrians')
    by_scene = tuple((scene, family_ledger({m: t[t["scene"] == scene] for m, t in
                                            tables.items()}, own, None, cfg.treatment,
                                           comparisons, sensitivity=False, memo=memo))
                     for scene in present) if name == "default" else ()
    scene_counts = tuple({"scene": scene, **row} for scene in present
                         for row in outcome_counts({m: t[t["scene"] == scene]
                                                    for m, t in tables.items()}))
    settings = next(iter(family.settings.values()))
    ped = settings.scenario.pedestrians
    about = {"family": name, "platform": settings.vehicle.name,
             "track": "kinematic" if settings.controller.kind == "kinematic_mpc" else "lateral",
             "draw": ped.draw if ped is not None else "?",
             "walkers": ped.walkers if ped is not None else "?"}
    methods = (cfg.treatment, *comparisons)
    metrics = pd.DataFrame([{"method": m, **crowd_metrics(tables[m])} for m in methods])
    info = next(iter(family.info.values()), {})
    return PedestrianVerdicts(present, comparisons, ledger, by_scene,
                              tuple(outcome_counts(tables)), scene_counts, tables, about,
                              metrics, _difficulty(settings, info,
                                                   {m: tables[m] for m in methods}),
                              _other_pairs(ledger, tables, own, name, memo), pairs)


def _other_pairs(ledger: Ledger, tables: dict[str, pd.DataFrame], cfg: ClaimsConfig,
                    family: str, memo: IntervalMemo | None = None) -> tuple[dict, ...]:
    """The rows of ``ledger`` whose metric has a clock (C1's reaction, C4's recovery) judged
    again by the other rule of their pairs, at the row's level and margin: ``unsettled_last``
    beside a ledger of the pairs where neither collided, and ``neither_collided`` beside one
    of ``unsettled_last`` (make pedestrians'). Among walkers a run often passes every threat
    and never settles before it ends; ``neither_collided`` leaves every such pair out (C4 on
    17 of 200 crossings), ``unsettled_last`` ranks that run last."""
    from pipeline.analysis.claims.statistics import compare, judge
    from pipeline.analysis.objectives import CENSORED_AT_RUN_END

    other = "neither_collided" if cfg.pairs == "unsettled_last" else "unsettled_last"
    rows = []
    for row in ledger.rows:
        if row.claim.primary_metric not in CENSORED_AT_RUN_END:
            continue
        pair = (tables[ledger.treatment], tables[row.comparison])
        result = compare(*pair, row.claim, cfg, pairs=other,
                         level=row.result.ci_level, margin=row.margin, memo=memo)
        outcome, _ = judge(result, row.margin, cfg, row.claim)
        rows.append({"family": family, "claim": row.claim.claim_id,
                     "comparison": row.comparison, "metric": row.claim.primary_metric,
                     "pairs_rule": other, "outcome": str(outcome),
                     "pairs_rule_ledger": cfg.pairs, "outcome_ledger": str(row.outcome),
                     "estimate": result.estimate, "ci_low": result.ci_low,
                     "ci_high": result.ci_high, "ci_level": result.ci_level,
                     "n_better": result.n_better, "n_tied": result.n_tied,
                     "n_worse": result.n_worse, "pairs": result.n_pairs,
                     "pairs_ledger": row.result.n_pairs})
    return tuple(rows)


def _difficulty(settings: Any, info: dict, tables: dict[str, pd.DataFrame]) -> dict:
    """The family's difficulty from the recording alone (``crossing_difficulty`` of each
    member, as its metrics recorded it; for run folders written before they did, each member
    drawn again: the family's base is its first member's scenario with the family's name,
    seed and size from ``family.json`` and no drawn scene) and each method's collision
    rate on the crossings where a platform standing still is not touched
    (:func:`~pipeline.analysis.crowd.collision_rates`)."""
    from pipeline.analysis.crowd import collision_rates, flag_value
    from pipeline.loop.pedestrians import CrossingDifficulty, crossing_difficulty
    from pipeline.loop.scenario import family_members
    from pipeline.loop.settings import FamilyConfig

    radius = settings.vehicle.footprint_radius_m
    member, ped = settings.scenario, settings.scenario.pedestrians
    first = next(iter(tables.values()))
    recorded = {str(n): CrossingDifficulty(meets, touched) for n, meets, touched
                in zip(first["scenario"], map(flag_value, first["straight_line_meets"]),
                       map(flag_value, first["standing_touched"]), strict=True)
                if meets is not None and touched is not None} \
        if {"straight_line_meets", "standing_touched"} <= set(first.columns) else {}
    if len(recorded) == len(first):
        judged = recorded  # each run's metrics hold its crossing's difficulty
    elif ped is None or "seed" not in info or "size" not in info:
        return {}
    else:
        # run folders written before the metrics held it: the members drawn again
        base = dataclasses.replace(
            member, name=str(info.get("scenario", "pedestrians")),
            family=FamilyConfig(seed=int(info["seed"]), size=int(info["size"])),
            pedestrians=dataclasses.replace(ped, scene=None, window_start_s=None))
        judged = {m.name: crossing_difficulty(m, radius)
                  for m in family_members(base, radius)}
    names = [n for n in first["scenario"].astype(str) if n in judged]
    if not names:
        return {}
    safe = {n for n in names if not judged[n].standing_touched}
    out: dict = {"crossings": len(names),
                 "straight_line_meets_share": float(np.mean(
                     [judged[n].straight_line_meets for n in names])),
                 "standing_touched_share": float(np.mean(
                     [judged[n].standing_touched for n in names])),
                 "standing_safe_crossings": len(safe)}
    for method, table in tables.items():
        # every contact; the avoidable ones (the published label: a manoeuvre from the
        # walker's appearance or another method on the crossing avoided it); those with a
        # walker the platform had seen (not one whose recorded track began on or against it)
        (out[f"collision_rate_standing_safe_{method}"],
         out[f"collision_rate_standing_safe_avoidable_{method}"],
         out[f"collision_rate_standing_safe_seen_{method}"]) = \
            collision_rates(table[table["scenario"].astype(str).isin(safe)])
    return out


def _apf_alone(family: FamilyInputs, cfg: ClaimsConfig, default: FamilyVerdicts | None,
               default_inputs: FamilyInputs | None, memo: IntervalMemo | None = None
               ) -> ApfAloneVerdicts:
    """The ledger without the MPC's half-planes, judged as the default one (the same
    :func:`family_ledger`, settings, C2 window and all-pairs sensitivity; no paper-scenario column:
    the paper scenario runs with them), plus ``mpc_no_apf`` as a comparison: what the
    treatment's APF adds over no APF at all. The counts with the half-planes are the default
    family's, given only when it is the same family (size and seed)."""
    tables = {m: family.primary[m] for m in ordered(family.primary)}
    comparisons = tuple(dict.fromkeys(c for c in (*cfg.controls, "mpc_no_apf")
                                      if c in tables and c != cfg.treatment))
    # C2 on the window the default ledger reads it on (a common one needs the runs' jerk)
    jerks = family.jerks if all(m in family.jerks for m in (cfg.treatment, *comparisons)) \
        else None
    if jerks is None:
        cfg = dataclasses.replace(cfg, c2_window="own")
    ledger = family_ledger(tables, cfg, None, cfg.treatment, comparisons, jerks=jerks,
                           memo=memo)

    def drawn(info: dict[str, dict]) -> set[tuple]:
        return {(i.get("size"), i.get("seed")) for i in info.values()}

    same = default_inputs is not None and drawn(family.info) == drawn(default_inputs.info)
    counts_with = tuple(c for c in default.counts if c["method"] in tables) \
        if default is not None and same else ()
    return ApfAloneVerdicts(tables, ledger, comparisons, tuple(outcome_counts(tables)),
                            counts_with)


def _readings(kinematic: TrackRuns, readings: dict[str, list[LabelledRun]], cfg: ClaimsConfig
              ) -> tuple[tuple[str, dict[str, str]], ...]:
    """The paper scenario's claims on the Appendix-A track under each reading of the
    baseline (the default and ``kinematic_readings``): treatment against baseline, "not
    comparable" where either method stays farther than ``comparable_clearance_m``."""
    def outcomes(runs: Iterable[LabelledRun]) -> dict[str, str] | None:
        by = {r.method: r.metrics() for r in runs}
        if cfg.treatment not in by or "baseline" not in by:
            return None
        met = all((by[m].get("min_clearance_m") or math.inf) <= cfg.comparable_clearance_m
                  for m in (cfg.treatment, "baseline"))
        table = claims_table({m: by[m] for m in (cfg.treatment, "baseline")}, cfg.margins,
                             ("baseline",), improved=cfg.treatment, claims=claims_of(cfg))
        return {row["claim"]: row.get("vs baseline", "n/a")
                if met or row["claim"] in rate_claims(cfg) else "not comparable"
                for row in table}

    columns: list[tuple[str, dict[str, str]]] = []
    default = [r for r in kinematic.runs if r.method in (cfg.treatment, "baseline")]
    base = next((r for r in default if r.method == "baseline"), None)
    if base is not None and (o := outcomes(default)) is not None:
        columns.append((reading_of(base.config) + " (default)", o))
    for variant, variant_runs in readings.items():
        if (o := outcomes(variant_runs)) is not None:
            columns.append((variant, o))
    return tuple(columns) if len(columns) >= 2 else ()


def _validity(family: FamilyInputs, inputs: ReportInputs, cfg: ClaimsConfig,
              memo: IntervalMemo | None = None) -> ValidityVerdicts:
    tables = family.primary
    comparisons = tuple(c for c in cfg.controls if c in tables)
    default = family_ledger(tables, cfg, None, cfg.treatment, comparisons,
                            sensitivity=False, memo=memo) if cfg.treatment in tables else None
    valid = valid_scenario_ledgers(tables, cfg, cfg.treatment, comparisons, memo)
    other_frame = inputs.validity.other_frame if inputs.validity is not None else ()
    other_tables = {str(f.info.get("method")): f.table for f in other_frame}
    other = family_ledger(other_tables, cfg, None, cfg.treatment, comparisons,
                          sensitivity=False, memo=memo) if cfg.treatment in other_tables \
        else None
    return ValidityVerdicts(comparisons, default, valid, other)
