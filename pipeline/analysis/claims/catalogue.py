"""The paper's claims as data: each :class:`Claim` with its primary and secondary metrics, read
from the claim catalogue (``conf/claim/<id>.yaml``, ``claims.catalogue``:
:class:`~pipeline.analysis.settings.ClaimEntry`; :data:`ALL_CLAIMS`: the package's, C0 safety
first, then :data:`CLAIMS` C1-C5; :func:`claims_of`: a configuration's, a user's claim
included), the four outcomes (:class:`Outcome`) and the rules' text (:data:`OUTCOME_RULE`,
:data:`SINGLE_RULE`)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from pipeline.analysis.settings import ClaimEntry, ClaimsConfig, builtin_catalogue


@dataclass(frozen=True)
class Claim:
    """One claim of the paper and the metric that stands for it."""

    claim_id: str
    text: str
    primary_metric: str
    lower_is_better: bool
    secondary_metrics: tuple[str, ...]
    criterion: str = ""
    paper_description: str = ""
    paper_indicator: str = ""
    paper_improved: str = ""
    paper_original: str = ""
    definition: str = ""
    #: "paired" (a paired difference of a metric) or "rate" (a rate of events, e.g. C0)
    kind: str = "paired"
    #: the smallest effect of interest (units of the primary metric; C0: a rate difference),
    #: ``claims.catalogue.<id>.margin``, and why it is what it is
    margin: float = 0.0
    margin_reason: str = ""

    @property
    def is_rate(self) -> bool:
        return self.kind == "rate"


def claim_of(claim_id: str, entry: ClaimEntry) -> Claim:
    """The :class:`Claim` of one catalogue entry (``claims.catalogue.<claim_id>``)."""
    return Claim(claim_id, entry.text, entry.metric, entry.better == "lower",
                 tuple(entry.secondary), criterion=entry.criterion,
                 paper_description=entry.paper_description,
                 paper_indicator=entry.paper_indicator, paper_improved=entry.paper_improved,
                 paper_original=entry.paper_original, definition=entry.definition,
                 kind=entry.kind, margin=float(entry.margin or 0.0),
                 margin_reason=entry.margin_reason)


def claims_of(cfg: ClaimsConfig) -> tuple[Claim, ...]:
    """Every claim ``cfg`` judges (its catalogue: the package's, and any of a user's), in the
    catalogue's order."""
    return tuple(claim_of(claim_id, entry) for claim_id, entry in cfg.entries.items())


def force_claims(cfg: ClaimsConfig) -> tuple[str, ...]:
    """The claims of ``cfg`` that read the APF's repulsive force (``reads_apf_force``): not
    judged against the methods the paper names, none of which has one (their force columns
    are zero: C3a would "contradict" improved for any repulsion at all)."""
    return tuple(k for k, e in cfg.entries.items() if e.reads_apf_force)


#: Every claim of the package's catalogue (``conf/claim/``) in the order the report shows them:
#: safety first. A configuration's own (a user's claim added) is :func:`claims_of`.
ALL_CLAIMS: tuple[Claim, ...] = tuple(claim_of(k, e) for k, e in builtin_catalogue().items())
#: The safety claim (a rate: the collision rate), judged first.
SAFETY: Claim = next(c for c in ALL_CLAIMS if c.is_rate)
#: The paper's Table 1 claims (C1-C5, C3 as Table 2's two halves).
CLAIMS: tuple[Claim, ...] = tuple(c for c in ALL_CLAIMS if not c.is_rate)
#: Every claim's id of the package's catalogue, in that order (the ledger's rows per comparison).
CLAIM_IDS: tuple[str, ...] = tuple(c.claim_id for c in ALL_CLAIMS)
#: The claim whose primary metric a metric is (for messages).
CLAIM_OF_METRIC: dict[str, str] = {c.primary_metric: c.claim_id for c in ALL_CLAIMS}
#: The package's claims that read the APF's repulsive force (:func:`force_claims`).
FORCE_CLAIMS: tuple[str, ...] = tuple(k for k, e in builtin_catalogue().items()
                                      if e.reads_apf_force)


class Outcome(StrEnum):
    """The four outcomes of a claim over a family (:data:`OUTCOME_RULE`)."""

    SUPPORTED = "supported"
    CONTRADICTED = "contradicted"
    EQUIVALENT = "equivalent"
    INCONCLUSIVE = "inconclusive"
    #: the estimate and the probability of improvement point opposite ways
    MIXED = "mixed"


OUTCOMES = tuple(o.value for o in Outcome)

OUTCOME_RULE = (
    "per claim, d = improved - comparison on each scenario (d < 0 is the claimed improvement); "
    "C1-C5 on pairs where neither method collided (all pairs as a sensitivity), pairs with a "
    "missing value counted apart. Estimate: Hodges-Lehmann of d (claims.estimator) with a paired "
    "bootstrap interval (scipy.stats.bootstrap, BCa where defined, claims.n_resamples, seeded); "
    "C0 (a rate): the difference of collision rates with Newcombe's hybrid score interval for "
    "paired proportions (Wilson limits from scipy.stats, honest at zero events). Every interval "
    "is at the level 1 - alpha / 7 (claims.interval_adjustment: Bonferroni over the seven "
    "claims against one comparison), and the interval is the test: 'equivalent' when it lies "
    "inside (-margin, +margin); otherwise 'supported' when it lies strictly below zero, the "
    "estimate is below zero and the probability of improvement PI = P(d < 0) + P(d = 0)/2 is "
    "not below 1/2, 'contradicted' the same way round, 'mixed' when the interval excludes "
    "zero but PI points the other way (both numbers in the note), and 'inconclusive' exactly "
    "when the interval contains zero and reaches past the margin (also with fewer than "
    "claims.min_pairs pairs). An estimate of exactly 0 or an interval ending at 0 (lattice "
    "metrics) never gives a direction. For C0 the interval alone gives the direction. The "
    "paired test (Wilcoxon signed-rank with Pratt's zeros, or the sign test; C0 McNemar's exact "
    "test) is shown Holm-adjusted beside it; where it disagrees with the interval the note says "
    "so. An interval clear of zero inside the margin is a real but small effect: the note says "
    "so; a claim on which claims.floor_tie_share of the pairs tie at the metric's floor notes "
    "that neither method shows the behaviour")

SINGLE_RULE = (
    "paper scenario: 'better' if improved beats the comparison on the primary metric by at "
    "least the claim's margin, 'worse' if it trails by at least the margin, 'within margin' "
    "otherwise, 'missing' when either value is missing")
