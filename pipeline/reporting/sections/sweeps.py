"""A sweep of parameters (``make sweep``): its summary table, metric-versus-parameter figures
and the claims' verdicts per swept value."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pipeline.reporting.figure import Figure, Figures
from pipeline.reporting.tables import sweep_table, sweep_verdicts
from pipeline.studies.results import SweepSummary


@dataclass(frozen=True)
class SweepSection:
    name: str
    dir: str
    swept: tuple[str, ...]
    columns: tuple[str, ...]
    rows: tuple[tuple, ...]
    figures: tuple[Figure, ...]
    verdict_cols: tuple[str, ...]
    verdict_rows: tuple[dict, ...]
    value_keys: str


def sweep_section(sweep: SweepSummary, figures: Figures) -> SweepSection:
    name = sweep.name
    swept = list(sweep.swept_keys)
    table = sweep_table(sweep)
    drawn: list[Figure] = []
    for files in sweep.figures():
        figure = figures.copy(
            files, f"{name}_{files['png'].stem}", f"sweep_{name}",
            f"Sweep {name}: claim metrics versus {', '.join(k for k in swept if k != 'method')}"
            " (lines: median per method, band: range over family seeds; heatmaps: median per "
            "cell).", f"Metrics versus swept parameters of sweep {name}")
        if figure is not None:  # listed by the result, so always there
            drawn.append(figure)
    verdict_rows: list[dict[str, Any]] = []
    verdict_cols: list[str] = []
    verdicts = sweep_verdicts(sweep)
    if verdicts is not None:
        pivot = verdicts.pivot_table(index="setting", columns="claim", values="verdict",
                                     aggfunc="first")
        verdict_cols = list(pivot.columns)
        verdict_rows = [{"setting": idx, "verdicts": [str(v) for v in row.values],
                         "basis": verdicts.loc[verdicts["setting"] == idx, "basis"].iloc[0]}
                        for idx, row in pivot.iterrows()]
    return SweepSection(name, str(sweep.folder), tuple(swept), tuple(table.columns),
                        tuple(tuple(r) for r in table.itertuples(index=False)), tuple(drawn),
                        tuple(verdict_cols), tuple(verdict_rows),
                        ", ".join(k for k in swept if k != "method"))
