"""The answer's family-wise rule: one declared primary comparison per claim, every other row
secondary, Holm over all of a claim's rows in the answer.

The answer publishes many ledgers (the two controls, the APF by itself, the Appendix-A track,
the methods the paper names, the baseline against no APF, C2 on a common window). Within one
comparison the seven claims share ``alpha`` (each interval at ``1 - alpha / 7``,
:func:`~pipeline.analysis.claims.statistics.interval_level`); across comparisons nothing was
adjusted, so a direction found in the fifth comparison tried was as strong as the first. Here
each claim is its own family at level ``alpha / 7`` (the claims' Bonferroni share): Holm's
step-down over the paired tests' p-values of every row of that claim in the answer (Wilcoxon
signed-rank, McNemar's exact test for C0: analytic, no Monte-Carlo error). A row keeps a
direction (supported, contradicted, mixed) only when its interval excludes zero *and* its
Holm-adjusted p-value is below ``alpha / 7``; otherwise it reads inconclusive and says why.
Equivalence is read off the interval as before (it claims no direction). Holm rather than
Bonferroni intervals at ``1 - alpha / (7 m)``: the outcomes are read from intervals, and a
bootstrap interval at such levels rests on a handful of resamples beyond each end; Holm's gate
on the analytic tests keeps the intervals where they are trustworthy and is never less strict
than the intervals alone.

The primary comparison (``claims.controls[0]``, ref. [18]'s baseline, on the default family)
carries the headline; it is inside the family too (its p-values are usually the smallest, so it
is usually judged first at ``alpha / (7 m)``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

from pipeline.analysis.claims.catalogue import Outcome
from pipeline.analysis.claims.ledger import Ledger, LedgerRow
from pipeline.analysis.claims.statistics import holm
from pipeline.analysis.settings import ClaimsConfig

#: the outcomes that claim a direction (what the gate may withdraw)
DIRECTIONS = (Outcome.SUPPORTED, Outcome.CONTRADICTED, Outcome.MIXED)


def claim_level(cfg: ClaimsConfig) -> float:
    """Each claim's share of the answer's family-wise error rate: ``alpha / 7`` (the
    catalogue's claims; ``alpha`` with ``claims.interval_adjustment: none``)."""
    return cfg.alpha if cfg.interval_adjustment == "none" else cfg.alpha / len(cfg.entries)


def adjust_answer(ledgers: Sequence[tuple[str, Ledger]], primary: tuple[str, str],
                  cfg: ClaimsConfig) -> list[Ledger]:
    """The answer's ledgers after the family-wise rule (see the module docstring).

    Parameters
    ----------
    ledgers : sequence of (name, Ledger)
        Every ledger the answer publishes, by a name (``family``, ``apf_alone``, ...).
    primary : (name, comparison)
        The ledger and comparison that carry the headline (role ``primary``).
    cfg : ClaimsConfig

    Returns
    -------
    list of Ledger
        The same ledgers in the same order, each row with its role, ``p_holm_claim`` (Holm
        over the claim's rows with a p-value), ``holm_family_size``, ``outcome_unadjusted``
        and, where the gate withdrew a direction, ``inconclusive`` with the reason in its note.
    """
    level = claim_level(cfg)
    places = [(i, j, row) for i, (_, ledger) in enumerate(ledgers)
              for j, row in enumerate(ledger.rows)]
    adjusted: dict[tuple[int, int], LedgerRow] = {}
    for claim in dict.fromkeys(row.claim_id for _, _, row in places):
        members = [(i, j, row) for i, j, row in places if row.claim_id == claim]
        p_values = [row.result.p_value if row.result.n_pairs >= cfg.min_pairs else math.nan
                    for _, _, row in members]
        family_size = sum(1 for p in p_values if math.isfinite(p))
        for (i, j, row), p_claim in zip(members, holm(p_values), strict=True):
            role = "primary" if (ledgers[i][0], row.comparison) == primary else "secondary"
            before = row.outcome_unadjusted or row.outcome
            outcome, note = before, row.note
            if before in DIRECTIONS and not p_claim < level:
                outcome = Outcome.INCONCLUSIVE
                reason = (f"not after multiplicity: {before} alone, but Holm over the "
                          f"{family_size} rows of {claim} in the answer gives p = "
                          f"{p_claim:.2g}, not below alpha/7 = {level:.3g}")
                note = f"{note}; {reason}" if note else reason
            adjusted[(i, j)] = dataclasses.replace(
                row, outcome=outcome, note=note, role=role, outcome_unadjusted=before,
                p_holm_claim=float(p_claim), holm_family_size=family_size)
    return [ledger.with_rows(tuple(adjusted[(i, j)] for j in range(len(ledger.rows))))
            for i, (_, ledger) in enumerate(ledgers)]
