"""'Against the methods the paper names': the treatment judged against MPC with
discrete-time CBFs, the CBF-QP safety filter, velocity obstacles and (Appendix-A track) the
dynamic window approach, on the same scenarios as each track's ledger (``make reproduce``'s
``peers`` and ``kinematic_peers`` families; ``tables/claims_ledger_peers.csv``), with each
method's collisions and solve time per step (``tables/peers_collisions.csv``), and who wins
each claim; per peer that ``make tune-peers`` tuned against the treatment, each claim's tuned
outcome beside its untuned one on that tuning's held-out family."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pipeline.reporting.format import override_value
from pipeline.reporting.inputs import ReportInputs
from pipeline.reporting.movers import ledger_movers
from pipeline.reporting.sections.family import ledger_groups
from pipeline.reporting.verdicts import PeerVerdicts, Verdicts


def peer_title(method: str, inputs: ReportInputs) -> str:
    """A peer's name on the page and the work it comes from: its runs' own ``run.label`` and
    ``run.citation`` (a peer of one's own brings them), else its preset's
    (:mod:`pipeline.methods`)."""
    from pipeline.methods import method_info

    for family in (inputs.peers, inputs.kinematic_peers):
        settings = family.settings.get(method) if family is not None else None
        if settings is not None:
            return method_info(method, settings.run).title
    return method_info(method).title


@dataclass(frozen=True)
class PeerRow:
    """One method on one track: its scenarios, collisions and solve time per step (median,
    95th percentile; None when its runs recorded none)."""

    method: str
    scenarios: int
    collisions: int
    unavoidable: int
    solve_median_ms: float | None
    solve_p95_ms: float | None
    #: the peer's own settings as its family ran them (``planner.params`` and
    #: ``controller.params``), ``key=value`` joined; empty for the treatment
    settings: str = ""


@dataclass(frozen=True)
class PeerTrack:
    """What the page shows for one track."""

    track: str
    title: str
    size: int
    seed: Any
    peers: tuple[str, ...]
    rows: tuple[PeerRow, ...]
    ledger: tuple[dict, ...]
    winners: tuple[dict, ...]


@dataclass(frozen=True)
class PeerTuned:
    """One peer's tuning against the treatment (``tune_peers/<peer>``): per claim the untuned
    outcome (both methods' presets) and the tuned one (both tuned by make tune's rules), each
    on the tuning's held-out family."""

    peer: str
    treatment: str
    heldout: int
    replicates: int
    #: why the tuning is not at the default budget or did not converge ("" when it is and did)
    label: str
    #: per claim: ``claim``, ``untuned``, ``tuned`` (the settled outcome or "not settled"),
    #: ``counts`` (each replicate's outcome, counted)
    rows: tuple[dict, ...]
    #: the peer's tuned compromise settings, one line per replicate
    settings: tuple[str, ...]
    #: the families' track: "lateral" (Section 2's lateral MPC) or "kinematic" (Appendix A)
    track: str = "lateral"


def tuned_peers(inputs: ReportInputs) -> tuple[PeerTuned, ...]:
    """Every peer tuning the report read, in the methods' order (:mod:`pipeline.methods`)."""
    from pipeline.methods import method_info

    out = []
    # a peer on the Appendix-A track is tuned as its method preset <peer>_kinematic
    for peer, result in sorted(inputs.peer_tunes.items(), key=lambda kv: (
            method_info(kv[0].removesuffix("_kinematic")).order, kv[0])):
        summary = result.summary
        rows = tuple({"claim": c.claim, "untuned": c.default, "tuned": c.tuned,
                      "counts": c.counts} for c in summary.claims)
        settings = tuple(
            f"replicate {r}: " + ", ".join(f"{k.split('.')[-1]}={v:.4g}" if isinstance(v, float)
                                           else f"{k.split('.')[-1]}={v}"
                                           for k, v in params.items())
            for r, params in sorted(summary.compromise.get(peer, {}).items()))
        replicates = len({h["replicate"] for h in summary.replicates})
        out.append(PeerTuned(peer, summary.methods[0], int(summary.families["heldout"]["size"]),
                             replicates, summary.label, rows, settings,
                             str(summary.settings.get("track", "lateral"))))
    return tuple(out)


@dataclass(frozen=True)
class PeersSection:
    """Both tracks (the lateral one first), the treatment and the peers' names."""

    treatment: str
    tracks: tuple[PeerTrack, ...]
    names: tuple[tuple[str, str], ...]
    #: the opening summary's lines, one per track
    sentences: tuple[str, ...] = ()
    #: the peers tuned against the treatment (make tune-peers), each claim tuned and untuned
    tuned: tuple[PeerTuned, ...] = ()


def winners(judged: PeerVerdicts) -> tuple[dict, ...]:
    """Per claim: the outcome against each peer, read as who wins: the treatment where the
    claim is supported, the peer where it is contradicted, "neither" where they are
    equivalent, "not settled" where the evidence does not decide."""
    by_claim: dict[str, dict[str, str]] = {}
    for row in judged.ledger:
        outcome = str(row.outcome)
        who = {"supported": judged.ledger.treatment, "contradicted": row.comparison,
               "equivalent": "neither"}.get(outcome, "not settled")
        by_claim.setdefault(row.claim_id, {})[row.comparison] = f"{who} ({outcome})"
    return tuple({"claim": claim, **outcomes} for claim, outcomes in by_claim.items())


def _track(judged: PeerVerdicts, inputs: ReportInputs) -> PeerTrack:
    family = inputs.peers if judged.track == "lateral" else inputs.kinematic_peers
    first: dict[str, Any] = next(iter(family.info.values()), {}) if family else {}
    times = inputs.solve_times.get(judged.track, {})

    def settings(method: str) -> str:
        label = family.label_of(method) if family is not None else None
        cfg = family.settings.get(label) if family is not None and label else None
        if cfg is None or method == judged.ledger.treatment:
            return ""
        params = {**{f"planner.params.{k}": v for k, v in cfg.planner.params.items()},
                  **{f"controller.params.{k}": v for k, v in cfg.controller.params.items()}}
        # as Hydra overrides read them (null, true, false: not Python's None, True, False)
        return ", ".join(f"{k}={override_value(v)}" for k, v in params.items())

    rows = tuple(PeerRow(c["method"], int(c["scenarios"]), int(c["collisions"]),
                         int(c["collisions_unavoidable"]),
                         1e3 * times[c["method"]][0] if c["method"] in times else None,
                         1e3 * times[c["method"]][1] if c["method"] in times else None,
                         settings(c["method"]))
                 for c in judged.counts)
    title = "the lateral track (the scenario family of the ledger)" if judged.track == \
        "lateral" else "the Appendix-A track (its family)"
    return PeerTrack(judged.track, title, int(first.get("size", rows[0].scenarios if rows
                                                        else 0)),
                     first.get("seed", "?"), judged.peers, rows,
                     tuple(ledger_groups(judged.ledger, _movers(judged, inputs),
                                         f"peers-{judged.track}-ledger")),
                     winners(judged))


def _movers(judged: PeerVerdicts, inputs: ReportInputs) -> dict:
    """The members that move each claim most against each peer (opened in the peers'
    experiment: member i is the same scenario as in the default family)."""
    family = inputs.peers if judged.track == "lateral" else inputs.kinematic_peers
    default = inputs.family if judged.track == "lateral" else inputs.kinematic_family
    treatment = judged.ledger.treatment
    if family is None or default is None or treatment not in default.primary:
        return {}
    tables = {treatment: default.primary[treatment],
              **{m: family.primary[m] for m in judged.peers if m in family.primary}}
    return ledger_movers(tables, treatment, judged.peers,
                         "peers" if judged.track == "lateral" else "kinematic_peers")


def peers_section(inputs: ReportInputs, verdicts: Verdicts) -> PeersSection | None:
    """The section; None when no peer family was given or could be judged."""
    if not verdicts.peers:
        return None
    tracks = tuple(_track(judged, inputs) for judged in verdicts.peers)
    shown = dict.fromkeys(m for t in tracks for m in t.peers)
    return PeersSection(verdicts.claims.treatment, tracks,
                        tuple((m, peer_title(m, inputs)) for m in shown),
                        tuple(summary_sentence(judged, t.size)
                              for judged, t in zip(verdicts.peers, tracks, strict=True)),
                        tuned_peers(inputs))


def summary_sentence(judged: PeerVerdicts, size: int) -> str:
    """One line for the opening summary: per peer, each claim's outcome."""
    track = "lateral track" if judged.track == "lateral" else "Appendix-A track"
    per_peer = []
    for peer in judged.peers:
        outcomes = [f"{row.claim_id} {row.outcome}" for row in judged.ledger
                    if row.comparison == peer]
        per_peer.append(f"vs {peer} " + ", ".join(outcomes))
    return (f"Against the methods the paper names ({track}, {size} scenarios, their presets' "
            f"settings): {judged.ledger.treatment} " + "; ".join(per_peer) + ".")
