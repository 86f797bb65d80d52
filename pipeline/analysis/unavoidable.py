"""The published collision label: "unavoidable" only where no manoeuvre tried by the per-run
oracle and no method in the ledger avoided the collision.

Each run labels its own collision (``collision_avoidable`` in its ``metrics.json``) by a sampled
reachability check from its state at the colliding obstacle's appearance
(:func:`pipeline.analysis.metrics.geometry.collision_is_avoidable`). A run cannot know the
others, so that label can call a collision unavoidable that another method, started on the same
scenario (same track, same family seed and member index), did not have: it came to the
obstacle at another speed, on another path. This stage, run where every method's table of a
track is known (the report's inputs), pools those tables and labels a collision unavoidable
only when the run's own check says so *and* every method of the pool collided on that scenario
too. ``unavoidable`` therefore means: no manoeuvre the oracle tried from the run's state at the
appearance avoided it, and no method in the ledger that ran the same scenario from the same
start avoided it. A method "avoided" a scenario when its run there ended without a collision
(within the run's length, goal reached or not).

Columns added to every table (the run's ``collision_avoidable`` is overwritten by the
published label, so every count read from the table uses it):

* ``collision_unavoidable_run``: the run's own label (True / False on a collision, None
  without one);
* ``collision_unavoidable``: the published label (the same, except False where a method of the
  pool avoided the scenario);
* ``collision_avoided_by``: the methods of the pool that ran the scenario without a collision
  (``"; "``-separated, in the pool's order; empty when none did or the run did not collide).
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping

import pandas as pd

from pipeline.analysis.tally import collided, optional_flags

#: The run's own label (what its metrics.json says), the published label, and who avoided it.
RUN_LABEL = "collision_unavoidable_run"
LABEL = "collision_unavoidable"
AVOIDED_BY = "collision_avoided_by"
#: The column naming a scenario: a family's member is ``family_s<seed>_i<index>``, the same
#: scenario in every family of that seed (and the same scenario settings, see ``pools``).
SCENARIO = "scenario"


def _keys(table: pd.DataFrame) -> pd.Series:
    """The scenario of each row (its name; the member index when the table has no name)."""
    column = SCENARIO if SCENARIO in table else "member"
    return table[column].astype(str)


def run_labels(table: pd.DataFrame) -> pd.Series:
    """Per row, the run's own label: True (unavoidable) / False (avoidable) on a collision, None
    without one or where the run did not label it."""
    hit = collided(table)
    avoidable = optional_flags(table, "collision_avoidable")
    return pd.Series([(not a) if h and a is not None else None
                      for h, a in zip(hit, avoidable, strict=True)],
                     index=table.index, dtype=object)


def label_across_methods(tables: Mapping[str, pd.DataFrame],
                         vouchers: tuple[str, ...] | None = None,
                         pools: Mapping[str, Hashable] | None = None
                         ) -> dict[str, pd.DataFrame]:
    """Every table with the published collision label (see the module docstring).

    Parameters
    ----------
    tables : mapping of str to DataFrame
        Per-scenario tables (columns ``scenario``, ``collision``, ``collision_avoidable``), by
        the name the reason gives the method (e.g. ``"vo"``, ``"improved (apf_alone)"``).
    vouchers : tuple of str, optional
        The tables whose runs can show a scenario avoidable (the methods of the ledger: the
        judged family of each method); every table by default. The others are labelled but
        vouch for nothing.
    pools : mapping of str to hashable, optional
        The scenario family each table was drawn from (e.g. its track and its first member's
        scenario settings): tables of different pools never vouch for each other, a scenario
        of the same name there being another one. One pool by default.

    Returns
    -------
    dict of str to DataFrame
        Copies of ``tables`` (same order) with ``collision_unavoidable_run``,
        ``collision_unavoidable``, ``collision_avoided_by`` and ``collision_avoidable`` set to
        the published label.
    """
    vouching = tuple(tables) if vouchers is None else tuple(n for n in vouchers if n in tables)
    pool_of = {name: (pools or {}).get(name) for name in tables}
    # per pool and scenario: the vouching methods that ran it without a collision
    avoided: dict[tuple[Hashable, str], list[str]] = {}
    for name in vouching:
        table = tables[name]
        clean = ~collided(table) & table["collision"].notna() if "collision" in table \
            else pd.Series(False, index=table.index)
        for key in _keys(table)[clean.to_numpy()]:
            avoided.setdefault((pool_of[name], key), []).append(name)
    out: dict[str, pd.DataFrame] = {}
    for name, table in tables.items():
        table = table.copy()
        # a table labelled before keeps its runs' own labels (its collision_avoidable is the
        # published one by then): labelling again gives the same table
        own = optional_flags(table, RUN_LABEL) if RUN_LABEL in table else run_labels(table)
        by = [[m for m in avoided.get((pool_of[name], key), []) if m != name]
              if label is not None else [] for key, label in zip(_keys(table), own, strict=True)]
        final = [None if label is None else bool(label) and not others
                 for label, others in zip(own, by, strict=True)]
        table[RUN_LABEL] = own
        table[LABEL] = pd.Series(final, index=table.index, dtype=object)
        table[AVOIDED_BY] = ["; ".join(others) for others in by]
        table["collision_avoidable"] = pd.Series(
            [None if f is None else not f for f in final], index=table.index, dtype=object)
        out[name] = table
    return out


def collision_rows(tables: Mapping[str, pd.DataFrame]) -> pd.DataFrame:
    """One row per collision of the labelled ``tables``: the table's name, the scenario, the
    run's label, the published label and the methods that avoided it."""
    frames = []
    for name, table in tables.items():
        hit = collided(table).to_numpy()
        if not hit.any() or LABEL not in table:
            continue
        frames.append(pd.DataFrame({"method": name, "scenario": _keys(table)[hit].to_numpy(),
                                    RUN_LABEL: table[RUN_LABEL][hit].to_numpy(),
                                    LABEL: table[LABEL][hit].to_numpy(),
                                    AVOIDED_BY: table[AVOIDED_BY][hit].to_numpy()}))
    columns = ["method", "scenario", RUN_LABEL, LABEL, AVOIDED_BY]
    return pd.concat(frames, ignore_index=True)[columns] if frames \
        else pd.DataFrame(columns=columns)
