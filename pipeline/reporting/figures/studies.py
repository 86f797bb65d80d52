"""Figures of the studies' results: sweeps, ablations, Pareto fronts, the benchmark's
scaling, the multiverse's specification curves."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")  # files only, no display

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from pipeline.reporting.figures.colors import method_color

SWEEP_METRICS = ("reaction_delay_s", "lateral_jerk_rms_mps3", "repulsion_unneeded_share",
                 "recovery_time_s", "oscillation_count", "min_clearance_m")


def _sortable(values: pd.Series) -> pd.Series:
    numeric = pd.to_numeric(values, errors="coerce")
    return numeric if numeric.notna().all() else values.astype(str)


def sweep_figure(summary: pd.DataFrame, swept: list[str]) -> list[tuple[Figure, str]]:
    """Metric versus swept parameter: lines per method (band over family seeds) for one swept
    key, heatmaps for two. Returns ``(figure, file stem)`` pairs (none for other cases)."""
    params = [k for k in swept if k not in ("method", "run.method", "planner",
                                            "scenario.family.seed")]
    metrics = [m for m in SWEEP_METRICS if m in summary]
    methods = list(summary["method"].unique()) if "method" in summary else ["all"]
    out = []
    if len(params) == 1 and metrics:
        key = params[0]
        fig, axes = plt.subplots(1, len(metrics), figsize=(2.8 * len(metrics), 3.2),
                                 layout="constrained", squeeze=False)
        for ax, metric in zip(axes[0], metrics, strict=True):
            for method in methods:
                part = summary if method == "all" else summary[summary["method"] == method]
                x = _sortable(part[key])
                grouped = part.assign(_x=x).groupby("_x")[metric]
                centre = grouped.median()
                ax.plot(centre.index, centre.values, marker="o", color=method_color(method),
                        label=method)
                if "scenario.family.seed" in swept:
                    ax.fill_between(centre.index, grouped.min().values, grouped.max().values,
                                    color=method_color(method), alpha=0.2)
            ax.set_xlabel(key, fontsize=8)
            ax.set_title(metric, fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(True, alpha=0.3)
        axes[0][0].legend(fontsize=7)
        out.append((fig, "sweep_lines"))
    elif len(params) == 2 and metrics:
        for method in methods:
            part = summary if method == "all" else summary[summary["method"] == method]
            fig, axes = plt.subplots(1, len(metrics), figsize=(3.0 * len(metrics), 3.0),
                                     layout="constrained", squeeze=False)
            for ax, metric in zip(axes[0], metrics, strict=True):
                grid = part.assign(_a=_sortable(part[params[0]]), _b=_sortable(part[params[1]])) \
                    .pivot_table(index="_a", columns="_b", values=metric, aggfunc="median")
                image = ax.imshow(grid.to_numpy(float), origin="lower", aspect="auto",
                                  cmap="viridis")
                ax.set_xticks(range(grid.shape[1]), [str(v) for v in grid.columns], fontsize=7)
                ax.set_yticks(range(grid.shape[0]), [str(v) for v in grid.index], fontsize=7)
                ax.set_xlabel(params[1], fontsize=8)
                ax.set_ylabel(params[0], fontsize=8)
                ax.set_title(f"{metric}", fontsize=8)
                fig.colorbar(image, ax=ax, shrink=0.8)
            fig.suptitle(f"method: {method}", fontsize=9)
            out.append((fig, f"sweep_heatmap_{method}"))
    return out


def ablation_forest_figure(effects: pd.DataFrame, reference: str = "baseline",
                           bundle: str = "improved") -> Figure:
    """Forest plot: paired effect versus ``reference`` (95 % CI) of each configuration, one
    panel per claim; left of zero is the paper's claimed direction."""
    claims = list(dict.fromkeys(effects["claim"]))
    configs = list(dict.fromkeys(effects["configuration"]))
    fig, axes = plt.subplots(1, len(claims), figsize=(2.6 * len(claims), 0.32 * len(configs) + 1.6),
                             layout="constrained", sharey=True, squeeze=False)
    y = np.arange(len(configs))[::-1]
    colors = ["#1f77b4" if c == bundle else "#2ca02c" if c.startswith("baseline+")
              else "#ff7f0e" for c in configs]
    for ax, claim in zip(axes[0], claims, strict=True):
        part = effects[effects["claim"] == claim].set_index("configuration").reindex(configs)
        med = part["effect"].to_numpy(float)
        low, high = part["ci_low"].to_numpy(float), part["ci_high"].to_numpy(float)
        finite = np.concatenate([v[np.isfinite(v)] for v in (med, low, high)])
        span = max(np.max(np.abs(finite)) if finite.size else 1.0, 1e-9) * 1.1
        med, low, high = (np.clip(v, -span, span) for v in (med, low, high))
        for yi, m, lo, hi, color in zip(y, med, low, high, colors, strict=True):
            ax.plot([lo, hi], [yi, yi], color=color, lw=2)
            ax.plot([m], [yi], "o", color=color, ms=5)
        ax.axvline(0.0, color="k", lw=0.8)
        ax.set_title(f"{claim}: {part['metric'].iloc[0]}", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, axis="x", alpha=0.3)
    axes[0][0].set_yticks(y, configs, fontsize=7)
    fig.supxlabel(f"median paired effect vs {reference} (95 % CI); < 0 = the claimed improvement",
                  fontsize=8)
    return fig


def pareto_front_figure(points: dict[str, np.ndarray], labels: list[str],
                        title: str) -> Figure:
    """The Pareto settings of each tuned method on shared axes, one panel per pair of
    objectives (smaller is better on every axis unless its label says otherwise).

    Parameters
    ----------
    points : dict of method -> ndarray, shape (n, k)
        Objective values of each method's Pareto settings.
    labels : list of str
        The ``k`` objectives' labels.
    """
    k = len(labels)
    pairs = [(a, b) for a in range(k) for b in range(a + 1, k)] or [(0, 0)]
    fig, axes = plt.subplots(1, len(pairs), figsize=(3.4 * len(pairs), 3.3),
                             layout="constrained", squeeze=False)
    markers = ("o", "s", "^", "D")
    for ax, (a, b) in zip(axes[0], pairs, strict=True):
        for n, (method, values) in enumerate(points.items()):
            values = np.asarray(values, float).reshape(-1, k)
            ax.scatter(values[:, a], values[:, b], s=28, marker=markers[n % len(markers)],
                       color=method_color(method), edgecolor="k", linewidth=0.4, alpha=0.85,
                       label=f"{method} ({len(values)})")
        ax.set_xlabel(labels[a], fontsize=8)
        ax.set_ylabel(labels[b], fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=7, loc="best")
    fig.suptitle(f"Pareto settings of each tuned method, {title}", fontsize=9)
    return fig


def hypervolume_history_figure(histories: list[dict], window: int) -> Figure:
    """Each method's feasible-front hypervolume against its complete trials, one line per
    replicate, the point where it converged marked (an open end: stopped by the cap).

    Parameters
    ----------
    histories : list of dict
        ``{"replicate", "method", "hypervolume": [...], "converged_at": int | None}``.
    window : int
        The convergence window in trials (drawn as a bracket before each stop).
    """
    methods = list(dict.fromkeys(h["method"] for h in histories))
    fig, axes = plt.subplots(1, len(methods), figsize=(4.2 * len(methods), 3.2),
                             layout="constrained", squeeze=False, sharey=True)
    for ax, method in zip(axes[0], methods, strict=True):
        for h in (h for h in histories if h["method"] == method):
            values = np.asarray(h["hypervolume"], float)
            trials = np.arange(1, values.size + 1)
            line, = ax.plot(trials, values, lw=1.1, label=f"replicate {h['replicate']}")
            stop = h.get("converged_at")
            if stop:
                ax.plot([stop], [values[stop - 1]], "o", color=line.get_color(), ms=4)
                ax.plot([max(stop - window, 1), stop], [values[stop - 1]] * 2, "-",
                        color=line.get_color(), lw=3, alpha=0.3)
            elif values.size:
                ax.plot([values.size], [values[-1]], "x", color=line.get_color(), ms=6)
        ax.set_title(f"{method}", fontsize=9, color=method_color(method))
        ax.set_xlabel("complete trials", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("hypervolume (fixed bounds)", fontsize=8)
    axes[0][0].legend(fontsize=7, loc="lower right")
    fig.suptitle(f"Front hypervolume per replicate (dot: converged, band: the last {window} "
                 "trials; cross: stopped by the cap)", fontsize=9)
    return fig


def bench_scaling_figure(lateral: pd.DataFrame) -> Figure:
    """``make bench``'s scaling plot: the controller step (APF + QP; the direct and the CVXPY
    backend) and Clarabel's floor against the horizon, one line per obstacle count (the
    benchmark's ``lateral`` table, one row per timed QP)."""
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.4), layout="constrained")
    for n_obs, part in lateral.groupby("obstacles"):
        med = part.groupby("N")[["cvxpy_step_s", "direct_step_s", "floor_s"]].median() * 1e3
        axes[0].plot(med.index, med["direct_step_s"], marker="o", label=f"direct, {n_obs} obs")
        axes[0].plot(med.index, med["cvxpy_step_s"], marker="s", ls="--",
                     label=f"cvxpy, {n_obs} obs")
        axes[1].plot(med.index, med["floor_s"], marker="^", label=f"floor, {n_obs} obs")
    for ax, title in zip(axes, ("controller step (APF + QP) [ms]", "Clarabel floor [ms]"), strict=True):
        ax.set_xlabel("horizon N")
        ax.set_title(title, fontsize=9)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    return fig


#: The specification curve's colour of each outcome.
OUTCOME_COLORS = {"supported": "#2ca02c", "contradicted": "#d62728", "equivalent": "#7f7f9f",
                  "inconclusive": "#e0a000", "mixed": "#9467bd"}


def specification_curve_figure(specifications: pd.DataFrame, changed: pd.DataFrame,
                               claim: str) -> Figure:
    """Specification curve of one claim: estimates with intervals, sorted, coloured by outcome,
    per comparison; below, the indicator matrix of the non-default choices.

    Parameters
    ----------
    specifications : DataFrame
        Every specification's ledger rows with its design (``spec_id``, ``kind``, ``claim``,
        ``comparison``, ``estimate``, ``ci_low``, ``ci_high``, ``outcome``, ``margin``).
    changed : DataFrame
        Indexed by ``spec_id``, one boolean column per dimension (in the space's order): the
        specification's choice differs from the default.
    """
    part = specifications[specifications["claim"] == claim]
    comparisons = list(dict.fromkeys(part["comparison"]))
    dims = list(changed.columns)
    fig, axes = plt.subplots(len(comparisons) + 1, 1, figsize=(11.0, 2.4 * len(comparisons)
                                                                + 0.22 * len(dims) + 1.0),
                             layout="constrained", squeeze=False,
                             gridspec_kw={"height_ratios": [2.2] * len(comparisons)
                                          + [0.22 * len(dims) + 0.4]})
    order = None
    for ax, comparison in zip(axes[:-1, 0], comparisons, strict=True):
        rows = part[part["comparison"] == comparison].copy()
        if order is None:
            rows = rows.sort_values("estimate", na_position="first").reset_index(drop=True)
            order = rows["spec_id"].tolist()
        else:
            rows = rows.set_index("spec_id").loc[order].reset_index()
        _draw_curve(ax, rows, comparison)
    first = axes[0, 0]
    first.set_title(f"{claim}: specification curve over {len(order or [])} specifications "
                    "(estimate d = improved - comparison, CI at 1 - alpha/7; grey band: margin)",
                    fontsize=9)
    _draw_choice_matrix(axes[-1, 0], changed, order or [], dims)
    return fig


def _draw_curve(ax, rows: pd.DataFrame, comparison: str) -> None:
    """One comparison's estimates and intervals in the specifications' order, coloured by
    outcome, with the default, zero and the margin's band."""
    x = np.arange(len(rows))
    for outcome, color in OUTCOME_COLORS.items():
        sel = rows["outcome"] == outcome
        if sel.any():
            ax.vlines(x[sel], rows["ci_low"][sel], rows["ci_high"][sel], color=color,
                      alpha=0.5, lw=1.2)
            ax.scatter(x[sel], rows["estimate"][sel], s=10, color=color, label=outcome,
                       zorder=3)
    default = rows.index[rows["kind"] == "default"]
    if len(default):
        ax.axvline(default[0], color="k", lw=0.8, ls=":", label="default")
    ax.axhline(0.0, color="k", lw=0.6)
    margin = float(rows["margin"].iloc[0]) if len(rows) else 0.0
    ax.axhspan(-margin, margin, color="#dddddd", alpha=0.5, lw=0)
    ax.set_ylabel(f"d vs {comparison}", fontsize=8)
    ax.set_xlim(-1, len(rows))
    ax.set_xticks([])
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7, ncol=5, loc="upper left")


def _draw_choice_matrix(matrix, changed: pd.DataFrame, order: list, dims: list) -> None:
    """The indicator matrix: a mark where a specification's choice is away from its default."""
    spec_rows = changed.loc[order]
    for i, dim in enumerate(dims):
        xs = np.nonzero(spec_rows[dim].to_numpy())[0]
        matrix.scatter(xs, np.full(xs.size, i), marker="|", s=40, color="#1f77b4")
    matrix.set_yticks(range(len(dims)))
    matrix.set_yticklabels(dims, fontsize=6)
    matrix.set_ylim(-0.7, len(dims) - 0.3)
    matrix.set_xlim(-1, len(order))
    matrix.set_xlabel("specifications, sorted by the estimate against the first comparison; "
                      "a mark: a choice away from its default", fontsize=7)
    matrix.tick_params(axis="x", labelsize=7)
