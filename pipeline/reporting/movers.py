"""The scenarios behind a verdict: per claim and comparison, the family members whose paired
difference moves the estimate most in each direction, each with the link that opens it in the
scenario explorer (:func:`explorer_href`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from pipeline.analysis.claims import ALL_CLAIMS, Claim, paired_differences
from pipeline.reporting.explorer import explorer_href

#: how many members each direction lists
MOVERS_SHOWN = 2


@dataclass(frozen=True)
class Mover:
    """One member and its paired difference d (treatment − comparison, signed so that d < 0
    is the claimed improvement)."""

    member: int
    d: float
    href: str


@dataclass(frozen=True)
class Movers:
    """The members that move one claim most: ``better`` (most negative d first) and ``worse``
    (most positive first); empty where no pair differs."""

    better: tuple[Mover, ...] = ()
    worse: tuple[Mover, ...] = ()

    @property
    def strongest(self) -> Mover | None:
        """The member with the largest |d|."""
        both = [*self.better[:1], *self.worse[:1]]
        return max(both, key=lambda m: abs(m.d)) if both else None

    def toward(self, estimate: float) -> Mover | None:
        """The member that moves the estimate's own way most (its sign; the strongest
        member when the estimate is zero or missing)."""
        if np.isfinite(estimate) and estimate < 0 and self.better:
            return self.better[0]
        if np.isfinite(estimate) and estimate > 0 and self.worse:
            return self.worse[0]
        return self.strongest


def claim_movers(treatment: pd.DataFrame, comparison: pd.DataFrame, claim: Claim,
                 experiment: str, shown: int = MOVERS_SHOWN) -> Movers:
    """The members of one pair of family tables (with ``scenario`` and ``member`` columns)
    that move ``claim`` most, on the pairs the ledger judges it on (neither collided for a
    paired claim, every pair for a rate)."""
    if "member" not in treatment or claim.primary_metric not in treatment \
            or claim.primary_metric not in comparison:
        return Movers()
    pairs = paired_differences(treatment, comparison, claim, "neither_collided")
    members = dict(zip(treatment["scenario"], treatment["member"], strict=False))
    d = pd.to_numeric(pairs["d"], errors="coerce").to_numpy(float)
    keep = np.isfinite(d) & (d != 0)
    scenarios, d = pairs["scenario"].to_numpy()[keep], d[keep]
    order = np.argsort(d, kind="stable")

    def mover(i: int) -> Mover:
        member = int(members[scenarios[i]])
        return Mover(member, float(d[i]), explorer_href(experiment, member))

    better = tuple(mover(i) for i in order[:shown] if d[i] < 0)
    worse = tuple(mover(i) for i in order[::-1][:shown] if d[i] > 0)
    return Movers(better, worse)


def ledger_movers(tables: dict[str, pd.DataFrame], treatment: str,
                  comparisons: tuple[str, ...], experiment: str,
                  claims: tuple[Claim, ...] = ALL_CLAIMS) -> dict[tuple[str, str], Movers]:
    """:func:`claim_movers` for every claim (``claims``: by default the package's catalogue)
    against every comparison present, keyed like the ledger's rows ``(claim_id,
    comparison)``."""
    if treatment not in tables:
        return {}
    return {(claim.claim_id, comparison): claim_movers(tables[treatment], tables[comparison],
                                                       claim, experiment)
            for comparison in comparisons if comparison in tables for claim in claims}
