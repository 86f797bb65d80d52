"""Figures stage: matplotlib figures from logged runs (never shown on screen).

Each ``*_figure`` function takes run data and returns a ``matplotlib.figure.Figure``;
:func:`save_figure` writes it as SVG and PNG. Nothing here simulates.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only, no display

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Circle  # noqa: E402

METHOD_COLORS = {"baseline": "#d62728", "improved": "#1f77b4", "velocity_aware": "#2ca02c",
                 "mpc_no_apf": "#9467bd", "apf_pursuit": "#8c564b"}


def method_color(method: str) -> str:
    return METHOD_COLORS.get(method, "#7f7f7f")


def _obstacle_indices(trajectory: pd.DataFrame) -> list[int]:
    j, out = 0, []
    while f"obs{j}_x_m" in trajectory.columns:
        out.append(j)
        j += 1
    return out


def trajectory_figure(trajectory: pd.DataFrame, method: str, goal_xy_m: tuple[float, float],
                      vehicle_radius_m: float, snapshot_times_s: tuple[float, ...] = (3.0, 4.0,
                                                                                      5.0, 6.0),
                      title: str | None = None, limits: tuple | None = None) -> Figure:
    """Figure 2/3 analogue: vehicle path, obstacle where it was at several times, start, goal.

    Parameters
    ----------
    trajectory : DataFrame
        A run's ``trajectory.csv``.
    method : str
    goal_xy_m : tuple
    vehicle_radius_m : float
        Drawn as the vehicle's footprint at the snapshot times.
    snapshot_times_s : tuple of float
        Times at which obstacle and vehicle are drawn (only while the obstacle is visible).
    limits : tuple, optional
        ``(xmin, xmax, ymin, ymax)`` so that several panels share axes.
    """
    fig, ax = plt.subplots(figsize=(7.0, 3.6), layout="constrained")
    t = trajectory["time_s"].to_numpy(float)
    color = method_color(method)
    ax.plot(trajectory["X_m"], trajectory["Y_m"], color=color, lw=2, label=f"{method} path")
    cmap = plt.get_cmap("Greys")
    for n, ts in enumerate(snapshot_times_s):
        k = int(np.argmin(np.abs(t - ts)))
        if abs(t[k] - ts) > 0.051:
            continue
        shade = 0.35 + 0.6 * n / max(len(snapshot_times_s) - 1, 1)
        ax.add_patch(Circle((trajectory["X_m"].iloc[k], trajectory["Y_m"].iloc[k]),
                            vehicle_radius_m, fill=False, ls=":", color=color, alpha=0.8))
        for j in _obstacle_indices(trajectory):
            if not bool(trajectory[f"obs{j}_visible"].iloc[k]):
                continue
            centre = (trajectory[f"obs{j}_x_m"].iloc[k], trajectory[f"obs{j}_y_m"].iloc[k])
            ax.add_patch(Circle(centre, trajectory[f"obs{j}_radius_m"].iloc[k],
                                color=cmap(shade), alpha=0.9))
            ax.annotate(f"{t[k]:.1f} s", centre, textcoords="offset points", xytext=(10, 0),
                        fontsize=7)
    ax.plot(trajectory["X_m"].iloc[0], trajectory["Y_m"].iloc[0], "ko", label="start")
    ax.plot(*goal_xy_m, marker="*", color="gold", mec="k", ms=14, ls="none", label="goal")
    ax.axhline(0.0, color="k", lw=0.5, ls="--")
    ax.set_aspect("equal", adjustable="box" if limits is not None else "datalim")
    if limits is not None:
        ax.set_xlim(limits[0], limits[1])
        ax.set_ylim(limits[2], limits[3])
    ax.set_xlabel("X [m]")
    ax.set_ylabel("Y [m]")
    ax.set_title(title or f"{method}: path and obstacle (grey, darker = later)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower left", fontsize=8)
    return fig


def overlay_figure(runs: dict[str, pd.DataFrame], goal_xy_m: tuple[float, float]) -> Figure:
    """All methods' paths on one axes, with the obstacle's track."""
    fig, ax = plt.subplots(figsize=(7.0, 3.6), layout="constrained")
    for method, tr in runs.items():
        ax.plot(tr["X_m"], tr["Y_m"], color=method_color(method), lw=2, label=method)
    first = next(iter(runs.values()))
    for j in _obstacle_indices(first):
        vis = first[f"obs{j}_visible"].astype(bool)
        ax.plot(first.loc[vis, f"obs{j}_x_m"], first.loc[vis, f"obs{j}_y_m"], color="0.4",
                lw=6, alpha=0.35, solid_capstyle="round", label="obstacle track" if j == 0 else None)
    ax.plot(*goal_xy_m, marker="*", color="gold", mec="k", ms=14, ls="none", label="goal")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("X [m]")
    ax.set_ylabel("Y [m]")
    ax.set_title("Paths of all methods")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def timeseries_figure(runs: dict[str, pd.DataFrame], appear_time_s: float | None) -> Figure:
    """Steering angle, steering rate, heading and lateral deviation over time."""
    panels = [("delta_rad", "steering angle [rad]"),
              ("steering_rate_rad_s", "steering rate [rad/s]"),
              ("psi_rad", "heading [rad]"), ("e_y_m", "lateral deviation [m]")]
    fig, axes = plt.subplots(len(panels), 1, figsize=(7.0, 7.5), sharex=True,
                             layout="constrained")
    for ax, (column, label) in zip(axes, panels):
        for method, tr in runs.items():
            if column in tr:
                ax.plot(tr["time_s"], tr[column], color=method_color(method), lw=1.5,
                        label=method)
        if appear_time_s is not None and np.isfinite(appear_time_s):
            ax.axvline(appear_time_s, color="k", ls=":", lw=1)
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8, ncols=3)
    axes[-1].set_xlabel("time [s] (dotted: obstacle appears)")
    return fig


def apf_force_figure(runs: dict[str, pd.DataFrame]) -> Figure:
    """Magnitudes of the APF's attractive and repulsive forces at the vehicle over time."""
    fig, axes = plt.subplots(2, 1, figsize=(7.0, 4.5), sharex=True, layout="constrained")
    for method, tr in runs.items():
        if "apf_rep_norm" not in tr:
            continue
        att = np.hypot(tr["apf_att_x"], tr["apf_att_y"])
        axes[0].plot(tr["time_s"], tr["apf_rep_norm"], color=method_color(method), label=method)
        axes[1].plot(tr["time_s"], att, color=method_color(method), label=method)
    axes[0].set_ylabel("|F_rep| at vehicle")
    axes[1].set_ylabel("|F_att| at vehicle")
    axes[1].set_xlabel("time [s]")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8)
    return fig


def save_figure(fig: Figure, out_dir: Path, stem: str) -> dict[str, Path]:
    """Write ``stem.svg`` and ``stem.png`` into ``out_dir`` and close the figure."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {"svg": out_dir / f"{stem}.svg", "png": out_dir / f"{stem}.png"}
    engine = fig.get_layout_engine()
    if engine is not None:
        # the layout solved once for both files (each savefig would solve it again: it was
        # 40 % of the report's time), then frozen
        engine.execute(fig)
        fig.set_layout_engine("none")
    # fixed metadata so that identical data give identical files
    fig.savefig(paths["svg"], metadata={"Date": None})
    fig.savefig(paths["png"], dpi=130, metadata={"Software": None})
    plt.close(fig)
    return paths


def claim_differences_figure(differences: dict[tuple[str, str], np.ndarray],
                             metric_names: dict[str, str],
                             intervals: dict[tuple[str, str], tuple[float, float, float]]
                             ) -> Figure:
    """Per-scenario paired differences (improved - comparison, < 0 is better): one row per
    comparison, one panel per claim, with the estimate and its interval.

    Keys of ``differences`` and ``intervals`` are ``(claim_id, comparison)``; intervals are
    ``(low, high, estimate)``.
    """
    keys = list(differences)
    claims = list(dict.fromkeys(claim for claim, _ in keys))
    comparisons = list(dict.fromkeys(comparison for _, comparison in keys))
    fig, axes = plt.subplots(len(comparisons), len(claims),
                             figsize=(1.9 * len(claims) + 0.8, 2.9 * len(comparisons)),
                             layout="constrained", squeeze=False)
    rng = np.random.default_rng(0)  # jitter only
    for r, comparison in enumerate(comparisons):
        for c, claim in enumerate(claims):
            ax = axes[r][c]
            key = (claim, comparison)
            if key not in differences:
                ax.set_visible(False)
                continue
            d = np.asarray(differences[key], dtype=float)
            span = max(np.max(np.abs(d)) if d.size else 1.0, 1e-9) * 1.15
            ax.scatter(rng.uniform(-0.25, 0.25, d.size), d, s=7, alpha=0.4, color="#1f77b4")
            ax.axhline(0.0, color="k", lw=0.8)
            low, high, estimate = intervals[key]
            if np.isfinite(estimate):
                ax.errorbar([0.45], [estimate],
                            yerr=[[max(estimate - low, 0.0)], [max(high - estimate, 0.0)]],
                            fmt="D", color="#d62728", capsize=4, label="estimate, 95% CI")
            ax.set_ylim(-span, span)
            ax.set_title(f"{claim} vs {comparison}", fontsize=8)
            if r == len(comparisons) - 1:
                ax.set_xlabel(metric_names.get(claim, claim), fontsize=7)
            ax.set_xticks([])
            ax.set_xlim(-0.6, 0.7)
            ax.tick_params(axis="y", labelsize=7)
            ax.grid(True, axis="y", alpha=0.3)
        axes[r][0].set_ylabel(f"improved - {comparison}\n(< 0: improved better)", fontsize=8)
    axes[0][0].legend(fontsize=7, loc="lower left")
    return fig


def family_distribution_figure(tables: dict[str, pd.DataFrame], metrics: list[str]) -> Figure:
    """Box plots of metrics per method over the scenario family."""
    fig, axes = plt.subplots(1, len(metrics), figsize=(2.6 * len(metrics), 3.8),
                             layout="constrained", squeeze=False)
    methods = list(tables)
    for ax, metric in zip(axes[0], metrics):
        data = [tables[m][metric].astype(float).dropna().to_numpy() for m in methods]
        parts = ax.boxplot(data, tick_labels=methods, showfliers=True, patch_artist=True,
                           flierprops={"markersize": 2})
        for patch, method in zip(parts["boxes"], methods):
            patch.set_facecolor(method_color(method))
            patch.set_alpha(0.5)
        ax.set_title(metric, fontsize=8)
        ax.tick_params(axis="x", labelrotation=60, labelsize=7)
        ax.tick_params(axis="y", labelsize=7)
        ax.grid(True, axis="y", alpha=0.3)
    return fig


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
        for ax, metric in zip(axes[0], metrics):
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
            for ax, metric in zip(axes[0], metrics):
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


def ablation_forest_figure(effects: pd.DataFrame) -> Figure:
    """Forest plot: paired effect versus baseline (95 % CI) of each configuration, one
    panel per claim; left of zero is the paper's claimed direction."""
    claims = list(dict.fromkeys(effects["claim"]))
    configs = list(dict.fromkeys(effects["configuration"]))
    fig, axes = plt.subplots(1, len(claims), figsize=(2.6 * len(claims), 0.32 * len(configs) + 1.6),
                             layout="constrained", sharey=True, squeeze=False)
    y = np.arange(len(configs))[::-1]
    colors = ["#1f77b4" if c == "improved" else "#2ca02c" if c.startswith("baseline+")
              else "#ff7f0e" for c in configs]
    for ax, claim in zip(axes[0], claims):
        part = effects[effects["claim"] == claim].set_index("configuration").reindex(configs)
        med = part["effect"].to_numpy(float)
        low, high = part["ci_low"].to_numpy(float), part["ci_high"].to_numpy(float)
        finite = np.concatenate([v[np.isfinite(v)] for v in (med, low, high)])
        span = max(np.max(np.abs(finite)) if finite.size else 1.0, 1e-9) * 1.1
        med, low, high = (np.clip(v, -span, span) for v in (med, low, high))
        for yi, m, lo, hi, color in zip(y, med, low, high, colors):
            ax.plot([lo, hi], [yi, yi], color=color, lw=2)
            ax.plot([m], [yi], "o", color=color, ms=5)
        ax.axvline(0.0, color="k", lw=0.8)
        ax.set_title(f"{claim}: {part['metric'].iloc[0]}", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, axis="x", alpha=0.3)
    axes[0][0].set_yticks(y, configs, fontsize=7)
    fig.supxlabel("median paired effect vs baseline (95 % CI); < 0 = the claimed improvement",
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
    for ax, (a, b) in zip(axes[0], pairs):
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
