"""The paper scenario: the Figure 2/3 analogues, every method's metrics, the claims on that
one scenario, the solve times."""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd
import yaml

from pipeline.analysis.claims import claims_of
from pipeline.methods import PRESENTATION_KEYS
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
    #: the method every other config is shown against (the treatment)
    config_reference: str = ""
    #: the other methods, in the columns of :attr:`config_diff_rows`
    config_diff_methods: tuple[str, ...] = ()
    #: every key where a method's config differs from the reference's, with the reference's
    #: value and each other method's ("" where it is the reference's; "(none)" where one has
    #: no such key); a method's name and presentation left out (:data:`NOT_RUN_KEYS`)
    config_diff_rows: tuple[tuple[str, str, tuple[str, ...]], ...] = ()
    #: each method's whole resolved config, a file beside the page (path relative to it)
    config_files: dict[str, str] = field(default_factory=dict)


def flat_config(data: object, prefix: str = "") -> dict[str, object]:
    """A nested config as ``{"planner.beta": 0.25, ...}`` (lists are values)."""
    if isinstance(data, dict):
        out: dict[str, object] = {}
        for key, value in data.items():
            out.update(flat_config(value, f"{prefix}{key}."))
        return out
    return {prefix[:-1]: data}


def config_diff(config: dict, reference: dict) -> tuple[tuple[str, str, str], ...]:
    """The keys whose values differ between ``config`` and ``reference`` (in ``config``'s
    order, then the reference's keys it lacks), each as (key, value, reference's value)."""
    mine, theirs = flat_config(config), flat_config(reference)
    missing = "(none)"
    from pipeline.reporting.format import override_value

    rows = [(k, override_value(v), override_value(theirs[k]) if k in theirs else missing)
            for k, v in mine.items() if k not in theirs or theirs[k] != v]
    rows += [(k, missing, override_value(v)) for k, v in theirs.items() if k not in mine]
    return tuple(rows)


#: What a method's config says that changes no run: its name and presentation (label,
#: citation, description, colour, order, role; the glossary and the legends show them).
NOT_RUN_KEYS = frozenset({"run.method"} | {f"run.{k}" for k in PRESENTATION_KEYS})


def config_diff_table(configs: dict[str, dict], reference: str
                      ) -> tuple[tuple[str, ...], tuple[tuple[str, str, tuple[str, ...]], ...]]:
    """One table of every method's config against ``reference``'s: the other methods, and a
    row per key where any differs (:func:`config_diff`'s order, method by method; keys in
    :data:`NOT_RUN_KEYS` left out) with the reference's value and each method's, "" where it
    equals the reference's."""
    from pipeline.reporting.format import override_value

    others = tuple(m for m in configs if m != reference)
    diffs = {m: {key: value for key, value, _ in config_diff(configs[m], configs[reference])}
             for m in others}
    theirs = flat_config(configs[reference])
    keys = list(dict.fromkeys(key for m in others for key in diffs[m] if key not in NOT_RUN_KEYS))
    return others, tuple((key, override_value(theirs[key]) if key in theirs else "(none)",
                          tuple(diffs[m].get(key, "") for m in others)) for key in keys)


def write_config_files(configs: dict[str, str], out_dir: Path) -> dict[str, str]:
    """Each method's resolved config as ``configs/<method>.yaml`` beside the page; the paths
    relative to the page."""
    from pipeline.store.files import write_text_atomic

    written = {}
    for method, text in configs.items():
        relative = f"configs/{method}.yaml"
        (out_dir / "configs").mkdir(parents=True, exist_ok=True)
        write_text_atomic(out_dir / relative, text)
        written[method] = relative
    return written


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
    configs = {m: yaml.safe_dump(r.config, sort_keys=False) for m, r in by_method.items()}
    reference = cfg.treatment if cfg.treatment in by_method else next(iter(by_method))
    diff_methods, diff_rows = config_diff_table({m: r.config for m, r in by_method.items()},
                                                reference)
    return PaperSection(
        scenario=runs.scenario, methods=tuple(runs.methods), figures=tuple(drawn),
        metric_rows=metric_rows(runs), timing_rows=timing,
        claims=claim_rows(claims, runs.methods), comparisons=claims.comparisons,
        claim_secondary={c.claim_id: ", ".join(c.secondary_metrics) for c in claims_of(cfg)},
        configs=configs,
        hashes={m: r.record.info.config_hash for m, r in by_method.items()},
        run_dirs={m: str(r.folder) for m, r in by_method.items()},
        config_reference=reference,
        config_diff_methods=diff_methods, config_diff_rows=diff_rows,
        config_files=write_config_files(configs, figures.out_dir))


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
