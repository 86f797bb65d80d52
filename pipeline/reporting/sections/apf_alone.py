"""'What each APF does by itself': the claims judged on ``make reproduce``'s ``apf_alone``
families (the MPC's collision half-planes off, ``controller.collision_constraints=false``) as
their own ledger beside the default one (``tables/claims_ledger_apf_alone.csv``), the
collisions per method with and without the half-planes, and the opening summary's sentence on
what the APF and what the MPC contribute to safety."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pipeline.reporting.inputs import ReportInputs
from pipeline.reporting.movers import ledger_movers
from pipeline.reporting.sections.family import ledger_groups
from pipeline.reporting.verdicts import ApfAloneVerdicts, Verdicts

#: The peer without an APF (the same MPC tracking a straight-to-goal reference).
NO_APF = "mpc_no_apf"
#: What the opening summary says when the ``apf_alone`` families are not among the outputs.
MISSING_NOTE = ("Each APF by itself (the MPC's collision constraints off): not run here "
                "(make reproduce runs it).")


@dataclass(frozen=True)
class CollisionRow:
    """One method's collisions over the family with the MPC's half-planes (the default
    family; None when that is not the same family) and without them."""

    method: str
    scenarios: int
    without: int
    without_unavoidable: int
    with_: int | None


@dataclass(frozen=True)
class ApfAloneSection:
    """What the page shows: the family, the ledger grouped by claim, the collisions per
    method, and the sentence of the opening summary."""

    size: int
    seed: Any
    treatment: str
    comparisons: tuple[str, ...]
    ledger: tuple[dict, ...]
    collisions: tuple[CollisionRow, ...]
    sentence: str


def _name(method: str, treatment: str) -> str:
    """How the sentence names a method's reference."""
    if method == NO_APF:
        return f"no APF ({NO_APF})"
    return f"{method}'s APF alone" if method == treatment else f"{method}'s"


def _series(items: list[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def safety_sentence(rows: tuple[CollisionRow, ...], treatment: str) -> str:
    """The opening summary's sentence: how often each method collides without the MPC's
    collision constraints and with them, and which of the two does the avoiding, by rule:
    the constraints "do most of the avoiding" when by themselves (no APF) they avoid at least
    half of the collisions no APF has without them; an APF "is what avoids when they are
    absent" when by itself it avoids at least half of them."""
    if not rows:
        return ""
    n = rows[0].scenarios
    without = [f"{_name(r.method, treatment)} {'collides ' if i == 0 else ''}in {r.without}"
               + (f" of {n} scenarios" if i == 0 else "") for i, r in enumerate(rows)]
    text = "Without the MPC's collision constraints " + _series(without)
    if all(r.with_ is not None for r in rows):
        text += "; with them " + ("they collide" if len(rows) > 1 else "it collides") \
            + " in " + _series([str(r.with_) for r in rows])
    by = {r.method: r for r in rows}
    none = by.get(NO_APF)
    if none is None or none.without == 0:
        return text + "."
    clauses = []
    if none.with_ is not None:
        avoided = none.without - none.with_
        doing = "do most of the avoiding" if 2 * avoided >= none.without \
            else "avoid less than half of the collisions"
        clauses.append(f"the MPC's constraints {doing} ({avoided} of no APF's {none.without} "
                       "collisions by themselves)")
    avoiders = [r for r in rows if r.method != NO_APF
                and 2 * (none.without - r.without) >= none.without]
    if avoiders:
        names = _series([f"{r.method}'s" for r in avoiders])
        clauses.append(f"{names} APF{'s are' if len(avoiders) > 1 else ' is'} what avoids when "
                       "they are absent ("
                       + _series([f"{none.without - r.without} of {none.without}"
                                  for r in avoiders]) + ")")
    else:
        clauses.append("no APF avoids half of no APF's collisions by itself")
    return text + ": " + ", and ".join(clauses) + "."


def _rows(judged: ApfAloneVerdicts) -> tuple[CollisionRow, ...]:
    """The treatment first, then the controls, no APF last."""
    without = {c["method"]: c for c in judged.counts}
    with_ = {c["method"]: c["collisions"] for c in judged.counts_with}
    order = [judged.ledger.treatment, *[c for c in judged.comparisons if c != NO_APF]]
    order += [NO_APF] if NO_APF in without else []
    return tuple(CollisionRow(m, int(without[m]["scenarios"]), int(without[m]["collisions"]),
                              int(without[m]["collisions_unavoidable"]), with_.get(m))
                 for m in order if m in without)


def apf_alone_section(inputs: ReportInputs, verdicts: Verdicts) -> ApfAloneSection | None:
    """The section; None when the ``apf_alone`` families were not given or cannot be judged
    (the page then says so in its opening summary)."""
    judged, family = verdicts.apf_alone, inputs.apf_alone
    if judged is None or family is None:
        return None
    first: dict[str, Any] = next(iter(family.info.values()), {})
    rows = _rows(judged)
    return ApfAloneSection(
        size=int(first.get("size", rows[0].scenarios if rows else 0)),
        seed=first.get("seed", "?"), treatment=judged.ledger.treatment,
        comparisons=judged.comparisons, ledger=tuple(ledger_groups(judged.ledger, ledger_movers(
            judged.tables, judged.ledger.treatment, judged.comparisons, "apf_alone"),
            "apf-alone-ledger")),
        collisions=rows, sentence=safety_sentence(rows, judged.ledger.treatment))
