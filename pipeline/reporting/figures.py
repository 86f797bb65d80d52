"""Figures stage: matplotlib figures from logged runs (never shown on screen).

Each ``*_figure`` function takes run data and returns a ``matplotlib.figure.Figure``;
:func:`save_figure` writes it as SVG and PNG. Nothing here simulates.
"""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only, no display

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Circle  # noqa: E402

METHOD_COLORS = {"baseline": "#d62728", "improved": "#1f77b4", "velocity_aware": "#2ca02c",
                 "mpc_no_apf": "#9467bd", "apf_pursuit": "#8c564b",
                 "baseline_matched": "#ff7f0e"}
#: colours for methods without their own (a user's method, extra runs): stable by name
EXTRA_COLORS = ("#17becf", "#bcbd22", "#e377c2", "#7f7f7f", "#393b79", "#8c6d31")


def method_color(method: str) -> str:
    """A method's colour; any other name gets one of :data:`EXTRA_COLORS`, the same on every
    call (a stable hash of the name, not Python's salted one)."""
    if method in METHOD_COLORS:
        return METHOD_COLORS[method]
    import zlib

    return EXTRA_COLORS[zlib.crc32(method.encode()) % len(EXTRA_COLORS)]


def _obstacle_indices(trajectory: pd.DataFrame) -> list[int]:
    j, out = 0, []
    while f"obs{j}_x_m" in trajectory.columns:
        out.append(j)
        j += 1
    return out


#: line styles that keep every method visible where paths coincide (with the colours)
LABEL_BOX = {"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.85}
LINE_STYLES = ("-", "--", "-.", ":", (0, (5, 1, 1, 1)), (0, (1, 1)))


def _time_colormap():
    return plt.get_cmap("viridis")


def snapshot_times(trajectory: pd.DataFrame, appear_time_s: float | None,
                   n: int = 7, span_s: float = 4.5) -> np.ndarray:
    """Instants at which vehicle and obstacles are drawn: ``n`` evenly spaced from the
    appearance (or the start) over ``span_s`` seconds, within the run."""
    t = trajectory["time_s"].to_numpy(float)
    first = float(appear_time_s) if appear_time_s is not None and np.isfinite(appear_time_s) \
        else float(t[0])
    last = min(first + span_s, float(t[-1]))
    return np.linspace(first, last, n) if last > first else np.array([first])


def closest_approach(trajectory: pd.DataFrame, vehicle_radius_m: float) -> dict | None:
    """Where the footprint came closest to a visible obstacle: time, vehicle and obstacle
    centres, clearance (centre distance minus both radii)."""
    best = None
    x, y = trajectory["X_m"].to_numpy(float), trajectory["Y_m"].to_numpy(float)
    for j in _obstacle_indices(trajectory):
        visible = trajectory[f"obs{j}_visible"].astype(bool).to_numpy()
        if not visible.any():
            continue
        ox, oy = trajectory[f"obs{j}_x_m"].to_numpy(float), trajectory[f"obs{j}_y_m"].to_numpy(float)
        clearance = np.hypot(x - ox, y - oy) - trajectory[f"obs{j}_radius_m"].to_numpy(float) \
            - vehicle_radius_m
        clearance = np.where(visible, clearance, np.inf)
        k = int(np.argmin(clearance))
        if best is None or clearance[k] < best["clearance_m"]:
            best = {"time_s": float(trajectory["time_s"].iloc[k]), "vehicle": (x[k], y[k]),
                    "obstacle": (ox[k], oy[k]), "clearance_m": float(clearance[k]), "j": j}
    return best


def paths_figure(runs: dict[str, pd.DataFrame], goal_xy_m: tuple[float, float],
                 vehicle_radius_m: float, appear_time_s: float | None,
                 limits: tuple | None = None, titles: dict[str, str] | None = None,
                 width_in: float = 7.0) -> Figure:
    """Figure 2/3 analogues as small multiples on shared limits (one panel per method, top
    to bottom): the path; the vehicle's footprint and every visible obstacle at the same
    instants in the same colour (time colour bar); where each obstacle appears (x and the time);
    the closest approach (a segment, its clearance and time).

    Parameters
    ----------
    runs : dict of method -> trajectory
    goal_xy_m : tuple
    vehicle_radius_m : float
    appear_time_s : float or None
        The threatening obstacle's appearance (the first snapshot).
    limits : tuple, optional
        ``(xmin, xmax, ymin, ymax)``; by default the data's, shared by all panels.
    titles : dict, optional
        Panel titles by method.
    """
    methods = list(runs)
    frames = list(runs.values())
    if limits is None:
        xs = np.concatenate([f["X_m"].to_numpy(float) for f in frames] + [[goal_xy_m[0]]])
        ys = np.concatenate([f["Y_m"].to_numpy(float) for f in frames] + [[goal_xy_m[1]]])
        limits = (np.nanmin(xs) - 1.5, np.nanmax(xs) + 1.5, np.nanmin(ys) - 2.0,
                  np.nanmax(ys) + 2.0)
    x_span, y_span = limits[1] - limits[0], limits[3] - limits[2]
    # equal scales (circles stay circles); a flat path gets a taller window, never a
    # stretched one: panels at least 1.7 in tall, the lateral limits widened about the data
    panel_h = max(width_in * 0.84 * y_span / x_span, 1.7)
    y_span_shown = panel_h * x_span / (width_in * 0.84)
    centre = 0.5 * (limits[2] + limits[3])
    limits = (limits[0], limits[1], centre - 0.5 * y_span_shown, centre + 0.5 * y_span_shown)
    fig, axes = plt.subplots(len(methods), 1, figsize=(width_in, panel_h * len(methods) + 0.9),
                             sharex=True, sharey=True, layout="constrained", squeeze=False)
    cmap = _time_colormap()
    times = snapshot_times(frames[0], appear_time_s)
    norm = matplotlib.colors.Normalize(times[0], times[-1] if times[-1] > times[0]
                                       else times[0] + 1.0)
    for ax, method, tr in zip(axes[:, 0], methods, frames):
        t = tr["time_s"].to_numpy(float)
        ax.plot(tr["X_m"], tr["Y_m"], color=method_color(method), lw=2, zorder=3)
        for ts in times:
            k = int(np.argmin(np.abs(t - ts)))
            if abs(t[k] - ts) > 0.051:
                continue
            colour = cmap(norm(t[k]))
            ax.add_patch(Circle((tr["X_m"].iloc[k], tr["Y_m"].iloc[k]), vehicle_radius_m,
                                fill=False, lw=1.2, color=colour, zorder=4))
            for j in _obstacle_indices(tr):
                if bool(tr[f"obs{j}_visible"].iloc[k]):
                    ax.add_patch(Circle((tr[f"obs{j}_x_m"].iloc[k], tr[f"obs{j}_y_m"].iloc[k]),
                                        tr[f"obs{j}_radius_m"].iloc[k], color=colour,
                                        alpha=0.55, lw=0, zorder=2))
        for j in _obstacle_indices(tr):
            visible = tr[f"obs{j}_visible"].astype(bool).to_numpy()
            if visible.any():
                k = int(np.argmax(visible))
                ax.plot(tr[f"obs{j}_x_m"].iloc[k], tr[f"obs{j}_y_m"].iloc[k], "kx", ms=6,
                        zorder=5)
                if j == 0:
                    ax.annotate(f"appears {t[k]:.1f} s", (tr[f"obs{j}_x_m"].iloc[k],
                                                         tr[f"obs{j}_y_m"].iloc[k]),
                                xytext=(6, 6), textcoords="offset points", fontsize=7,
                                gid="label-appear", bbox=LABEL_BOX, zorder=7)
        near = closest_approach(tr, vehicle_radius_m)
        if near is not None:
            (vx, vy), (ox, oy) = near["vehicle"], near["obstacle"]
            ax.plot([vx, ox], [vy, oy], color="k", lw=1.0, zorder=6)
            ax.annotate(f"closest {near['clearance_m']:.2f} m at {near['time_s']:.1f} s",
                        (vx, vy), xytext=(6, -12), textcoords="offset points", fontsize=7,
                        gid="label-closest", bbox=LABEL_BOX, zorder=7)
        ax.plot(tr["X_m"].iloc[0], tr["Y_m"].iloc[0], "ko", ms=4)
        ax.plot(*goal_xy_m, marker="*", color="gold", mec="k", ms=12, ls="none")
        ax.axhline(goal_xy_m[1], color="k", lw=0.5, ls="--")
        ax.set_xlim(limits[0], limits[1])
        ax.set_ylim(limits[2], limits[3])
        ax.set_aspect("equal", adjustable="box")
        ax.set_title((titles or {}).get(method, method), fontsize=9, loc="left")
        ax.set_ylabel("Y [m]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("X [m]   (dot: start, star: goal, x: where an obstacle appears)",
                           fontsize=8)
    bar = fig.colorbar(matplotlib.cm.ScalarMappable(norm=norm, cmap=cmap), ax=axes[:, 0],
                       shrink=0.9, pad=0.01)
    bar.set_label("time [s]: footprint and obstacles", fontsize=8)
    bar.ax.tick_params(labelsize=7)
    return fig


def overlay_figure(runs: dict[str, pd.DataFrame], goal_xy_m: tuple[float, float],
                   width_in: float = 7.0) -> Figure:
    """All methods' paths on one axes, each with its own colour and line style (so that
    coinciding paths stay visible), the obstacles' tracks while visible, the legend outside."""
    fig, ax = plt.subplots(figsize=(width_in, 3.4), layout="constrained")
    for n, (method, tr) in enumerate(runs.items()):
        ax.plot(tr["X_m"], tr["Y_m"], color=method_color(method), lw=2.4 - 0.25 * min(n, 5),
                ls=LINE_STYLES[n % len(LINE_STYLES)], label=method, zorder=3 + n)
    first = next(iter(runs.values()))
    for j in _obstacle_indices(first):
        vis = first[f"obs{j}_visible"].astype(bool)
        ax.plot(first.loc[vis, f"obs{j}_x_m"], first.loc[vis, f"obs{j}_y_m"], color="0.4",
                lw=6, alpha=0.35, solid_capstyle="round", label="obstacle track" if j == 0 else None)
    ax.plot(*goal_xy_m, marker="*", color="gold", mec="k", ms=12, ls="none", label="goal")
    ax.set_xlabel("X [m]")
    ax.set_ylabel("Y [m]")
    ax.grid(True, alpha=0.3)
    fig.legend(loc="outside right upper", fontsize=8, frameon=False)
    return fig


def avoidance_window(runs: dict[str, pd.DataFrame], appear_time_s: float | None
                     ) -> tuple[float, float] | None:
    """From the appearance until the last method's vehicle has passed the first obstacle
    (its along-track position beyond the obstacle's), within the runs."""
    if appear_time_s is None or not np.isfinite(appear_time_s):
        return None
    end = appear_time_s
    for tr in runs.values():
        if "obs0_x_m" not in tr:
            continue
        t = tr["time_s"].to_numpy(float)
        passed = (tr["X_m"].to_numpy(float) > tr["obs0_x_m"].to_numpy(float)
                  + tr["obs0_radius_m"].to_numpy(float)) & (t >= appear_time_s)
        end = max(end, float(t[np.argmax(passed)]) if passed.any() else float(t[-1]))
    return (float(appear_time_s), end) if end > appear_time_s else None


def timeseries_figure(runs: dict[str, pd.DataFrame], appear_time_s: float | None,
                      width_in: float = 7.0) -> Figure:
    """Steering angle, steering rate, heading and lateral deviation over time; the avoidance
    window (appearance until every vehicle has passed the obstacle) shaded; legend above."""
    panels = [("delta_rad", "steering angle [rad]"),
              ("steering_rate_rad_s", "steering rate [rad/s]"),
              ("psi_rad", "heading [rad]"), ("e_y_m", "lateral deviation [m]")]
    panels = [p for p in panels if any(p[0] in tr for tr in runs.values())]
    fig, axes = plt.subplots(len(panels), 1, figsize=(width_in, 1.7 * len(panels) + 0.8),
                             sharex=True, layout="constrained", squeeze=False)
    window = avoidance_window(runs, appear_time_s)
    for ax, (column, label) in zip(axes[:, 0], panels):
        for n, (method, tr) in enumerate(runs.items()):
            if column in tr:
                ax.plot(tr["time_s"], tr[column], color=method_color(method),
                        lw=1.8 - 0.2 * min(n, 5), ls=LINE_STYLES[n % len(LINE_STYLES)],
                        label=method if ax is axes[0, 0] else None)
        if window is not None:
            ax.axvspan(*window, color="0.85", zorder=0,
                       label="avoidance window" if ax is axes[0, 0] else None)
        ax.set_ylabel(label, fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("time [s] (shaded: from the obstacle's appearance until every "
                           "vehicle has passed it)", fontsize=8)
    fig.legend(loc="outside upper center", ncols=min(len(runs) + 1, 4), fontsize=8,
               frameon=False)
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


def figure_paths(out_dir: Path, stem: str, style=None) -> dict[str, Path]:
    """Where :func:`save_figure` writes ``stem``: ``"png"`` and ``"svg"`` (the vector file,
    whatever ``style``'s vector format)."""
    vector = getattr(style, "vector_format", "svg")
    return {"svg": Path(out_dir) / f"{stem}.{vector}", "png": Path(out_dir) / f"{stem}.png"}


def save_figure(fig: Figure, out_dir: Path, stem: str, style=None) -> dict[str, Path]:
    """Write ``stem.<vector format>`` and ``stem.png`` into ``out_dir`` and close the figure.

    ``style`` (a :class:`pipeline.reporting.style.FigureStyle`, or anything with its
    ``width_in``, ``dpi`` and ``vector_format``) sets the width, the PNG's resolution and the
    vector format; by default each figure as designed, 130 dpi, SVG. The returned mapping has
    ``"png"`` and ``"svg"`` (the vector file, whatever its format)."""
    width_in = getattr(style, "width_in", None)
    dpi = getattr(style, "dpi", 130)
    vector = getattr(style, "vector_format", "svg")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = figure_paths(out_dir, stem, style)
    if width_in is not None:
        width, height = fig.get_size_inches()
        fig.set_size_inches(width_in, height * width_in / width)
    engine = fig.get_layout_engine()
    if engine is not None:
        # the layout solved once for both files (each savefig would solve it again: it was
        # 40 % of the report's time), then frozen. No engine at all afterwards: with any engine
        # left (even the "none" placeholder) savefig draws the figure once more, unrendered,
        # before drawing it for the file
        engine.execute(fig)
        with matplotlib.rc_context({"figure.autolayout": False,
                                    "figure.constrained_layout.use": False}):
            fig.set_layout_engine(None)
    # fixed metadata so that identical data give identical files
    fig.savefig(paths["svg"], metadata={"CreationDate": None} if vector == "pdf"
                else {"Date": None})
    fig.savefig(paths["png"], dpi=dpi, metadata={"Software": None})
    plt.close(fig)
    return paths


class FigureWriter:
    """Writes figures like :func:`save_figure`, each in a forked child process when it can, so
    that building and drawing them (most of a report's time) runs beside the caller's work.

    :meth:`save` takes a figure, or a function of no arguments that builds one (then the child
    builds it too), and returns the paths at once; the files exist after :meth:`close` (or the
    end of a ``with`` block). A child inherits the figure, its data and the matplotlib settings
    in force by ``fork`` (nothing is pickled) and exits with the files written. A child that
    fails leaves its figure to be written here, in this process, at :meth:`close`
    (:attr:`written_here` counts them). With ``max_workers=1``, or where ``os.fork`` does not
    exist, every figure is written here at once.

    Parameters
    ----------
    style : FigureStyle or None
        As for :func:`save_figure`.
    max_workers : int or None
        Children at the same time; None: twice the machine's cores (the caller keeps working
        while they run, so a few more than the cores keep every core busy).
    """

    def __init__(self, style=None, max_workers: int | None = None) -> None:
        self.style = style
        self.max_workers = int(max_workers or 2 * (os.cpu_count() or 1))
        self.parallel = self.max_workers > 1 and hasattr(os, "fork")
        self.forked = 0          # children started
        self.written_here = 0    # figures written in this process (serial, or a child failed)
        self._running: list = []  # (pid, figure or builder, out_dir, stem), oldest first

    def save(self, figure, out_dir: Path, stem: str) -> dict[str, Path]:
        """Write ``figure`` (a Figure, or a function returning one) as ``stem.<vector format>``
        and ``stem.png`` under ``out_dir`` (now, or in a child); the paths as
        :func:`save_figure` returns them."""
        out_dir = Path(out_dir)
        if not self.parallel:
            self.written_here += 1
            return self._write(figure, out_dir, stem)
        import sys
        import warnings

        out_dir.mkdir(parents=True, exist_ok=True)
        while len(self._running) >= self.max_workers:
            self._reap_oldest()
        # nothing buffered may be written twice (the child leaves by os._exit, unflushed)
        sys.stdout.flush()
        sys.stderr.flush()
        with warnings.catch_warnings():
            # Python >= 3.12 warns on fork with threads; here the only other threads are the
            # BLAS library's idle workers, and the child draws one figure and exits
            warnings.simplefilter("ignore", DeprecationWarning)
            pid = os.fork()
        if pid == 0:  # the child: write the files, leave without running the parent's exit code
            code = 1
            try:
                self._write(figure, out_dir, stem)
                code = 0
            finally:
                os._exit(code)
        self.forked += 1
        if isinstance(figure, Figure):
            plt.close(figure)  # out of pyplot's registry; the object stays for a fallback
        self._running.append((pid, figure, out_dir, stem))
        return figure_paths(out_dir, stem, self.style)

    def _write(self, figure, out_dir: Path, stem: str) -> dict[str, Path]:
        return save_figure(figure if isinstance(figure, Figure) else figure(), out_dir, stem,
                           self.style)

    def _reap_oldest(self, redraw: bool = True) -> None:
        pid, figure, out_dir, stem = self._running.pop(0)
        _, status = os.waitpid(pid, 0)
        if redraw and not (os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0):
            # the child failed (or was killed): write the figure here instead
            self.written_here += 1
            self._write(figure, out_dir, stem)

    def close(self, redraw: bool = True) -> None:
        """Wait for every child; afterwards every figure saved so far is on disk (with
        ``redraw=False``, what failed in a child is left undrawn)."""
        while self._running:
            self._reap_oldest(redraw)

    def __enter__(self) -> "FigureWriter":
        return self

    def __exit__(self, exc_type, *exc) -> None:
        # leaving on an error or a signal (Ctrl-C reaches the children too): wait for the
        # children, never redraw what they left, so that stopping stays prompt
        self.close(redraw=exc_type is None)


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
    for ax, title in zip(axes, ("controller step (APF + QP) [ms]", "Clarabel floor [ms]")):
        ax.set_xlabel("horizon N")
        ax.set_title(title, fontsize=9)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    return fig
