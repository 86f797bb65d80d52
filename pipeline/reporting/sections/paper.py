"""The paper scenario: the Figure 2/3 analogues, every method's metrics, the claims on that
one scenario, the solve times."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import pandas as pd
import yaml

from pipeline.analysis.claims import claims_of
from pipeline.reporting.figure import Figure, Figures
from pipeline.reporting.figures import (
    apf_force_figure,
    overlay_figure,
    paths_figure,
    timeseries_figure,
)
from pipeline.reporting.inputs import ReportInputs, TrackRuns
from pipeline.reporting.verdicts import TrackClaims, Verdicts

#: Bookkeeping, not metrics: left out of the metrics table.
NOT_METRICS = ("method", "scenario", "config_hash", "track")


@dataclass(frozen=True)
class MetricRow:
    metric: str
    values: tuple


@dataclass(frozen=True)
class TimingRow:
    method: str
    median_s: float | None
    p95_s: float | None
    max_s: float | None
    compile_s: float | None
    compiles: int | None


@dataclass(frozen=True)
class PaperSection:
    """The paper scenario on the lateral track."""

    scenario: str
    methods: tuple[str, ...]
    figures: tuple[Figure, ...]
    metric_rows: tuple[MetricRow, ...]
    timing_rows: tuple[TimingRow, ...]
    claims: tuple[dict, ...]
    comparisons: tuple[str, ...]
    claim_secondary: dict[str, str]
    configs: dict[str, str]
    hashes: dict[str, str]
    run_dirs: dict[str, str]


def metric_rows(runs: TrackRuns) -> tuple[MetricRow, ...]:
    """Every metric of every judged run, one row per metric (in ``metrics.json``'s order)."""
    metrics = runs.metrics()
    names = pd.DataFrame(metrics).index  # the order of tables/metrics_*.csv
    return tuple(MetricRow(k, tuple(metrics[m].get(k) for m in runs.methods))
                 for k in names if k not in NOT_METRICS)


def claim_rows(claims: TrackClaims, methods: list[str]) -> tuple[dict, ...]:
    """The claims' rows with each method's primary metric under ``values``."""
    return tuple({**row, "values": [row.get(m) for m in methods]} for row in claims.rows)


def paper_section(inputs: ReportInputs, verdicts: Verdicts, figures: Figures
                  ) -> PaperSection | None:
    """The section; None on a page without the paper scenario (sweeps only)."""
    runs, claims = inputs.lateral, verdicts.paper
    if runs is None or claims is None:
        return None
    cfg = verdicts.claims
    by_method = runs.by_method
    drawn = paper_figures(runs, figures, treatment=cfg.treatment,
                          control=cfg.controls[0] if cfg.controls else "baseline",
                          extras={r.label: r.trajectory for r in runs.extra})
    timing = tuple(TimingRow(m, r.timing["solve_time_median_s"], r.timing["solve_time_p95_s"],
                             r.timing["solve_time_max_s"], r.timing["compile_time_s"],
                             r.metrics().get("compile_count"))
                   for m, r in by_method.items())
    return PaperSection(
        scenario=runs.scenario, methods=tuple(runs.methods), figures=tuple(drawn),
        metric_rows=metric_rows(runs), timing_rows=timing,
        claims=claim_rows(claims, runs.methods), comparisons=claims.comparisons,
        claim_secondary={c.claim_id: ", ".join(c.secondary_metrics) for c in claims_of(cfg)},
        configs={m: yaml.safe_dump(r.config, sort_keys=False) for m, r in by_method.items()},
        hashes={m: r.record.info.config_hash for m, r in by_method.items()},
        run_dirs={m: str(r.folder) for m, r in by_method.items()})


def paper_figures(runs: TrackRuns, figures: Figures, prefix: str = "", group_prefix: str = "",
                  treatment: str = "improved", control: str = "baseline",
                  extras: dict | None = None) -> list[Figure]:
    """Figure 2/3 analogues (control above treatment, shared limits, time colours), overlay
    of every method (and of ``extras``, other runs by label, each in its own colour), time
    series with the avoidance window, APF forces."""
    by_method = runs.by_method
    first = next(iter(by_method.values())).config
    goal = tuple(first["scenario"]["goal_xy_m"])
    radius = first["vehicle"]["footprint_radius_m"]
    appear = next(iter(by_method.values())).metrics().get("obstacle_appear_time_s")
    scenario = runs.scenario
    pair = [m for m in (control, treatment) if m in by_method] or list(by_method)[:2]
    names = {control: "Figure 2 analogue", treatment: "Figure 3 analogue"} \
        if (control, treatment) == ("baseline", "improved") else {}
    titles = {m: f"{names.get(m, m)}: {m}" if m in names else m for m in pair}
    out = [figures.draw(functools.partial(
        paths_figure, {m: by_method[m].trajectory for m in pair}, goal, radius, appear,
        titles=titles), f"{prefix}trajectory_pair", f"{group_prefix}paths",
        f"{' and '.join(titles.values())} on {scenario}, on shared axes: the path; the "
        "footprint and the obstacles at the same instants in the same colour (colour bar: "
        "time from the obstacle's appearance); x where an obstacle appears; the segment at the "
        "closest approach with its clearance and time.",
        f"Paths of {' and '.join(pair)} with the obstacle at the same instants")]
    trajectories = {m: r.trajectory for m, r in by_method.items()}
    for stem, fig, caption, alt in (
            ("overlay", functools.partial(overlay_figure, {**trajectories, **(extras or {})},
                                          goal),
             "Every method's path on the same axes, each in its own colour and line style"
             + (" (other runs, not judged, labelled by what differs)" if extras else "")
             + "; the grey band is the obstacle's track while visible.",
             "Paths of all methods overlaid"),
            ("timeseries", functools.partial(timeseries_figure, trajectories, appear),
             "Steering angle, steering rate (the input), heading and lateral deviation over "
             "time; shaded: the avoidance window, from the obstacle's appearance until every "
             "vehicle has passed it.", "Time series of steering, heading and lateral deviation"),
            ("apf_forces", functools.partial(apf_force_figure, trajectories),
             "Magnitude of the APF's repulsive and attractive forces at the vehicle's position "
             "(first rollout point).", "APF force magnitudes over time")):
        out.append(figures.draw(fig, prefix + stem,
                                f"{group_prefix}{'paths' if stem == 'overlay' else 'series'}",
                                caption, alt))
    return out
