"""Figures of runs: paths (the Figure 2/3 analogues), overlays, time series, APF forces."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")  # files only, no display

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.patches import Circle

from pipeline.reporting.figures.colors import EXTRA_COLORS, method_color  # noqa: F401


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
    limits, panel_h = _panel_limits(frames, goal_xy_m, limits, width_in)
    fig, axes = plt.subplots(len(methods), 1, figsize=(width_in, panel_h * len(methods) + 0.9),
                             sharex=True, sharey=True, layout="constrained", squeeze=False)
    cmap = _time_colormap()
    times = snapshot_times(frames[0], appear_time_s)
    norm = matplotlib.colors.Normalize(times[0], times[-1] if times[-1] > times[0]
                                       else times[0] + 1.0)
    for ax, method, tr in zip(axes[:, 0], methods, frames, strict=True):
        t = tr["time_s"].to_numpy(float)
        ax.plot(tr["X_m"], tr["Y_m"], color=method_color(method), lw=2, zorder=3)
        _draw_snapshots(ax, tr, t, times, cmap, norm, vehicle_radius_m)
        _mark_appearances(ax, tr, t)
        _mark_closest_approach(ax, tr, vehicle_radius_m)
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


def _panel_limits(frames: list[pd.DataFrame], goal_xy_m: tuple[float, float],
                  limits: tuple | None, width_in: float) -> tuple[tuple, float]:
    """The panels' shared limits (the data's by default) on equal scales, and a panel's
    height (in)."""
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
    return limits, panel_h


def _draw_snapshots(ax, tr: pd.DataFrame, t: np.ndarray, times: np.ndarray, cmap, norm,
                    vehicle_radius_m: float) -> None:
    """The vehicle's footprint and the visible obstacles at each snapshot time, coloured by
    time."""
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


def _mark_appearances(ax, tr: pd.DataFrame, t: np.ndarray) -> None:
    """A cross where each obstacle appears; the first one's time beside it."""
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


def _mark_closest_approach(ax, tr: pd.DataFrame, vehicle_radius_m: float) -> None:
    """The closest approach: a segment from the vehicle to the obstacle, its clearance and
    time."""
    near = closest_approach(tr, vehicle_radius_m)
    if near is not None:
        (vx, vy), (ox, oy) = near["vehicle"], near["obstacle"]
        ax.plot([vx, ox], [vy, oy], color="k", lw=1.0, zorder=6)
        ax.annotate(f"closest {near['clearance_m']:.2f} m at {near['time_s']:.1f} s",
                    (vx, vy), xytext=(6, -12), textcoords="offset points", fontsize=7,
                    gid="label-closest", bbox=LABEL_BOX, zorder=7)


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
    for ax, (column, label) in zip(axes[:, 0], panels, strict=True):
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
