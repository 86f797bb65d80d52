"""'Runs given': which run of each method the claims judge (when several were given), the
other runs (shown, never judged) and every folder passed over with its reason."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from pipeline.reporting.inputs import ReportInputs

#: The columns of an other run's row.
OTHER_RUN_METRICS = ("collision", "min_clearance_m", "reaction_delay_s", "recovery_time_s",
                     "time_to_goal_s")


@dataclass(frozen=True)
class RunsGivenSection:
    notes: tuple[str, ...]
    other_runs: tuple[dict, ...]
    skipped: tuple[dict, ...]


def runs_given_section(inputs: ReportInputs, skipped) -> RunsGivenSection:
    """The section (``skipped``: every folder passed over, the report's too)."""
    notes = []
    if inputs.lateral is not None:
        notes += list(inputs.lateral.notes)
    if inputs.family is not None:
        notes += list(inputs.family.notes)
    others = tuple({"label": r.label, "scenario": r.scenario, "track": r.track,
                    "folder": str(r.folder),
                    "values": [r.metrics().get(k) for k in OTHER_RUN_METRICS]}
                   for r in inputs.other_runs)
    rows = []
    for item in skipped:
        try:
            where = str(Path(item.folder).relative_to(inputs.run_root))
        except ValueError:
            where = str(item.folder)
        rows.append({"folder": where, "reason": item.reason})
    return RunsGivenSection(tuple(notes), others, tuple(rows))
